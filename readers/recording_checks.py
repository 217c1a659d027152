"""The loader's rules for recordings (``readers.recording``): the table specifications, the
checks of meta.json, of each table and across tables, and the errors they raise. Each problem
raises :class:`RecordingError` naming file, column and row with a one-line fix; the format
itself is described in ``readers.recording``."""

from __future__ import annotations

import dataclasses
import difflib
import json
import re
import warnings
from typing import Any

import numpy as np
import pandas as pd

from oaraim.readers.transmitters import MIN_SEPARATION_M, first_near_pair

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
class TableSpec:
    """The columns of one table and the rules the loader checks on them: required and
    optional columns, text (id) columns, optional groups that go together, the time order of
    ``t_s`` ("strict", "nondecreasing" or "none"), the unique key, the columns that must be
    positive, ECEF triples, and the defaults of absent optional columns."""

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

SPECS: dict[str, TableSpec] = {
    "transmitters": TableSpec(
        required=("tx_id", "kind", "group", "x_m", "y_m", "z_m", "clock_bias_m",
                  "clock_drift_mps"),
        optional=("clock_t0_s",), text=("tx_id", "kind", "group"), time="none",
        ecef=(("x_m", "y_m", "z_m"),), defaults=(("clock_t0_s", 0.0),)),
    "pseudoranges": TableSpec(
        required=("t_s", "tx_id", "pseudorange_m"), optional=("sigma_m", "cn0_dbhz"),
        text=("tx_id",), key=("t_s", "tx_id"), positive=("sigma_m",)),
    "imu": TableSpec(required=_IMU_COLUMNS, time="strict"),
    "gnss": TableSpec(
        required=("t_s", "sv_id", "pseudorange_m", "sat_x_m", "sat_y_m", "sat_z_m",
                  "sat_clock_m"),
        optional=("iono_m", "tropo_m", "sigma_m", "el_deg", "cn0_dbhz"), text=("sv_id",),
        key=("t_s", "sv_id"), positive=("sigma_m",), ecef=(("sat_x_m", "sat_y_m", "sat_z_m"),)),
    "truth": TableSpec(
        required=("t_s", "x_m", "y_m", "z_m"),
        optional=("vx_mps", "vy_mps", "vz_mps", "qx", "qy", "qz", "qw", "rx_clock_m",
                  "rx_clock_drift_mps"),
        groups=(("vx_mps", "vy_mps", "vz_mps"), ("qx", "qy", "qz", "qw")), time="strict",
        ecef=(("x_m", "y_m", "z_m"),)),
}
#: the tables in the order they are checked and written
TABLES = ("transmitters", "pseudoranges", "imu", "gnss", "truth")


# ----------------------------------------------------------------------------- errors

class Where:
    """How to name a table's location in messages: a file path, CSV or not, or in memory."""

    def __init__(self, label: str, csv: bool = False, writing: bool = False,
                 meta: bool = False):
        self.label, self.csv, self.writing, self.meta = label, csv, writing, meta

    def err(self, problem: str, fix: str = "", column: str | None = None,
            row: int | None = None) -> RecordingError:
        """The ``RecordingError`` of ``problem`` at this location (column, row), with ``fix``."""
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

def check_meta(meta: Any, where: Where) -> dict:
    """meta.json checked (format, version, origin, GPS time, IMU rate, frames, source);
    returns it as plain JSON. Raises ``RecordingError`` at ``where``."""
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


def check_table(name: str, df: Any, where: Where) -> pd.DataFrame:
    """Table ``name`` checked against ``SPECS[name]`` and normalized (float64 numbers, text
    ids, 0..n-1 index, defaults filled). Raises ``RecordingError`` at ``where``."""
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
                            "readers.sort_recording, or df.sort_values('t_s', "
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
        near = first_near_pair(df[["x_m", "y_m", "z_m"]].to_numpy(float),
                               df["group"].to_numpy())
        if near is not None:
            first, r, d = near
            at = "the position" if d < 1e-6 else f"a position {d:.3g} m from the position"
            raise where.err(f"transmitter {df['tx_id'].iloc[r]!r} has {at} and clock "
                            f"group of {df['tx_id'].iloc[first]!r} (row {first}): closer than "
                            f"{MIN_SEPARATION_M:g} m, the same transmitter twice would count "
                            "as two independent ranges",
                            "Keep one row per transmitter (co-located antennas of one clock "
                            "group are one transmitter)", column="tx_id", row=r)
    return df


def cross_checks(meta, tables, where_of) -> None:
    """Rules across tables: a ranging table exists, pseudoranges have their transmitters and
    name known ones, the IMU steps match meta.json's ``imu_rate_hz``."""
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
