"""The broadcast Keplerian orbit model shared by GPS and Galileo ephemerides and almanacs.

IS-GPS-200 (Rev. N) section 20.3.3.4.3, Table 20-IV ("Elements of coordinate systems"): the
user algorithm for satellite ECEF position from the 16 ephemeris parameters, with the GPS
constants below. The Galileo OS SIS ICD (Issue 2.0, section 5.1.1, Table 60) prescribes the
same algorithm with its own mu; Galileo's Omega_E equals GPS's. Almanacs (IS-GPS-200
20.3.3.5.2.3) use the same algorithm with the harmonic corrections, delta_n and IDOT set to
zero, t_oa in place of t_oe, and delta_i added to i_0 = 0.30 semicircles.

Satellite clock (IS-GPS-200 20.3.3.3.3.1; Galileo OS SIS ICD 5.1.4):
dt_sv = a_f0 + a_f1 (t - t_oc) + a_f2 (t - t_oc)^2 + dt_r with the relativistic term
dt_r = F e sqrt(A) sin(E_k). The group delays (T_GD, BGD) are left to the range model.

Everything is pure JAX and elementwise over any batch shape: the callers gather one record's
parameters per (epoch, satellite) and pass arrays of equal shape.
"""

from typing import NamedTuple

import jax.numpy as jnp

from oaraim.constants import GPS_PI, OMEGA_E_GNSS_RAD_S  # noqa: F401  (GPS_PI: kept here)

#: relativistic clock constant F = -2 sqrt(mu) / c^2, s/m^(1/2) (IS-GPS-200 20.3.3.3.3.1)
F_GPS_S_SQRT_M = -4.442807633e-10
#: the same with Galileo's mu (Galileo OS SIS ICD Issue 2.0, section 5.1.4)
F_GAL_S_SQRT_M = -4.442807309e-10
#: Newton iterations for Kepler's equation E - e sin E = M. From E_0 = M the error contracts
#: quadratically; for e <= 0.3 (the largest we accept) 8 steps reach machine precision.
KEPLER_ITERATIONS = 8


class OrbitElements(NamedTuple):
    """One broadcast record per element (arrays of one common shape), SI units and radians.

    ``toe_s`` and ``t`` are absolute GPS seconds (``readers.gpstime``), so t - t_oe needs no
    week-crossover fix; ``toe_tow_s`` is t_oe within its week, needed by the Omega term.
    """

    toe_s: object
    toe_tow_s: object
    sqrt_a: object
    e: object
    i0_rad: object
    idot_rad_s: object
    omega0_rad: object
    omegadot_rad_s: object
    omega_rad: object
    m0_rad: object
    delta_n_rad_s: object
    cuc_rad: object
    cus_rad: object
    crc_m: object
    crs_m: object
    cic_rad: object
    cis_rad: object
    mu_m3_s2: object


def eccentric_anomaly(m_rad, e):
    """Solve Kepler's equation E - e sin E = M with a fixed number of Newton steps."""
    ecc = m_rad
    for _ in range(KEPLER_ITERATIONS):
        ecc = ecc - (ecc - e * jnp.sin(ecc) - m_rad) / (1.0 - e * jnp.cos(ecc))
    return ecc


def orbit_ecef(el: OrbitElements, t_gps_s):
    """ECEF position (metres, ``(..., 3)``) and eccentric anomaly at GPS time ``t_gps_s``.

    IS-GPS-200 Table 20-IV, step by step (t_k = t - t_oe).
    """
    tk = t_gps_s - el.toe_s
    a = el.sqrt_a * el.sqrt_a
    n = jnp.sqrt(el.mu_m3_s2 / (a * a * a)) + el.delta_n_rad_s
    ecc = eccentric_anomaly(el.m0_rad + n * tk, el.e)
    se, ce = jnp.sin(ecc), jnp.cos(ecc)
    nu = jnp.arctan2(jnp.sqrt(1.0 - el.e * el.e) * se, ce - el.e)
    phi = nu + el.omega_rad
    s2, c2 = jnp.sin(2.0 * phi), jnp.cos(2.0 * phi)
    u = phi + el.cus_rad * s2 + el.cuc_rad * c2
    r = a * (1.0 - el.e * ce) + el.crs_m * s2 + el.crc_m * c2
    inc = el.i0_rad + el.cis_rad * s2 + el.cic_rad * c2 + el.idot_rad_s * tk
    x_orb, y_orb = r * jnp.cos(u), r * jnp.sin(u)
    node = (el.omega0_rad + (el.omegadot_rad_s - OMEGA_E_GNSS_RAD_S) * tk
            - OMEGA_E_GNSS_RAD_S * el.toe_tow_s)
    sn, cn, ci = jnp.sin(node), jnp.cos(node), jnp.cos(inc)
    ecef = jnp.stack([x_orb * cn - y_orb * ci * sn, x_orb * sn + y_orb * ci * cn,
                      y_orb * jnp.sin(inc)], -1)
    return ecef, ecc


def relativistic_clock_s(f_s_sqrt_m, e, sqrt_a, ecc_anomaly):
    """dt_r = F e sqrt(A) sin(E_k), seconds (IS-GPS-200 20.3.3.3.3.1)."""
    return f_s_sqrt_m * e * sqrt_a * jnp.sin(ecc_anomaly)


def clock_polynomial_s(af0_s, af1_s_s, af2_s_s2, toc_s, t_gps_s):
    """a_f0 + a_f1 (t - t_oc) + a_f2 (t - t_oc)^2, seconds (IS-GPS-200 20.3.3.3.3.1)."""
    dt = t_gps_s - toc_s
    return af0_s + af1_s_s * dt + af2_s_s2 * dt * dt
