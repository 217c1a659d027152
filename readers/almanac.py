"""GPS/Galileo almanacs: the YUMA and SEM readers (their propagation: ``geometry.Almanac``).

An almanac holds one reduced Keplerian record per satellite (IS-GPS-200 20.3.3.5.1.2, Table
20-VI): e, t_oa, i (SEM: delta_i from i_0 = 0.30 semicircles), Omega-dot, sqrt(A), Omega_0
(the longitude of the ascending node at the weekly epoch), omega, M_0, a_f0, a_f1 and a health
word. The readers refuse a record whose orbit is not one of its constellation's
(``readers.orbit_limits``: semi-major axis, eccentricity, inclination) with the file and
line. The records (``AlmanacRecords``) become orbits in ``oaraim.geometry``
(``geometry.read_yuma``, ``geometry.read_sem``: the ephemeris algorithm with the harmonic terms,
delta_n and IDOT zero, IS-GPS-200 20.3.3.5.2.3; the almanac clock a_f0 + a_f1 t_k).

YUMA is the text format of the US Coast Guard NAVCEN (keys ``ID:``, ``Health:``, ... in radians
and seconds); SEM is NAVCEN's column format (angles in semicircles). Week numbers: YUMA and SEM
files of GPS usually write the week modulo 1024; they are taken literally unless
``week_reference_t_gps_s`` is given, in which case the full week nearest to that time is used
(``readers.gpstime.resolve_week``). MAAST's ``almmops.txt`` (week 703: June 1993) is already
literal.
"""

import os
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from oaraim.constants import GPS_PI
from oaraim.readers import gpstime
from oaraim.readers.orbit_limits import implausible_orbit


class AlmanacFileError(ValueError):
    """A malformed almanac file: names the file, the line and the field."""


class AlmanacRecords(NamedTuple):
    """Per-satellite almanac elements, each ``(S,)``, SI units and radians."""

    prn: np.ndarray  # int
    health: np.ndarray  # int
    e: np.ndarray
    toa_s: np.ndarray  # absolute GPS seconds of t_oa
    toa_tow_s: np.ndarray  # t_oa within its week
    i_rad: np.ndarray
    omegadot_rad_s: np.ndarray
    sqrt_a: np.ndarray
    omega0_rad: np.ndarray
    omega_rad: np.ndarray
    m0_rad: np.ndarray
    af0_s: np.ndarray
    af1_s_s: np.ndarray


#: what each almanac field must satisfy (a record breaking one is a parse error naming the
#: file and line): e in [0, 1) (an orbit), sqrt(A) > 0, integers in their ranges where the
#: format has them (RINEX 3 satellite numbers have two digits; the almanac health is 8 bits)
_FIELD_RULES = {"e": (lambda v: 0.0 <= v < 1.0, "in [0, 1) (an elliptical orbit)"),
                "sqrt_a": (lambda v: v > 0.0, "> 0 (sqrt of the semi-major axis, sqrt(m))"),
                "prn": (lambda v: 1 <= v <= 99 and v == int(v), "an integer in 1..99"),
                "health": (lambda v: 0 <= v <= 255 and v == int(v),
                           "an integer in 0..255 (an 8-bit health word)"),
                "week": (lambda v: 0 <= v <= 100000 and v == int(v),
                         "an integer in 0..100000 (a GPS week)"),
                "toa": (lambda v: 0 <= v < 604800, "in [0, 604800) s of the week")}


def _check_rows(p, rows, lines_of, system):
    """AlmanacFileError (file, line) for a non-finite or unphysical value, an orbit that is
    not one of ``system``'s ('G', 'E': ``readers.orbit_limits``) or a PRN given twice.
    ``lines_of(i, key)``: the line of field ``key`` of record ``i``."""
    seen = {}
    for i, r in enumerate(rows):
        for key, v in r.items():
            if not np.isfinite(v):
                raise AlmanacFileError(f"{p}: line {lines_of(i, key)}: {key} is {v!r}; every "
                                       "almanac value must be a finite number")
            rule = _FIELD_RULES.get(key)
            if rule is not None and not rule[0](v):
                raise AlmanacFileError(f"{p}: line {lines_of(i, key)}: {key} = {v!r} must be "
                                       f"{rule[1]}")
        bad = implausible_orbit(system, r["sqrt_a"], r["e"], r["i"])
        if bad is not None:
            raise AlmanacFileError(f"{p}: line {lines_of(i, bad[0])}: satellite {int(r['prn'])}: "
                                   f"{bad[1]}; fix that record or use another almanac")
        prn = int(r["prn"])
        if prn in seen:
            raise AlmanacFileError(f"{p}: line {lines_of(i, 'prn')}: satellite {prn} appears "
                                   f"again (first at line {seen[prn]}); one record per "
                                   "satellite")
        seen[prn] = lines_of(i, "prn")


