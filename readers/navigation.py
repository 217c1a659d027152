"""GPS and Galileo broadcast ephemerides from RINEX 2 / 3 navigation files: the records.

Parsing: after a check of our own that names the file and line of anything malformed or
truncated, RINEX 2 files by georinex, RINEX 3 files by field position
(``readers.rinex_nav3``: georinex drops merged-file records that leave optional fields blank).
Plain or gzipped files. ``read_navigation`` returns the records as arrays
(``NavigationRecords``); the orbits are computed from them in ``oaraim.geometry``
(``geometry.load_navigation`` -> ``geometry.Ephemeris``: the record choice per epoch and
satellite, the health rules and the Kepler propagation, ``geometry.kepler``).

A record that is no orbit at all (e outside [0, 1), sqrt(A) <= 0, a blank orbital element, a
number that is not finite), a GPS or Galileo record whose orbit is not one its constellation
flies (semi-major axis, eccentricity, inclination: ``readers.orbit_limits``; such records used
to be dropped, counted only in an attribute), a record given twice, or a second GPS record of a
satellite at the same t_oc (Galileo: and the same data source) is an error naming the file and
line.
"""

import collections
import datetime
import functools
import gzip
import io
import os
import re
import warnings
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from oaraim.readers import gpstime, rinex_nav3, rinex_text
from oaraim.readers.orbit_limits import ORBIT_LIMITS, implausible_orbit

#: constellation codes of ``geometry.sky`` (DESIGN.md: GPS 0, Galileo 1)
GPS, GALILEO = 0, 1
SYSTEM_CODES = {"G": GPS, "E": GALILEO}
SYSTEM_NAMES = {GPS: "GPS", GALILEO: "Galileo"}

#: default validity window |t - t_oe| for choosing a record (``geometry.Ephemeris``)
DEFAULT_MAX_AGE_S = 4 * 3600.0

#: the largest eccentricity of a record that loads (``readers.orbit_limits``: GPS 0.05,
#: Galileo 0.2, for E14/E18 at ~0.16)
E_MAX = max(lim.e_max for lim in ORBIT_LIMITS.values())

#: record fields kept per record besides the orbit and clock, readable with
#: ``Ephemeris.record_field`` (RINEX 3.05 Tables A6/A8: GPS T_GD; Galileo data source, BGDs, SISA)
RECORD_FIELDS = ("TGD", "DataSrc", "BGDe5a", "BGDe5b", "SISA")
#: Galileo data-source masks (RINEX 3.05 Table A8, field 'Data sources'): I/NAV records set
#: bit 0 (E1-B) and/or bit 2 (E5b-I), F/NAV records bit 1 (E5a-I)
GALILEO_SOURCES = {"inav": 0b101, "fnav": 0b010}

#: RINEX 3 systems of navigation records (lines per record: ``rinex_nav3.record_lines``)
_RINEX3_LINES = {"G": 8, "E": 8, "C": 8, "J": 8, "I": 8, "R": 4, "S": 4}
_FIELD = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([EeD][-+]?\d+)?\s*$")
_INT = re.compile(r"^\s*[-+]?\d+\s*$")
#: header records georinex reads as numbers: (label, RINEX 3?) -> [(start, end, int?)]
_HEADER_NUMBERS = {
    ("ION ALPHA", False): [(2 + 12 * i, 14 + 12 * i, False) for i in range(4)],
    ("ION BETA", False): [(2 + 12 * i, 14 + 12 * i, False) for i in range(4)],
    ("IONOSPHERIC CORR", True): [(5 + 12 * i, 17 + 12 * i, False) for i in range(4)],
    ("TIME SYSTEM CORR", True): [(5, 22, False), (22, 38, False), (38, 45, True),
                                 (45, 50, True)],
}


class NavigationFileError(ValueError):
    """A navigation file that cannot be read: names the file, the line and how to fix it."""


