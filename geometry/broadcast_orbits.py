"""GPS and Galileo satellites from broadcast ephemerides: the orbit and clock of each record
(``geometry.kepler``: IS-GPS-200 20.3.3.4.3; Galileo OS SIS ICD 5.1.1), vectorized over epochs
x satellites in JAX. The records come from ``readers.read_navigation`` (RINEX 2 / 3 navigation
files, checked there).

Record choice, per epoch and satellite: the *healthy* record nearest in time (|t - t_oe|),
within ``max_age_s`` (default 4 h: the GPS fit interval is 4 h and Galileo's validity is 4 h,
Galileo OS SDD; a single-station file may lack late records, and for geometry an extrapolated
orbit is good to metres-to-hundreds-of-metres, i.e. milli-degrees of direction). The age is
returned so a caller can tighten it. A satellite is used at t only if

* over the whole file more than half of its records are healthy (a satellite flagged unhealthy
  all day may carry a lone record with health 0 that is not a usable orbit: G01 of
  ``brdc1820.10n`` disagrees with the precise orbit by 41,000 km), and
* no unhealthy record is nearer to t than the chosen healthy one (a health flag raised in the
  file holds until the next healthy record takes over).

GPS records are healthy when the health word is 0; Galileo records when the signal health and
data-validity bits are all 0 (RINEX 3.04 Table A8).
"""

import os
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.constants import MU_GAL_M3_S2, MU_GPS_M3_S2
from oaraim.geometry.kepler import (
    F_GAL_S_SQRT_M,
    F_GPS_S_SQRT_M,
    OrbitElements,
    clock_polynomial_s,
    orbit_ecef,
    relativistic_clock_s,
)
from oaraim.readers import (
    DEFAULT_MAX_AGE_S,
    GALILEO,
    GPS,
    RECORD_FIELDS,
    SYSTEM_CODES,
    SYSTEM_NAMES,
    gpstime,
    read_navigation,
)


class SatState(NamedTuple):
    """The satellites at T epochs from broadcast ephemerides (``Ephemeris.sat_state``)."""

    ecef_m: jax.Array
    """(T, S, 3) position in the ECEF frame at t, metres (0 where not valid)."""
    clock_s: jax.Array
    """(T, S) satellite clock offset dt_sv including the relativistic term, seconds."""
    valid: jax.Array
    """(T, S) bool: the satellite is healthy and its nearest healthy record lies within
    ``max_age_s`` of t, with no unhealthy record nearer."""
    age_s: jax.Array
    """(T, S) t - t_oe of the record used, seconds (0 where not valid)."""
    prns: np.ndarray
    """(S,) satellite names such as ``'G05'``, ``'E11'``."""


