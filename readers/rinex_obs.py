"""RINEX 2/3 observation files: a strict reader of the observation format.

Forms read: plain text, gzip (``.gz``), Hatanaka-compressed RINEX (CRINEX 1 / 3, ``.crx``,
``.d``), alone or under gzip or Unix compress, decoded with the ``hatanaka`` package (the
maintained decoder; a truncated or garbled CRINEX file is an error naming the file and the
CRINEX line the decoder stopped at). Errors inside the decoded text name lines of that text
("line 1234 of the decompressed text"). One file or several of one receiver (hourly files of a
day): ``read_observation_table([a, b, ...])``.

``read_observation_table``: every observation of every system and type the header declares
(``readers.ObservationTable``: GPS, Galileo, BeiDou, GLONASS, QZSS, SBAS,
NavIC; code, carrier, Doppler, C/N0), NaN where blank.

Reading (``read_observations``): our own reader of the RINEX 2.11 / 3.04 observation format
(RINEX 2.11 Table A2, RINEX 3.04 Table A3), strict by default: every header record it uses,
every epoch line, satellite list and F14.3 observation field is checked, each epoch must have
the lines it announces and a later time than the one before, and the file must end with a line
break, so a truncated, garbled or duplicated epoch is an ``ObservationFileError`` naming the
file and line instead of a silently shorter result (georinex, used before, dropped a garbled
epoch without a word and named no line). ``lenient=True`` skips such epochs and reports each
one (``ObservationFileWarning``). Returns arrays: GPS times of the epochs
(receiver time tags; RINEX observation epochs are in GPS time for GPS files), satellite ids,
L1 code pseudoranges (RINEX 2: C1, gaps filled from P1; RINEX 3: C1C, then C1W / C1P / C1X)
and the header's APPROX POSITION XYZ. ``read_observations`` keeps GPS only (the L1 replay);
Galileo E1 needs its own group delay (BGD), the later dual-frequency replay's work.

The GNSS pseudorange model of real-data replay (transmit-time satellite states, Sagnac,
receiver terms) is ``geometry.pseudorange_model``; the navigation extras it takes (Klobuchar
coefficients, T_GD) are read by ``readers.navigation_extras``.
"""

import datetime
import functools
import math
import os
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from oaraim.readers import rinex_text
from oaraim.readers.observation_table import ObservationTable, decode_fields, merge_tables

#: L1 code observables in order of preference (RINEX 2.11 section 5.1; RINEX 3.03 5.2.17)
RINEX2_L1_CODES = ("C1", "P1")
RINEX3_L1_CODES = ("C1C", "C1W", "C1P", "C1X", "C1Y", "C1S", "C1L")

#: a pseudorange outside this span (metres) is not a GPS code measurement (GPS ranges are
#: 19,100-25,600 km; receivers may add a clock offset of up to ~1 ms = 300 km)
PSEUDORANGE_SPAN_M = (1.8e7, 3.0e7)


class ObservationFileError(ValueError):
    """An observation file that cannot be used: names the file, the line and what is wrong."""


class ObservationFileWarning(UserWarning):
    """An epoch skipped by ``read_observations(..., lenient=True)``: names the file and line."""


class Observations(NamedTuple):
    """What ``read_observations`` returns: L1 code pseudoranges of the GPS satellites over
    the epochs, with the header facts the replay uses."""

    t_gps_s: np.ndarray  # (T,) receiver time tags, GPS seconds
    sv: np.ndarray  # (S,) satellite ids such as 'G05'
    pseudorange_m: np.ndarray  # (T, S) L1 code pseudorange; 0 where not valid
    valid: np.ndarray  # (T, S) bool: observed and plausible
    code: str  # observable used ('C1', 'C1C', ...); 'C1+P1' if gaps were filled
    approx_position_m: np.ndarray | None  # (3,) header APPROX POSITION XYZ, or None
    interval_s: float | None
    version: float
    marker: str
    path: str
    skipped: tuple = ()  # lenient reads: one message per skipped epoch (file and line)


