"""Earth frames: WGS-84 ECEF <-> geodetic, the local ENU frame, azimuth and elevation.

Constants of the WGS-84 ellipsoid from NIMA TR8350.2, "Department of Defense World Geodetic
System 1984", 3rd edition (2000), Table 3.1 (defining parameters) and Table 3.3 (derived).

Conventions: angles in radians unless the name says ``_deg``; heights above the ellipsoid in
metres; ECEF in metres; azimuth clockwise from geodetic north in [0, 2 pi); elevation above the
plane normal to the ellipsoid normal (geodetic up). All functions are pure JAX, batch first:
leading axes broadcast, the last axis of a position is its 3 coordinates.
"""

import jax.numpy as jnp

#: WGS-84 semi-major axis a, metres (NIMA TR8350.2 Table 3.1)
WGS84_A_M = 6378137.0
#: WGS-84 flattening f = 1 / 298.257223563 (NIMA TR8350.2 Table 3.1)
WGS84_F = 1.0 / 298.257223563
#: WGS-84 angular velocity of the Earth, rad/s (NIMA TR8350.2 Table 3.1)
WGS84_OMEGA_E_RAD_S = 7.292115e-5
#: Earth rotation rate of the GPS and Galileo broadcast models, rad/s (IS-GPS-200 Table 20-IV;
#: Galileo OS SIS ICD Issue 2.0 Table 59): the value the ephemeris user algorithm must use
OMEGA_E_GNSS_RAD_S = 7.2921151467e-5
#: WGS-84 GM including the atmosphere, m^3/s^2 (NIMA TR8350.2 Table 3.1). The GPS broadcast
#: model uses IS-GPS-200's 3.986005e14 instead (geometry.ephemeris).
WGS84_GM_M3_S2 = 3.986004418e14
#: first eccentricity squared e^2 = f (2 - f) (NIMA TR8350.2 Table 3.3: 6.69437999014e-3)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
#: semi-minor axis b = a (1 - f) (NIMA TR8350.2 Table 3.3: 6356752.3142 m)
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
#: second eccentricity squared e'^2 = e^2 / (1 - e^2)
WGS84_EP2 = WGS84_E2 / (1.0 - WGS84_E2)
#: speed of light in vacuum, m/s (IS-GPS-200 20.3.4.3; exact by definition)
C_M_S = 299792458.0

#: fixed number of Bowring iterations in ``ecef_to_geodetic`` (jit-friendly). Bowring's
#: parametric-latitude iteration converges cubically: one step is below 1 um of height error
#: anywhere from the Earth's surface to GNSS altitudes, three leave only rounding.
_BOWRING_ITERATIONS = 3


def geodetic_to_ecef(lat_rad, lon_rad, h_m):
    """ECEF position of a geodetic point (WGS-84), shape ``(..., 3)``.

    x = (N + h) cos(lat) cos(lon), y = (N + h) cos(lat) sin(lon), z = (N (1 - e^2) + h) sin(lat)
    with N = a / sqrt(1 - e^2 sin^2 lat) the prime-vertical radius of curvature.
    """
    lat_rad, lon_rad, h_m = jnp.broadcast_arrays(
        jnp.asarray(lat_rad, jnp.float64), jnp.asarray(lon_rad, jnp.float64),
        jnp.asarray(h_m, jnp.float64))
    s, c = jnp.sin(lat_rad), jnp.cos(lat_rad)
    n = WGS84_A_M / jnp.sqrt(1.0 - WGS84_E2 * s * s)
    return jnp.stack([(n + h_m) * c * jnp.cos(lon_rad), (n + h_m) * c * jnp.sin(lon_rad),
                      (n * (1.0 - WGS84_E2) + h_m) * s], axis=-1)


def ecef_to_geodetic(ecef_m):
    """Geodetic latitude, longitude (radians) and ellipsoidal height (metres) of ECEF points.

    Bowring's method with a fixed iteration count (no data-dependent loop, so it jits and vmaps):
    iterate the parametric latitude beta, tan(lat) = (z + e'^2 b sin^3 beta) /
    (p - e^2 a cos^3 beta), tan(beta) = (1 - f) tan(lat); height from the component along the
    normal, h = p cos(lat) + z sin(lat) - a^2 / N, which is accurate at every latitude (also at
    the poles, where p cos(lat) alone would fail). At the Earth's centre the result is lat = 0,
    h = -a (finite, no NaN).

    Returns:
      ``(lat_rad, lon_rad, h_m)``, each of shape ``ecef_m.shape[:-1]``.
    """
    ecef_m = jnp.asarray(ecef_m, jnp.float64)
    x, y, z = ecef_m[..., 0], ecef_m[..., 1], ecef_m[..., 2]
    p = jnp.hypot(x, y)
    lon = jnp.arctan2(y, x)
    beta = jnp.arctan2(z, (1.0 - WGS84_F) * p)
    lat = beta
    for _ in range(_BOWRING_ITERATIONS):
        sb, cb = jnp.sin(beta), jnp.cos(beta)
        lat = jnp.arctan2(z + WGS84_EP2 * WGS84_B_M * sb**3, p - WGS84_E2 * WGS84_A_M * cb**3)
        beta = jnp.arctan2((1.0 - WGS84_F) * jnp.sin(lat), jnp.cos(lat))
    s, c = jnp.sin(lat), jnp.cos(lat)
    n = WGS84_A_M / jnp.sqrt(1.0 - WGS84_E2 * s * s)
    h = p * c + z * s - WGS84_A_M**2 / n
    return lat, lon, h