def _check_fields(path, lineno, line, start, n_fields, required=()):
    """The 19-character D/E-format numeric fields of a data line: blank or a finite number
    (fields ``required`` not blank). Returns the values (NaN where blank)."""
    values = []
    for k in range(n_fields):
        a, b = start + 19 * k, start + 19 * (k + 1)
        field = line[a:b]
        if not field.strip():
            if k in required:
                raise NavigationFileError(
                    f"{path}: line {lineno}, columns {a + 1}-{b}: an orbital element is blank; "
                    "the record is incomplete (re-download the file or fix that record)")
            values.append(float("nan"))
            continue
        if not _FIELD.match(field):
            raise NavigationFileError(
                f"{path}: line {lineno}, columns {a + 1}-{b}: cannot read {field.strip()!r} as a "
                "number; the file is malformed (re-download it or fix that record)")
        x = float(field.strip().replace("D", "E"))
        if not np.isfinite(x):
            raise NavigationFileError(
                f"{path}: line {lineno}, columns {a + 1}-{b}: {field.strip()!r} is not a finite "
                "number; the file is malformed (re-download it or fix that record)")
        values.append(x)
    return values


#: fields that must not be blank in a Keplerian record (GPS, Galileo, BeiDou, QZSS, NavIC),
#: per data line 1..7: IODE/IODnav and the orbit (Crs .. OmegaDot), IDOT, the health word
_REQUIRED_KEPLER = {1: (0, 1, 2, 3), 2: (0, 1, 2, 3), 3: (0, 1, 2, 3), 4: (0, 1, 2, 3),
                    5: (0,), 6: (1,)}


def _check_epoch(path, lineno, date, rinex3):
    """A record's t_oc: 'YYYY MM DD hh mm ss' (RINEX 3) or 'YY MM DD hh mm ss.s' (RINEX 2,
    I2.2,4(1X,I2),F5.1), a valid date and time."""
    pattern = (r"(\d{4}) ([ \d]\d) ([ \d]\d) ([ \d]\d) ([ \d]\d) ([ \d]\d)" if rinex3 else
               r" ([ \d]\d) ([ \d]\d) ([ \d]\d) ([ \d]\d) ([ \d]\d)( [ \d]\d\.\d)")
    m = re.fullmatch(pattern, date)
    try:
        if m is None:
            raise ValueError("not in the record's date format")
        year = int(m[1]) if rinex3 else 2000 + int(m[1]) if int(m[1]) < 80 else 1900 + int(m[1])
        sec = float(m[6])
        day = datetime.datetime(year, int(m[2]), int(m[3]), int(m[4]), int(m[5]))
        if not sec < 60:
            raise ValueError("second out of range")
    except ValueError as e:
        raise NavigationFileError(
            f"{path}: line {lineno}: cannot read the record epoch {date.strip()!r} ({e})") from None
    return gpstime.gps_seconds(day.year, day.month, day.day, day.hour, day.minute, sec)


def _navigation_text(path: Path) -> str:
    """The file (plain or .gz) as the text both the check and georinex read: a UTF-8
    byte-order mark dropped, bytes that are not ASCII as U+FFFD (so that they fail the field
    checks instead of being dropped and shifting columns), line ends as "\n"."""
    try:
        raw = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
    except (OSError, EOFError, zlib.error) as e:
        raise NavigationFileError(f"{path}: cannot read the file ({e}); check the path and that "
                                  "a .gz file is complete") from None
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    return raw.decode("ascii", errors="replace").replace("\r\n", "\n").replace("\r", "\n")


def check_navigation_file(path: str | os.PathLike) -> dict:
    """Structural check of a RINEX 2 (GPS) or 3 navigation file before georinex parses it.

    Returns the header facts ``{"version", "records", "systems"}``. Raises
    ``NavigationFileError`` naming the file and the line for a missing or malformed header, a
    record whose first line is not a record start, a non-numeric field, or a file that ends
    inside a record (truncated download).
    """
    return _check_navigation_text(Path(path), _navigation_text(Path(path)))