#: a header longer than this many lines is not a RINEX header
_MAX_HEADER_LINES = 5000
#: RINEX satellite system letters (RINEX 3.04 section 3.5); a blank one means GPS in RINEX 2
_SYSTEMS = "GRECJIS"
#: one observation field: F14.3 (RINEX 2.11 Table A2, RINEX 3.04 Table A3) or blank
_OBS_VALUE = re.compile(r" *-?\d*\.\d{3}")  # 14 columns, right-aligned
#: epoch lines (RINEX 2.11 Table A2: 1X,I2.2,4(1X,I2),F11.7,2X,I1,I3; RINEX 3.04 Table A3:
#: A1,1X,I4,4(1X,I2.2),F11.7,2X,I1,I3); the date fields may be blank for event flags 2-5
_EPOCH2 = re.compile(r" (?P<y>[ \d]\d) (?P<mo>[ \d]\d) (?P<d>[ \d]\d) (?P<h>[ \d]\d) "
                     r"(?P<mi>[ \d]\d)(?P<s> [ \d]\d\.\d{7})  (?P<flag>\d)(?P<n>  \d| \d\d|\d{3})")
_EPOCH3 = re.compile(r"> (?P<y>\d{4}) (?P<mo>[ \d]\d) (?P<d>[ \d]\d) (?P<h>[ \d]\d) "
                     r"(?P<mi>[ \d]\d)(?P<s> [ \d]\d\.\d{7})  (?P<flag>\d)(?P<n>  \d| \d\d|\d{3})")
_EVENT2 = re.compile(r" {28}(?P<flag>[2-5])(?P<n>  \d| \d\d|\d{3})")
_EVENT3 = re.compile(r"> {30}(?P<flag>[2-5])(?P<n>  \d| \d\d|\d{3})")
_CLOCK = re.compile(r" *(-?\d*\.\d+)? *")
_SAT = re.compile(r"[ GRECJIS][ \d]\d")
_DAY0_ORDINAL = datetime.date(1980, 1, 6).toordinal()


class _Bad(Exception):
    """A malformed line inside the body: (line number, what is wrong)."""

    def __init__(self, lineno, message):
        super().__init__(message)
        self.lineno, self.message = lineno, message


def _read_lines(path: Path) -> rinex_text.RinexText:
    """The file's lines in any form (``readers.rinex_text``), whether it ends with a line
    break, whether it was CRINEX (the lines are then those of the decoded text) and what the
    CRINEX decoder skipped."""
    return rinex_text.read_lines(path, ObservationFileError)


def _epoch_seconds(lineno, text, year, month, day, hour, minute, second):
    """GPS seconds of an epoch's date fields (a calendar reading in GPS time); ``_Bad`` naming
    the line when they are not a valid date and time."""
    try:
        date = datetime.date(int(year), int(month), int(day))
        hour, minute, sec = int(hour), int(minute), float(second)
        if not (hour < 24 and minute < 60 and sec < 60.0):
            raise ValueError("hour, minute or second out of range")
    except ValueError as e:
        raise _Bad(lineno, f"the epoch time {text.strip()!r} is not a valid date and time "
                   f"({e})") from None
    return (date.toordinal() - _DAY0_ORDINAL) * 86400.0 + hour * 3600 + minute * 60 + sec


def _match_seconds(lineno, m, year):
    return _epoch_seconds(lineno, m.group(0)[:m.start("flag") - 2], year, m["mo"], m["d"],
                          m["h"], m["mi"], m["s"])


def _types_block(path, header, k, label, count_cols, types_from, width, pattern):
    """An observable list of the header that may continue on lines with the same label:
    (next index, [types]). Errors name the line."""
    line = header[k]
    n_txt = line[count_cols[0]:count_cols[1]]
    if not n_txt.strip().isdigit():
        raise ObservationFileError(f"{path}: line {k + 1}: {label}: cannot read the number of "
                                   f"observables {n_txt.strip()!r} (columns "
                                   f"{count_cols[0] + 1}-{count_cols[1]})")
    n = int(n_txt)
    obs = line[types_from:60].split()
    while len(obs) < n and k + 1 < len(header) and header[k + 1][60:80].strip() == label \
            and not header[k + 1][:count_cols[1]].strip():
        k += 1
        obs += header[k][types_from:60].split()
    if len(obs) != n or n == 0:
        raise ObservationFileError(f"{path}: line {k + 1}: {label}: {n} observables announced, "
                                   f"{len(obs)} listed; the header is malformed")
    for o in obs:
        if len(o) != width or not re.fullmatch(pattern, o):
            raise ObservationFileError(f"{path}: line {k + 1}: {label}: {o!r} is not an "
                                       "observable code")
    if len(set(obs)) != len(obs):
        dup = next(o for o in obs if obs.count(o) > 1)
        raise ObservationFileError(f"{path}: line {k + 1}: {label}: observable {dup} is listed "
                                   "twice")
    return k, obs


