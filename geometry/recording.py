"""Recorded drives and flights on disk: the format, a validating loader, a writer, and the
array helpers that replay code needs.

One drive (or flight) is one folder. Real recorded data and synthesized data use the same format
and go through the same loader, so a user replays their own drive by writing these files.

Format (``format_version`` 1)
=============================

::

    my_drive/
        meta.json              required
        transmitters.parquet   required when pseudoranges exist (terrestrial transmitters)
        pseudoranges.parquet   terrestrial pseudoranges, one row per (epoch, transmitter)
        imu.parquet            optional (a GNSS-only or snapshot replay has none)
        gnss.parquet           optional GNSS pseudoranges, one row per (epoch, satellite)
        truth.parquet          optional ground truth

Every table may instead be ``NAME.csv`` (or ``NAME.csv.gz``); the loader picks whichever exists
(both at once is an error). At least one of ``pseudoranges`` and ``gnss`` must exist. Other
files in the folder are ignored. Units are in the column names. Time ``t_s`` is seconds since the
start of the recording (float64; ``meta.json`` may tie t = 0 to GPS time). Positions are WGS-84
ECEF metres. Tables are "long": one row per sample or per measurement.

``meta.json``
  ``format`` = ``"oaraim-recording"`` (required); ``format_version`` = 1 (required, integer);
  ``origin`` = ``{"lat_deg", "lon_deg", "h_m"}`` (required): the geodetic origin of the local
  ENU frame used for navigation (usually the start point); ``name``, ``description`` (text);
  ``t0_gps_week`` (full GPS week, not modulo 1024) and ``t0_gps_tow_s`` (time of week, s) of
  t_s = 0, both or neither; ``imu_rate_hz`` (nominal IMU rate; checked against the IMU time
  stamps, 5 % tolerance on the median step); ``body_frame`` = ``"FLU"`` (the only one accepted:
  right-handed, x front, y left, z up; seed 000's "x front, y right, z up" is left-handed and
  must be converted); ``quaternion`` = ``"JPL"`` (the only one accepted: scalar last, see truth);
  ``source`` = ``{"kind": "real" | "synthesized", ...}`` (free parameters beside ``kind``).
  Other keys are kept and not checked.

``imu`` (optional)
  ``t_s`` (strictly increasing), ``gyro_x_radps``, ``gyro_y_radps``, ``gyro_z_radps`` (angular
  rate of the body w.r.t. inertial space, body axes), ``accel_x_mps2``, ``accel_y_mps2``,
  ``accel_z_mps2`` (specific force, body axes: a vehicle at rest reads about +9.8 on z).

``transmitters`` (required with pseudoranges)
  ``tx_id`` (text, unique), ``kind`` (text: ``"lte"``, ``"nr"``, ``"dtv"``, ...), ``group``
  (text: clock group, e.g. the carrier; transmitters of one group share a receiver-side clock
  column in an OARAIM solution, seed 004 eq. 4), ``x_m``, ``y_m``, ``z_m`` (ECEF),
  ``clock_bias_m``, ``clock_drift_mps`` and optional ``clock_t0_s`` (default 0): the
  transmitter clock as the first-order polynomial of seed 000 eq. (3),
  ``c dt_s(t) = clock_bias_m + clock_drift_mps (t_s - clock_t0_s)`` (write 0, 0 when unknown and
  let the estimator carry the clocks).

``pseudoranges``
  ``t_s`` (non-decreasing), ``tx_id`` (must be in transmitters), ``pseudorange_m``; optional
  ``sigma_m`` (> 0, 1-sigma noise), ``cn0_dbhz``. Model (seed 000 eq. 3):
  ``pseudorange_m = |r_rx(t) - r_tx| + c dt_rx(t) - c dt_tx(t) + noise``.
  Rows with the same ``t_s`` (bit-identical float) form one epoch. A missing measurement is a
  missing row, never a NaN. (t_s, tx_id) is unique.

``gnss`` (optional)
  ``t_s`` (non-decreasing), ``sv_id`` (RINEX 3 satellite id: system letter G, R, E, C, J, I or S
  and two digits, e.g. ``"G05"``), ``pseudorange_m``, ``sat_x_m``, ``sat_y_m``, ``sat_z_m``
  (satellite antenna position at transmit time, expressed in the ECEF frame of the *reception*
  time, i.e. Earth rotation during transit already applied: ``geometry.earth_rotation_correction``
  with tau = range / c), ``sat_clock_m`` (c times the satellite clock offset, complete: broadcast
  polynomial plus relativistic term minus T_GD for L1 single-frequency users, IS-GPS-200
  20.3.3.3.3.1-2); optional ``iono_m``, ``tropo_m`` (model delays, positive, NOT yet removed
  from ``pseudorange_m``), ``sigma_m`` (> 0), ``el_deg`` ([-90, 90]), ``cn0_dbhz``. Model:
  ``pseudorange_m = |r_rx - r_sat| + c dt_rx - sat_clock_m + iono_m + tropo_m + noise``.
  (t_s, sv_id) is unique.

``truth`` (optional)
  ``t_s`` (strictly increasing), ``x_m``, ``y_m``, ``z_m`` (ECEF); optional together
  ``vx_mps``, ``vy_mps``, ``vz_mps`` (ECEF velocity); optional together ``qx``, ``qy``, ``qz``,
  ``qw``: the attitude as seed 000's JPL quaternion ^B_G q (scalar last, unit norm to 1e-6)
  whose matrix C(q) = (2 qw^2 - 1) I - 2 qw [q_v x] + 2 q_v q_v^T maps ENU vectors to body
  vectors, v_body = C(q) v_enu (so a vehicle yawed by psi counter-clockwise from east has
  q = [0, 0, sin(psi/2), cos(psi/2)]); optional ``rx_clock_m``, ``rx_clock_drift_mps`` (the
  receiver clock c dt_rx and its rate, when known: synthesized data).

Rules of the loader
-------------------

Every problem raises :class:`RecordingError` (a ``ValueError``) with ``.file``, ``.column`` and
``.row`` and a message that names them and says how to fix it; the first offending row is named,
counted from 0 over the data rows (for CSV the message also gives the file line, header = line
1). Checked: missing meta.json / table / required column (all required columns are listed);
partial column groups; unparseable values; NaN or inf in any known column (an optional column is
either absent or complete); empty tables; ids missing or empty; duplicate tx_id, or a
transmitter with the position and clock group of another (the same transmitter twice); time order
(imu, truth strictly increasing; pseudoranges, gnss non-decreasing); duplicate (t_s, tx_id) or
(t_s, sv_id); unknown transmitter ids; sigma_m <= 0; el_deg out of range; malformed sv_id;
ECEF positions closer than 6000 km to the Earth's centre (ENU written as ECEF); non-unit
quaternions; meta.json format, version, origin, GPS time, imu_rate_hz against the IMU steps.
A CSV table is checked as text first, naming the file line: UTF-8 (a byte-order mark accepted),
no NUL, valid quoting, every row with the header's number of fields, at least one data row, and
a final line break (a file cut short ends without one).
Extra columns are allowed and kept (Parquet keeps their types; CSV infers them); an extra
column whose name is close to a known optional column that is absent (``sigma`` for
``sigma_m``) gives a :class:`RecordingWarning`. Numeric columns become float64, id columns text.

Pivoting: :func:`pseudorange_matrix` and :func:`gnss_matrix` turn a long table into padded
``(T, L)`` arrays: epochs are the sorted unique ``t_s``; columns follow the transmitters table
order (or sorted sv_id for GNSS), or the ids given; an absent (epoch, source) is value 0 with
``valid`` False, so no NaN ever leaks. The result does not depend on the row order of the table.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import gzip
import io
import json
import math
import re
import warnings
import zlib
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from oaraim.geometry import frames

FORMAT_NAME = "oaraim-recording"
FORMAT_VERSION = 1

#: Positions closer than this to the Earth's centre are taken for local coordinates written as
#: ECEF (the WGS-84 polar radius is 6356.75 km, NIMA TR8350.2 Table 3.3; 350 km of margin).
_MIN_ECEF_NORM_M = 6.0e6
#: tolerance on |q| - 1 for truth quaternions
_QUAT_TOL = 1e-6
#: tolerance of the median IMU step against 1 / imu_rate_hz
_RATE_TOL = 0.05
#: RINEX 3 satellite system identifiers (RINEX 3.04, section 3.5) and two-digit numbers
_SV_RE = re.compile(r"^[GRECJIS][0-9]{2}$")


#: exact float parsing of CSV: pandas >= 3 parses round-trip exactly by default (and deprecates
#: the argument); pandas 2 needs float_precision="round_trip"
_CSV_PRECISION = ({} if int(pd.__version__.split(".")[0]) >= 3
                  else {"float_precision": "round_trip"})


class RecordingError(ValueError):
    """A recording that cannot be used. ``file``, ``column`` and ``row`` name the first problem
    (``column``/``row`` are None where they do not apply; ``row`` counts data rows from 0)."""

    def __init__(self, message: str, file: str | None = None, column: str | None = None,
                 row: int | None = None):
        super().__init__(message)
        self.file = file
        self.column = column
        self.row = row


class RecordingWarning(UserWarning):
    """Something in a recording that is allowed but probably a mistake (a misspelled column)."""


@dataclasses.dataclass(frozen=True)
class _Spec:
    required: tuple[str, ...]
    optional: tuple[str, ...] = ()
    text: tuple[str, ...] = ()
    groups: tuple[tuple[str, ...], ...] = ()
    time: str = "nondecreasing"  # or "strict"
    key: tuple[str, ...] | None = None
    positive: tuple[str, ...] = ()
    ecef: tuple[tuple[str, str, str], ...] = ()
    defaults: tuple[tuple[str, float], ...] = ()


_IMU_COLUMNS = ("t_s", "gyro_x_radps", "gyro_y_radps", "gyro_z_radps",
                "accel_x_mps2", "accel_y_mps2", "accel_z_mps2")

SPECS: dict[str, _Spec] = {
    "transmitters": _Spec(
        required=("tx_id", "kind", "group", "x_m", "y_m", "z_m", "clock_bias_m",
                  "clock_drift_mps"),
        optional=("clock_t0_s",), text=("tx_id", "kind", "group"), time="none",
        ecef=(("x_m", "y_m", "z_m"),), defaults=(("clock_t0_s", 0.0),)),
    "pseudoranges": _Spec(
        required=("t_s", "tx_id", "pseudorange_m"), optional=("sigma_m", "cn0_dbhz"),
        text=("tx_id",), key=("t_s", "tx_id"), positive=("sigma_m",)),
    "imu": _Spec(required=_IMU_COLUMNS, time="strict"),
    "gnss": _Spec(
        required=("t_s", "sv_id", "pseudorange_m", "sat_x_m", "sat_y_m", "sat_z_m",
                  "sat_clock_m"),
        optional=("iono_m", "tropo_m", "sigma_m", "el_deg", "cn0_dbhz"), text=("sv_id",),
        key=("t_s", "sv_id"), positive=("sigma_m",), ecef=(("sat_x_m", "sat_y_m", "sat_z_m"),)),
    "truth": _Spec(
        required=("t_s", "x_m", "y_m", "z_m"),
        optional=("vx_mps", "vy_mps", "vz_mps", "qx", "qy", "qz", "qw", "rx_clock_m",
                  "rx_clock_drift_mps"),
        groups=(("vx_mps", "vy_mps", "vz_mps"), ("qx", "qy", "qz", "qw")), time="strict",
        ecef=(("x_m", "y_m", "z_m"),)),
}
#: the tables in the order they are checked and written
TABLES = ("transmitters", "pseudoranges", "imu", "gnss", "truth")


@dataclasses.dataclass(frozen=True, eq=False)
class Recording:
    """One drive or flight. ``meta`` is the meta.json dict; tables are pandas DataFrames (None
    when absent) with the columns of the module docstring. Build one by hand, then
    ``validate_recording`` (or ``write_recording``) checks it; ``load_recording`` returns
    validated, normalized tables (float64 numbers, text ids, a 0..n-1 index)."""

    meta: dict
    transmitters: pd.DataFrame | None = None
    pseudoranges: pd.DataFrame | None = None
    imu: pd.DataFrame | None = None
    gnss: pd.DataFrame | None = None
    truth: pd.DataFrame | None = None

    def table(self, name: str) -> pd.DataFrame | None:
        return getattr(self, name)


# ----------------------------------------------------------------------------- errors

class _Where:
    """How to name a table's location in messages: a file path, CSV or not, or in memory."""

    def __init__(self, label: str, csv: bool = False, writing: bool = False,
                 meta: bool = False):
        self.label, self.csv, self.writing, self.meta = label, csv, writing, meta

    def err(self, problem: str, fix: str = "", column: str | None = None,
            row: int | None = None) -> RecordingError:
        parts = [self.label]
        if column is not None:
            parts.append(f"key {column!r}" if self.meta else f"column {column!r}")
        if row is not None:
            parts.append(f"row {row} (file line {row + 2})" if self.csv else
                         f"row {row} (counted from 0)")
        elif self.csv and column is not None:
            parts.append("header (file line 1)")
        msg = ", ".join(parts) + f": {problem}"
        if fix:
            msg += f". {fix}"
        if self.writing:
            msg = "cannot write the recording: " + msg
        return RecordingError(msg, file=self.label, column=column, row=row)