def _check_navigation_text(path: Path, text: str) -> dict:
    lines = text.split("\n")
    if lines and not lines[-1]:
        lines.pop()
    if not lines:
        raise NavigationFileError(f"{path}: line 1: the file is empty")
    head = lines[0]
    version = rinex_text.header_version(path, head, NavigationFileError)
    file_type = head[20:21]
    if head[60:80].rstrip() != "RINEX VERSION / TYPE" or file_type not in ("N", "n"):
        raise NavigationFileError(
            f"{path}: line 1: not a RINEX navigation file (type {file_type!r} in column 21; "
            "GPS RINEX 2 'N' or RINEX 3 'N' files are supported)")
    if not (2.0 <= version < 4.0):
        raise NavigationFileError(f"{path}: line 1: RINEX version {version:g} is not supported "
                                  "(2.x and 3.x are)")
    end = next((k for k, s in enumerate(lines) if "END OF HEADER" in s[60:80]), None)
    if end is None:
        raise NavigationFileError(f"{path}: line {len(lines)}: no 'END OF HEADER' line; the "
                                  "header is truncated or malformed")
    rinex3 = version >= 3.0
    for k in range(1, end):
        spans = _HEADER_NUMBERS.get((lines[k][60:80].strip(), rinex3), ())
        if lines[k][:4] == "GAL ":  # Galileo's ionospheric model has three coefficients
            spans = spans[:3]
        for a, b, integer in spans:
            field = lines[k][a:b]
            x = _INT.match(field) if integer else _FIELD.match(field)
            if x is None or not integer and not np.isfinite(float(field.replace("D", "E"))):
                raise NavigationFileError(
                    f"{path}: line {k + 1}, columns {a + 1}-{b}: cannot read {field.strip()!r} "
                    f"as a number in the header record {lines[k][60:80].strip()!r}")
    k, records, systems = end + 1, 0, set()
    seen_text, seen_key, index = {}, {}, []
    while k < len(lines):
        line = lines[k]
        if not line.strip():
            k += 1
            continue
        if rinex3:
            sysch = line[0]
            if sysch not in _RINEX3_LINES or not line[1:3].strip().isdigit():
                raise NavigationFileError(
                    f"{path}: line {k + 1}: expected a record start 'Snn YYYY MM DD hh mm ss' "
                    f"(system letter and satellite number), got {line[:23]!r}")
            n_lines = rinex_nav3.record_lines(sysch, version)
            first_start, data_start = 23, 4
        else:
            sysch = "G"
            if not line[0:2].strip().isdigit():
                raise NavigationFileError(
                    f"{path}: line {k + 1}: expected a record start 'PRN YY MM DD hh mm ss.s', "
                    f"got {line[:22]!r}")
            n_lines, first_start, data_start = 8, 22, 3
        if k + n_lines > len(lines):
            raise NavigationFileError(
                f"{path}: line {len(lines)}: the file ends inside the record that starts at "
                f"line {k + 1} ({line[:3].strip()}): {n_lines} lines expected, "
                f"{len(lines) - k} present; the file is truncated (re-download it)")
        date = line[4:23] if rinex3 else line[2:22]
        toc_s = _check_epoch(path, k + 1, date, rinex3)
        kepler = n_lines == 8
        if rinex3:
            clock = _check_fields(path, k + 1, line, first_start, 3)
            required = _REQUIRED_KEPLER if kepler else {}
        else:  # georinex reads every field of a RINEX 2 record but the last line's spares
            clock = _check_fields(path, k + 1, line, first_start, 3, (0, 1, 2))
            required = {j: (0, 1, 2, 3) for j in range(1, 7)} | {7: (0,)}
        for j in range(n_lines):
            text = lines[k + j]
            bad = next((c for c, ch in enumerate(text) if not " " <= ch <= "~"), None)
            if bad is None and j > 0 and text[:data_start].strip():
                bad = 0
            if bad is None and text[data_start + 76 if j else first_start + 57:].strip():
                bad = (data_start + 76) if j else first_start + 57
            if bad is not None:
                raise NavigationFileError(
                    f"{path}: line {k + j + 1}, column {bad + 1}: unexpected character "
                    f"{text[bad]!r} (a record line holds its number fields and blanks only)")
        orbit = [_check_fields(path, k + j + 1, lines[k + j], data_start, 4,
                               required.get(j, ()))
                 for j in range(1, n_lines)]
        if kepler:  # e and sqrt(A): BROADCAST ORBIT 2, fields 2 and 4
            e, sqrt_a = orbit[1][1], orbit[1][3]
            col = data_start + 19
            if not 0.0 <= e < 1.0:
                raise NavigationFileError(
                    f"{path}: line {k + 3}, columns {col + 1}-{col + 19}: eccentricity {e!r} is "
                    "outside [0, 1): not an orbit (re-download the file or fix that record)")
            if not sqrt_a > 0.0:
                col += 38
                raise NavigationFileError(
                    f"{path}: line {k + 3}, columns {col + 1}-{col + 19}: sqrt(A) {sqrt_a!r} is "
                    "not positive: not an orbit (re-download the file or fix that record)")
            bad = implausible_orbit(sysch, sqrt_a, e, orbit[3][0])  # i0: ORBIT 4, field 1
            if bad is not None:
                row, col = {"sqrt_a": (k + 3, col + 38), "e": (k + 3, col),
                            "i": (k + 5, data_start)}[bad[0]]
                sv = line[:3] if rinex3 else f"G{int(line[:2]):02d}"
                raise NavigationFileError(
                    f"{path}: line {row}, columns {col + 1}-{col + 19}: {sv}: {bad[1]} "
                    "(re-download the file or fix that record)")
        # a record is its values, not its layout: optional fields written or left blank, lines
        # cut after their last field (merged files mix contributors' layouts)
        text = (line[:3], date, rinex_nav3.record_meaning(sysch, clock + sum(orbit, [])))
        if text in seen_text:
            raise NavigationFileError(
                f"{path}: line {k + 1}: the record of {line[:3].strip()} repeats the record at "
                f"line {seen_text[text]} exactly: a duplicated record (remove one)")
        seen_text[text] = k + 1
        # GPS: one record per satellite and t_oc; Galileo: per t_oc and data source (I/NAV and
        # F/NAV records share a t_oc; BROADCAST ORBIT 5, field 2)
        key = None
        if sysch == "G":
            key = (line[:3].strip(), date)
        elif sysch == "E":
            key = (line[:3], date, orbit[4][1])
        if key is not None:
            if key in seen_key:
                raise NavigationFileError(
                    f"{path}: line {k + 1}: a second record of {line[:3].strip()} at "
                    f"{date.strip()!r} (the first is at line {seen_key[key]}), with other "
                    "values: ambiguous (remove one)")
            seen_key[key] = k + 1
        sv_id = sysch + line[1:3].replace(" ", "0") if rinex3 else f"G{int(line[:2]):02d}"
        index.append((sv_id, round(float(toc_s), 3), k + 1))
        records += 1
        systems.add(sysch)
        k += n_lines
    if records == 0:
        raise NavigationFileError(f"{path}: line {len(lines)}: the file has a header but no "
                                  "navigation records")
    return {"version": version, "records": records, "systems": sorted(systems),
            "index": index, "header_lines": end + 1}


