"""GPS/Galileo almanacs as orbits: the records of a YUMA or SEM file
(``readers.read_yuma_records``, ``readers.read_sem_records``) or of a nominal constellation
(``geometry.nominal``) propagated by the ephemeris algorithm with the harmonic terms, delta_n and
IDOT zero (IS-GPS-200 20.3.3.5.2.3), through ``geometry.kepler.orbit_ecef``; the almanac clock
is a_f0 + a_f1 t_k.
"""

import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.constants import MU_GAL_M3_S2, MU_GPS_M3_S2
from oaraim.geometry.kepler import OrbitElements, orbit_ecef
from oaraim.readers import (
    GALILEO,
    GPS,
    SYSTEM_NAMES,
    AlmanacRecords,
    read_sem_records,
    read_yuma_records,
)


class Almanac:
    """Satellites of an almanac or a nominal constellation (one Keplerian record each).

    ``sat_position_ecef(t_gps_s, prns=None)`` has the signature of ``Ephemeris``'s: it returns
    ``(ecef (T, S, 3), valid (T, S), prns (S,))`` where valid is the health word == 0.
    """

    def __init__(self, records: AlmanacRecords, system: int, name: str):
        self.records = records
        self.system = int(system)
        self.name = name
        letter = "G" if system == GPS else "E"
        self.prns = np.array([f"{letter}{int(p):02d}" for p in records.prn])
        self.prn_number = np.asarray(records.prn, np.int32)
        self.constellation = np.full(self.prns.size, system, np.int32)
        self.sat_healthy = np.asarray(records.health) == 0
        mu = MU_GAL_M3_S2 if system == GALILEO else MU_GPS_M3_S2
        r = records
        z = np.zeros(self.prns.size)
        self._elements = OrbitElements(
            toe_s=r.toa_s, toe_tow_s=r.toa_tow_s, sqrt_a=r.sqrt_a, e=r.e, i0_rad=r.i_rad,
            idot_rad_s=z, omega0_rad=r.omega0_rad, omegadot_rad_s=r.omegadot_rad_s,
            omega_rad=r.omega_rad, m0_rad=r.m0_rad, delta_n_rad_s=z, cuc_rad=z, cus_rad=z,
            crc_m=z, crs_m=z, cic_rad=z, cis_rad=z, mu_m3_s2=np.full(z.shape, mu))

    def __repr__(self):
        return (f"Almanac({self.name}: {self.prns.size} {SYSTEM_NAMES[self.system]} satellites, "
                f"{int(np.sum(~self.sat_healthy))} unhealthy)")

    def _select(self, prns):
        if prns is None:
            return np.arange(self.prns.size)
        where = {p: k for k, p in enumerate(self.prns)}
        missing = [str(p) for p in np.atleast_1d(prns) if str(p) not in where]
        if missing:
            raise ValueError(f"prns {missing} are not in {self.name}; available: "
                             f"{', '.join(self.prns)}")
        return np.array([where[str(p)] for p in np.atleast_1d(prns)])

    def sat_position_ecef(self, t_gps_s, prns=None):
        """``(ecef (T, S, 3) metres, valid (T, S), prns (S,))`` at GPS times ``t_gps_s`` (T,),
        as ``Ephemeris.sat_position_ecef``: Keplerian propagation of each almanac record (no
        harmonic corrections), ECEF at time t; valid is health == 0, invalid entries hold 0.
        ``prns`` selects satellites by name (default: all)."""
        idx = self._select(prns)
        el = OrbitElements(*(jnp.asarray(np.asarray(x)[idx]) for x in self._elements))
        t = jnp.atleast_1d(jnp.asarray(t_gps_s, jnp.float64))
        ecef = _almanac_ecef(el, t)
        valid = jnp.broadcast_to(jnp.asarray(self.sat_healthy[idx]), ecef.shape[:-1])
        return jnp.where(valid[..., None], ecef, 0.0), valid, self.prns[idx]

    def clock_s(self, t_gps_s):
        """Almanac clock a_f0 + a_f1 (t - t_oa), ``(T, S)`` seconds."""
        t = np.atleast_1d(np.asarray(t_gps_s, np.float64))[:, None]
        return self.records.af0_s + self.records.af1_s_s * (t - self.records.toa_s)


@jax.jit
def _almanac_ecef(el, t):
    el_b = OrbitElements(*(x[None, :] for x in el))
    ecef, _ = orbit_ecef(el_b, t[:, None])
    return ecef


def read_yuma(path: str | os.PathLike, system: str = "G",
              week_reference_t_gps_s: float | None = None) -> Almanac:
    """Read a YUMA almanac (``readers.read_yuma_records``: the checks and the week rule) as
    orbits. ``system``: 'G' (GPS) or 'E' (Galileo, e.g. MAAST's ED-259 file)."""
    records = read_yuma_records(path, system, week_reference_t_gps_s)
    return Almanac(records, GPS if system == "G" else GALILEO, Path(path).expanduser().name)


def read_sem(path: str | os.PathLike, system: str = "G",
             week_reference_t_gps_s: float | None = None) -> Almanac:
    """Read a SEM almanac (NAVCEN ``.al3``; ``readers.read_sem_records``: the layout, the checks
    and the week rule) as orbits."""
    records = read_sem_records(path, system, week_reference_t_gps_s)
    return Almanac(records, GPS if system == "G" else GALILEO, Path(path).expanduser().name)