def _suggest(name: str, candidates) -> str:
    m = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean {m[0]!r}?)" if m else ""


# ----------------------------------------------------------------------------- meta

def _check_meta(meta: Any, where: _Where) -> dict:
    if not isinstance(meta, dict):
        raise where.err(f"meta.json must hold a JSON object, got {type(meta).__name__}",
                        "Write {\"format\": \"oaraim-recording\", \"format_version\": 1, "
                        "\"origin\": {...}}")
    try:
        meta = json.loads(json.dumps(meta, allow_nan=False))
    except (TypeError, ValueError) as e:
        raise where.err(f"meta is not plain JSON ({e})",
                        "Use only strings, finite numbers, lists, dicts, true/false/null") \
            from None
    if meta.get("format") != FORMAT_NAME:
        raise where.err(f"'format' must be {FORMAT_NAME!r}, got {meta.get('format')!r}",
                        f"Add \"format\": \"{FORMAT_NAME}\"", column="format")
    v = meta.get("format_version")
    if isinstance(v, bool) or not isinstance(v, int):
        raise where.err(f"'format_version' must be the integer {FORMAT_VERSION}, got {v!r}",
                        f"Add \"format_version\": {FORMAT_VERSION}", column="format_version")
    if v != FORMAT_VERSION:
        raise where.err(f"format_version {v} is not supported (this toolkit reads version "
                        f"{FORMAT_VERSION})", "Convert the recording or update the toolkit",
                        column="format_version")
    origin = meta.get("origin")
    if not isinstance(origin, dict):
        raise where.err("'origin' is missing or not an object",
                        "Add \"origin\": {\"lat_deg\": ..., \"lon_deg\": ..., \"h_m\": ...}, the "
                        "geodetic origin of the local ENU frame", column="origin")
    bounds = {"lat_deg": (-90.0, 90.0), "lon_deg": (-180.0, 360.0), "h_m": (-1e4, 1e6)}
    for k, (lo, hi) in bounds.items():
        x = origin.get(k)
        if isinstance(x, bool) or not isinstance(x, int | float) or not lo <= x <= hi:
            raise where.err(f"origin.{k} must be a number in [{lo:g}, {hi:g}], got {x!r}",
                            "Give the origin in WGS-84 degrees and metres", column=f"origin.{k}")
    wk, tow = meta.get("t0_gps_week"), meta.get("t0_gps_tow_s")
    if (wk is None) != (tow is None):
        raise where.err("'t0_gps_week' and 't0_gps_tow_s' go together",
                        "Give both (the GPS time of t_s = 0) or neither",
                        column="t0_gps_week" if wk is None else "t0_gps_tow_s")
    if wk is not None:
        if isinstance(wk, bool) or not isinstance(wk, int) or wk < 0:
            raise where.err(f"t0_gps_week must be a non-negative integer (full week number, "
                            f"not modulo 1024), got {wk!r}", column="t0_gps_week")
        if isinstance(tow, bool) or not isinstance(tow, int | float) or not 0 <= tow < 604800:
            raise where.err(f"t0_gps_tow_s must be in [0, 604800), got {tow!r}",
                            column="t0_gps_tow_s")
    rate = meta.get("imu_rate_hz")
    if rate is not None and (isinstance(rate, bool) or not isinstance(rate, int | float)
                             or not rate > 0):
        raise where.err(f"imu_rate_hz must be a positive number or null, got {rate!r}",
                        column="imu_rate_hz")
    if meta.get("body_frame", "FLU") != "FLU":
        raise where.err(f"body_frame {meta.get('body_frame')!r} is not supported",
                        "Convert the IMU and attitude to \"FLU\" (right-handed: x front, "
                        "y left, z up; from FRD negate y and z)", column="body_frame")
    if meta.get("quaternion", "JPL") != "JPL":
        raise where.err(f"quaternion convention {meta.get('quaternion')!r} is not supported",
                        "Write JPL quaternions, scalar last (see the truth table)",
                        column="quaternion")
    src = meta.get("source")
    if src is not None and (not isinstance(src, dict)
                            or src.get("kind") not in ("real", "synthesized")):
        raise where.err(f"'source' must be an object with \"kind\": \"real\" or "
                        f"\"synthesized\", got {src!r}", column="source")
    for k in ("name", "description"):
        if k in meta and not isinstance(meta[k], str):
            raise where.err(f"{k!r} must be text, got {meta[k]!r}", column=k)
    return meta


