"""BeiDou (BDS-2 / BDS-3) broadcast ephemerides of MEO and IGSO satellites, for the
broadcast-vs-precise comparison (``geometry.sis_error``); the records are read by
``readers.read_beidou_records``. GEO satellites (C01-C05, C59-C63)
are left out: their broadcast orbit uses another transformation (BDS-SIS-ICD-B1I 3.0,
5.2.4.12) that this module does not implement. The satellites are not part of
``geometry.Ephemeris`` (the ARAIM constellations are GPS and Galileo).

Sources: BeiDou Navigation Satellite System Signal In Space Interface Control Document, Open
Service Signal B1I, Version 3.0 (CSNO, 2019), and RINEX 3.05 Table A12 (the D1/D2 records).

* Time: BeiDou Time (BDT) starts at 2006-01-01 00:00:00 UTC, when GPS time was 14 s ahead of
  UTC (ICD 4.1.2; 1356 weeks after the GPS epoch): t_GPS = t_BDT + 14 s. RINEX writes the BDT
  week ('BDT week') and t_oc in BDT (2023-01-01 00:00:00 BDT = 00:00:14 GPS, week 887).
* Orbit: the GPS algorithm (``geometry.kepler``) with the CGCS2000 constants mu = 3.986004418e14
  m^3/s^2 and Omega_e = 7.2921150e-5 rad/s (ICD 5.2.4.10): the node angle is rotated by the
  difference of Omega_e from the GPS value, (Omega_GPS - Omega_BDS) (t_k + t_oe).
* Clock: a_f0..a_f2 refer to B3I; a B1I user applies T_GD1 (dt_B1I = dt - T_GD1, ICD
  5.2.4.8), so the B1I/B3I ionosphere-free clock, that of the MGEX precise clocks, is
  dt - f_B1I^2 / (f_B1I^2 - f_B3I^2) T_GD1. The relativistic term F e sqrt(A) sin E is added as
  for GPS.
* Health: SatH1 0 is healthy; records are chosen like GPS's (the healthy record nearest in t_oe,
  within ``max_age_s``).
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from oaraim.constants import (
    F_B1I_HZ,
    F_B3I_HZ,
    MU_BDS_M3_S2,
    OMEGA_E_BDS_RAD_S,
    OMEGA_E_GNSS_RAD_S,
)
from oaraim.geometry.kepler import (
    F_GAL_S_SQRT_M,
    OrbitElements,
    clock_polynomial_s,
    orbit_ecef,
    relativistic_clock_s,
)
from oaraim.readers import GEO_PRNS, read_beidou_records  # noqa: F401  (GEO_PRNS: kept here)

#: IGSO satellites flying in 2023 (BDS-2 C06-C10, C13, C16; BDS-3 C38-C40): their SISRE
#: weights differ from the MEO ones
IGSO_PRNS = frozenset((6, 7, 8, 9, 10, 13, 16, 38, 39, 40))
#: relativistic clock constant with the CGCS2000 mu (= WGS-84's: the Galileo value)
F_BDS_S_SQRT_M = F_GAL_S_SQRT_M


class BeidouState(NamedTuple):
    """BeiDou satellites at T epochs (``BeidouEphemeris.sat_state``)."""

    ecef_m: np.ndarray
    """(T, S, 3) position in the ECEF frame at t, metres (0 where not valid)."""
    clock_s: np.ndarray
    """(T, S) clock offset for the ephemeris' ``clock`` reference, relativistic term included."""
    valid: np.ndarray
    """(T, S) bool: a healthy record within ``max_age_s`` and none unhealthy nearer."""
    age_s: np.ndarray
    """(T, S) t - t_oe of the record used, seconds."""
    prns: np.ndarray
    """(S,) satellite names such as ``'C20'``."""


