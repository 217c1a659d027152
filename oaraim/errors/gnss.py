"""The receiver-side GNSS error model of seed 004 Appendix A: the diagonals of C_int and C_acc
(variances) of a satellite's pseudorange.

    C_int(l, l) = sigma_URA,l^2 + sigma_iono,l^2 + sigma_tropo,l^2 + sigma_user,l^2
    C_acc(l, l) = sigma_URE,l^2 + sigma_iono,l^2 + sigma_tropo,l^2 + sigma_user,l^2

(variances add; the seed's missing square on sigma_user is a slip, DESIGN.md). The GNSS terms
are those of the WG-C ARAIM Airborne Algorithm Description Document (ADD v2.0/v3.0, section 2.2),
for a dual-frequency (L1/L5, E1/E5a) airborne user, so sigma_iono = 0 (Appendix A: the
ionosphere-free combination removes it). The terrestrial SOPs' model is ``errors.sop``.

Every function is replaceable: ``gnss_variances`` takes the tropospheric and user models as
arguments, and ``protection_levels`` only ever sees the resulting variance arrays.
"""

import jax.numpy as jnp

#: carrier frequencies, Hz (IS-GPS-200 section 3.3.1.1, IS-GPS-705 section 3.3.1.1);
#: Galileo E1 and E5a share them (Galileo OS SIS ICD section 2.3)
F_L1_HZ = 1575.42e6
F_L5_HZ = 1176.45e6

#: ADD convention (DESIGN.md): sigma_URE = 2/3 sigma_URA for GPS
URE_OVER_URA = 2.0 / 3.0


def sigma_tropo_m(el_rad):
    """Residual tropospheric error after the MOPS model, metres (RTCA DO-229, App. A.4.2.4;
    ADD section 2.2): 0.12 m * 1.001 / sqrt(0.002001 + sin^2 el)."""
    return 0.12 * 1.001 / jnp.sqrt(0.002001 + jnp.sin(el_rad) ** 2)


def iono_free_factor(f1_hz=F_L1_HZ, f2_hz=F_L5_HZ):
    """Noise amplification of the ionosphere-free combination, sqrt((f1^4 + f2^4)/(f1^2-f2^2)^2)
    (ADD section 2.2; 2.588 for L1/L5)."""
    return ((f1_hz**4 + f2_hz**4) / (f1_hz**2 - f2_hz**2) ** 2) ** 0.5


def sigma_multipath_m(el_rad):
    """Airborne multipath, metres (ADD section 2.2; RTCA DO-253): 0.13 + 0.53 exp(-el/10 deg)."""
    return 0.13 + 0.53 * jnp.exp(-jnp.rad2deg(el_rad) / 10.0)


def sigma_noise_m(el_rad):
    """Airborne receiver noise, metres (ADD section 2.2, GPS L1 curve):
    0.15 + 0.43 exp(-el/6.9 deg)."""
    return 0.15 + 0.43 * jnp.exp(-jnp.rad2deg(el_rad) / 6.9)


def sigma_user_airborne_m(el_rad, f1_hz=F_L1_HZ, f2_hz=F_L5_HZ):
    """Dual-frequency airborne code noise and multipath, metres (ADD section 2.2):
    iono_free_factor * sqrt(sigma_MP^2 + sigma_noise^2). The ADD gives Galileo its own noise
    table; we use the GPS curve for both (documented simplification; pass your own model)."""
    return iono_free_factor(f1_hz, f2_hz) * jnp.sqrt(
        sigma_multipath_m(el_rad) ** 2 + sigma_noise_m(el_rad) ** 2)


def gnss_variances(el_rad, sigma_ura_m=1.0, sigma_ure_m=None, sigma_iono_m=0.0,
                   tropo_model=sigma_tropo_m, user_model=sigma_user_airborne_m):
    """(var_int_m2, var_acc_m2) of GNSS sources at elevation ``el_rad`` (seed 004 App. A).

    Args:
      el_rad: elevations, radians, (..., L).
      sigma_ura_m: URA for integrity (Table I: 1 m for GPS).
      sigma_ure_m: URE for accuracy; default 2/3 sigma_URA (ADD convention, DESIGN.md).
      sigma_iono_m: residual ionosphere; 0 for dual-frequency users (App. A).
      tropo_model, user_model: functions of elevation returning standard deviations in metres.
    """
    el_rad = jnp.asarray(el_rad, jnp.float64)
    if sigma_ure_m is None:
        sigma_ure_m = URE_OVER_URA * jnp.asarray(sigma_ura_m, jnp.float64)
    common = sigma_iono_m**2 + tropo_model(el_rad) ** 2 + user_model(el_rad) ** 2
    return sigma_ura_m**2 + common, sigma_ure_m**2 + common


def sigma_user_ed259a_m(el_rad):
    """Dual-frequency airborne error of EUROCAE ED-259A (DFMC SBAS MOPS), metres, as MAAST for
    ARAIM 2 uses it (``af_cnmp_259a`` with the dual-frequency residual ionosphere of
    ``usrprocess_araim``), el in degrees inside: sqrt(0.4^2 + (0.34 + 0.40 exp(-el/14))^2 +
    (40 / (261 + el^2) + 0.018)^2). Pass it as ``gnss_variances(..., user_model=...)``; below
    about 35 deg it is smaller than the ADD curve (``sigma_user_airborne_m``: 0.68 against
    1.06 m at 10 deg, 0.75 against 1.49 m at 5 deg), above it up to 2 % larger."""
    el_deg = jnp.rad2deg(el_rad)
    return jnp.sqrt(0.4**2 + (0.34 + 0.40 * jnp.exp(-el_deg / 14.0)) ** 2
                    + (40.0 / (261.0 + el_deg**2) + 0.018) ** 2)


#: the airborne user models by name (``availability-map``'s ``airborne_model``)
AIRBORNE_MODELS = {"add": sigma_user_airborne_m, "ed259a": sigma_user_ed259a_m}
