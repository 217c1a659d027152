"""RINEX 3 navigation records read by field position (RINEX 3.05 Tables A6-A16).

Why not georinex (the RINEX 2 parser of ``readers.navigation``): a navigation record is a fixed
grid of 19-column fields, and RINEX 3 lets a writer leave an optional or spare field blank or
fill it, and cut a line after its last written field. Merged files (the IGS ``BRDC00IGS``
daily file) mix records from several contributors, so one satellite's records differ in these
details. georinex 1.16 joins a record's lines into one string and maps the fields by the layout
of the satellite's *first* record; a blank field in the middle of a record (Galileo's spare on
BROADCAST ORBIT 5, written blank by some contributors) makes it drop the whole record with an
INFO log line only: 3,408 of the 5,390 Galileo records of ``BRDC00IGS_R_20240010000_01D_MN``
and 91 of its 452 GPS records were lost. It also reads RINEX 3.05 GLONASS records (5 lines) as 4.

Here each field is read at its own columns (record line j, field i: columns 4 + 19 i of line
j >= 1, 23 + 19 i of the first line), whatever the line length, and a blank field is NaN: the
layout of a record carries no meaning, its values do. The structural and semantic checks
(numbers where numbers belong, required orbital elements, times, duplicates) are
``readers.check_navigation_file``'s; this module assumes a checked text.
"""

import datetime

import numpy as np

#: field names per system, in record order (first line: 3 fields, then 4 per line). Keplerian
#: systems: RINEX 3.05 Tables A6 (GPS), A8 (Galileo), A10 (QZSS), A12 (BeiDou), A14 (NavIC);
#: GLONASS A10 / SBAS A16 (positions in km as in the file)
_KEPLER_ORBIT = ("Crs", "DeltaN", "M0", "Cuc", "Eccentricity", "Cus", "sqrtA", "Toe", "Cic",
                 "Omega0", "Cis", "Io", "Crc", "omega", "OmegaDot", "IDOT")
_CLOCK = ("SVclockBias", "SVclockDrift", "SVclockDriftRate")
FIELDS = {
    "G": (*_CLOCK, "IODE", *_KEPLER_ORBIT, "CodesL2", "GPSWeek", "L2Pflag", "SVacc", "health",
          "TGD", "IODC", "TransTime", "FitIntvl", "spare0", "spare1"),
    "J": (*_CLOCK, "IODE", *_KEPLER_ORBIT, "CodesL2", "GPSWeek", "L2Pflag", "SVacc", "health",
          "TGD", "IODC", "TransTime", "FitIntvl", "spare0", "spare1"),
    "E": (*_CLOCK, "IODnav", *_KEPLER_ORBIT, "DataSrc", "GALWeek", "spare0", "SISA", "health",
          "BGDe5a", "BGDe5b", "TransTime", "spare1", "spare2", "spare3"),
    "C": (*_CLOCK, "AODE", *_KEPLER_ORBIT, "spare0", "BDTWeek", "spare1", "SVacc", "health",
          "TGD1", "TGD2", "TransTime", "AODC", "spare2", "spare3"),
    "I": (*_CLOCK, "IODEC", *_KEPLER_ORBIT, "spare0", "IRNWeek", "spare1", "URA", "health",
          "TGD", "spare2", "TransTime", "spare3", "spare4", "spare5"),
    "R": ("TauN", "GammaN", "MessageFrameTime", "X_km", "dX_km_s", "dX2_km_s2", "health",
          "Y_km", "dY_km_s", "dY2_km_s2", "FreqNum", "Z_km", "dZ_km_s", "dZ2_km_s2", "AgeOpInfo",
          "StatusFlags", "DelayL1L2", "URAI", "HealthFlags"),
    "S": ("aGf0", "aGf1", "MessageFrameTime", "X_km", "dX_km_s", "dX2_km_s2", "health",
          "Y_km", "dY_km_s", "dY2_km_s2", "URA", "Z_km", "dZ_km_s", "dZ2_km_s2", "IODN"),
}


def record_lines(sysch: str, version: float) -> int:
    """Lines of one navigation record of system ``sysch`` in a RINEX ``version`` file: 8 for the
    Keplerian systems, 4 for SBAS, 4 for GLONASS up to 3.04 and 5 from 3.05 on (a line of
    status flags, L1/L2 delay difference, URAI and health flags was added)."""
    if sysch == "R":
        return 5 if version >= 3.05 - 1e-9 else 4
    return 4 if sysch == "S" else 8


def record_meaning(sysch: str, values) -> tuple:
    """What identifies a record's content for the duplicate check: its values in field order
    (``FIELDS[sysch]``), spare fields left out and a blank (NaN) kept as None, so two records
    that differ only in layout (a spare written as 0 or left blank, a line cut after its last
    field) are the same record."""
    names = FIELDS.get(sysch, ())
    return tuple(None if v != v else v for i, v in enumerate(values)
                 if i >= len(names) or not names[i].startswith("spare"))


