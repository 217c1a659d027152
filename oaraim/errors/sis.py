"""Signal-in-space error of broadcast ephemerides: broadcast minus precise orbits and clocks.

``geometry.compare_broadcast_precise`` evaluates a broadcast file (GPS and Galileo, BeiDou
MEO/IGSO) against precise orbits and clocks and hands the arrays to ``sis_errors``. Per
satellite and epoch: the orbit error dr = r_broadcast - r_precise (ECEF, metres) split into
radial R, along-track A and cross-track C (R along r, C along r x v with the inertial velocity v
= v_ECEF + Omega_e x r, A = C x R), its 3D norm, the clock error c (dt_broadcast - dt_precise),
and the global-average signal-in-space range error

    SISRE = sqrt((w_R R - c dt)^2 + w_AC^2 (A^2 + C^2))

(Montenbruck et al. 2015, GPS Solutions 19:321-333: the RMS over the Earth's visible surface of
the range error a user sees; the weights are ``oaraim.constants.SISRE_WEIGHTS``). It is
the instantaneous global-average value, not the worst-user-location one (the error projected on
the worst line of sight, which is larger).

Clock datum. Precise clocks refer to an analysis centre's clock reference, broadcast clocks to
the system time (GPS time, GST): the two differ by one offset per constellation and epoch (for
Galileo also the GGTO, ``geometry.galileo_nav``). As is standard, the per-epoch mean of
c (dt_broadcast - dt_precise) over the constellation's compared satellites is removed from the
clock error (``clock_m``; ``datum_m`` keeps the mean); a user's receiver clock absorbs it the
same way. Precise clocks leave out the periodic relativistic term that broadcast clocks include
(``geometry.compare_broadcast_precise`` adds it back).

Centre of mass vs antenna. Precise orbits (SP3) give the centre of mass, broadcast orbits the
antenna phase centre; no antenna offset is applied here (the IGS ANTEX values are not available
to this package). The offset is radial, towards the Earth: the measured mean radial error on
2023-01-01 is -0.6 to -1.6 m per GPS satellite (by block) and -0.7 to -0.9 m per Galileo one.
Like the clock datum, its constellation-wide part is a common range offset, so ``sisre_m``
removes the per-epoch constellation mean of the range error w_R R - c dt (both datums at once:
SISRE = sqrt((w_R (R - mean R) - c dt)^2 + w_AC^2 (A^2 + C^2)) with c dt already less its mean);
``sisre_clock_datum_m`` keeps the radial offset (only the clock mean removed), and the orbit
components R, A, C and the 3D error keep it too. The satellite-to-satellite spread of the
offset (GPS blocks differ by ~0.8 m) stays in both.
"""

from typing import NamedTuple

import numpy as np

from oaraim.constants import C_M_S, OMEGA_E_GNSS_RAD_S, SISRE_WEIGHTS


class SISError(NamedTuple):
    """Broadcast-minus-precise errors at E epochs x S satellites (``sis_errors``); NaN where
    not ``valid``."""

    radial_m: np.ndarray
    """(E, S) radial orbit error R, metres (positive: broadcast farther from the Earth)."""
    along_m: np.ndarray
    """(E, S) along-track orbit error A, metres."""
    cross_m: np.ndarray
    """(E, S) cross-track orbit error C, metres."""
    orbit_3d_m: np.ndarray
    """(E, S) |r_broadcast - r_precise|, metres."""
    clock_m: np.ndarray
    """(E, S) c (dt_broadcast - dt_precise) less the constellation's per-epoch mean, metres."""
    sisre_m: np.ndarray
    """(E, S) global-average SISRE, sqrt((w_R (R - mean R) - c dt)^2 + w_AC^2 (A^2 + C^2)),
    the constellation's per-epoch mean radial error and clock datum removed, metres."""
    sisre_clock_datum_m: np.ndarray
    """(E, S) the SISRE with only the clock datum removed, sqrt((w_R R - c dt)^2 + ...): it
    keeps the constellation-wide radial offset of centre of mass vs antenna, metres."""
    sisre_orbit_m: np.ndarray
    """(E, S) its orbit-only part, sqrt(w_R^2 R^2 + w_AC^2 (A^2 + C^2)), metres."""
    datum_m: np.ndarray
    """(E, S) the per-epoch clock datum removed from each satellite's clock error, metres."""
    radial_mean_m: np.ndarray
    """(E, S) the per-epoch mean radial error of the satellite's constellation, metres."""
    valid: np.ndarray
    """(E, S) bool: broadcast and precise orbit and clock are all present."""
    sats: np.ndarray
    """(S,) satellite names such as ``'G05'``, ``'E11'``."""


