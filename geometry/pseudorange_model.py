"""The GNSS pseudorange model of real-data replay (``studies.rinex_replay``).

Pseudorange model of one L1 code measurement (IS-GPS-200, sections cited inline)::

    P = |x(t_r) - R3(Omega_e tau) s(t_tx)| + c dt_r - c (dt_sv(t_tx) - T_GD) + I_L1 + T + e

* transmit time (IS-GPS-200 20.3.3.3.3.1): t_tx = t_r - P / c - dt_sv, with t_r the receiver
  time tag. The receiver clock error is in both t_r and P and cancels, so t_tx is GPS time
  without any receiver-position or clock estimate (iterated twice for dt_sv(t_tx));
* dt_sv: broadcast clock polynomial plus the relativistic term (``Ephemeris.sat_state``);
  single-frequency L1 users subtract T_GD (IS-GPS-200 20.3.3.3.3.2);
* s(t_tx): broadcast orbit at the transmit time, in the ECEF frame of t_tx;
* Sagnac / Earth rotation during the transit (IS-GPS-200 20.3.3.4.3.4): the transmit-time
  position is rotated into the frame of the reception time by -Omega_e tau, with the travel
  time tau = |x - R3 s| / c iterated from the receiver position estimate;
* I_L1: Klobuchar (``errors.atmosphere.klobuchar_delay_m``) from the navigation header's
  alpha / beta; T: RTCA MOPS troposphere (``errors.atmosphere.tropo_delay_m``).

The receiver-position-dependent parts (Sagnac, elevation, atmosphere) are pure functions of a
position estimate (``receiver_terms``); the caller iterates them with its solver
(``studies.rinex_replay.gnss_replay_inputs``).
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.constants import C_M_S
from oaraim.errors import atmosphere
from oaraim.geometry.frames import (
    az_el_from_rotation,
    earth_rotation_correction,
    ecef_to_geodetic,
    enu_rotation,
)
from oaraim.readers import (  # noqa: F401  (the navigation extras moved there; kept importable)
    NavigationExtras,
    gpstime,
    navigation_extras,
    tgd_at,
)

# --------------------------------------------------------------------------- pseudorange model


class SatellitesAtTransmit(NamedTuple):
    """Broadcast satellite states at the transmit time of each observation (T epochs, S
    satellites)."""

    t_tx_s: np.ndarray  # (T, S) transmit time, GPS seconds
    ecef_tx_m: np.ndarray  # (T, S, 3) broadcast position at t_tx in the ECEF frame of t_tx
    clock_s: np.ndarray  # (T, S) dt_sv(t_tx): polynomial + relativistic (without T_GD)
    tgd_s: np.ndarray  # (T, S)
    valid: np.ndarray  # (T, S) observed, ephemeris available and healthy
    age_s: np.ndarray  # (T, S) t_tx - t_oe of the record used


def satellites_at_transmit(ephemeris, t_rx_s, pseudorange_m, valid, sv, tgd_s,
                           n_iter=2) -> SatellitesAtTransmit:
    """Transmit times, satellite positions and clocks for pseudoranges (T, S) (module text).

    ``ephemeris``: ``geometry.load_navigation(...)``; ``t_rx_s`` (T,) receiver time tags;
    ``sv`` (S,) ids; ``tgd_s`` (T, S). Satellites absent from the navigation file are not
    valid. Every returned array is finite (0 where not valid).
    """
    t_rx = np.asarray(t_rx_s, np.float64)
    pr = np.asarray(pseudorange_m, np.float64)
    valid = np.asarray(valid, bool).copy()
    n_t, n_s = pr.shape
    t_sv = t_rx[:, None] - np.where(valid, pr, 0.0) / C_M_S  # satellite-clock transmit time
    ecef = np.zeros((n_t, n_s, 3))
    clock = np.zeros((n_t, n_s))
    age = np.zeros((n_t, n_s))
    known = set(str(p) for p in ephemeris.prns)
    t_tx = t_sv.copy()
    for j, s in enumerate(sv):
        if str(s) not in known:
            valid[:, j] = False
            continue
        tt = t_sv[:, j]
        for _ in range(n_iter):  # t = t_sv - dt_sv(t) (IS-GPS-200 20.3.3.3.3.1)
            st = ephemeris.sat_state(tt, prns=[str(s)])
            tt = t_sv[:, j] - np.asarray(st.clock_s)[:, 0]
        st = ephemeris.sat_state(tt, prns=[str(s)])
        t_tx[:, j] = tt
        ecef[:, j] = np.asarray(st.ecef_m)[:, 0]
        clock[:, j] = np.asarray(st.clock_s)[:, 0]
        age[:, j] = np.asarray(st.age_s)[:, 0]
        valid[:, j] &= np.asarray(st.valid)[:, 0]
    z = lambda x: np.where(valid, x, 0.0)  # noqa: E731
    return SatellitesAtTransmit(z(t_tx), np.where(valid[..., None], ecef, 0.0), z(clock),
                                z(np.asarray(tgd_s, np.float64)), valid, z(age))


def sagnac_rotate(receiver_ecef_m, sat_tx_ecef_m, n_iter=3):
    """Satellite positions in the ECEF frame of the reception time and the travel times.

    ``receiver_ecef_m`` (..., 3) against ``sat_tx_ecef_m`` (..., S, 3): tau = |x - R3(Omega_e
    tau) s| / c by fixed-point iteration from tau = |x - s| / c (each step shrinks the error by
    ~|v| / c ~ 1e-5; three are exact to rounding). Returns (rotated positions, tau_s).
    """
    x = jnp.asarray(receiver_ecef_m, jnp.float64)[..., None, :]
    s = jnp.asarray(sat_tx_ecef_m, jnp.float64)
    tau = jnp.linalg.norm(s - x, axis=-1) / C_M_S
    for _ in range(n_iter):
        rot = earth_rotation_correction(s, tau)
        tau = jnp.linalg.norm(rot - x, axis=-1) / C_M_S
    return earth_rotation_correction(s, tau), tau


class ReceiverTerms(NamedTuple):
    """The terms of the pseudorange model that depend on a receiver position estimate."""

    sat_ecef_m: jax.Array  # (T, S, 3) rotated into the reception-time frame (Sagnac)
    travel_time_s: jax.Array  # (T, S)
    az_rad: jax.Array  # (T, S)
    el_rad: jax.Array  # (T, S)
    iono_m: jax.Array  # (T, S) Klobuchar L1 delay (0 without coefficients)
    tropo_m: jax.Array  # (T, S) MOPS slant delay
    sigma_iono_m: jax.Array  # (T, S) DO-229 J.2.3 residual sigma (or the full-delay bound)
    geomagnetic_lat_rad: jax.Array  # (T, S)


@functools.partial(jax.jit, static_argnames=("use_iono",))
def _receiver_terms(x, sat_tx, t_rx, day_of_year, alpha, beta, use_iono):
    rot, tau = sagnac_rotate(x, sat_tx)
    lat, lon, h = ecef_to_geodetic(x)
    r = enu_rotation(lat, lon)
    az, el, _ = az_el_from_rotation(r[..., None, :, :], rot - x[..., None, :])
    la, lo, hh = lat[..., None], lon[..., None], h[..., None]
    phi_m = atmosphere.klobuchar_geomagnetic_latitude_rad(la, lo, az, el)
    if use_iono:
        iono = atmosphere.klobuchar_delay_m(t_rx[..., None], la, lo, az, el, alpha, beta)
    else:
        iono = jnp.zeros_like(el)
    el_t = jnp.maximum(el, jnp.deg2rad(2.0))  # the models are meaningless below the horizon
    tropo = atmosphere.tropo_delay_m(la, hh, day_of_year[..., None], el_t)
    sig_iono = atmosphere.sigma_iono_klobuchar_m(iono, el_t, phi_m)
    if not use_iono:  # uncorrected: bound the whole delay (DO-229 J.2.3 vertical values x F_pp)
        sig_iono = atmosphere.iono_obliquity(el_t) * jnp.where(
            jnp.abs(jnp.rad2deg(phi_m)) <= 20.0, 9.0, jnp.where(
                jnp.abs(jnp.rad2deg(phi_m)) <= 55.0, 4.5, 6.0))
    return ReceiverTerms(rot, tau, az, el, iono, tropo, sig_iono, phi_m)


def receiver_terms(receiver_ecef_m, sat_tx_ecef_m, t_rx_s, alpha=None, beta=None):
    """Receiver-position-dependent terms of the pseudorange model, batched over epochs.

    Args:
      receiver_ecef_m: (T, 3) receiver position estimate (ECEF, reception time).
      sat_tx_ecef_m: (T, S, 3) satellite positions at transmit time (``satellites_at_transmit``).
      t_rx_s: (T,) GPS time of reception (Klobuchar local time, MOPS day of year).
      alpha, beta: Klobuchar coefficients (4,) each, or None for no ionospheric correction.

    Returns:
      ``ReceiverTerms``: Sagnac-rotated satellite positions, travel times, azimuth / elevation,
      Klobuchar and MOPS delays and the residual ionospheric sigma.
    """
    t = np.asarray(t_rx_s, np.float64)
    doy = np.asarray((gpstime.to_datetime64(t).astype("datetime64[D]")
                      - gpstime.to_datetime64(t).astype("datetime64[Y]")).astype(np.int64) + 1,
                     np.float64)
    use = alpha is not None and beta is not None
    a = jnp.asarray(alpha if use else np.zeros(4), jnp.float64)
    b = jnp.asarray(beta if use else np.zeros(4), jnp.float64)
    return _receiver_terms(jnp.asarray(receiver_ecef_m, jnp.float64),
                           jnp.asarray(sat_tx_ecef_m, jnp.float64), jnp.asarray(t),
                           jnp.asarray(doy), a, b, use_iono=bool(use))