# ----------------------------------------------------------------------------- tables

def _first(mask) -> int:
    return int(np.flatnonzero(np.asarray(mask))[0])


def _check_table(name: str, df: Any, where: _Where) -> pd.DataFrame:
    spec = SPECS[name]
    if not isinstance(df, pd.DataFrame):
        raise where.err(f"the {name} table must be a pandas DataFrame, got "
                        f"{type(df).__name__}")
    df = df.reset_index(drop=True)
    if len(df) == 0:
        raise where.err("the table has no rows", "Leave the table out if it has no data")
    cols = [str(c) for c in df.columns]
    df.columns = cols
    missing = [c for c in spec.required if c not in cols]
    if missing:
        hint = "".join(f" {c!r}{_suggest(c, [x for x in cols if x not in spec.required])}"
                       for c in missing)
        raise where.err(f"missing required column(s):{hint}",
                        f"The {name} table needs the columns {', '.join(spec.required)}",
                        column=missing[0])
    for g in spec.groups:
        present = [c for c in g if c in cols]
        if present and len(present) < len(g):
            lack = [c for c in g if c not in cols]
            raise where.err(f"column(s) {', '.join(lack)} missing: {', '.join(g)} go together",
                            "Give all of them or none", column=lack[0])
    known = set(spec.required) | set(spec.optional)
    absent_optional = [c for c in spec.optional if c not in cols]
    for c in cols:
        if c not in known:
            m = difflib.get_close_matches(c, absent_optional, n=1, cutoff=0.75)
            if m:
                warnings.warn(f"{where.label}: extra column {c!r} is kept but not used; did you "
                              f"mean the optional column {m[0]!r}?", RecordingWarning,
                              stacklevel=3)
    # text columns
    for c in spec.text:
        s = df[c]
        if pd.api.types.is_float_dtype(s.dtype) and not s.isna().all():
            raise where.err("ids must be text or integers, got floating-point numbers",
                            "Write the ids as text (e.g. 'T1')", column=c,
                            row=_first(s.notna()))
        bad = s.isna().to_numpy()
        if bad.any():
            raise where.err("missing id", "Every row needs an id", column=c, row=_first(bad))
        s = s.astype(str)
        bad = (s.str.len() == 0).to_numpy()
        if bad.any():
            raise where.err("empty id", "Every row needs a non-empty id", column=c,
                            row=_first(bad))
        df[c] = s
    # numeric columns
    for c in [c for c in (*spec.required, *spec.optional) if c in cols and c not in spec.text]:
        s = df[c]
        if pd.api.types.is_bool_dtype(s.dtype):
            raise where.err("true/false values in a numeric column", column=c, row=0)
        num = pd.to_numeric(s, errors="coerce")
        unparsed = (num.isna() & s.notna()).to_numpy()
        if unparsed.any():
            r = _first(unparsed)
            raise where.err(f"cannot read {s.iloc[r]!r} as a number",
                            "Write plain decimal numbers in SI units", column=c, row=r)
        v = num.to_numpy(dtype=np.float64, na_value=np.nan)
        bad = ~np.isfinite(v)
        if bad.any():
            r = _first(bad)
            raise where.err(f"value {float(v[r])!r} is not finite (NaN, empty or inf)",
                            "Drop the row or leave the whole optional column out; a missing "
                            "measurement is a missing row", column=c, row=r)
        df[c] = v
    for c, val in spec.defaults:
        if c not in df.columns:
            df[c] = np.float64(val)
    for c in spec.positive:
        if c in df.columns:
            bad = df[c].to_numpy() <= 0
            if bad.any():
                r = _first(bad)
                raise where.err(f"{c} must be > 0, got {float(df[c].iloc[r])!r}",
                                "Give standard deviations in metres", column=c, row=r)
    for xyz in spec.ecef:
        norm = np.linalg.norm(df[list(xyz)].to_numpy(), axis=1)
        bad = norm < _MIN_ECEF_NORM_M
        if bad.any():
            r = _first(bad)
            raise where.err(f"position {norm[r]:.1f} m from the Earth's centre: these look like "
                            f"local coordinates, not ECEF", "Convert with "
                            "geometry.enu_to_ecef(enu_m, origin_ecef_m)", column=xyz[0], row=r)
    if name == "gnss":
        bad = ~df["sv_id"].str.match(_SV_RE).to_numpy(dtype=bool)
        if bad.any():
            r = _first(bad)
            raise where.err(f"sv_id {df['sv_id'].iloc[r]!r} is not a RINEX 3 satellite id",
                            "Write a system letter (G, R, E, C, J, I, S) and two digits, "
                            "e.g. 'G05'", column="sv_id", row=r)
        if "el_deg" in df.columns:
            bad = np.abs(df["el_deg"].to_numpy()) > 90
            if bad.any():
                r = _first(bad)
                raise where.err(f"elevation {float(df['el_deg'].iloc[r])!r} deg is outside "
                                "[-90, 90]", "Give el_deg in degrees", column="el_deg", row=r)
    if name == "truth" and "qw" in df.columns:
        q = df[["qx", "qy", "qz", "qw"]].to_numpy()
        bad = np.abs(np.linalg.norm(q, axis=1) - 1.0) > _QUAT_TOL
        if bad.any():
            r = _first(bad)
            raise where.err(f"quaternion norm {np.linalg.norm(q[r]):.9g} is not 1 "
                            f"(tolerance {_QUAT_TOL:g})", "Normalize qx, qy, qz, qw",
                            column="qw", row=r)
    if spec.time != "none":
        t = df["t_s"].to_numpy()
        d = np.diff(t)
        bad = d <= 0 if spec.time == "strict" else d < 0
        if bad.any():
            r = _first(bad) + 1
            if d[r - 1] == 0:
                raise where.err(f"t_s = {float(t[r])!r} s repeats the previous row; {name} samples "
                                "must be strictly increasing", "Drop duplicate samples",
                                column="t_s", row=r)
            order = "strictly increasing" if spec.time == "strict" else "non-decreasing"
            raise where.err(f"t_s = {float(t[r])!r} s is earlier than {float(t[r - 1])!r} s on "
                            f"the row before; t_s must be {order}", "Sort the table by t_s (e.g. "
                            "geometry.recording.sort_recording, or df.sort_values('t_s', "
                            "kind='stable'))", column="t_s", row=r)
    if spec.key is not None:
        dup = df.duplicated(list(spec.key), keep="first").to_numpy()
        if dup.any():
            r = _first(dup)
            k = spec.key[1]
            t, i = df["t_s"].iloc[r], df[k].iloc[r]
            first = _first((df["t_s"] == t).to_numpy() & (df[k] == i).to_numpy())
            raise where.err(f"a second measurement of {k} {i!r} at t_s = {float(t)!r} s (the "
                            f"first is row {first})", f"Keep one row per (t_s, {k})",
                            column=k, row=r)
    if name == "transmitters":
        dup = df.duplicated(["tx_id"]).to_numpy()
        if dup.any():
            r = _first(dup)
            raise where.err(f"tx_id {df['tx_id'].iloc[r]!r} appears twice",
                            "Give each transmitter one row", column="tx_id", row=r)
        same = ["x_m", "y_m", "z_m", "group"]
        dup = df.duplicated(same).to_numpy()
        if dup.any():
            r = _first(dup)
            first = _first((df[same] == df[same].iloc[r]).all(axis=1).to_numpy())
            raise where.err(f"transmitter {df['tx_id'].iloc[r]!r} has the position and clock "
                            f"group of {df['tx_id'].iloc[first]!r} (row {first}): the same "
                            "transmitter twice would count as two independent ranges",
                            "Keep one row per transmitter (co-located antennas of one clock "
                            "group are one transmitter)", column="tx_id", row=r)
    return df