_SYSTEM_NAMES = {"G": "GPS", "E": "Galileo"}


@functools.lru_cache(maxsize=4)
def georinex_navigation(path_str: str, mtime_ns: int, size: int, systems: tuple):
    """(``check_navigation_file`` info, Dataset of the ``systems`` records present: georinex's
    for RINEX 2, ``rinex_nav3.navigation_dataset`` (the same shape) for RINEX 3),
    cached per (file, mtime, size, systems): the one place a navigation file is parsed, shared
    by ``read_navigation`` and ``readers.navigation_extras``.

    Raises ``NavigationFileError`` naming the file when it is malformed, holds none of
    ``systems``, or georinex cannot parse it.
    """
    import georinex

    text = _navigation_text(Path(path_str))
    info = _check_navigation_text(Path(path_str), text)
    use = [s for s in systems if s in info["systems"]]
    if not use:
        wanted = " or ".join(_SYSTEM_NAMES.get(s, s) for s in systems)
        raise NavigationFileError(
            f"{path_str}: no {wanted} records (the file holds "
            f"{', '.join(info['systems'])}); give a file with {wanted} ephemerides")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # georinex/xarray FutureWarnings on merge defaults
        try:
            # georinex reads the checked text, not the file: the same lines, a BOM dropped
            ds = (rinex_nav3.navigation_dataset(text.split("\n"), info["index"], use,
                                                info["version"], info["header_lines"],
                                                Path(path_str).name)
                  if info["version"] >= 3 else georinex.load(io.StringIO(text)))
        except Exception as e:  # georinex raises assorted types; one message for the user
            raise NavigationFileError(f"{path_str}: georinex could not parse the file "
                                      f"({type(e).__name__}: {e})") from None
    return info, ds