def rac_unit_vectors(ecef_m, vel_ecef_m_s):
    """Radial, along-track and cross-track unit vectors (each (..., 3)) of satellites at
    ``ecef_m`` moving at ``vel_ecef_m_s`` relative to the rotating Earth; the cross-track
    direction uses the inertial velocity v + Omega_e x r."""
    r = np.asarray(ecef_m, np.float64)
    v = np.asarray(vel_ecef_m_s, np.float64)
    v_inertial = v + np.cross([0.0, 0.0, OMEGA_E_GNSS_RAD_S], r)
    with np.errstate(invalid="ignore", divide="ignore"):  # zeros where not valid: NaN
        e_r = r / np.linalg.norm(r, axis=-1, keepdims=True)
        h = np.cross(r, v_inertial)
        e_c = h / np.linalg.norm(h, axis=-1, keepdims=True)
    return e_r, np.cross(e_c, e_r), e_c


def sis_errors(sats, broadcast_ecef_m, broadcast_vel_m_s, broadcast_clock_s, precise_ecef_m,
               precise_clock_s, valid, weights=None) -> SISError:
    """Broadcast-minus-precise orbit, clock and SISRE errors (module docstring).

    Args:
      sats: (S,) satellite names; the first letter picks the SISRE weights ('G', 'E', 'C').
      broadcast_ecef_m: (E, S, 3) broadcast positions; broadcast_vel_m_s their ECEF velocity.
      broadcast_clock_s: (E, S) broadcast clock offsets (relativistic term included).
      precise_ecef_m: (E, S, 3) precise (centre-of-mass) positions.
      precise_clock_s: (E, S) precise clock offsets.
      valid: (E, S) bool: where all four are present.
      weights: {satellite: (w_R, w_AC^2)} for satellites whose weights are not their system's
        (BeiDou IGSO: ``SISRE_WEIGHTS["C_IGSO"]``).
    """
    sats = np.asarray(sats).astype(str)
    systems = np.array([s[0] for s in sats])
    unknown = sorted(set(systems) - set(SISRE_WEIGHTS))
    if unknown:
        raise ValueError(f"no SISRE weights for systems {unknown}; known: "
                         f"{', '.join(SISRE_WEIGHTS)}")
    ok = np.asarray(valid, bool)
    nan = np.where(ok, 0.0, np.nan)
    dr = np.asarray(broadcast_ecef_m, np.float64) - np.asarray(precise_ecef_m, np.float64)
    e_r, e_a, e_c = rac_unit_vectors(broadcast_ecef_m, broadcast_vel_m_s)
    rad = np.sum(dr * e_r, -1) + nan
    along = np.sum(dr * e_a, -1) + nan
    cross = np.sum(dr * e_c, -1) + nan
    dclk = C_M_S * (np.asarray(broadcast_clock_s, np.float64)
                    - np.asarray(precise_clock_s, np.float64)) + nan
    datum = np.full(ok.shape, np.nan)
    r_mean = np.full(ok.shape, np.nan)
    w_r = np.zeros(sats.size)
    w_ac2 = np.zeros(sats.size)
    for sysch in set(systems):
        cols = systems == sysch
        w_r[cols], w_ac2[cols] = SISRE_WEIGHTS[sysch]
    for j, sat in enumerate(sats):
        if weights is not None and sat in weights:
            w_r[j], w_ac2[j] = weights[sat]
    for sysch in set(systems):
        cols = systems == sysch
        x = np.where(ok[:, cols], dclk[:, cols], 0.0)
        n = ok[:, cols].sum(1)
        mean = np.where(n > 0, x.sum(1) / np.maximum(n, 1), np.nan)
        datum[:, cols] = mean[:, None] + nan[:, cols]
        xr = np.where(ok[:, cols], rad[:, cols], 0.0).sum(1) / np.maximum(n, 1)
        r_mean[:, cols] = xr[:, None] + nan[:, cols]
    clock = dclk - datum
    sisre_clock = np.sqrt((w_r * rad - clock) ** 2 + w_ac2 * (along ** 2 + cross ** 2))
    sisre = np.sqrt((w_r * (rad - r_mean) - clock) ** 2 + w_ac2 * (along ** 2 + cross ** 2))
    sisre_orbit = np.sqrt((w_r * rad) ** 2 + w_ac2 * (along ** 2 + cross ** 2))
    return SISError(rad, along, cross, np.linalg.norm(dr, axis=-1) + nan, clock, sisre,
                    sisre_clock, sisre_orbit, datum, r_mean, ok, sats)


def summary(err: SISError, system: str) -> dict:
    """Median, 95th percentile and max of |R|, |A|, |C|, 3D, |clock|, SISRE (orbit only and
    full) over the valid satellite-epochs of one system letter, plus the sample count."""
    cols = np.array([s[0] == system for s in err.sats])
    ok = err.valid[:, cols]
    out = {"n": int(ok.sum())}
    for name in ("radial_m", "along_m", "cross_m", "orbit_3d_m", "clock_m", "sisre_orbit_m",
                 "sisre_clock_datum_m", "sisre_m"):
        x = np.abs(getattr(err, name)[:, cols][ok])
        out[name] = (float(np.median(x)), float(np.percentile(x, 95)), float(x.max())) \
            if x.size else (np.nan, np.nan, np.nan)
    return out