def _cross_checks(meta, tables, where_of) -> None:
    pr, tx = tables.get("pseudoranges"), tables.get("transmitters")
    if pr is None and tables.get("gnss") is None:
        raise where_of("pseudoranges").err(
            "no ranging table: a recording needs pseudoranges (with transmitters) or gnss",
            "Add pseudoranges.parquet|csv and transmitters.parquet|csv, or gnss.parquet|csv")
    if pr is not None and tx is None:
        raise where_of("transmitters").err(
            "the transmitters table is missing but pseudoranges exist",
            "Add transmitters.parquet|csv with columns "
            + ", ".join(SPECS["transmitters"].required))
    if pr is not None:
        known = pd.Index(tx["tx_id"])
        bad = ~pr["tx_id"].isin(known).to_numpy()
        if bad.any():
            r = _first(bad)
            i = pr["tx_id"].iloc[r]
            shown = ", ".join(repr(x) for x in known[:10]) + (", ..." if len(known) > 10 else "")
            raise where_of("pseudoranges").err(
                f"unknown transmitter id {i!r}{_suggest(i, known)} (not in the transmitters "
                f"table, which has {shown})", "Add the transmitter to the transmitters table or "
                "drop its rows", column="tx_id", row=r)
    imu, rate = tables.get("imu"), meta.get("imu_rate_hz")
    if imu is not None and rate is not None and len(imu) > 1:
        step = float(np.median(np.diff(imu["t_s"].to_numpy())))
        if abs(step * rate - 1.0) > _RATE_TOL:
            raise where_of("imu").err(
                f"the median IMU step {step:.6g} s does not match imu_rate_hz = {rate!r} in "
                "meta.json", "Check that t_s is in seconds and the rate in Hz", column="t_s")


