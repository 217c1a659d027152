"""Atmospheric delays of GNSS pseudoranges: the broadcast (Klobuchar) ionosphere and the RTCA
MOPS tropospheric model, with the residual-error sigmas of single-frequency users.

Pure JAX functions, batched over any leading axes, float64. Angles in radians, delays in metres
(positive: the signal arrives late, so the delay is *subtracted* from the pseudorange).

Ionosphere: the GPS single-frequency user algorithm of IS-GPS-200 section 20.3.3.5.2.5
(Klobuchar 1987) with the eight broadcast coefficients alpha_0..3, beta_0..3 of the navigation
message (RINEX 2 header lines ``ION ALPHA`` / ``ION BETA``; RINEX 3 ``IONOSPHERIC CORR`` GPSA /
GPSB). The algorithm works in semicircles; trigonometric functions take radians, so every
semicircle angle is multiplied by pi before cos. The delay is for L1 (the coefficients are
defined for L1); scale by (f_L1 / f)^2 for another carrier.

Troposphere: RTCA DO-229 (MOPS for WAAS airborne equipment), Appendix A.4.2.4: zenith
hydrostatic and wet delays from the latitude- and season-interpolated meteorological table
(P, T, e, beta, lambda), scaled to the receiver height, times the MOPS mapping function
1.001 / sqrt(0.002001 + sin^2 E). This is the model whose residual error the ADD and
``araim.error_models.sigma_tropo_m`` (0.12 m at zenith) describe, so the correction and its
sigma are consistent. Seed 004 section VII used the Hopfield model; both are zenith-delay-plus-
mapping models of the same class and agree to centimetres at zenith (the MOPS one needs no
surface meteorology). ``saastamoinen_zhd_m`` (Saastamoinen 1972, in the form of Davis et al.
1985, Radio Science 20(6)) is given for cross-checks.
"""

import jax.numpy as jnp

from oaraim.constants import C_M_S, STANDARD_GRAVITY_MPS2

SEMICIRCLE_RAD = jnp.pi

# --------------------------------------------------------------------------- ionosphere


def klobuchar_delay_m(t_gps_s, lat_rad, lon_rad, az_rad, el_rad, alpha, beta):
    """Klobuchar L1 ionospheric slant delay, metres (IS-GPS-200 section 20.3.3.5.2.5).

    Args:
      t_gps_s: GPS time of the measurement (receiver time), seconds; only the time of day
        enters (GPS seconds since 1980-01-06 00:00 are whole days apart from day starts).
      lat_rad, lon_rad: geodetic latitude and longitude of the user, radians.
      az_rad, el_rad: azimuth and elevation of the satellite, radians.
      alpha, beta: broadcast coefficients, last axis 4 (alpha: s, s/semicircle,
        s/semicircle^2, s/semicircle^3; beta: s, ...), as in the navigation message;
        ``alpha[..., k]`` must broadcast against the other arguments (e.g. shape (4,)).

    Returns:
      The L1 delay c T_iono in metres, broadcast over the inputs. The night-time floor is
      5 ns times the obliquity factor F.
    """
    alpha = jnp.asarray(alpha, jnp.float64)
    beta = jnp.asarray(beta, jnp.float64)
    e_sc = jnp.asarray(el_rad, jnp.float64) / SEMICIRCLE_RAD  # elevation, semicircles
    phi_u = jnp.asarray(lat_rad, jnp.float64) / SEMICIRCLE_RAD
    lam_u = jnp.asarray(lon_rad, jnp.float64) / SEMICIRCLE_RAD
    az = jnp.asarray(az_rad, jnp.float64)
    # Earth's central angle between user and ionospheric pierce point (semicircles)
    psi = 0.0137 / (e_sc + 0.11) - 0.022
    # geodetic latitude of the pierce point, clamped to +-0.416 semicircles
    phi_i = jnp.clip(phi_u + psi * jnp.cos(az), -0.416, 0.416)
    # geodetic longitude of the pierce point
    lam_i = lam_u + psi * jnp.sin(az) / jnp.cos(phi_i * SEMICIRCLE_RAD)
    # geomagnetic latitude of the pierce point
    phi_m = phi_i + 0.064 * jnp.cos((lam_i - 1.617) * SEMICIRCLE_RAD)
    # local time at the pierce point, seconds in [0, 86400)
    t = jnp.mod(4.32e4 * lam_i + jnp.asarray(t_gps_s, jnp.float64), 86400.0)
    # obliquity factor
    f = 1.0 + 16.0 * (0.53 - e_sc) ** 3
    a, b = [alpha[..., k] for k in range(4)], [beta[..., k] for k in range(4)]
    amp = jnp.maximum(a[0] + phi_m * (a[1] + phi_m * (a[2] + phi_m * a[3])), 0.0)  # seconds
    per = jnp.maximum(b[0] + phi_m * (b[1] + phi_m * (b[2] + phi_m * b[3])), 72000.0)
    x = 2.0 * jnp.pi * (t - 50400.0) / per  # phase, radians
    day = f * (5e-9 + amp * (1.0 - x**2 / 2.0 + x**4 / 24.0))
    night = f * 5e-9
    t_iono = jnp.where(jnp.abs(x) < 1.57, day, night)
    return C_M_S * t_iono


