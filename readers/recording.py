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
import gzip
import io
import json
import os
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd
from jax.typing import ArrayLike
from jaxtyping import Float, Real

from oaraim.readers.recording_checks import (  # noqa: F401  (re-exported)
    FORMAT_NAME,
    FORMAT_VERSION,
    SPECS,
    TABLES,
    RecordingError,
    RecordingWarning,
    Where,
    check_meta,
    check_table,
    cross_checks,
)

#: exact float parsing of CSV: pandas >= 3 parses round-trip exactly by default (and deprecates
#: the argument); pandas 2 needs float_precision="round_trip"
_CSV_PRECISION = ({} if int(pd.__version__.split(".")[0]) >= 3
                  else {"float_precision": "round_trip"})


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
        """The table ``name`` (one of ``TABLES``), None when absent."""
        return getattr(self, name)


def _validate(meta, tables: dict, where_of) -> Recording:
    meta = check_meta(meta, where_of("meta"))
    out = {}
    for name in TABLES:
        df = tables.get(name)
        out[name] = None if df is None else check_table(name, df, where_of(name))
    cross_checks(meta, out, where_of)
    return Recording(meta=meta, **out)


def validate_recording(recording: Recording) -> Recording:
    """Check an in-memory recording with the loader's rules; return it normalized (float64
    numbers, text ids, 0..n-1 index, defaults filled). Raises :class:`RecordingError`."""
    def where_of(name):
        return Where("meta", meta=True) if name == "meta" else Where(f"{name} table")

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
    where = Where(str(path), csv=True)

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


def load_recording(path: str | os.PathLike) -> Recording:
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
    tables, wheres = {}, {"meta": Where(str(meta_path), meta=True)}
    for name in TABLES:
        p = _find(folder, name)
        if p is None:
            wheres[name] = Where(str(folder / f"{name}.parquet|csv"))
            continue
        wheres[name] = Where(str(p), csv=p.suffix != ".parquet")
        tables[name] = _read(p, name)
    return _validate(meta, tables, wheres.__getitem__)


def write_recording(path: str | os.PathLike, recording: Recording,
                    format: str = "parquet",  # noqa: A002
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
        return Where(str(folder / f), writing=True, meta=name == "meta")

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
        t_off = float(times[int(np.flatnonzero(off)[0])])
        raise ValueError(f"a measurement at t_s = {t_off!r} s is not on the given epoch grid t_s")
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


def pseudorange_matrix(recording: Recording, tx_ids: Sequence[str] | None = None,
                       value: str | Sequence[str] = "pseudorange_m",
                       t_s: Real[ArrayLike, " T"] | Sequence[float] | None = None
                      ) -> EpochMatrix:
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


def gnss_matrix(recording: Recording, sv_ids: Sequence[str] | None = None,
                value: str | Sequence[str] = "pseudorange_m",
                t_s: Real[ArrayLike, " T"] | Sequence[float] | None = None
               ) -> EpochMatrix:
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


def tower_clock_m(recording: Recording, t_s: Real[ArrayLike, "*t"] | Sequence[float],
                  tx_ids: Sequence[str] | None = None) -> Float[np.ndarray, "*t L"]:
    """Transmitter clocks c dt_s(t) = clock_bias_m + clock_drift_mps (t_s - clock_t0_s) (seed 000
    eq. 3), shape ``t_s.shape + (L,)``, columns in ``tx_ids`` (default: table) order."""
    tx = _tx_rows(recording, tx_ids)
    t = np.asarray(t_s, np.float64)[..., None]
    t0 = tx["clock_t0_s"].to_numpy(np.float64) if "clock_t0_s" in tx else 0.0
    return (tx["clock_bias_m"].to_numpy(np.float64)
            + tx["clock_drift_mps"].to_numpy(np.float64) * (t - t0))


def transmitters_ecef_m(recording: Recording, tx_ids=None) -> np.ndarray:
    """ECEF positions (L, 3) of the transmitters, metres, in ``tx_ids`` (default: table)
    order (``geometry.recording_frame.transmitters_enu_m``: in the local frame)."""
    return _tx_rows(recording, tx_ids)[["x_m", "y_m", "z_m"]].to_numpy(np.float64)


def t_gps_s(recording: Recording, t_s) -> np.ndarray | float:
    """GPS seconds (since 1980-01-06, ``readers.gpstime``) of recording times ``t_s``."""
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
