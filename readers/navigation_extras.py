"""What a GPS navigation file holds beyond the orbits and clocks, for the pseudorange model of
real-data replay (``geometry.pseudorange_model``): the Klobuchar coefficients of the header
(IS-GPS-200 20.3.3.5.2.5; RINEX 2 ``ION ALPHA`` / ``ION BETA``, RINEX 3 ``IONOSPHERIC CORR GPSA``
/ ``GPSB``) and each record's T_GD (IS-GPS-200 20.3.3.3.3.2). Read through the one parse of a
navigation file (``readers.navigation.georinex_navigation``).
"""

import functools
import os
from typing import NamedTuple

import numpy as np

from oaraim.readers import gpstime
from oaraim.readers.navigation import (
    NavigationFileError,
    georinex_navigation,
    navigation_file_key,
    navigation_systems,
)


class NavigationExtras(NamedTuple):
    """What the replay needs from a navigation file beyond the orbits and clocks."""

    alpha: np.ndarray | None  # (4,) Klobuchar alpha_0..3, or None if the header lacks them
    beta: np.ndarray | None  # (4,) Klobuchar beta_0..3
    tgd_sv: np.ndarray  # (R,) satellite id of each record
    tgd_time_s: np.ndarray  # (R,) t_oc of each record, GPS seconds
    tgd_s: np.ndarray  # (R,) T_GD of each record, seconds (0 where blank)


@functools.lru_cache(maxsize=8)
def _nav_extras(path_str, mtime_ns, size):
    _, ds = georinex_navigation(path_str, mtime_ns, size, ("G",))
    ion = ds.attrs.get("ionospheric_corr_GPS")
    alpha = beta = None
    if ion is not None:
        ion = np.asarray(ion, np.float64).ravel()
        if ion.size == 8 and np.all(np.isfinite(ion)) and np.any(ion != 0):
            alpha, beta = ion[:4].copy(), ion[4:].copy()
    svs = np.array([str(s) for s in ds["sv"].values])
    toc = gpstime.from_datetime64(ds["time"].values)
    tgd = (np.asarray(ds["TGD"].values, np.float64) if "TGD" in ds
           else np.zeros((toc.size, svs.size)))
    present = np.isfinite(np.asarray(ds["sqrtA"].values, np.float64))
    ti, sj = np.nonzero(present)
    rec_tgd = np.nan_to_num(tgd[ti, sj])
    return NavigationExtras(alpha, beta, svs[sj], toc[ti], rec_tgd)


def navigation_extras(path) -> NavigationExtras:
    """Klobuchar coefficients (header) and per-record T_GD of a GPS navigation file, or of
    several (``path`` a sequence: the first file's coefficients that has them, every GPS
    file's T_GD; files without GPS records are passed over).

    The Klobuchar coefficients are ``None`` when the header lacks ``ION ALPHA`` / ``ION BETA``
    (RINEX 2) or ``IONOSPHERIC CORR GPSA / GPSB`` (RINEX 3), or holds only zeros; the caller
    then decides (the replay applies no ionospheric correction and says so).
    """
    if not isinstance(path, (str, os.PathLike)):  # several files: those with GPS records
        parts = [navigation_extras(one) for one in path
                 if "G" in navigation_systems(*navigation_file_key(one))]
        if not parts:
            raise NavigationFileError("none of the navigation files holds GPS records; add "
                                      "the GPS (GN or mixed MN) file")
        with_ion = [x for x in parts if x.alpha is not None]
        ion = with_ion[0] if with_ion else parts[0]
        return NavigationExtras(ion.alpha, ion.beta,
                                *(np.concatenate([getattr(x, k) for x in parts])
                                  for k in ("tgd_sv", "tgd_time_s", "tgd_s")))
    return _nav_extras(*navigation_file_key(path))


def tgd_at(extras: NavigationExtras, sv, t_gps_s):
    """T_GD (seconds) of each satellite ``sv`` (S,) at times ``t_gps_s`` (T,): the value of the
    record whose t_oc is nearest (T_GD changes rarely; 0 for a satellite without records)."""
    t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
    out = np.zeros((t.size, len(sv)))
    for j, s in enumerate(sv):
        m = extras.tgd_sv == s
        if not m.any():
            continue
        toc, val = extras.tgd_time_s[m], extras.tgd_s[m]
        k = np.argmin(np.abs(t[:, None] - toc[None, :]), axis=1)
        out[:, j] = val[k]
    return out