def _validate(meta, tables: dict, where_of) -> Recording:
    meta = _check_meta(meta, where_of("meta"))
    out = {}
    for name in TABLES:
        df = tables.get(name)
        out[name] = None if df is None else _check_table(name, df, where_of(name))
    _cross_checks(meta, out, where_of)
    return Recording(meta=meta, **out)


def validate_recording(recording: Recording) -> Recording:
    """Check an in-memory recording with the loader's rules; return it normalized (float64
    numbers, text ids, 0..n-1 index, defaults filled). Raises :class:`RecordingError`."""
    def where_of(name):
        return _Where("meta", meta=True) if name == "meta" else _Where(f"{name} table")

    return _validate(recording.meta, {n: recording.table(n) for n in TABLES}, where_of)


# ----------------------------------------------------------------------------- load / write

def _find(folder: Path, name: str) -> Path | None:
    found = [folder / f"{name}{ext}" for ext in (".parquet", ".csv", ".csv.gz")
             if (folder / f"{name}{ext}").is_file()]
    if len(found) > 1:
        raise RecordingError(f"{folder}: both {found[0].name} and {found[1].name} exist; keep "
                             f"one file per table", file=str(found[1]))
    return found[0] if found else None


def _csv_text(path: Path) -> str:
    """The text of a CSV table, checked line by line before pandas parses it: UTF-8 (a
    byte-order mark accepted), no NUL, every row with the header's number of fields, and a final
    line break (a file cut short ends without one). ``RecordingError`` names the file line."""
    try:
        raw = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
    except (OSError, EOFError, zlib.error) as e:
        raise RecordingError(f"{path}: cannot read the file ({e})", file=str(path)) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise RecordingError(f"{path}: file line {line}: not UTF-8 text (byte {e.start}); save "
                             "the table as UTF-8 CSV", file=str(path)) from None
    where = _Where(str(path), csv=True)

    def err(line, problem, fix=""):
        e = where.err(f"file line {line}: {problem}", fix)
        e.row = line - 2 if line >= 2 else None
        return e

    if not text.strip():
        raise err(1, "the file is empty", "Write a header line and one line per row")
    if "\0" in text:
        raise err(text[:text.index("\0")].count("\n") + 1, "a NUL character: not a text file")
    if text and not text.endswith(("\n", "\r")):
        raise err(text.count("\n") + 1, "the last line does not end with a line break: the file "
                  "is truncated", "Write the table again (pandas to_csv ends every line)")
    reader = csv.reader(io.StringIO(text, newline=""), strict=True, skipinitialspace=True)
    n_fields = None
    try:
        for row in reader:
            if n_fields is None:
                n_fields = len(row)
            elif row and len(row) != n_fields:
                raise err(reader.line_num, f"{len(row)} fields where the header has {n_fields}")
    except csv.Error as e:
        raise err(reader.line_num, f"not CSV ({e})") from None
    if reader.line_num < 2:
        raise err(2, "no data rows after the header", "Leave the table out if it has no data")
    return text


def _read(path: Path, name: str) -> pd.DataFrame:
    text = None if path.suffix == ".parquet" else _csv_text(path)
    try:
        if text is None:
            return pd.read_parquet(path, engine="pyarrow")
        dtypes = {c: str for c in SPECS[name].text}
        return pd.read_csv(io.StringIO(text), dtype=dtypes, keep_default_na=False,
                           na_values=[""], skipinitialspace=True, **_CSV_PRECISION)
    except Exception as e:  # pyarrow / parser errors have many types
        raise RecordingError(f"{path}: cannot read the file ({type(e).__name__}: {e}); write it "
                             f"with pandas to_parquet / to_csv", file=str(path)) from None


def load_recording(path) -> Recording:
    """Load and validate the recording in folder ``path`` (or the folder of ``path`` when it
    names meta.json). Raises :class:`RecordingError` naming file, column and row."""
    folder = Path(path).expanduser()
    if folder.is_file() and folder.name == "meta.json":
        folder = folder.parent
    if not folder.is_dir():
        raise RecordingError(f"{folder}: not a folder; a recording is a folder with meta.json "
                             "and tables", file=str(folder))
    meta_path = folder / "meta.json"
    if not meta_path.is_file():
        raise RecordingError(f"{meta_path}: missing; every recording needs meta.json with "
                             f"\"format\": \"{FORMAT_NAME}\", \"format_version\": "
                             f"{FORMAT_VERSION} and \"origin\"", file=str(meta_path))
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise RecordingError(f"{meta_path}: line {e.lineno}, column {e.colno}: not valid JSON "
                             f"({e.msg})", file=str(meta_path)) from None
    except (OSError, UnicodeDecodeError) as e:
        raise RecordingError(f"{meta_path}: cannot read ({e})", file=str(meta_path)) from None
    tables, wheres = {}, {"meta": _Where(str(meta_path), meta=True)}
    for name in TABLES:
        p = _find(folder, name)
        if p is None:
            wheres[name] = _Where(str(folder / f"{name}.parquet|csv"))
            continue
        wheres[name] = _Where(str(p), csv=p.suffix != ".parquet")
        tables[name] = _read(p, name)
    return _validate(meta, tables, wheres.__getitem__)