class Ephemeris:
    """Broadcast ephemerides of one navigation file, padded to arrays (S satellites x R records).

    Use ``geometry.load_navigation(path)``. Attributes: ``prns`` (S,) names, ``constellation``
    (S,) codes (GPS 0, Galileo 1), ``prn_number`` (S,) ints, ``sat_healthy`` (S,) whole-file
    health, ``n_records`` (S,), ``path``.
    """

    def __init__(self, table, path, max_age_s=DEFAULT_MAX_AGE_S):
        self.path = str(path)
        self.max_age_s = float(max_age_s)
        t = table  # every record is an orbit of its constellation (checked with its line)
        prns = np.array(sorted(set(t["sv"])))
        self.prns = prns
        self.constellation = np.array([SYSTEM_CODES[p[0]] for p in prns], np.int32)
        self.prn_number = np.array([int(p[1:]) for p in prns], np.int32)
        s_of = {p: k for k, p in enumerate(prns)}
        s_idx = np.array([s_of[p] for p in t["sv"]], np.int64)
        counts = np.bincount(s_idx, minlength=prns.size)
        self.n_records = counts
        r_max = int(counts.max())
        # records of each satellite sorted by t_oe, padded to r_max
        order = np.lexsort((t["toe_s"], s_idx))
        s_sorted = s_idx[order]
        first = np.searchsorted(s_sorted, np.arange(prns.size))
        r_idx = np.arange(order.size) - first[s_sorted]
        healthy = t["health"] == 0
        self.sat_healthy = np.bincount(s_idx, weights=healthy, minlength=prns.size) > 0.5 * counts

        def pad(x, fill=0.0):
            out = np.full((prns.size, r_max), fill, np.float64)
            out[s_sorted, r_idx] = x[order]
            return out

        toe = pad(t["toe_s"], np.inf)
        ok = pad(healthy.astype(float)) > 0
        present = np.isfinite(toe)
        # sorted t_oe of the usable (healthy) and of the unhealthy records, +inf padded
        self._toe_healthy = np.sort(np.where(ok & present, toe, np.inf), axis=1)
        self._toe_unhealthy = np.sort(np.where(~ok & present, toe, np.inf), axis=1)
        # the healthy records in the same sorted order as _toe_healthy
        perm = np.argsort(np.where(ok & present, toe, np.inf), axis=1, kind="stable")
        take = lambda x: np.take_along_axis(x, perm, 1)  # noqa: E731
        gal = (self.constellation == GALILEO)[:, None]
        toe_h = take(np.where(present, toe, 0.0))
        self._params = {
            "toe_s": toe_h,
            "toe_tow_s": toe_h - gpstime.SECONDS_PER_WEEK * np.floor(
                toe_h / gpstime.SECONDS_PER_WEEK),
            "toc_s": take(pad(t["toc_s"])),
            "af0": take(pad(t["SVclockBias"])), "af1": take(pad(t["SVclockDrift"])),
            "af2": take(pad(t["SVclockDriftRate"])),
            "sqrt_a": take(pad(t["sqrtA"], 5153.0)), "e": take(pad(t["Eccentricity"])),
            "i0": take(pad(t["Io"])), "idot": take(pad(t["IDOT"])),
            "omega0": take(pad(t["Omega0"])), "omegadot": take(pad(t["OmegaDot"])),
            "omega": take(pad(t["omega"])), "m0": take(pad(t["M0"])),
            "delta_n": take(pad(t["DeltaN"])), "cuc": take(pad(t["Cuc"])),
            "cus": take(pad(t["Cus"])), "crc": take(pad(t["Crc"])), "crs": take(pad(t["Crs"])),
            "cic": take(pad(t["Cic"])), "cis": take(pad(t["Cis"])),
            "mu": np.where(gal, MU_GAL_M3_S2, MU_GPS_M3_S2) * np.ones((1, r_max)),
            "f_rel": np.where(gal, F_GAL_S_SQRT_M, F_GPS_S_SQRT_M) * np.ones((1, r_max)),
        }
        self._fields = {n: take(pad(t[n])) for n in RECORD_FIELDS if n in t}
        self._device = None

    def __repr__(self):
        n = {SYSTEM_NAMES[c]: int(np.sum(self.constellation == c)) for c in (GPS, GALILEO)}
        return (f"Ephemeris({Path(self.path).name}: {n}, {int(self.n_records.sum())} records, "
                f"unhealthy {[str(p) for p in self.prns[~self.sat_healthy]]})")

    @property
    def toe_healthy_s(self):
        """t_oe of every healthy record in the file, GPS seconds (1-D, sorted per satellite)."""
        return self._toe_healthy[np.isfinite(self._toe_healthy)]

    @property
    def record_span_s(self):
        """(first, last) t_oe over the file, GPS seconds."""
        t = self.toe_healthy_s
        return float(t.min()), float(t.max())

    def _select(self, prns):
        if prns is None:
            return np.arange(self.prns.size)
        prns = [str(p) for p in np.atleast_1d(prns)]
        missing = [p for p in prns if p not in set(self.prns)]
        if missing:
            raise ValueError(f"prns {missing} are not in {self.path}; available: "
                             f"{', '.join(self.prns)}")
        where = {p: k for k, p in enumerate(self.prns)}
        return np.array([where[p] for p in prns])

    def _arrays(self):
        if self._device is None:
            self._device = (
                {k: jnp.asarray(v) for k, v in self._params.items()},
                jnp.asarray(self._toe_healthy), jnp.asarray(self._toe_unhealthy),
                jnp.asarray(self.sat_healthy))
        return self._device

    def sat_state(self, t_gps_s, prns=None, max_age_s=None) -> SatState:
        """Positions, clocks, validity and record age at GPS times ``t_gps_s`` (T,)."""
        idx = self._select(prns)
        params, toe_h, toe_u, sat_ok = self._arrays()
        if prns is not None:
            params = {k: v[idx] for k, v in params.items()}
            toe_h, toe_u, sat_ok = toe_h[idx], toe_u[idx], sat_ok[idx]
        t = jnp.atleast_1d(jnp.asarray(t_gps_s, jnp.float64))
        age = self.max_age_s if max_age_s is None else float(max_age_s)
        ecef, clock, valid, age_s = _propagate(params, toe_h, toe_u, sat_ok, t, age)
        return SatState(ecef, clock, valid, age_s, self.prns[idx])

    def record_field(self, name, t_gps_s, prns=None) -> np.ndarray:
        """(T, S) field ``name`` of ``RECORD_FIELDS`` (in the file's units: seconds for T_GD and
        the BGDs, metres for SISA) of the record ``sat_state`` uses at each t (NaN where the
        satellite is not valid there)."""
        if name not in self._fields:
            raise ValueError(f"record field {name!r} is not kept; one of {RECORD_FIELDS}")
        idx = self._select(prns)
        st = self.sat_state(t_gps_s, prns)
        t = jnp.atleast_1d(jnp.asarray(t_gps_s, jnp.float64))
        k = np.asarray(jax.vmap(_nearest, in_axes=(0, None))(
            jnp.asarray(self._toe_healthy[idx]), t)[0])  # (S, T)
        out = np.take_along_axis(self._fields[name][idx], k, axis=1).T
        return np.where(np.asarray(st.valid), out, np.nan)

    def sat_position_ecef(self, t_gps_s, prns=None):
        """``(ecef (T, S, 3) metres, valid (T, S), prns (S,))`` at GPS times ``t_gps_s`` (T,).

        Positions are in the ECEF frame at time t (no light-time or Sagnac correction: see
        ``geometry.frames.earth_rotation_correction``). Invalid entries hold 0, never NaN.
        """
        s = self.sat_state(t_gps_s, prns)
        return s.ecef_m, s.valid, s.prns