def klobuchar_geomagnetic_latitude_rad(lat_rad, lon_rad, az_rad, el_rad):
    """Geomagnetic latitude of the pierce point phi_m of the Klobuchar model, radians (for the
    vertical-delay sigma of ``sigma_iono_klobuchar_m``)."""
    e_sc = jnp.asarray(el_rad, jnp.float64) / SEMICIRCLE_RAD
    psi = 0.0137 / (e_sc + 0.11) - 0.022
    phi_i = jnp.clip(jnp.asarray(lat_rad) / SEMICIRCLE_RAD + psi * jnp.cos(az_rad), -0.416, 0.416)
    lam_i = jnp.asarray(lon_rad) / SEMICIRCLE_RAD + psi * jnp.sin(az_rad) / jnp.cos(
        phi_i * SEMICIRCLE_RAD)
    return (phi_i + 0.064 * jnp.cos((lam_i - 1.617) * SEMICIRCLE_RAD)) * SEMICIRCLE_RAD


#: mean Earth radius and ionospheric shell height of the MOPS obliquity factor, metres
#: (RTCA DO-229 Appendix A.4.4.10.4 and J.2.3: R_e = 6378.1363 km, h_I = 350 km)
IONO_RE_M = 6378136.3
IONO_SHELL_H_M = 350e3


def iono_obliquity(el_rad):
    """F_pp = [1 - (R_e cos E / (R_e + h_I))^2]^(-1/2) (RTCA DO-229 A.4.4.10.4)."""
    r = IONO_RE_M * jnp.cos(el_rad) / (IONO_RE_M + IONO_SHELL_H_M)
    return 1.0 / jnp.sqrt(1.0 - r**2)


def sigma_iono_klobuchar_m(delay_m, el_rad, geomagnetic_lat_rad):
    """Residual ionospheric error sigma after the Klobuchar correction, metres.

    RTCA DO-229 Appendix J.2.3 (GPS-only users applying the broadcast model):
    sigma^2 = max((c T_iono / 5)^2, (F_pp tau_vert)^2), tau_vert = 9 m for |phi_m| <= 20 deg,
    4.5 m for 20 < |phi_m| <= 55 deg, 6 m above 55 deg (phi_m: geomagnetic latitude of the
    pierce point).
    """
    phi_m_deg = jnp.abs(jnp.rad2deg(geomagnetic_lat_rad))
    tau_vert = jnp.where(phi_m_deg <= 20.0, 9.0, jnp.where(phi_m_deg <= 55.0, 4.5, 6.0))
    return jnp.maximum(jnp.abs(delay_m) / 5.0, iono_obliquity(el_rad) * tau_vert)


# --------------------------------------------------------------------------- troposphere

#: RTCA DO-229 Table A-2 (A.4.2.4): latitudes (deg) of the meteorological table
_MOPS_LAT_DEG = (15.0, 30.0, 45.0, 60.0, 75.0)
#: averages: pressure (mbar), temperature (K), water vapour pressure (mbar), temperature lapse
#: rate beta (K/m), water vapour lapse rate lambda (dimensionless)
_MOPS_AVG = (
    (1013.25, 1017.25, 1015.75, 1011.75, 1013.00),
    (299.65, 294.15, 283.15, 272.15, 263.65),
    (26.31, 21.79, 11.66, 6.78, 4.11),
    (6.30e-3, 6.05e-3, 5.58e-3, 5.39e-3, 4.53e-3),
    (2.77, 3.15, 2.57, 1.81, 1.55),
)
#: seasonal variations of the same five quantities
_MOPS_SEASON = (
    (0.00, -3.75, -2.25, -1.75, -0.50),
    (0.00, 7.00, 11.00, 15.00, 14.50),
    (0.00, 8.85, 7.24, 5.36, 3.39),
    (0.00e-3, 0.25e-3, 0.32e-3, 0.81e-3, 0.62e-3),
    (0.00, 0.33, 0.46, 0.74, 0.30),
)
#: refractivity constants k1 (K/mbar), k2 (K^2/mbar), dry-air gas constant Rd (J/(kg K)),
#: gravity at the atmospheric column centroid g_m and at the surface g (m/s^2): DO-229 A.4.2.4
MOPS_K1 = 77.604
MOPS_K2 = 382000.0
MOPS_RD = 287.054
MOPS_GM = 9.784
MOPS_G = STANDARD_GRAVITY_MPS2