def write_recording(path, recording: Recording, format: str = "parquet",  # noqa: A002
                    overwrite: bool = False) -> Path:
    """Validate ``recording`` and write it to folder ``path`` (created) as meta.json plus one
    ``NAME.parquet`` or ``NAME.csv`` per present table. Refuses to write an invalid recording
    (:class:`RecordingError`) or into a folder that already holds recording files unless
    ``overwrite`` (which removes only the files of this format's tables). Returns the folder."""
    if format not in ("parquet", "csv"):
        raise ValueError(f"format must be 'parquet' or 'csv', got {format!r}")
    folder = Path(path).expanduser()
    ext = ".parquet" if format == "parquet" else ".csv"

    def where_of(name):
        f = "meta.json" if name == "meta" else f"{name}{ext}"
        return _Where(str(folder / f), writing=True, meta=name == "meta")

    rec = _validate(recording.meta, {n: recording.table(n) for n in TABLES}, where_of)
    existing = [folder / f"{n}{e}" for n in TABLES for e in (".parquet", ".csv", ".csv.gz")
                if (folder / f"{n}{e}").exists()]
    if (folder / "meta.json").exists():
        existing.append(folder / "meta.json")
    if existing and not overwrite:
        raise FileExistsError(f"{folder} already holds a recording ({existing[0].name}); pass "
                              "overwrite=True or choose another folder")
    folder.mkdir(parents=True, exist_ok=True)
    for p in existing:
        p.unlink()
    (folder / "meta.json").write_text(json.dumps(rec.meta, indent=2, allow_nan=False) + "\n",
                                      encoding="utf-8")
    for name in TABLES:
        df = rec.table(name)
        if df is None:
            continue
        if format == "parquet":
            df.to_parquet(folder / f"{name}.parquet", engine="pyarrow", index=False)
        else:
            df.to_csv(folder / f"{name}.csv", index=False)
    return folder


def sort_recording(recording: Recording) -> Recording:
    """The same recording with its tables sorted the way the loader requires (stable sorts:
    imu, truth by t_s; pseudoranges by (t_s, tx_id); gnss by (t_s, sv_id))."""
    keys = {"imu": ["t_s"], "truth": ["t_s"], "pseudoranges": ["t_s", "tx_id"],
            "gnss": ["t_s", "sv_id"]}
    new = {}
    for name, k in keys.items():
        df = recording.table(name)
        if df is not None:
            new[name] = df.sort_values(k, kind="stable").reset_index(drop=True)
    return dataclasses.replace(recording, **new)


# ----------------------------------------------------------------------------- arrays

class EpochMatrix(NamedTuple):
    """A long table pivoted to ``(T, L)`` (or ``(T, L, K)`` for several value columns)."""

    t_s: np.ndarray  # (T,) sorted epochs
    values: np.ndarray  # (T, L[, K]) float64, 0 where not valid
    valid: np.ndarray  # (T, L) bool
    ids: np.ndarray  # (L,) ids of the columns (object array of str)


def _pivot(df: pd.DataFrame, key: str, ids, value, t_s) -> EpochMatrix:
    ids = np.asarray([str(i) for i in ids], dtype=object)
    if len(set(ids)) != len(ids):
        raise ValueError(f"{key}s must be unique, got {list(ids)}")
    index = pd.Index(ids)
    col = index.get_indexer(df[key].astype(str))
    keep = col >= 0
    times = df["t_s"].to_numpy(np.float64)[keep]
    col = col[keep]
    if t_s is None:
        t = np.unique(times)
    else:
        t = np.asarray(t_s, np.float64).reshape(-1)
        if np.any(np.diff(t) <= 0):
            raise ValueError("t_s must be strictly increasing")
    row = np.searchsorted(t, times)
    row_c = np.minimum(row, max(len(t) - 1, 0))
    off = (row >= len(t)) | (t[row_c] != times) if len(t) else np.ones(len(times), bool)
    if off.any():
        raise ValueError(f"a measurement at t_s = {float(times[_first(off)])!r} s is not on the "
                         "given epoch grid t_s")
    single = isinstance(value, str)
    names = [value] if single else list(value)
    vals = df.loc[keep, names].to_numpy(np.float64) if len(names) else np.zeros((keep.sum(), 0))
    if not np.all(np.isfinite(vals)):
        raise ValueError(f"non-finite values in {names}; validate the recording first")
    flat = row * len(ids) + col
    if len(np.unique(flat)) != len(flat):
        raise ValueError(f"duplicate (t_s, {key}) rows; validate the recording first")
    out = np.zeros((len(t), len(ids), len(names)))
    valid = np.zeros((len(t), len(ids)), bool)
    out[row, col] = vals
    valid[row, col] = True
    return EpochMatrix(t, out[..., 0] if single else out, valid, ids)


def pseudorange_matrix(recording: Recording, tx_ids=None, value="pseudorange_m",
                       t_s=None) -> EpochMatrix:
    """Terrestrial pseudoranges as ``(t_s (T,), values (T, L), valid (T, L), ids (L,))``.

    Epochs are the sorted unique ``t_s`` of the table (or the strictly increasing grid ``t_s``
    given; a row off the grid is a ValueError). Columns are ``tx_ids`` (default: every
    transmitter, in the transmitters table order; rows of other transmitters are dropped).
    ``value`` is a column name (``"sigma_m"``, ``"cn0_dbhz"``, ...) or a list of names (then
    ``values`` is ``(T, L, K)``). Absent entries are 0 with ``valid`` False. Row order of the
    table does not matter."""
    if recording.pseudoranges is None:
        raise ValueError("the recording has no pseudoranges table")
    if tx_ids is None:
        tx_ids = recording.transmitters["tx_id"].tolist()
    return _pivot(recording.pseudoranges, "tx_id", tx_ids, value, t_s)


def gnss_matrix(recording: Recording, sv_ids=None, value="pseudorange_m",
                t_s=None) -> EpochMatrix:
    """GNSS rows pivoted like :func:`pseudorange_matrix`; columns default to the sorted unique
    sv_id (``"E11" < "G05"``). ``value=["sat_x_m", "sat_y_m", "sat_z_m"]`` gives positions."""
    if recording.gnss is None:
        raise ValueError("the recording has no gnss table")
    if sv_ids is None:
        sv_ids = sorted(recording.gnss["sv_id"].astype(str).unique())
    return _pivot(recording.gnss, "sv_id", sv_ids, value, t_s)


def epochs(recording: Recording) -> np.ndarray:
    """Sorted unique ``t_s`` over the pseudoranges and gnss tables (a common grid for both
    matrices: pass it as ``t_s=``)."""
    ts = [df["t_s"].to_numpy(np.float64) for df in (recording.pseudoranges, recording.gnss)
          if df is not None]
    return np.unique(np.concatenate(ts)) if ts else np.zeros(0)