def _records(rows, system, week_reference_t_gps_s):
    arr = {k: np.array([r[k] for r in rows], np.float64) for k in rows[0]}
    week = arr["week"].astype(np.int64)
    if week_reference_t_gps_s is not None:
        week = gpstime.resolve_week(week, week_reference_t_gps_s)
    return AlmanacRecords(
        prn=arr["prn"].astype(np.int32), health=arr["health"].astype(np.int64), e=arr["e"],
        toa_s=gpstime.from_week_tow(week, arr["toa"]), toa_tow_s=arr["toa"], i_rad=arr["i"],
        omegadot_rad_s=arr["omegadot"], sqrt_a=arr["sqrt_a"], omega0_rad=arr["omega0"],
        omega_rad=arr["omega"], m0_rad=arr["m0"], af0_s=arr["af0"], af1_s_s=arr["af1"])


_YUMA_KEYS = {
    "id": "prn", "health": "health", "eccentricity": "e", "time of applicability": "toa",
    "orbital inclination": "i", "rate of right ascen": "omegadot", "sqrt(a)": "sqrt_a",
    "right ascen at week": "omega0", "right ascen at toa": "omega0",
    "argument of perigee": "omega", "mean anom": "m0", "af0": "af0", "af1": "af1",
    "week": "week",
}


def _yuma_key(label):
    label = label.strip().lower()
    for k, v in _YUMA_KEYS.items():
        if label.startswith(k):
            return v
    return None