def _nearest(sorted_toe, t):
    """Index into ``sorted_toe`` (R,) (+inf padded) of the value nearest each t (T,), and the
    distance (inf if the row is empty)."""
    k = jnp.searchsorted(sorted_toe, t)
    lo = jnp.clip(k - 1, 0, sorted_toe.shape[0] - 1)
    hi = jnp.clip(k, 0, sorted_toe.shape[0] - 1)
    d_lo = jnp.abs(t - sorted_toe[lo])
    d_hi = jnp.abs(sorted_toe[hi] - t)
    d_lo = jnp.where(jnp.isfinite(sorted_toe[lo]), d_lo, jnp.inf)
    d_hi = jnp.where(jnp.isfinite(sorted_toe[hi]), d_hi, jnp.inf)
    pick_hi = d_hi < d_lo
    return jnp.where(pick_hi, hi, lo), jnp.minimum(d_lo, d_hi)


@jax.jit
def _propagate(params, toe_healthy, toe_unhealthy, sat_ok, t, max_age_s):
    # (S, T) record choice per satellite
    idx, dist = jax.vmap(_nearest, in_axes=(0, None))(toe_healthy, t)
    _, dist_bad = jax.vmap(_nearest, in_axes=(0, None))(toe_unhealthy, t)
    valid = sat_ok[:, None] & (dist <= max_age_s) & ~(dist_bad < dist)
    g = {k: jnp.take_along_axis(v, idx, axis=1).T for k, v in params.items()}  # (T, S)
    tt = t[:, None]
    el = OrbitElements(
        toe_s=g["toe_s"], toe_tow_s=g["toe_tow_s"], sqrt_a=g["sqrt_a"], e=g["e"],
        i0_rad=g["i0"], idot_rad_s=g["idot"], omega0_rad=g["omega0"],
        omegadot_rad_s=g["omegadot"], omega_rad=g["omega"], m0_rad=g["m0"],
        delta_n_rad_s=g["delta_n"], cuc_rad=g["cuc"], cus_rad=g["cus"], crc_m=g["crc"],
        crs_m=g["crs"], cic_rad=g["cic"], cis_rad=g["cis"], mu_m3_s2=g["mu"])
    # a far t_k on padding/invalid entries would only waste precision: clamp it
    t_eval = jnp.where(valid.T, tt, g["toe_s"])
    ecef, ecc = orbit_ecef(el, t_eval)
    clock = (clock_polynomial_s(g["af0"], g["af1"], g["af2"], g["toc_s"], t_eval)
             + relativistic_clock_s(g["f_rel"], g["e"], g["sqrt_a"], ecc))
    v = valid.T
    return (jnp.where(v[..., None], ecef, 0.0), jnp.where(v, clock, 0.0), v,
            jnp.where(v, tt - g["toe_s"], 0.0))

def load_navigation(path: str | os.PathLike | Sequence[str | os.PathLike],
                    systems: Sequence[str] = ("G", "E"), max_age_s: float = DEFAULT_MAX_AGE_S,
                    galileo_source: str | None = None) -> Ephemeris:
    """Broadcast ephemerides of a RINEX 2 (GPS) or RINEX 3 navigation file (plain or .gz), or
    of several files read as one (a station's separate GPS ``GN`` and Galileo ``EN`` files, or
    consecutive days): the records of ``readers.read_navigation`` (merged, a record present in
    more than one file kept once) as orbits.

    Args:
      path: the file, or a sequence of files (each keeps the systems of ``systems`` it has;
        a file with none of them is passed over, and none at all is an error).
      systems: RINEX system letters to keep ('G' GPS, 'E' Galileo).
      max_age_s: largest |t - t_oe| of a usable record (default 4 h).
      galileo_source: None (every Galileo record, I/NAV and F/NAV alike), 'fnav' (only F/NAV
        records: clock for E1/E5a) or 'inav' (only I/NAV: clock for E1/E5b), see
        ``readers.galileo_nav``.

    Raises:
      NavigationFileError: (a ValueError) naming the file and line when the file is missing,
        malformed or truncated.
    """
    nav = read_navigation(path, systems, galileo_source)
    return Ephemeris(nav.records, nav.path, max_age_s)
