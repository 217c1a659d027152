"""Signal-in-space error of a broadcast file against precise orbits and clocks:
``compare_broadcast_precise`` evaluates the broadcast ephemeris (GPS and Galileo,
``geometry.Ephemeris``; BeiDou MEO/IGSO, ``geometry.beidou_nav``) at the precise products' epochs
and hands the arrays to the SISRE model, ``errors.sis`` (the error models' home: the radial,
along- and cross-track split, the clock datum, the SISRE weights, ``SISError``, ``summary``),
whose names this module also keeps.
"""

from collections.abc import Sequence

import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Real

from oaraim.constants import C_M_S
from oaraim.errors import SISError, sis, sis_errors
from oaraim.geometry.beidou_nav import BeidouEphemeris
from oaraim.geometry.broadcast_orbits import Ephemeris
from oaraim.readers import PreciseClocks, PreciseOrbits


def compare_broadcast_precise(ephemeris: Ephemeris | BeidouEphemeris, orbits: PreciseOrbits,
                              clocks: PreciseClocks | None = None,
                              t_gps_s: Real[ArrayLike, " T"] | None = None,
                              systems: Sequence[str] = ("G", "E"), weights: dict | None = None,
                              prns: Sequence[str] | None = None) -> SISError:
    """``sis_errors`` of a broadcast ``geometry.Ephemeris`` against precise ``orbits``
    (``geometry.read_sp3``) and ``clocks`` (``geometry.rinex_clk.read_clock_rinex``; None uses
    the SP3 clocks; either way the periodic relativistic term -2 r.v / c^2 is added to them, as
    the broadcast clock has it), for the satellites of ``systems`` present in all of them, at
    ``t_gps_s`` (default: the SP3 epochs). Precise values are taken at the SP3 / clock epochs
    themselves (no interpolation): every t must be an epoch of both files. The broadcast
    velocity is the central difference of positions 0.5 s either side. ``ephemeris`` may also
    be a ``geometry.beidou_nav.BeidouEphemeris``; ``weights`` as in ``sis_errors``; ``prns``
    limits the comparison (and so the clock datum) to those satellites.
    """
    t = np.asarray(orbits.t_gps_s if t_gps_s is None else t_gps_s, np.float64)
    sats = [str(s) for s in ephemeris.prns if s[0] in systems and s in set(orbits.prns)]
    if clocks is not None:
        sats = [s for s in sats if s in set(clocks.sats)]
    if prns is not None:
        sats = [s for s in sats if s in {str(p) for p in prns}]
    if not sats:
        raise ValueError("no satellite is in the broadcast file, the orbits and the clocks")

    def rows(grid, name):
        k = np.searchsorted(grid, t)
        k = np.clip(k, 0, grid.size - 1)
        if not np.all(np.abs(grid[k] - t) < 1e-3):
            raise ValueError(f"epochs are not all on the {name} epoch grid; give t_gps_s on it")
        return k

    ko = rows(orbits.t_gps_s, "SP3")
    so = np.searchsorted(orbits.prns, sats)
    p_ecef = orbits.ecef_m[ko][:, so]
    p_ok = orbits.valid[ko][:, so]
    if clocks is None:
        p_clk, c_ok = orbits.clock_s[ko][:, so], orbits.clock_valid[ko][:, so]
    else:
        kc = rows(clocks.t_gps_s, "clock file")
        sc = np.searchsorted(clocks.sats, sats)
        p_clk, c_ok = clocks.clock_s[kc][:, sc], clocks.valid[kc][:, sc]
    st = ephemeris.sat_state(t, prns=sats)
    plus = np.asarray(ephemeris.sat_state(t + 0.5, prns=sats).ecef_m)
    minus = np.asarray(ephemeris.sat_state(t - 0.5, prns=sats).ecef_m)
    ok = np.asarray(st.valid) & p_ok & c_ok
    ecef, vel = np.asarray(st.ecef_m), plus - minus
    # precise clocks leave out the periodic relativistic term (IGS convention; IERS
    # Conventions 2010, 10.2: dt_rel = -2 r.v / c^2), which the broadcast clock includes
    rel = -2.0 * np.sum(ecef * vel, -1) / C_M_S ** 2
    return sis_errors(sats, ecef, vel, np.asarray(st.clock_s), p_ecef, p_clk + rel, ok,
                      weights)


#: the SISRE model's names, kept here (their home is ``errors.sis``)
rac_unit_vectors = sis.rac_unit_vectors
summary = sis.summary

__all__ = ["SISError", "compare_broadcast_precise", "rac_unit_vectors", "sis_errors", "summary"]