def _mops_met(lat_rad, day_of_year):
    """(P, T, e, beta, lambda) at |latitude| and day of year, DO-229 A.4.2.4: linear in
    latitude between the table rows (constant beyond 15 / 75 deg), seasonal cosine with
    D_min = 28 (north) or 211 (south)."""
    lat_deg = jnp.abs(jnp.rad2deg(jnp.asarray(lat_rad, jnp.float64)))
    grid = jnp.asarray(_MOPS_LAT_DEG)
    d_min = jnp.where(jnp.asarray(lat_rad) >= 0, 28.0, 211.0)
    season = jnp.cos(2.0 * jnp.pi * (jnp.asarray(day_of_year, jnp.float64) - d_min) / 365.25)
    out = []
    for avg, dv in zip(_MOPS_AVG, _MOPS_SEASON, strict=True):
        a = jnp.interp(lat_deg, grid, jnp.asarray(avg))
        d = jnp.interp(lat_deg, grid, jnp.asarray(dv))
        out.append(a - d * season)
    return out


def mops_zenith_delays_m(lat_rad, height_m, day_of_year):
    """Zenith hydrostatic and wet delays at the receiver height, metres (DO-229 A.4.2.4).

    ``height_m``: height above mean sea level (an ellipsoidal height differs by the geoid
    undulation, at most ~100 m: under 3 cm of zenith delay).
    """
    p, t, e, beta, lam = _mops_met(lat_rad, day_of_year)
    z_hyd = 1e-6 * MOPS_K1 * MOPS_RD * p / MOPS_GM
    z_wet = 1e-6 * MOPS_K2 * MOPS_RD / (MOPS_GM * (lam + 1.0) - beta * MOPS_RD) * e / t
    base = jnp.maximum(1.0 - beta * jnp.asarray(height_m, jnp.float64) / t, 1e-6)
    d_hyd = base ** (MOPS_G / (MOPS_RD * beta)) * z_hyd
    d_wet = base ** ((lam + 1.0) * MOPS_G / (MOPS_RD * beta) - 1.0) * z_wet
    return d_hyd, d_wet


def mops_mapping(el_rad):
    """MOPS tropospheric mapping function 1.001 / sqrt(0.002001 + sin^2 E) (DO-229 A.4.2.4),
    valid for E >= 4 deg."""
    return 1.001 / jnp.sqrt(0.002001 + jnp.sin(el_rad) ** 2)


def tropo_delay_m(lat_rad, height_m, day_of_year, el_rad):
    """Slant tropospheric delay (d_hyd + d_wet) m(E), metres (RTCA DO-229 A.4.2.4)."""
    d_hyd, d_wet = mops_zenith_delays_m(lat_rad, height_m, day_of_year)
    return (d_hyd + d_wet) * mops_mapping(el_rad)


def saastamoinen_zhd_m(pressure_hpa, lat_rad, height_m):
    """Saastamoinen zenith hydrostatic delay, metres: 0.0022768 P / (1 - 0.00266 cos 2 phi -
    0.00028 H_km) (Saastamoinen 1972; Davis et al. 1985, Radio Science 20(6), eq. A11)."""
    return 0.0022768 * pressure_hpa / (1.0 - 0.00266 * jnp.cos(2.0 * jnp.asarray(lat_rad))
                                       - 0.00028e-3 * jnp.asarray(height_m))


def standard_pressure_hpa(height_m):
    """Pressure of the standard atmosphere (ICAO / ISO 2533 troposphere), hPa:
    1013.25 (1 - 2.25577e-5 h)^5.25588."""
    return 1013.25 * (1.0 - 2.25577e-5 * jnp.asarray(height_m, jnp.float64)) ** 5.25588