def enu_rotation(lat_rad, lon_rad):
    """Rotation from ECEF to the local East-North-Up frame at (lat, lon), shape ``(..., 3, 3)``.

    Rows are the unit vectors east, north and up (the ellipsoid normal) in ECEF, so
    ``enu = R @ (ecef - ecef_0)``.
    """
    lat_rad, lon_rad = jnp.broadcast_arrays(jnp.asarray(lat_rad, jnp.float64),
                                            jnp.asarray(lon_rad, jnp.float64))
    sl, cl = jnp.sin(lat_rad), jnp.cos(lat_rad)
    so, co = jnp.sin(lon_rad), jnp.cos(lon_rad)
    zero = jnp.zeros_like(sl)
    east = jnp.stack([-so, co, zero], -1)
    north = jnp.stack([-sl * co, -sl * so, cl], -1)
    up = jnp.stack([cl * co, cl * so, sl], -1)
    return jnp.stack([east, north, up], -2)


def ecef_to_enu(ecef_m, origin_ecef_m):
    """ENU coordinates (metres) of ECEF points relative to an origin, using the origin's
    geodetic latitude and longitude. ``ecef_m`` ``(..., 3)`` broadcasts against the origin."""
    origin_ecef_m = jnp.asarray(origin_ecef_m, jnp.float64)
    lat, lon, _ = ecef_to_geodetic(origin_ecef_m)
    d = jnp.asarray(ecef_m, jnp.float64) - origin_ecef_m
    return jnp.einsum("...ij,...j->...i", enu_rotation(lat, lon), d)


def enu_to_ecef(enu_m, origin_ecef_m):
    """Inverse of ``ecef_to_enu``: ECEF of points given in the origin's ENU frame."""
    origin_ecef_m = jnp.asarray(origin_ecef_m, jnp.float64)
    lat, lon, _ = ecef_to_geodetic(origin_ecef_m)
    r = enu_rotation(lat, lon)
    return origin_ecef_m + jnp.einsum("...ji,...j->...i", r, jnp.asarray(enu_m, jnp.float64))


def azimuth_elevation(receiver_ecef_m, transmitter_ecef_m):
    """Azimuth, elevation and range of transmitters seen from receivers.

    Args:
      receiver_ecef_m: ``(..., 3)``.
      transmitter_ecef_m: ``(..., 3)``, broadcast against the receiver (e.g. receiver
        ``(R, 1, 1, 3)`` against satellites ``(T, S, 3)``).

    Returns:
      ``(az_rad, el_rad, range_m)``: azimuth clockwise from geodetic north in [0, 2 pi),
      elevation in [-pi/2, pi/2] above the receiver's geodetic horizon, geometric range. A
      transmitter at the receiver itself gives az = el = 0 and range 0 (no NaN).
    """
    receiver_ecef_m = jnp.asarray(receiver_ecef_m, jnp.float64)
    lat, lon, _ = ecef_to_geodetic(receiver_ecef_m)
    r = enu_rotation(lat, lon)
    d = jnp.asarray(transmitter_ecef_m, jnp.float64) - receiver_ecef_m
    return _az_el_from_rotation(r, d)


def _az_el_from_rotation(r, d):
    """Az, el, range of line-of-sight vectors ``d`` (..., 3) in ECEF given ENU rotation ``r``."""
    e = jnp.sum(r[..., 0, :] * d, -1)
    n = jnp.sum(r[..., 1, :] * d, -1)
    u = jnp.sum(r[..., 2, :] * d, -1)
    horiz = jnp.hypot(e, n)
    az = jnp.mod(jnp.arctan2(e, n), 2.0 * jnp.pi)
    el = jnp.arctan2(u, horiz)
    return az, el, jnp.hypot(horiz, u)


def earth_rotation_correction(sat_ecef_m, travel_time_s):
    """Sagnac correction: a satellite position in the ECEF frame of the *reception* time.

    The ECEF frame rotates by Omega_e tau while the signal travels for tau seconds; the
    transmit-time position, expressed in the receive-time frame, is rotated about z by
    -Omega_e tau (IS-GPS-200 20.3.3.4.3.4; Omega_e of IS-GPS-200 Table 20-IV). For a geometry it
    is negligible (about 1.4 arcsec of direction); ranging (replay) needs it.
    """
    sat_ecef_m = jnp.asarray(sat_ecef_m, jnp.float64)
    a = OMEGA_E_GNSS_RAD_S * jnp.asarray(travel_time_s, jnp.float64)
    c, s = jnp.cos(a), jnp.sin(a)
    x, y, z = sat_ecef_m[..., 0], sat_ecef_m[..., 1], sat_ecef_m[..., 2]
    return jnp.stack([c * x + s * y, -s * x + c * y, z], -1)