def read_yuma_records(path: str | os.PathLike, system: str = "G",
                      week_reference_t_gps_s: float | None = None) -> AlmanacRecords:
    """The records of a YUMA almanac (``geometry.read_yuma`` makes the orbits of them).
    ``system``: 'G' (GPS) or 'E' (Galileo, e.g. MAAST's ED-259 file).

    The satellite number is taken from the block header ('PRN-01', 'SVID- 1') when present,
    else from ``ID:``. Health: the 3-digit health field (0 = healthy).
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise AlmanacFileError(f"almanac file {str(path)!r} not found")
    if system not in ("G", "E"):
        raise ValueError(f"system must be 'G' or 'E', got {system!r}")
    rows, row_lines, cur = [], [], None
    need = set(_YUMA_KEYS.values())
    lines = p.read_text(encoding="ascii", errors="replace").splitlines()

    def close(lineno):
        if cur is None:
            return
        missing = sorted(need - set(cur) - {"_lines"})
        if missing:
            raise AlmanacFileError(f"{p}: line {lineno}: the almanac block starting at line "
                                   f"{cur['_line']} lacks {', '.join(missing)}; the file is "
                                   "truncated or not YUMA")
        start = cur.pop("_line")
        header_prn = cur.pop("_header_prn")
        where = cur.pop("_lines")
        if header_prn is not None:
            cur["prn"] = header_prn
            where["prn"] = start
        rows.append(cur)
        row_lines.append(where)

    for k, line in enumerate(lines, start=1):
        if line.startswith("****"):
            close(k)
            m = re.search(r"(?:PRN|SVID)-\s*(\d+)", line)
            cur = {"_line": k, "_header_prn": int(m.group(1)) if m else None, "_lines": {}}
            continue
        if ":" not in line or cur is None:
            if line.strip() and cur is None:
                raise AlmanacFileError(f"{p}: line {k}: text before the first '****' block "
                                       "header; not a YUMA almanac")
            continue
        label, _, value = line.partition(":")
        key = _yuma_key(label)
        if key is None:
            continue
        try:
            cur[key] = float(value.strip().replace("D", "E"))
        except ValueError:
            raise AlmanacFileError(f"{p}: line {k}: cannot read {label.strip()!r} value "
                                   f"{value.strip()!r} as a number") from None
        if key in cur["_lines"] and key != "omega0":
            raise AlmanacFileError(f"{p}: line {k}: {label.strip()!r} given twice in the block "
                                   f"starting at line {cur['_line']}")
        cur["_lines"][key] = k
    close(len(lines))
    if not rows:
        raise AlmanacFileError(f"{p}: line {max(len(lines), 1)}: no almanac blocks ('******** "
                               "Week ... almanac for PRN-nn ********') up to the end of the "
                               "file; not a YUMA almanac")
    _check_rows(p, rows, lambda i, key: row_lines[i].get(key, "?"), system)
    return _records(rows, system, week_reference_t_gps_s)


def read_sem_records(path: str | os.PathLike, system: str = "G",
                     week_reference_t_gps_s: float | None = None) -> AlmanacRecords:
    """The records of a SEM almanac (NAVCEN ``.al3``): angles in semicircles, inclination as delta_i
    from 0.30 semicircles (GPS). Layout: count and title; week and t_oa; then per satellite
    PRN, SVN, URA, (e, delta_i, Omega-dot), (sqrt A, Omega_0, omega), (M_0, a_f0, a_f1),
    health, configuration (8 lines), separated by blank lines."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise AlmanacFileError(f"almanac file {str(path)!r} not found")
    if system not in ("G", "E"):
        raise ValueError(f"system must be 'G' or 'E', got {system!r}")
    lines = p.read_text(encoding="ascii", errors="replace").splitlines()
    tokens = []  # (line number, [numbers]) of non-blank lines
    for k, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            nums = [float(v.replace("D", "E")) for v in line.split()[:3]]
        except ValueError:
            try:
                if k != 1:
                    raise ValueError
                nums = [float(line.split()[0])]  # title text after the count
            except ValueError:
                raise AlmanacFileError(f"{p}: line {k}: cannot read {line.strip()!r} as "
                                       "numbers; not a SEM almanac") from None
        tokens.append((k, nums))
    if len(tokens) < 2:
        raise AlmanacFileError(f"{p}: line {len(lines)}: no SEM header (count, week and t_oa)")
    n_sats = tokens[0][1][0]
    if not (np.isfinite(n_sats) and n_sats == int(n_sats) and 1 <= n_sats <= 1000):
        raise AlmanacFileError(f"{p}: line {tokens[0][0]}: the satellite count {n_sats!r} is "
                               "not an integer in 1..1000; not a SEM almanac")
    n_sats = int(n_sats)
    if len(tokens[1][1]) < 2:
        raise AlmanacFileError(f"{p}: line {tokens[1][0]}: expected the week and t_oa; not a "
                               "SEM almanac")
    week, toa = tokens[1][1][0], tokens[1][1][1]
    body = tokens[2:]
    if len(body) < 8 * n_sats:
        raise AlmanacFileError(
            f"{p}: line {len(lines)}: {n_sats} satellites announced, 8 lines each, but only "
            f"{len(body)} lines follow; the file is truncated")
    sc = GPS_PI  # semicircles -> radians (IS-GPS-200 20.3.3.5.1.2)
    rows, starts = [], []
    for s in range(n_sats):
        b = [nums for _, nums in body[8 * s: 8 * s + 8]]
        k0 = body[8 * s][0]
        if len(b[3]) < 3 or len(b[4]) < 3 or len(b[5]) < 3:
            raise AlmanacFileError(f"{p}: line {k0 + 3}: expected three numbers per orbit line "
                                   "of the satellite record starting here")
        rows.append({
            "prn": b[0][0], "health": b[6][0], "e": b[3][0], "toa": toa,
            "i": (0.30 + b[3][1]) * sc, "omegadot": b[3][2] * sc, "sqrt_a": b[4][0],
            "omega0": b[4][1] * sc, "omega": b[4][2] * sc, "m0": b[5][0] * sc,
            "af0": b[5][1], "af1": b[5][2], "week": week})
        starts.append([k for k, _ in body[8 * s: 8 * s + 8]])
    sem_line = {"prn": 0, "e": 3, "i": 3, "omegadot": 3, "sqrt_a": 4, "omega0": 4, "omega": 4,
                "m0": 5, "af0": 5, "af1": 5, "health": 6}
    _check_rows(p, rows, lambda i, key: starts[i][sem_line[key]] if key in sem_line
                else tokens[1][0], system)
    return _records(rows, system, week_reference_t_gps_s)