@functools.lru_cache(maxsize=16)
def _parsed_records(path_str: str, mtime_ns: int, size: int, systems: tuple):
    """georinex parse -> flat NumPy record table, cached per (file, mtime, size, systems).

    georinex needs ~2 s for a daily multi-GNSS RINEX 3 file on these machines (0.05 s for a
    RINEX 2 GPS file); a study, a test module or the benchmark that loads the same file again
    gets it from here.
    """
    info, ds = georinex_navigation(path_str, mtime_ns, size, systems)
    table = _record_table(ds, systems, path_str)
    # every checked record must be in georinex's result (georinex skips what it cannot read,
    # e.g. "malformed line", with a log message only)
    got = collections.Counter(zip(table["sv"].tolist(), np.round(table["toc_s"], 3).tolist(),
                                  strict=True))
    for sv_id, toc_s, lineno in info["index"]:
        if sv_id[0] not in systems:
            continue
        if got[(sv_id, toc_s)] == 0:
            raise NavigationFileError(f"{path_str}: line {lineno}: georinex did not read the "
                                      f"record of {sv_id}; the record is malformed")
        got[(sv_id, toc_s)] -= 1
    return table


def _var(ds, name, n_time, n_sv):
    if name in ds:
        return np.asarray(ds[name].values, np.float64)
    return np.full((n_time, n_sv), np.nan)


def _record_table(ds, systems, path_str):
    svs = [str(s) for s in ds["sv"].values]
    nt, ns = ds.sizes["time"], len(svs)
    toc = gpstime.from_datetime64(ds["time"].values)
    names = ("SVclockBias", "SVclockDrift", "SVclockDriftRate", "Crs", "DeltaN", "M0", "Cuc",
             "Eccentricity", "Cus", "sqrtA", "Toe", "Cic", "Omega0", "Cis", "Io", "Crc", "omega",
             "OmegaDot", "IDOT", "health", "GPSWeek", "GALWeek", *RECORD_FIELDS)
    v = {n: _var(ds, n, nt, ns) for n in names}
    rows = []
    for j, sv in enumerate(svs):
        sysch = sv[0]
        if sysch not in systems:
            continue
        week = v["GPSWeek"][:, j] if sysch == "G" else v["GALWeek"][:, j]
        present = np.isfinite(v["sqrtA"][:, j]) & np.isfinite(v["Toe"][:, j])
        for i in np.flatnonzero(present):
            rows.append((sv[:3], i, j, week[i]))
    if not rows:
        raise NavigationFileError(f"{path_str}: no usable {'/'.join(systems)} records")
    sv_name = np.array([r[0] for r in rows])
    ti = np.array([r[1] for r in rows])
    sj = np.array([r[2] for r in rows])
    week = np.array([r[3] for r in rows])
    table = {n: v[n][ti, sj] for n in names if n not in ("GPSWeek", "GALWeek")}
    table["sv"] = sv_name
    table["toc_s"] = toc[ti]
    week = np.where(np.isfinite(week), week, gpstime.week_tow(toc[ti])[0])
    week = gpstime.resolve_week(week.astype(np.int64), toc[ti])
    toe_abs = gpstime.from_week_tow(week, table["Toe"])
    # a t_oe more than half a week from t_oc belongs to the neighbouring week (week numbers
    # written with t_oc's week near a week boundary)
    toe_abs = toe_abs - gpstime.SECONDS_PER_WEEK * np.round((toe_abs - table["toc_s"])
                                                            / gpstime.SECONDS_PER_WEEK)
    table["toe_s"] = toe_abs
    table["health"] = np.where(np.isfinite(table["health"]), table["health"], 0.0)
    for arr in table.values():
        if arr.dtype.kind == "f":
            np.nan_to_num(arr, copy=False)  # blank optional fields (e.g. a_f2) read as NaN
    return table


def navigation_file_key(path) -> tuple:
    """(resolved path, mtime ns, size) of a navigation file: the key of the parse caches; a
    missing file is a ``NavigationFileError`` in one line."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise NavigationFileError(f"navigation file {str(path)!r} not found; give an existing "
                                  "RINEX 2/3 navigation file (plain or .gz)")
    st = os.stat(p)
    return str(p.resolve()), st.st_mtime_ns, st.st_size


@functools.lru_cache(maxsize=16)
def navigation_systems(path_str, mtime_ns, size):
    """The system letters whose records a navigation file holds (its structural check),
    cached per (resolved path, mtime, size)."""
    text = _navigation_text(Path(path_str))
    return tuple(_check_navigation_text(Path(path_str), text)["systems"])


def _merged(tables):
    """Record tables of several files as one; a record in more than one file (same satellite,
    t_oc, t_oe and data source) kept once, the first file's."""
    keys = tables[0].keys()
    t = {k: np.concatenate([tb[k] for tb in tables]) for k in keys}
    src = np.nan_to_num(np.asarray(t["DataSrc"], np.float64)) if "DataSrc" in t else 0.0
    ident = np.rec.fromarrays([t["sv"].astype(str), np.round(t["toc_s"], 3),
                               np.round(t["toe_s"], 3),
                               np.broadcast_to(src, t["toc_s"].shape)])
    _, first = np.unique(ident, return_index=True)
    keep = np.sort(first)
    return {k: v[keep] for k, v in t.items()}