def _parse_header(path: Path, lines: list[str]) -> dict:
    """The header facts read_observations needs; ``ObservationFileError`` naming the line of
    anything missing or malformed."""
    if not lines or (len(lines) == 1 and not lines[0].strip()):
        raise ObservationFileError(f"{path}: line 1: the file is empty")
    head = lines[0]
    version = rinex_text.header_version(path, head, ObservationFileError)
    if "RINEX VERSION / TYPE" not in head or head[20:21] not in ("O", "o"):
        raise ObservationFileError(
            f"{path}: line 1: not a RINEX observation file (type {head[20:21]!r} in column 21, "
            "expected 'O'); pass the observation file as obs and the navigation file as nav")
    if not (2.0 <= version < 4.0):
        raise ObservationFileError(f"{path}: line 1: RINEX version {version:g} is not "
                                   "supported (2.x and 3.x are)")
    end = next((k for k, s in enumerate(lines[:_MAX_HEADER_LINES])
                if "END OF HEADER" in s[60:80]), None)
    if end is None:
        n = min(len(lines), _MAX_HEADER_LINES)
        raise ObservationFileError(f"{path}: line {n}: no 'END OF HEADER' line; the header is "
                                   "truncated or malformed")
    header = lines[:end + 1]
    types: dict = {}
    approx, marker, interval = None, "", None
    last_obs, time_system = None, (0, "")
    k = 0
    while k < len(header):
        line = header[k]
        label = line[60:80].strip()
        if label == "APPROX POSITION XYZ":
            try:
                approx = np.array([float(line[14 * i:14 * (i + 1)]) for i in range(3)])
            except ValueError:
                raise ObservationFileError(
                    f"{path}: line {k + 1}: cannot read APPROX POSITION XYZ "
                    f"{line[:42].strip()!r}") from None
        elif label == "MARKER NAME":
            marker = line[:60].strip()
        elif label == "INTERVAL":
            try:
                interval = float(line[:10])
            except ValueError:
                interval = math.nan
            if not (math.isfinite(interval) and interval > 0):
                raise ObservationFileError(f"{path}: line {k + 1}: INTERVAL "
                                           f"{line[:10].strip()!r} is not a positive number of "
                                           "seconds")
        elif label == "TIME OF LAST OBS":
            last_obs = (k + 1, line)
        elif label == "TIME OF FIRST OBS":
            time_system = (k + 1, line[48:51].strip())
        elif label == "# / TYPES OF OBSERV" and version < 3:
            if "G" in types:
                raise ObservationFileError(f"{path}: line {k + 1}: a second '# / TYPES OF "
                                           "OBSERV' record: the observables are given twice")
            k, types["G"] = _types_block(path, header, k, label, (0, 6), 6, 2,
                                         r"[A-Z][0-9A-Z]")
        elif label == "SYS / # / OBS TYPES" and version >= 3:
            sysch = line[0]
            if sysch not in _SYSTEMS:
                raise ObservationFileError(f"{path}: line {k + 1}: SYS / # / OBS TYPES: unknown "
                                           f"satellite system {sysch!r} in column 1")
            if sysch in types:
                raise ObservationFileError(f"{path}: line {k + 1}: the observables of system "
                                           f"{sysch} are given twice")
            k, types[sysch] = _types_block(path, header, k, label, (3, 6), 7, 3,
                                           r"[A-Z][0-9][A-Z]")
        k += 1
    if not types:
        raise ObservationFileError(
            f"{path}: line {end + 1}: the header lacks '# / TYPES OF OBSERV' (RINEX 2) or "
            "'SYS / # / OBS TYPES' (RINEX 3): the observables are unknown")
    if approx is not None and not (6.0e6 < np.linalg.norm(approx) < 6.5e6):
        approx = None  # a zero or placeholder position is not a position
    if last_obs is not None:
        lineno, line = last_obs
        m = re.fullmatch(r" *(\d{4}) +(\d+) +(\d+) +(\d+) +(\d+) +(\d+\.\d+)", line[:43])
        if m is None:
            raise ObservationFileError(f"{path}: line {lineno}: cannot read TIME OF LAST OBS "
                                       f"{line[:43].strip()!r}")
        try:
            last_obs = (lineno, _epoch_seconds(lineno, line[:43], *m.groups()))
        except _Bad as e:
            raise ObservationFileError(f"{path}: line {lineno}: {e.message}") from None
    return {"version": version, "types": types, "approx_position": approx, "marker": marker,
            "header_lines": len(header), "interval": interval, "last_obs": last_obs,
            "time_system": time_system}