def _field(line: str, a: int) -> float:
    text = line[a:a + 19].strip()
    return float(text.replace("D", "E").replace("d", "e")) if text else np.nan


def record_values(lines: list[str], start: int, sysch: str, version: float) -> np.ndarray:
    """The values of the record whose first line is ``lines[start]`` (0-based), in the order
    of ``FIELDS[sysch]``; NaN where a field is blank or the line ends before it."""
    n = record_lines(sysch, version)
    out = [_field(lines[start], 23 + 19 * i) for i in range(3)]
    for j in range(1, n):
        out += [_field(lines[start + j], 4 + 19 * i) for i in range(4)]
    return np.asarray(out[:len(FIELDS[sysch])], np.float64)


def record_time(line: str) -> np.datetime64:
    """t_oc of a record's first line ('Snn YYYY MM DD hh mm ss'), as written (the system's
    own time scale: GPS, GST, BDT...)."""
    return np.datetime64(datetime.datetime(int(line[4:8]), int(line[9:11]), int(line[12:14]),
                                           int(line[15:17]), int(line[18:20]),
                                           int(line[21:23])), "ns")


def ionospheric_corrections(header: list[str]) -> dict:
    """``IONOSPHERIC CORR`` records of a RINEX 3 header: {'GPSA': (4,), 'GPSB': (4,), 'GAL':
    (3,), ...}, the first record of each type (merged files repeat BeiDou's per satellite); a
    blank coefficient is NaN."""
    out = {}
    for line in header:
        if line[60:80].strip() != "IONOSPHERIC CORR":
            continue
        kind = line[:4].strip()
        n = 3 if kind == "GAL" else 4
        if kind not in out:
            vals = [line[5 + 12 * i:17 + 12 * i].strip() for i in range(n)]
            out[kind] = np.array([float(v.replace("D", "E")) if v else np.nan for v in vals])
    return out


def navigation_dataset(lines: list[str], index, systems, version: float, header_lines: int,
                       name: str = ""):
    """The records of ``systems`` as an xarray Dataset shaped as georinex's (dimensions time x
    sv, one variable per field of ``FIELDS``, NaN where a satellite has no record at a time;
    records of one satellite sharing a t_oc, such as Galileo's I/NAV and F/NAV, become
    satellites 'E01', 'E01_1', ...), attrs ``ionospheric_corr_GPS`` (alpha, beta) and
    ``ionospheric_corr_GAL`` when the header has them, ``version``.

    Args:
      lines: the checked text's lines.
      index: ``check_navigation_file``'s ``index``: (satellite id, t_oc, 1-based line) per record.
      systems: system letters to keep.
      version: the RINEX version of the header.
      header_lines: lines of the header, ``END OF HEADER`` included.
      name: the file name for ``attrs['filename']``.
    """
    import xarray as xr

    by_sv: dict = {}
    for sv_id, _toc, lineno in index:
        if sv_id[0] in systems:
            by_sv.setdefault(sv_id, []).append(lineno - 1)
    columns = []  # (column name, system, [(time, values)])
    for sv_id in sorted(by_sv):
        copies: list = []
        for k in by_sv[sv_id]:
            t = record_time(lines[k])
            vals = record_values(lines, k, sv_id[0], version)
            slot = next((c for c in copies if t not in c), None)
            if slot is None:
                slot = {}
                copies.append(slot)
            slot[t] = vals
        for n, c in enumerate(copies):
            columns.append((sv_id if n == 0 else f"{sv_id}_{n}", sv_id[0], c))
    times = np.array(sorted({t for _, _, c in columns for t in c}), dtype="datetime64[ns]")
    t_pos = {t: i for i, t in enumerate(times)}
    names = [f for s in sorted({s for _, s, _ in columns}) for f in FIELDS[s]]
    names = list(dict.fromkeys(names))
    arrays = {f: np.full((times.size, len(columns)), np.nan) for f in names}
    for j, (_, sysch, c) in enumerate(columns):
        for t, vals in c.items():
            for f, v in zip(FIELDS[sysch], vals, strict=True):
                arrays[f][t_pos[t], j] = v
    ds = xr.Dataset({f: (("time", "sv"), a) for f, a in arrays.items()},
                    coords={"time": times, "sv": [c[0] for c in columns]})
    iono = ionospheric_corrections(lines[:header_lines])
    if "GPSA" in iono and "GPSB" in iono:
        ds.attrs["ionospheric_corr_GPS"] = np.hstack((iono["GPSA"], iono["GPSB"]))
    if "GAL" in iono:
        ds.attrs["ionospheric_corr_GAL"] = iono["GAL"]
    ds.attrs["version"] = version
    ds.attrs["filename"] = name
    return ds