class NavigationRecords(NamedTuple):
    """The broadcast records of one navigation file, or of several read as one
    (``read_navigation``)."""

    records: dict
    """Record table: name -> (R,) array, one entry per record: ``sv`` (satellite names such as
    ``'G05'``), ``toc_s`` and ``toe_s`` (GPS seconds), ``health`` (0 healthy), the orbit and
    clock fields under their RINEX/georinex names (``sqrtA``, ``Eccentricity``, ``Io``,
    ``IDOT``, ``Omega0``, ``OmegaDot``, ``omega``, ``M0``, ``DeltaN``, ``Cuc`` ... ``Cis``,
    ``SVclockBias``, ``SVclockDrift``, ``SVclockDriftRate``; SI units, radians) and those of
    ``RECORD_FIELDS`` the file has."""
    path: Path
    """The file (several: their names joined by ``' + '``)."""


def read_navigation(path: str | os.PathLike | Sequence[str | os.PathLike],
                    systems: Sequence[str] = ("G", "E"),
                    galileo_source: str | None = None) -> NavigationRecords:
    """The broadcast records of a RINEX 2 (GPS) or RINEX 3 navigation file (plain or .gz), or
    of several files read as one (a station's separate GPS ``GN`` and Galileo ``EN`` files, or
    consecutive days): their records merged, a record present in more than one file (same
    satellite, t_oc, t_oe and data source) kept once. ``geometry.load_navigation`` makes the
    orbits of them.

    Args:
      path: the file, or a sequence of files (each keeps the systems of ``systems`` it has;
        a file with none of them is passed over, and none at all is an error).
      systems: RINEX system letters to keep ('G' GPS, 'E' Galileo).
      galileo_source: None (every Galileo record, I/NAV and F/NAV alike), 'fnav' (only F/NAV
        records: clock for E1/E5a) or 'inav' (only I/NAV: clock for E1/E5b), see
        ``readers.galileo_nav``.

    Raises:
      NavigationFileError: (a ValueError) naming the file and line when the file is missing,
        malformed or truncated.
    """
    paths = ([path] if isinstance(path, (str, os.PathLike)) else list(path))
    if not paths:
        raise NavigationFileError("no navigation file given; give a RINEX 2/3 navigation file "
                                  "(plain or .gz) or several")
    bad = [s for s in systems if s not in SYSTEM_CODES]
    if bad:
        raise ValueError(f"systems must be among 'G' (GPS) and 'E' (Galileo), got {bad}")
    if galileo_source is not None and galileo_source not in GALILEO_SOURCES:
        raise ValueError(f"galileo_source must be None, 'inav' or 'fnav', got {galileo_source!r}")
    tables = []
    for one in paths:
        key = navigation_file_key(one)
        use = systems
        if len(paths) > 1:  # each file keeps the systems it has
            use = tuple(x for x in systems if x in navigation_systems(*key))
            if not use:
                continue
        tables.append(_parsed_records(*key, tuple(use)))
    if not tables:
        raise NavigationFileError(f"{', '.join(str(x) for x in paths)}: no "
                                  f"{'/'.join(systems)} records in any of the files; add the "
                                  "navigation file of those systems")
    table = tables[0] if len(tables) == 1 else _merged(tables)
    p = Path(paths[0]).expanduser() if len(paths) == 1 else Path(
        " + ".join(Path(x).name for x in paths))
    if galileo_source is not None:
        gal = np.char.startswith(table["sv"].astype(str), "E")
        src = table["DataSrc"].astype(np.int64) & GALILEO_SOURCES[galileo_source]
        keep = ~gal | (src != 0)
        if not keep.any():
            raise NavigationFileError(f"{p}: no {galileo_source} Galileo records to load")
        table = {k: v[keep] for k, v in table.items()}
    return NavigationRecords(table, p)