def check_observation_file(path) -> dict:
    """Structural check of a RINEX 2/3 observation header.

    Returns ``{"version", "types" (per system letter, list of observables), "approx_position"
    ((3,) or None), "marker", "header_lines", "interval" (s or None), "last_obs",
    "time_system" ((line, TIME OF FIRST OBS time system))}``. Raises ``ObservationFileError``
    naming the file and the line or header record that is missing or malformed, or an empty
    body (for a CRINEX file, lines of its decompressed text).
    """
    path = Path(path)
    lines, _, crinex, _ = _read_lines(path)
    try:
        info = _parse_header(path, lines)
        if not any(s.strip() for s in lines[info["header_lines"]:]):
            raise ObservationFileError(f"{path}: line {info['header_lines'] + 1}: no "
                                       "observation epochs after the header (empty or "
                                       "truncated file)")
    except ObservationFileError as e:
        if crinex:
            raise ObservationFileError(rinex_text.decoded_lines(str(e))) from None
        raise
    return info


def _check_values(lineno, line, start, n_fields, max_fields):
    """Observation fields F14.3 + LLI + SSI (16 columns each) from column ``start``: each blank
    or a number, indicators blank or a digit, nothing after the last field."""
    for k in range(n_fields):
        a = start + 16 * k
        value, ind = line[a:a + 14], line[a + 14:a + 16]
        if value.strip() and not _OBS_VALUE.fullmatch(value):
            raise _Bad(lineno, f"columns {a + 1}-{a + 14}: cannot read {value.strip()!r} as an "
                       "observation (F14.3: a number with three decimals)")
        if ind.strip() and not re.fullmatch(r"[ \d]{1,2}", ind):
            raise _Bad(lineno, f"columns {a + 15}-{a + 16}: loss-of-lock / signal-strength "
                       f"indicators {ind!r} are not digits")
    tail = line[start + 16 * max_fields:]
    if tail.strip():
        raise _Bad(lineno, f"column {start + 16 * max_fields + 1}: unexpected text "
                   f"{tail.strip()[:20]!r} after the last observation field")