class BeidouEphemeris:
    """The MEO and IGSO BeiDou records of a RINEX 3 navigation file (``load_beidou``).
    Attributes: ``prns`` (S,), ``clock`` ('B3I' or 'B1I/B3I'), ``max_age_s``, ``path``."""

    def __init__(self, records: dict, path, clock="B1I/B3I", max_age_s=4 * 3600.0):
        if clock not in ("B3I", "B1I/B3I"):
            raise ValueError(f"clock must be 'B3I' or 'B1I/B3I', got {clock!r}")
        self.path, self.clock, self.max_age_s = str(path), clock, float(max_age_s)
        self.prns = np.array(sorted(records))
        self._rec = [records[p] for p in self.prns]

    def sat_state(self, t_gps_s, prns=None) -> BeidouState:
        """Positions, clocks, validity and record age at GPS times ``t_gps_s`` (T,)."""
        t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
        names = self.prns if prns is None else np.array([str(p) for p in np.atleast_1d(prns)])
        where = {p: k for k, p in enumerate(self.prns)}
        missing = [p for p in names if p not in where]
        if missing:
            raise ValueError(f"prns {missing} are not BeiDou MEO/IGSO satellites of {self.path}")
        ecef = np.zeros((t.size, names.size, 3))
        clock = np.zeros((t.size, names.size))
        valid = np.zeros((t.size, names.size), bool)
        age = np.zeros((t.size, names.size))
        for j, name in enumerate(names):
            r = self._rec[where[name]]
            good, bad = r["health"] == 0, r["health"] != 0
            d = np.abs(t[:, None] - r["toe_gps_s"][None, :])
            dg = np.where(good[None, :], d, np.inf)
            k = np.argmin(dg, axis=1)
            dmin = dg[np.arange(t.size), k]
            dbad = np.where(bad[None, :], d, np.inf).min(axis=1) if bad.any() else np.inf
            ok = (dmin <= self.max_age_s) & ~(dbad < dmin)
            g = {n: v[k] for n, v in r.items()}
            t_eval = np.where(ok, t, g["toe_gps_s"])
            el = OrbitElements(
                toe_s=g["toe_gps_s"], toe_tow_s=g["Toe"], sqrt_a=g["sqrtA"], e=g["Eccentricity"],
                i0_rad=g["Io"], idot_rad_s=g["IDOT"], omega0_rad=g["Omega0"],
                omegadot_rad_s=g["OmegaDot"], omega_rad=g["omega"], m0_rad=g["M0"],
                delta_n_rad_s=g["DeltaN"], cuc_rad=g["Cuc"], cus_rad=g["Cus"], crc_m=g["Crc"],
                crs_m=g["Crs"], cic_rad=g["Cic"], cis_rad=g["Cis"], mu_m3_s2=MU_BDS_M3_S2)
            pos, ecc = orbit_ecef(el, t_eval)
            # the node with the CGCS2000 Earth rate: rotate by (Omega_GPS - Omega_BDS)(t_k + t_oe)
            turn = (OMEGA_E_GNSS_RAD_S - OMEGA_E_BDS_RAD_S) * (t_eval - g["toe_gps_s"] + g["Toe"])
            c, s = jnp.cos(turn), jnp.sin(turn)
            pos = jnp.stack([c * pos[:, 0] - s * pos[:, 1], s * pos[:, 0] + c * pos[:, 1],
                             pos[:, 2]], -1)
            dt = (clock_polynomial_s(g["SVclockBias"], g["SVclockDrift"],
                                     g["SVclockDriftRate"], g["toc_gps_s"], t_eval)
                  + relativistic_clock_s(F_BDS_S_SQRT_M, g["Eccentricity"], g["sqrtA"], ecc))
            if self.clock == "B1I/B3I":
                dt = dt - F_B1I_HZ ** 2 / (F_B1I_HZ ** 2 - F_B3I_HZ ** 2) * g["TGD1"]
            ecef[:, j] = np.where(ok[:, None], np.asarray(pos), 0.0)
            clock[:, j] = np.where(ok, np.asarray(dt), 0.0)
            valid[:, j] = ok
            age[:, j] = np.where(ok, t - g["toe_gps_s"], 0.0)
        return BeidouState(ecef, clock, valid, age, names)


def load_beidou(path, clock="B1I/B3I", max_age_s=4 * 3600.0) -> BeidouEphemeris:
    """The BeiDou MEO and IGSO satellites of a RINEX 3 navigation file (plain or .gz), read and
    checked by ``readers.read_beidou_records``.

    Args:
      path: the file.
      clock: 'B1I/B3I' (ionosphere-free, as the MGEX precise clocks; default) or 'B3I' (the
        broadcast reference).
      max_age_s: largest |t - t_oe| of a usable record (default 4 h).
    """
    nav = read_beidou_records(path)
    return BeidouEphemeris(nav.records, nav.path, clock, max_age_s)