def _tx_rows(recording: Recording, tx_ids) -> pd.DataFrame:
    tx = recording.transmitters
    if tx is None:
        raise ValueError("the recording has no transmitters table")
    if tx_ids is None:
        return tx
    idx = pd.Index(tx["tx_id"].astype(str)).get_indexer([str(i) for i in tx_ids])
    if np.any(idx < 0):
        bad = [i for i, j in zip(tx_ids, idx, strict=True) if j < 0]
        raise ValueError(f"unknown transmitter ids {bad}")
    return tx.iloc[idx]


def tower_clock_m(recording: Recording, t_s, tx_ids=None) -> np.ndarray:
    """Transmitter clocks c dt_s(t) = clock_bias_m + clock_drift_mps (t_s - clock_t0_s) (seed 000
    eq. 3), shape ``t_s.shape + (L,)``, columns in ``tx_ids`` (default: table) order."""
    tx = _tx_rows(recording, tx_ids)
    t = np.asarray(t_s, np.float64)[..., None]
    t0 = tx["clock_t0_s"].to_numpy(np.float64) if "clock_t0_s" in tx else 0.0
    return (tx["clock_bias_m"].to_numpy(np.float64)
            + tx["clock_drift_mps"].to_numpy(np.float64) * (t - t0))


def origin_ecef_m(recording: Recording) -> np.ndarray:
    """ECEF (3,) of the ENU origin in meta.json."""
    o = recording.meta["origin"]
    return np.asarray(frames.geodetic_to_ecef(np.deg2rad(o["lat_deg"]), np.deg2rad(o["lon_deg"]),
                                              o["h_m"]))


def to_enu_m(recording: Recording, ecef_m) -> np.ndarray:
    """ENU (..., 3) of ECEF points ``(..., 3)`` in the recording's local frame."""
    return np.asarray(frames.ecef_to_enu(np.asarray(ecef_m, np.float64),
                                         origin_ecef_m(recording)))


def transmitters_enu_m(recording: Recording, tx_ids=None) -> np.ndarray:
    """ENU positions (L, 3) of the transmitters, in ``tx_ids`` (default: table) order."""
    tx = _tx_rows(recording, tx_ids)
    return to_enu_m(recording, tx[["x_m", "y_m", "z_m"]].to_numpy(np.float64))


class TruthENU(NamedTuple):
    t_s: np.ndarray  # (T,)
    position_enu_m: np.ndarray  # (T, 3)
    velocity_enu_mps: np.ndarray | None  # (T, 3) or None when the truth has no velocity
    quaternion: np.ndarray | None  # (T, 4) JPL ^B_G q [qx, qy, qz, qw] (G = the ENU frame)


def truth_enu(recording: Recording) -> TruthENU:
    """Ground truth in the local ENU frame of meta.json (velocity rotated, not translated)."""
    tr = recording.truth
    if tr is None:
        raise ValueError("the recording has no truth table")
    pos = to_enu_m(recording, tr[["x_m", "y_m", "z_m"]].to_numpy(np.float64))
    vel = None
    if "vx_mps" in tr:
        o = recording.meta["origin"]
        r = np.asarray(frames.enu_rotation(np.deg2rad(o["lat_deg"]), np.deg2rad(o["lon_deg"])))
        vel = tr[["vx_mps", "vy_mps", "vz_mps"]].to_numpy(np.float64) @ r.T
    q = tr[["qx", "qy", "qz", "qw"]].to_numpy(np.float64) if "qw" in tr else None
    return TruthENU(tr["t_s"].to_numpy(np.float64), pos, vel, q)


def t_gps_s(recording: Recording, t_s) -> np.ndarray:
    """GPS seconds (since 1980-01-06, ``geometry.gpstime``) of recording times ``t_s``."""
    wk, tow = recording.meta.get("t0_gps_week"), recording.meta.get("t0_gps_tow_s")
    if wk is None:
        raise ValueError("meta.json gives no t0_gps_week / t0_gps_tow_s")
    return wk * 604800.0 + tow + np.asarray(t_s, np.float64)


def jpl_quaternion_matrix(q) -> np.ndarray:
    """C(q) (..., 3, 3) of JPL quaternions ``[qx, qy, qz, qw]``: maps ENU vectors to body
    vectors for the truth table's ^B_G q (Trawny & Roumeliotis, "Indirect Kalman filter for 3D
    attitude estimation", 2005, eq. 78: C = (2 q4^2 - 1) I - 2 q4 [q x] + 2 q q^T)."""
    q = np.asarray(q, np.float64)
    v, w = q[..., :3], q[..., 3]
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = np.zeros_like(x)
    skew = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                     np.stack([-y, x, zero], -1)], -2)
    return ((2 * w**2 - 1)[..., None, None] * np.eye(3) - 2 * w[..., None, None] * skew
            + 2 * v[..., :, None] * v[..., None, :])


# ----------------------------------------------------------------------------- example

#: WGS-84 normal gravity on the ellipsoid (Somigliana): gamma_e and k, NIMA TR8350.2 eq. (4-1)
#: and Table 3.4 (gamma_e = 9.7803253359 m/s^2, k = 0.00193185265241)
_GAMMA_E_MPS2 = 9.7803253359
_SOMIGLIANA_K = 0.00193185265241
#: free-air gradient of normal gravity, about 0.3086 mGal/m (first-order term, NIMA TR8350.2
#: eq. 4-3 evaluated near the surface)
_FREE_AIR_MPS2_PER_M = 3.086e-6


def normal_gravity_mps2(lat_rad, h_m) -> np.ndarray:
    """WGS-84 normal gravity magnitude near the surface (Somigliana plus free-air term)."""
    s2 = np.sin(lat_rad) ** 2
    return (_GAMMA_E_MPS2 * (1 + _SOMIGLIANA_K * s2) / np.sqrt(1 - frames.WGS84_E2 * s2)
            - _FREE_AIR_MPS2_PER_M * np.asarray(h_m))