def _epoch_v2(path, lines, k, n_types):
    """One RINEX 2 epoch starting at index ``k``: (next index, time or None, {sv: the
    satellite's checked fields, 16 columns each})."""
    line = lines[k]
    m = _EPOCH2.match(line)
    if m is None:
        ev = _EVENT2.match(line)
        if ev is None:
            raise _Bad(k + 1, f"expected an epoch line ' YY MM DD hh mm ss.sssssss  F NNN' "
                       f"(RINEX 2.11 Table A2), got {line[:32]!r}")
        return _skip_records(lines, k, int(ev["n"]), "special records"), None, {}
    flag, n = int(m["flag"]), int(m["n"])
    if flag > 6:
        raise _Bad(k + 1, f"column 29: epoch flag {flag} is not 0-6")
    yy = int(m["y"])
    t = _match_seconds(k + 1, m, 2000 + yy if yy < 80 else 1900 + yy)
    if 2 <= flag <= 5:
        return _skip_records(lines, k, n, "special records"), None, {}
    lines_per_sat = max(1, -(-n_types // 5))
    sats, j = [], k
    while True:  # 12 satellites per line, continuation lines blank in columns 1-32
        row = lines[j]
        take = min(12, n - len(sats))
        for i in range(take):
            s = row[32 + 3 * i:35 + 3 * i]
            if not _SAT.fullmatch(s) or int(s[1:].replace(" ", "0")) == 0:
                raise _Bad(j + 1, f"columns {33 + 3 * i}-{35 + 3 * i}: {s!r} is not a "
                           f"satellite (system letter and number; {n} announced in columns 30-32)")
            sats.append(("G" if s[0] == " " else s[0]) + s[1:].replace(" ", "0"))
        rest = row[32 + 3 * take:68]
        if rest.strip():
            raise _Bad(j + 1, f"column {33 + 3 * take}: {rest.strip()[:12]!r} after the "
                       f"{n} satellites the epoch announces (columns 30-32)")
        clock = row[68:]
        if j > k and clock.strip() or j == k and not _CLOCK.fullmatch(clock):
            raise _Bad(j + 1, f"columns 69-80: cannot read the receiver clock offset "
                       f"{clock.strip()[:20]!r}")
        if len(sats) == n:
            break
        j += 1
        if j >= len(lines):
            raise _Bad(j, f"the file ends inside the satellite list of the epoch at line "
                       f"{k + 1}: the file is truncated")
        if lines[j][:32].strip():
            raise _Bad(j + 1, f"expected the continuation of the satellite list of the epoch "
                       f"at line {k + 1} (columns 1-32 blank), got {lines[j][:32]!r}")
    if len(set(sats)) != len(sats):
        dup = next(s for s in sats if sats.count(s) > 1)
        raise _Bad(k + 1, f"satellite {dup} is listed twice in the epoch")
    j += 1
    data = {}
    for i, s in enumerate(sats):
        rows = lines[j:j + lines_per_sat]
        if len(rows) < lines_per_sat:
            raise _Bad(len(lines), f"the file ends inside the epoch at line {k + 1} (the "
                       f"observations of {s} are missing): the file is truncated")
        for r, row in enumerate(rows):
            if _EPOCH2.match(row):
                raise _Bad(j + r + 1, f"an epoch line where the epoch at line {k + 1} has more "
                           f"observations ({n} satellites x {lines_per_sat} line(s) announced, "
                           f"{i} complete): lines are missing")
            fields = min(5, n_types - 5 * r)
            _check_values(j + r + 1, row, 0, fields, fields)
        if flag != 6:  # flag 6: cycle-slip records, not observations
            data[s] = "".join(f"{row:80s}"[:80] for row in rows)
        j += lines_per_sat
    return j, (None if flag == 6 else t), data


def _skip_records(lines, k, n, what):
    """Skip the ``n`` special records of an event epoch (flags 2-5) at index ``k``; a change
    of the observables there (flag 4 with a new observable list) is refused."""
    if k + 1 + n > len(lines):
        raise _Bad(len(lines), f"the file ends inside the {n} {what} announced at line {k + 1}: "
                   "the file is truncated")
    for j in range(k + 1, k + 1 + n):
        if lines[j][60:80].strip() in ("# / TYPES OF OBSERV", "SYS / # / OBS TYPES"):
            raise _Bad(j + 1, "the observables change inside the file (an event with new "
                       "header records); this reader needs one observable list: split the file")
    return k + 1 + n


def _epoch_v3(path, lines, k, types):
    """One RINEX 3 epoch starting at index ``k``: (next index, time or None, {sv: the
    satellite's checked fields, 16 columns each})."""
    line = lines[k]
    m = _EPOCH3.match(line)
    if m is None:
        ev = _EVENT3.match(line)
        if ev is None:
            raise _Bad(k + 1, f"expected an epoch line '> YYYY MM DD hh mm ss.sssssss  F NNN' "
                       f"(RINEX 3.04 Table A3), got {line[:35]!r}")
        return _skip_records(lines, k, int(ev["n"]), "special records"), None, {}
    flag, n = int(m["flag"]), int(m["n"])
    if flag > 6:
        raise _Bad(k + 1, f"column 32: epoch flag {flag} is not 0-6")
    t = _match_seconds(k + 1, m, int(m["y"]))
    if 2 <= flag <= 5:
        return _skip_records(lines, k, n, "special records"), None, {}
    rest = line[35:]
    if rest[:6].strip() or not _CLOCK.fullmatch(rest[6:]):
        raise _Bad(k + 1, f"columns 36-56: cannot read the receiver clock offset "
                   f"{rest.strip()[:21]!r}")
    if k + 1 + n > len(lines):
        raise _Bad(len(lines), f"the file ends inside the epoch at line {k + 1} ({n} satellites "
                   f"announced, {len(lines) - k - 1} lines present): the file is truncated")
    data, seen = {}, set()
    for j in range(k + 1, k + 1 + n):
        row = lines[j]
        s = row[:3]
        if _EPOCH3.match(row):
            raise _Bad(j + 1, f"an epoch line where the epoch at line {k + 1} has more "
                       f"satellites ({n} announced, {j - k - 1} present): lines are missing")
        if not _SAT.fullmatch(s) or s[0] == " " or int(s[1:].replace(" ", "0")) == 0:
            raise _Bad(j + 1, f"columns 1-3: expected a satellite (system letter and number) of "
                       f"the epoch at line {k + 1} ({n} announced), got {s!r}")
        s = s[0] + s[1:].replace(" ", "0")
        if s[0] not in types:
            raise _Bad(j + 1, f"satellite {s}: the header lists no observables of system {s[0]}")
        if s in seen:
            raise _Bad(j + 1, f"satellite {s} is listed twice in the epoch at line {k + 1}")
        seen.add(s)
        nf = len(types[s[0]])
        _check_values(j + 1, row, 3, nf, nf)
        if flag != 6:
            data[s] = row[3:]
    return k + 1 + n, (None if flag == 6 else t), data


def _parse_body(path: Path, lines, ends_with_newline, info, lenient):
    """Every epoch of the body checked.

    Returns ``(t (T,), epoch lines (T,), [{sv: fields text}] per epoch, skipped)``; in strict
    mode the first problem raises ``ObservationFileError`` naming the line, in lenient mode the
    epoch holding it is skipped and ``skipped`` gets one message per skipped epoch.
    """
    v3 = info["version"] >= 3
    n_types = len(info["types"].get("G", []))  # RINEX 2: the one list of the header
    epoch_re = _EPOCH3 if v3 else _EPOCH2
    times, starts, rows, skipped = [], [], [], []
    last_t, last_line = -math.inf, 0
    k = info["header_lines"]
    if not ends_with_newline and lines and lines[-1].strip():
        problem = (len(lines), "the last line does not end with a line break: the file is "
                   "truncated (re-download or re-export it)")
        if not lenient:
            raise ObservationFileError(f"{path}: line {problem[0]}: {problem[1]}")
    else:
        problem = None
    while k < len(lines):
        if not lines[k].strip():
            k += 1
            continue
        start = k
        try:
            if v3:
                k, t, data = _epoch_v3(path, lines, k, info["types"])
            else:
                k, t, data = _epoch_v2(path, lines, k, n_types)
            if problem is not None and k >= problem[0]:
                raise _Bad(*problem)
            if t is not None and t <= last_t:
                raise _Bad(start + 1, "the epoch time is not later than that of the epoch at "
                           f"line {last_line} ({'the same time' if t == last_t else 'earlier'}): "
                           "a duplicated or misplaced epoch")
        except _Bad as e:
            msg = f"{path}: line {e.lineno}: {e.message}"
            if not lenient:
                raise ObservationFileError(msg) from None
            k = start + 1
            while k < len(lines) and not epoch_re.match(lines[k]):
                k += 1
            skipped.append(f"{msg}; skipped the epoch at line {start + 1} (lines {start + 1}-{k})")
            continue
        if t is not None:
            times.append(t)
            starts.append(start + 1)
            rows.append(data)
            last_t, last_line = t, start + 1
    return np.asarray(times, np.float64), np.asarray(starts, np.int64), rows, skipped


#: time systems whose epochs are GPS time (RINEX 3.04 Table A2: GST, QZSST and IRNSST are
#: steered to GPS time; GLONASS time is UTC(SU) + 3 h and BDT is 14 s behind GPS time)
_GPS_ALIGNED = ("", "GPS", "GAL", "QZS", "IRN")


@functools.lru_cache(maxsize=8)
def _file_table(path_str, mtime_ns, size, lenient) -> ObservationTable:
    """The ``ObservationTable`` of one file, cached per (file, mtime, size, lenient); the
    messages of a CRINEX file's decoded text name its lines as such."""
    p = Path(path_str)
    lines, ends, crinex, notes = _read_lines(p)
    if notes and not lenient:  # the CRINEX decoder went past a garbled epoch
        raise ObservationFileError(notes[0])
    try:
        info = _parse_header(p, lines)
        t, starts, rows, skipped = _parse_body(p, lines, ends, info, lenient)
        if t.size == 0:
            why = "all skipped" if skipped else "empty or truncated file"
            raise ObservationFileError(f"{p}: line {info['header_lines'] + 1}: no observation "
                                       f"epochs after the header ({why})")
        last = info["last_obs"]
        if last is not None and t[-1] < last[1] - 1.0:
            msg = (f"{p}: line {last[0]}: TIME OF LAST OBS is {last[1] - t[-1]:.0f} s after "
                   "the last epoch of the file: the file is truncated")
            if not lenient:
                raise ObservationFileError(msg)
            skipped = [*skipped, msg]
        ts = info["time_system"]
        if ts[1] not in _GPS_ALIGNED:
            raise ObservationFileError(
                f"{p}: line {ts[0]}: TIME OF FIRST OBS: the epochs are in {ts[1]} time; this "
                "reader takes time tags in GPS time (GPS, GAL, QZS, IRN)")
    except ObservationFileError as e:
        if crinex:
            raise ObservationFileError(rinex_text.decoded_lines(str(e))) from None
        raise
    if crinex:
        skipped = [*notes, *(rinex_text.decoded_lines(m) for m in skipped)]
    v3 = info["version"] >= 3
    svs, values, lli = decode_fields(info["types"], rows, v3)
    types = (info["types"] if v3 else
             {sysch: info["types"]["G"] for sysch in sorted({s[0] for s in svs}) or ["G"]})
    return ObservationTable(t, svs, {k: tuple(v) for k, v in types.items()}, values, lli,
                            starts, np.zeros(t.size, np.int64), info["approx_position"],
                            info["interval"], info["version"], info["marker"], (str(p),),
                            tuple(skipped))


def _existing(path) -> Path:
    p = Path(path).expanduser()
    if not p.is_file():
        raise ObservationFileError(f"observation file {str(path)!r} not found; give an existing "
                                   "RINEX 2/3 observation file (plain, .gz or CRINEX)")
    return p


def _as_paths(path) -> list:
    if isinstance(path, (str, os.PathLike)):
        return [path]
    paths = list(path)
    if not paths:
        raise ObservationFileError("no observation file given")
    return paths


def read_observation_table(path: str | os.PathLike | Sequence[str | os.PathLike],
                           lenient: bool = False) -> ObservationTable:
    """Every observation of a RINEX 2/3 observation file, or of several files of one receiver.

    Forms: plain, gzip, CRINEX 1/3 (Hatanaka), CRINEX in gzip or compress. Every line is
    checked as ``read_observations`` checks it; every system and observation type the header
    declares is read (``ObservationTable``: one ``(T, S)`` array per type, NaN where blank).

    Args:
      path: a file, or a sequence of files of one receiver (one station, one interval, not
        overlapping in time; any order).
      lenient: skip bad epochs instead of failing; each skipped epoch gives an
        ``ObservationFileWarning`` naming the file and line and is listed in ``skipped``.

    Raises:
      ObservationFileError: (a ValueError) naming the file, the line (for a CRINEX file, of its
        decompressed text, or the CRINEX line the decoder stopped at) and what is wrong.
    """
    tables = []
    for one in _as_paths(path):
        p = _existing(one)
        st = os.stat(p)
        tables.append(_file_table(str(p.resolve()), st.st_mtime_ns, st.st_size, bool(lenient)))
    table = tables[0] if len(tables) == 1 else merge_tables(tables, ObservationFileError)
    for msg in table.skipped:
        warnings.warn(msg, ObservationFileWarning, stacklevel=2)
    return table


def _l1_codes(path) -> tuple:
    """The GPS L1 code observables of a file's header, in order of preference; an error naming
    the file when it has none (checked before the body, as the header is all it takes)."""
    p = _existing(path)
    lines, _, crinex, _ = _read_lines(p)
    try:
        info = _parse_header(p, lines)
    except ObservationFileError as e:
        raise ObservationFileError(rinex_text.decoded_lines(str(e)) if crinex else str(e)) from None
    have = info["types"].get("G", [])
    prefs = RINEX2_L1_CODES if info["version"] < 3 else RINEX3_L1_CODES
    codes = tuple(c for c in prefs if c in have)
    if not codes:
        raise ObservationFileError(
            f"{p}: no GPS L1 code observable: the header lists {have or 'no GPS observables'}; "
            f"need one of {', '.join(prefs)}")
    return codes


def read_observations(path: str | os.PathLike | Sequence[str | os.PathLike],
                      max_epochs: int | None = None, lenient: bool = False) -> Observations:
    """GPS L1 code pseudoranges of a RINEX 2/3 observation file (plain, .gz or CRINEX), or of
    several files of one receiver (``read_observation_table``).

    Every line is checked (epoch lines, satellite lists, the F14.3 observation fields, the
    number of lines each epoch announces, strictly increasing epoch times, a final line
    break): a truncated, garbled or duplicated epoch is an error naming the file and line,
    never a silently shorter result.

    Args:
      path: the observation file, or a sequence of files.
      max_epochs: keep only the first this many epochs (None: all; the whole file is checked).
      lenient: skip bad epochs instead of failing; each skipped epoch gives an
        ``ObservationFileWarning`` naming the file and line and is listed in ``skipped``.

    Returns:
      ``Observations`` with ``(T, S)`` arrays over epochs x GPS satellites; a satellite that is
      never observed is dropped. Pseudoranges outside 18,000-30,000 km are marked not valid.

    Raises:
      ObservationFileError: (a ValueError) naming the file, the line and what is wrong: a
        missing file, a bad header, no GPS L1 code observable (C1 / P1 or C1C / C1W / ...), a
        malformed or truncated epoch, no epochs.
    """
    paths = _as_paths(path)
    codes = tuple(dict.fromkeys(c for one in paths for c in _l1_codes(one)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = read_observation_table(paths, lenient)
    for w in caught:
        warnings.warn(w.message, w.category, stacklevel=2)
    gps = table.select("G")
    t, svs, skipped = gps.t_gps_s, gps.sv, table.skipped
    pr = np.full((t.size, svs.size), np.nan)
    used = []
    for c in codes:  # preferred code first, later codes only fill its gaps
        x = gps.values[c]
        fill = ~np.isfinite(pr) & np.isfinite(x)
        if fill.any():
            pr[fill] = x[fill]
            used.append(c)
    ok = np.isfinite(pr) & (pr > PSEUDORANGE_SPAN_M[0]) & (pr < PSEUDORANGE_SPAN_M[1])
    keep_sv = ok.any(0)
    where = ", ".join(table.paths)
    if not keep_sv.any():
        raise ObservationFileError(f"{where}: no plausible GPS {'/'.join(codes)} pseudoranges "
                                   f"(18,000-30,000 km) in {t.size} epochs")
    pr, ok = pr[:, keep_sv], ok[:, keep_sv]
    if max_epochs is not None:
        t, pr, ok = t[:max_epochs], pr[:max_epochs], ok[:max_epochs]
    return Observations(t, svs[keep_sv], np.where(ok, pr, 0.0), ok, "+".join(used) or codes[0],
                        table.approx_position_m, table.interval_s, table.version,
                        table.marker, where, tuple(skipped))
