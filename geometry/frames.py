"""Earth frames: WGS-84 ECEF <-> geodetic, the local ENU frame, azimuth and elevation.

The constants of the WGS-84 ellipsoid (NIMA TR8350.2) live in ``oaraim.constants``.

Conventions: angles in radians unless the name says ``_deg``; heights above the ellipsoid in
metres; ECEF in metres; azimuth clockwise from geodetic north in [0, 2 pi); elevation above the
plane normal to the ellipsoid normal (geodetic up). All functions are pure JAX, batch first:
leading axes broadcast, the last axis of a position is its 3 coordinates.
"""

import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Array, Float, Real

from oaraim.constants import (
    FREE_AIR_GRADIENT_PER_S2,
    OMEGA_E_GNSS_RAD_S,
    WGS84_A_M,
    WGS84_B_M,
    WGS84_E2,
    WGS84_EP2,
    WGS84_F,
    WGS84_GAMMA_E_MPS2,
    WGS84_SOMIGLIANA_K,
)

#: fixed number of Bowring iterations in ``ecef_to_geodetic`` (jit-friendly). Bowring's
#: parametric-latitude iteration converges cubically: one step is below 1 um of height error
#: anywhere from the Earth's surface to GNSS altitudes, three leave only rounding.
_BOWRING_ITERATIONS = 3


def geodetic_to_ecef(lat_rad: Real[ArrayLike, "..."], lon_rad: Real[ArrayLike, "..."],
                     h_m: Real[ArrayLike, "..."]
                     ) -> Float[Array, "... 3"]:
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


def ecef_to_geodetic(ecef_m: Real[ArrayLike, "*batch 3"]
                     ) -> tuple[Float[Array, "*batch"], Float[Array, "*batch"],
                                Float[Array, "*batch"]]:
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


def enu_rotation(lat_rad: Real[ArrayLike, "..."], lon_rad: Real[ArrayLike, "..."]
                 ) -> Float[Array, "... 3 3"]:
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


def ecef_to_enu(ecef_m: Real[ArrayLike, "... 3"], origin_ecef_m: Real[ArrayLike, "... 3"]
                ) -> Float[Array, "... 3"]:
    """ENU coordinates (metres) of ECEF points relative to an origin, using the origin's
    geodetic latitude and longitude. ``ecef_m`` ``(..., 3)`` broadcasts against the origin."""
    origin_ecef_m = jnp.asarray(origin_ecef_m, jnp.float64)
    lat, lon, _ = ecef_to_geodetic(origin_ecef_m)
    d = jnp.asarray(ecef_m, jnp.float64) - origin_ecef_m
    return jnp.einsum("...ij,...j->...i", enu_rotation(lat, lon), d)


def enu_to_ecef(enu_m: Real[ArrayLike, "... 3"], origin_ecef_m: Real[ArrayLike, "... 3"]
                ) -> Float[Array, "... 3"]:
    """Inverse of ``ecef_to_enu``: ECEF of points given in the origin's ENU frame."""
    origin_ecef_m = jnp.asarray(origin_ecef_m, jnp.float64)
    lat, lon, _ = ecef_to_geodetic(origin_ecef_m)
    r = enu_rotation(lat, lon)
    return origin_ecef_m + jnp.einsum("...ji,...j->...i", r, jnp.asarray(enu_m, jnp.float64))


def azimuth_elevation(receiver_ecef_m: Real[ArrayLike, "... 3"],
                      transmitter_ecef_m: Real[ArrayLike, "... 3"]
                      ) -> tuple[Float[Array, "..."], Float[Array, "..."],
                                 Float[Array, "..."]]:
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
    return az_el_from_rotation(r, d)


def az_el_from_rotation(r: Real[ArrayLike, "... 3 3"], d: Real[ArrayLike, "... 3"]
                        ) -> tuple[Float[Array, "..."], Float[Array, "..."],
                                 Float[Array, "..."]]:
    """Azimuth (rad, clockwise from north, [0, 2 pi)), elevation (rad) and range (m) of
    line-of-sight vectors ``d`` (..., 3, ECEF metres) given the ECEF -> ENU rotation ``r``
    (..., 3, 3) of ``enu_rotation``: for callers that already hold the rotation of the receiver
    (``azimuth_elevation`` computes it from the receiver position)."""
    e = jnp.sum(r[..., 0, :] * d, -1)
    n = jnp.sum(r[..., 1, :] * d, -1)
    u = jnp.sum(r[..., 2, :] * d, -1)
    horiz = jnp.hypot(e, n)
    az = jnp.mod(jnp.arctan2(e, n), 2.0 * jnp.pi)
    el = jnp.arctan2(u, horiz)
    return az, el, jnp.hypot(horiz, u)


def earth_rotation_correction(sat_ecef_m: Real[ArrayLike, "... 3"],
                              travel_time_s: Real[ArrayLike, "..."]
                              ) -> Float[Array, "... 3"]:
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


def normal_gravity_mps2(lat_rad: Real[ArrayLike, "..."], h_m: Real[ArrayLike, "..."] = 0.0
                        ) -> float | Float[np.ndarray, "..."]:
    """Magnitude of WGS-84 normal gravity at geodetic latitude ``lat_rad`` and a small height
    ``h_m`` above the ellipsoid, m/s^2: Somigliana's closed formula on the ellipsoid (NIMA
    TR8350.2 eq. 4-1) minus the free-air gradient times the height (the first-order term of
    eq. 4-3, ``oaraim.constants.FREE_AIR_GRADIENT_PER_S2``); within 0.3 % of the full
    eq. (4-3) height correction below 1 km.

    NumPy on the host (a float for scalar inputs, else an array broadcast over the inputs): the
    simulated drives and the replays take one value at their origin."""
    s2 = np.sin(lat_rad) ** 2
    g0 = WGS84_GAMMA_E_MPS2 * (1.0 + WGS84_SOMIGLIANA_K * s2) / np.sqrt(1.0 - WGS84_E2 * s2)
    g = g0 - FREE_AIR_GRADIENT_PER_S2 * np.asarray(h_m, np.float64)
    return float(g) if np.ndim(g) == 0 else g
