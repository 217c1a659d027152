"""BeiDou (BDS-2 / BDS-3) broadcast records of MEO and IGSO satellites from a RINEX 3 navigation
file, checked like every record by ``readers.check_navigation_file``; their orbits and clocks
are ``geometry.beidou_nav`` (``geometry.beidou_nav.load_beidou``). GEO satellites (C01-C05,
C59-C63) are left out: their broadcast orbit uses another transformation (BDS-SIS-ICD-B1I 3.0,
5.2.4.12) that the toolkit does not implement.

Time: BeiDou Time (BDT) starts at 2006-01-01 00:00:00 UTC, when GPS time was 14 s ahead of UTC
(ICD 4.1.2; 1356 weeks after the GPS epoch): t_GPS = t_BDT + 14 s. RINEX writes the BDT week
('BDT week') and t_oc in BDT (2023-01-01 00:00:00 BDT = 00:00:14 GPS, week 887); the records
are returned in GPS time (``toc_gps_s``, ``toe_gps_s``).
"""

import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from oaraim.constants import BDT_WEEK_OFFSET, GPS_MINUS_BDT_S
from oaraim.readers import gpstime
from oaraim.readers.navigation import NavigationFileError, georinex_navigation

#: GEO satellites (BDS-2 C01-C05, BDS-3 C59-C63): left out
GEO_PRNS = frozenset(range(1, 6)) | frozenset(range(59, 64))

_ELEMENTS = ("sqrtA", "Eccentricity", "Io", "IDOT", "Omega0", "OmegaDot", "omega", "M0",
             "DeltaN", "Cuc", "Cus", "Crc", "Crs", "Cic", "Cis", "SVclockBias", "SVclockDrift",
             "SVclockDriftRate", "TGD1", "TGD2", "health")


class BeidouRecords(NamedTuple):
    """The MEO and IGSO BeiDou records of a RINEX 3 navigation file (``read_beidou_records``)."""

    records: dict
    """Satellite name (``'C20'``) -> its records: field name (``sqrtA``, ``Eccentricity``, ...,
    ``TGD1``, ``TGD2``, ``health``, ``Toe``, ``BDTWeek``) -> (R,) array, with ``toc_gps_s``
    and ``toe_gps_s`` (GPS seconds); blank fields are 0."""
    path: Path
    """The file."""


def read_beidou_records(path: str | os.PathLike) -> BeidouRecords:
    """The BeiDou MEO and IGSO records of a RINEX 3 navigation file (plain or .gz).

    Raises:
      NavigationFileError: (a ValueError) naming the file when it is missing, malformed or
        holds no BeiDou MEO or IGSO record.
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise NavigationFileError(f"navigation file {str(path)!r} not found; give an "
                                  "existing RINEX 3 navigation file (plain or .gz)")
    st = os.stat(p)
    _info, ds = georinex_navigation(str(p.resolve()), st.st_mtime_ns, st.st_size, ("C",))
    toc_bdt = gpstime.from_datetime64(ds["time"].values)  # as written, BDT read as GPS seconds
    svs = [str(s) for s in ds["sv"].values]
    per_sat: dict = {}
    for j, sv in enumerate(svs):
        name = sv[:3]
        if int(name[1:]) in GEO_PRNS:
            continue
        vals = {n: np.asarray(ds[n].values[:, j], np.float64) for n in (*_ELEMENTS, "Toe",
                                                                         "BDTWeek")}
        have = np.isfinite(vals["sqrtA"]) & np.isfinite(vals["Toe"])
        if not have.any():
            continue
        rows = {n: v[have] for n, v in vals.items()}
        rows["toc_gps_s"] = toc_bdt[have] + GPS_MINUS_BDT_S
        week = np.where(np.isfinite(rows["BDTWeek"]), rows["BDTWeek"],
                        gpstime.week_tow(toc_bdt[have])[0] - BDT_WEEK_OFFSET)
        toe = gpstime.from_week_tow((week + BDT_WEEK_OFFSET).astype(np.int64), rows["Toe"])
        # a t_oe written with t_oc's week near a week boundary: the nearer week
        toe = toe - gpstime.SECONDS_PER_WEEK * np.round((toe - toc_bdt[have])
                                                        / gpstime.SECONDS_PER_WEEK)
        rows["toe_gps_s"] = toe + GPS_MINUS_BDT_S
        for n in rows:
            rows[n] = np.nan_to_num(rows[n])
        old = per_sat.get(name)
        per_sat[name] = rows if old is None else {n: np.concatenate([old[n], rows[n]])
                                                  for n in rows}
    if not per_sat:
        raise NavigationFileError(f"{p}: no BeiDou MEO or IGSO records")
    return BeidouRecords(per_sat, p)