def example_recording(duration_s: float = 5.0, imu_rate_hz: float = 100.0,
                      pr_rate_hz: float = 10.0, with_gnss: bool = False) -> Recording:
    """A tiny synthesized drive: a car at 10 m/s on a straight road heading 30 deg north of
    east past 3 LTE towers (two carriers), exact pseudoranges (no noise:
    |r - r_tx| + c dt_rx - c dt_tx), an ideal IMU and full truth (position, velocity, JPL
    attitude, receiver clock); with ``with_gnss`` also 5 GNSS satellites at 1 Hz (fixed
    positions, an illustration only). Values are illustrative, not from a paper: origin in
    downtown Riverside, CA (the area of seed 000's drive); tower clock biases of a few hundred
    metres, well inside LTE's 3 us (900 m) synchronization requirement quoted in seed 004 sec. I.

    The IMU is ideal in a flat, non-rotating ENU frame: zero angular rate (Earth rotation,
    7.3e-5 rad/s, is left out) and specific force (0, 0, g) with WGS-84 normal gravity.
    """
    lat, lon, h = 33.9806, -117.3755, 250.0
    psi = np.deg2rad(30.0)
    speed = 10.0
    n_imu = int(round(duration_s * imu_rate_hz)) + 1
    n_pr = int(round(duration_s * pr_rate_hz)) + 1
    t_imu = np.arange(n_imu) / imu_rate_hz
    t_pr = np.arange(n_pr) / pr_rate_hz
    origin = np.asarray(frames.geodetic_to_ecef(np.deg2rad(lat), np.deg2rad(lon), h))
    r_enu = np.asarray(frames.enu_rotation(np.deg2rad(lat), np.deg2rad(lon)))
    heading = np.array([np.cos(psi), np.sin(psi), 0.0])

    def pos_ecef(t):
        return origin + (speed * t[:, None] * heading) @ r_enu

    def rx_clock(t):  # c dt_rx: 1 km offset, 0.3 m/s drift (a free-running TCXO-like rate)
        return 1000.0 + 0.3 * t

    tx_enu = np.array([[200.0, 150.0, 30.0], [-150.0, 300.0, 25.0], [100.0, -250.0, 35.0]])
    tx_ecef = origin + tx_enu @ r_enu
    transmitters = pd.DataFrame({
        "tx_id": ["T1", "T2", "T3"], "kind": ["lte"] * 3,
        "group": ["carrier_a", "carrier_a", "carrier_b"],
        "x_m": tx_ecef[:, 0], "y_m": tx_ecef[:, 1], "z_m": tx_ecef[:, 2],
        "clock_bias_m": [150.0, -320.5, 75.25], "clock_drift_mps": [0.02, -0.015, 0.01],
        "clock_t0_s": [0.0, 0.0, 0.0]})
    p = pos_ecef(t_pr)
    rng = np.linalg.norm(p[:, None, :] - tx_ecef[None], axis=-1)
    clk = (transmitters["clock_bias_m"].to_numpy()
           + transmitters["clock_drift_mps"].to_numpy() * t_pr[:, None])
    rho = rng + rx_clock(t_pr)[:, None] - clk
    pseudoranges = pd.DataFrame({
        "t_s": np.repeat(t_pr, 3), "tx_id": np.tile(["T1", "T2", "T3"], n_pr),
        "pseudorange_m": rho.reshape(-1), "sigma_m": np.full(3 * n_pr, 2.0),
        "cn0_dbhz": np.tile([55.0, 48.0, 51.0], n_pr)})
    g = float(normal_gravity_mps2(np.deg2rad(lat), h))
    zeros = np.zeros(n_imu)
    imu = pd.DataFrame({"t_s": t_imu, "gyro_x_radps": zeros, "gyro_y_radps": zeros,
                        "gyro_z_radps": zeros, "accel_x_mps2": zeros, "accel_y_mps2": zeros,
                        "accel_z_mps2": np.full(n_imu, g)})
    pt = pos_ecef(t_imu)
    v = np.broadcast_to(speed * heading @ r_enu, (n_imu, 3))
    truth = pd.DataFrame({
        "t_s": t_imu, "x_m": pt[:, 0], "y_m": pt[:, 1], "z_m": pt[:, 2],
        "vx_mps": v[:, 0], "vy_mps": v[:, 1], "vz_mps": v[:, 2],
        "qx": zeros, "qy": zeros, "qz": np.full(n_imu, np.sin(psi / 2)),
        "qw": np.full(n_imu, np.cos(psi / 2)),
        "rx_clock_m": rx_clock(t_imu), "rx_clock_drift_mps": np.full(n_imu, 0.3)})
    gnss = None
    if with_gnss:
        sv = ["E11", "G02", "G05", "G12", "G25"]
        az = np.deg2rad([40.0, 100.0, 200.0, 290.0, 0.0])
        el = np.deg2rad([35.0, 60.0, 25.0, 45.0, 80.0])
        los = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)
        sat = origin + (21.0e6 * los) @ r_enu
        sat_clk = np.array([12.5, -30.25, 4.0, 101.0, -7.75])
        t_g = np.arange(int(math.floor(duration_s)) + 1, dtype=np.float64)
        pg = pos_ecef(t_g)
        rg = np.linalg.norm(pg[:, None, :] - sat[None], axis=-1)
        iono = np.broadcast_to(2.0 + 3.0 * (1 - np.sin(el)), rg.shape)
        tropo = np.broadcast_to(2.4 / np.sin(el), rg.shape)
        pr = rg + rx_clock(t_g)[:, None] - sat_clk + iono + tropo
        n = len(t_g)
        gnss = pd.DataFrame({
            "t_s": np.repeat(t_g, 5), "sv_id": np.tile(sv, n), "pseudorange_m": pr.reshape(-1),
            "sat_x_m": np.tile(sat[:, 0], n), "sat_y_m": np.tile(sat[:, 1], n),
            "sat_z_m": np.tile(sat[:, 2], n), "sat_clock_m": np.tile(sat_clk, n),
            "iono_m": iono.reshape(-1), "tropo_m": tropo.reshape(-1),
            "sigma_m": np.full(5 * n, 1.0), "el_deg": np.tile(np.rad2deg(el), n)})
    meta = {
        "format": FORMAT_NAME, "format_version": FORMAT_VERSION,
        "name": "example-straight-drive",
        "description": "Straight 10 m/s drive past 3 LTE towers, exact pseudoranges",
        "origin": {"lat_deg": lat, "lon_deg": lon, "h_m": h},
        "t0_gps_week": 2290, "t0_gps_tow_s": 345600.0, "imu_rate_hz": imu_rate_hz,
        "body_frame": "FLU", "quaternion": "JPL",
        "source": {"kind": "synthesized", "generator": "geometry.recording.example_recording",
                   "parameters": {"duration_s": duration_s, "imu_rate_hz": imu_rate_hz,
                                  "pr_rate_hz": pr_rate_hz, "with_gnss": with_gnss,
                                  "speed_mps": speed, "heading_deg_from_east": 30.0}},
    }
    return validate_recording(Recording(meta=meta, transmitters=transmitters,
                                        pseudoranges=pseudoranges, imu=imu, gnss=gnss,
                                        truth=truth))
