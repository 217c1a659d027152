"""Recorded-data format (readers.recording): round trips, the loader's rejections (each names
file, column and row), pivoting to padded (epoch, source) arrays, frames and clocks."""

import json
import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from oaraim import geometry, sim
from oaraim.geometry import recording_frame as F
from oaraim.readers import RecordingError
from oaraim.readers import recording as R


@pytest.fixture(scope="module")
def rec():
    return sim.example_recording(with_gnss=True)


def _tables(rec):
    return {n: rec.table(n) for n in R.TABLES if rec.table(n) is not None}


def _write_raw(folder, meta, tables, fmt="csv"):
    """Write files WITHOUT validation (the way a user's own exporter might)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "meta.json").write_text(json.dumps(meta))
    for name, df in tables.items():
        if fmt == "csv":
            df.to_csv(folder / f"{name}.csv", index=False)
        else:
            df.to_parquet(folder / f"{name}.parquet", index=False)
    return folder


# ----------------------------------------------------------------------------- round trips

@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_round_trip_is_exact(rec, tmp_path, fmt):
    out = R.write_recording(tmp_path / "drive", rec, format=fmt)
    back = R.load_recording(out)
    assert back.meta == rec.meta
    for name in R.TABLES:
        pd.testing.assert_frame_equal(back.table(name), rec.table(name), check_exact=True)
    ext = ".parquet" if fmt == "parquet" else ".csv"
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["meta.json"] + [f"{n}{ext}" for n in R.TABLES])
    # meta.json path works too
    back2 = R.load_recording(out / "meta.json")
    pd.testing.assert_frame_equal(back2.imu, rec.imu, check_exact=True)


def test_writer_refuses_existing_folder_and_bad_format(rec, tmp_path):
    R.write_recording(tmp_path / "d", rec, format="csv")
    with pytest.raises(FileExistsError):
        R.write_recording(tmp_path / "d", rec)
    R.write_recording(tmp_path / "d", rec, format="parquet", overwrite=True)
    assert not list((tmp_path / "d").glob("*.csv"))
    R.load_recording(tmp_path / "d")
    with pytest.raises(ValueError, match="format"):
        R.write_recording(tmp_path / "e", rec, format="xlsx")


def test_writer_refuses_invalid_recording(rec, tmp_path):
    pr = rec.pseudoranges.copy()
    pr.loc[4, "tx_id"] = "T9"
    bad = R.Recording(meta=rec.meta, transmitters=rec.transmitters, pseudoranges=pr)
    with pytest.raises(RecordingError, match="cannot write") as e:
        R.write_recording(tmp_path / "w", bad)
    assert e.value.file.endswith("pseudoranges.parquet")
    assert (e.value.column, e.value.row) == ("tx_id", 4)
    assert not (tmp_path / "w").exists()


def test_gnss_only_and_minimal_user_drive(rec, tmp_path):
    """What the README shows: a user writes their own drive with pandas."""
    meta = {"format": "oaraim-recording", "format_version": 1,
            "origin": {"lat_deg": 33.98, "lon_deg": -117.37, "h_m": 250.0}}
    tx = pd.DataFrame({"tx_id": [101, 102], "kind": "lte", "group": "att",
                       "x_m": rec.transmitters.x_m[:2], "y_m": rec.transmitters.y_m[:2],
                       "z_m": rec.transmitters.z_m[:2], "clock_bias_m": 0.0,
                       "clock_drift_mps": 0.0})
    pr = pd.DataFrame({"t_s": [0.0, 0.0, 0.1], "tx_id": [101, 102, 102],
                       "pseudorange_m": [1.0, 2.0, 3.0]})
    _write_raw(tmp_path / "u", meta, {"transmitters": tx, "pseudoranges": pr})
    r = R.load_recording(tmp_path / "u")
    assert r.imu is None and r.gnss is None and r.truth is None
    assert list(r.transmitters.clock_t0_s) == [0.0, 0.0]  # default filled
    m = R.pseudorange_matrix(r)
    assert list(m.ids) == ["101", "102"]  # integer ids become text
    np.testing.assert_array_equal(m.valid, [[True, True], [False, True]])
    g = R.Recording(meta=meta, gnss=rec.gnss)
    R.write_recording(tmp_path / "g", g)
    assert R.load_recording(tmp_path / "g").pseudoranges is None


# ----------------------------------------------------------------------------- the model

def test_example_pseudoranges_follow_the_documented_model(rec):
    t, rho, valid, ids = R.pseudorange_matrix(rec)
    assert valid.all() and list(ids) == ["T1", "T2", "T3"]
    tr = rec.truth.set_index("t_s").loc[t]
    pos = tr[["x_m", "y_m", "z_m"]].to_numpy()
    tx = rec.transmitters[["x_m", "y_m", "z_m"]].to_numpy()
    model = (np.linalg.norm(pos[:, None] - tx[None], axis=-1) + tr["rx_clock_m"].to_numpy()[:, None]
             - R.tower_clock_m(rec, t))
    np.testing.assert_allclose(rho, model, rtol=0, atol=1e-8)
    g = R.gnss_matrix(rec)
    sat = R.gnss_matrix(rec, value=["sat_x_m", "sat_y_m", "sat_z_m"]).values
    corr = R.gnss_matrix(rec, value=["sat_clock_m", "iono_m", "tropo_m"]).values
    tg = rec.truth.set_index("t_s").loc[g.t_s]
    pg = tg[["x_m", "y_m", "z_m"]].to_numpy()
    model = (np.linalg.norm(sat - pg[:, None], axis=-1) + tg["rx_clock_m"].to_numpy()[:, None]
             - corr[..., 0] + corr[..., 1] + corr[..., 2])
    np.testing.assert_allclose(g.values, model, rtol=0, atol=1e-6)
    assert list(g.ids) == ["E11", "G02", "G05", "G12", "G25"]


def test_frames_attitude_and_gps_time(rec):
    enu = F.transmitters_enu_m(rec)
    np.testing.assert_allclose(enu, [[200, 150, 30], [-150, 300, 25], [100, -250, 35]],
                               atol=1e-6)
    np.testing.assert_allclose(F.transmitters_enu_m(rec, ["T3"]), enu[2:], atol=0)
    tr = F.truth_enu(rec)
    psi = np.deg2rad(30.0)
    np.testing.assert_allclose(tr.velocity_enu_mps, np.broadcast_to(
        [10 * np.cos(psi), 10 * np.sin(psi), 0], tr.velocity_enu_mps.shape), atol=1e-9)
    np.testing.assert_allclose(tr.position_enu_m[-1], 50 * np.array([np.cos(psi), np.sin(psi), 0]),
                               atol=1e-6)
    c = R.jpl_quaternion_matrix(tr.quaternion)  # ENU -> body
    np.testing.assert_allclose(c @ tr.velocity_enu_mps[0], np.broadcast_to([10, 0, 0], (501, 3)),
                               atol=1e-9)
    np.testing.assert_allclose(c[0] @ c[0].T, np.eye(3), atol=1e-15)
    assert R.t_gps_s(rec, 1.5) == 2290 * 604800 + 345600 + 1.5
    np.testing.assert_allclose(np.linalg.norm(F.origin_ecef_m(rec)), 6.372e6, rtol=1e-3)


def test_tower_clock_hand_values(rec):
    tx = pd.DataFrame({"tx_id": ["a", "b"], "kind": "lte", "group": "g", "x_m": 6.4e6,
                       "y_m": 0.0, "z_m": 0.0, "clock_bias_m": [10.0, -5.0],
                       "clock_drift_mps": [2.0, 0.5], "clock_t0_s": [1.0, 0.0]})
    r = R.Recording(meta=rec.meta, transmitters=tx)
    np.testing.assert_array_equal(R.tower_clock_m(r, [1.0, 3.0]), [[10.0, -4.5], [14.0, -3.5]])
    np.testing.assert_array_equal(R.tower_clock_m(r, 3.0, tx_ids=["b"]), [-3.5])
    with pytest.raises(ValueError, match="unknown"):
        R.tower_clock_m(r, 0.0, tx_ids=["z"])


# ----------------------------------------------------------------------------- pivoting

def _hand_recording(rows):
    meta = {"format": "oaraim-recording", "format_version": 1,
            "origin": {"lat_deg": 0.0, "lon_deg": 0.0, "h_m": 0.0}}
    tx = pd.DataFrame({"tx_id": ["A", "B", "C"], "kind": "lte", "group": "g",
                       "x_m": 6.4e6, "y_m": [0.0, 1.0, 2.0], "z_m": 0.0,
                       "clock_bias_m": 0.0, "clock_drift_mps": 0.0})
    pr = pd.DataFrame(rows, columns=["t_s", "tx_id", "pseudorange_m", "sigma_m"])
    return R.Recording(meta=meta, transmitters=tx, pseudoranges=pr)


HAND = [(0.0, "B", 10.0, 1.0), (0.0, "A", 11.0, 2.0), (1.0, "C", 12.0, 3.0),
        (2.5, "A", 13.0, 4.0), (2.5, "C", 14.0, 5.0)]


def test_pseudorange_matrix_by_hand():
    r = R.validate_recording(_hand_recording(HAND))
    t, rho, valid, ids = R.pseudorange_matrix(r)
    np.testing.assert_array_equal(t, [0.0, 1.0, 2.5])
    np.testing.assert_array_equal(rho, [[11, 10, 0], [0, 0, 12], [13, 0, 14]])
    np.testing.assert_array_equal(valid, [[1, 1, 0], [0, 0, 1], [1, 0, 1]])
    assert list(ids) == ["A", "B", "C"]
    # a subset and order of transmitters: rows of B are dropped
    m = R.pseudorange_matrix(r, tx_ids=["C", "A"])
    np.testing.assert_array_equal(m.values, [[0, 11], [12, 0], [14, 13]])
    np.testing.assert_array_equal(m.valid, [[0, 1], [1, 0], [1, 1]])
    # a common grid with an empty epoch, several value columns
    m = R.pseudorange_matrix(r, value=["pseudorange_m", "sigma_m"], t_s=[0.0, 0.5, 1.0, 2.5])
    assert m.values.shape == (4, 3, 2)
    np.testing.assert_array_equal(m.values[..., 1], [[2, 1, 0], [0, 0, 0], [0, 0, 3], [4, 0, 5]])
    assert not m.valid[1].any() and np.isfinite(m.values).all()
    with pytest.raises(ValueError, match="grid"):
        R.pseudorange_matrix(r, t_s=[0.0, 2.5])
    # an unvalidated in-memory table with a duplicate is refused, not silently overwritten
    with pytest.raises(ValueError, match="duplicate"):
        R.pseudorange_matrix(_hand_recording(HAND + [(1.0, "C", 99.0, 1.0)]))
    np.testing.assert_array_equal(R.epochs(r), [0.0, 1.0, 2.5])


_pairs = st.lists(st.tuples(st.sampled_from([0.0, 0.1, 0.2, 1.0, 7.5]),
                            st.sampled_from(["A", "B", "C"])),
                  min_size=1, max_size=15, unique=True)


@settings(max_examples=60, deadline=None)
@given(pairs=_pairs, data=st.data())
def test_pseudorange_matrix_ignores_row_order(pairs, data):
    """Sorting rule: epochs are the sorted unique t_s, columns the transmitters-table order, so
    any permutation of the rows gives the same arrays (and sort_recording is a no-op on them)."""
    vals = data.draw(st.lists(st.floats(-1e7, 1e7), min_size=len(pairs), max_size=len(pairs)))
    rows = [(t, i, v, 1.0) for (t, i), v in zip(pairs, vals, strict=True)]
    perm = data.draw(st.permutations(rows))
    a = R.pseudorange_matrix(_hand_recording(rows))
    b = R.pseudorange_matrix(_hand_recording(perm))
    s = R.pseudorange_matrix(R.validate_recording(R.sort_recording(_hand_recording(perm))))
    for m in (b, s):
        np.testing.assert_array_equal(a.t_s, m.t_s)
        np.testing.assert_array_equal(a.values, m.values)
        np.testing.assert_array_equal(a.valid, m.valid)
    assert a.valid.sum() == len(rows)
    assert np.all(a.values[~a.valid] == 0)
    for t, i, v, _ in rows:
        k, j = int(np.searchsorted(a.t_s, t)), "ABC".index(i)
        assert a.valid[k, j] and a.values[k, j] == v


# ----------------------------------------------------------------------------- bad files

def _set(table, row, col, value):
    def f(tables, meta):
        df = tables[table].copy()
        df[col] = df[col].astype(object)
        df.loc[row, col] = value
        tables[table] = df
    return f


def _drop_col(table, col):
    def f(tables, meta):
        tables[table] = tables[table].drop(columns=[col])
    return f


def _drop_table(table):
    def f(tables, meta):
        del tables[table]
    return f


def _swap_rows(table, i, j):
    def f(tables, meta):
        df = tables[table].copy()
        df.iloc[[i, j]] = df.iloc[[j, i]].to_numpy()
        tables[table] = df
    return f


def _meta(**kv):
    def f(tables, meta):
        for k, v in kv.items():
            if v is _DEL:
                del meta[k]
            else:
                meta[k] = v
    return f


_DEL = object()

# (name, mutation, file stem, column, row, words in the message)
BAD = [
    ("missing table", _drop_table("transmitters"), "transmitters", None, None,
     ["missing", "tx_id, kind, group"]),
    ("no ranging table", lambda t, m: (t.pop("pseudoranges"), t.pop("gnss")), "pseudoranges",
     None, None, ["no ranging table"]),
    ("missing column", _drop_col("pseudoranges", "pseudorange_m"), "pseudoranges",
     "pseudorange_m", None, ["missing required column", "t_s, tx_id, pseudorange_m"]),
    ("misspelled column", lambda t, m: t.__setitem__("imu", t["imu"].rename(
        columns={"gyro_z_radps": "gyro_z_rads"})), "imu", "gyro_z_radps", None,
     ["did you mean 'gyro_z_rads'"]),
    ("partial group", _drop_col("truth", "vy_mps"), "truth", "vy_mps", None, ["go together"]),
    ("NaN", _set("pseudoranges", 7, "pseudorange_m", np.nan), "pseudoranges", "pseudorange_m",
     7, ["not finite", "file line 9"]),
    ("inf", _set("imu", 12, "gyro_x_radps", np.inf), "imu", "gyro_x_radps", 12, ["not finite"]),
    ("unparseable", _set("imu", 3, "accel_x_mps2", "abc"), "imu", "accel_x_mps2", 3,
     ["'abc'", "number"]),
    ("empty id", _set("transmitters", 1, "kind", np.nan), "transmitters", "kind", 1,
     ["missing id"]),
    ("non-monotonic imu", _swap_rows("imu", 10, 11), "imu", "t_s", 11,
     ["earlier", "strictly increasing", "sort"]),
    ("repeated imu time", _set("imu", 20, "t_s", 0.19), "imu", "t_s", 20, ["repeats"]),
    ("non-monotonic pseudoranges", _swap_rows("pseudoranges", 5, 6), "pseudoranges", "t_s", 6,
     ["earlier", "non-decreasing"]),
    ("unknown transmitter", _set("pseudoranges", 5, "tx_id", "T9"), "pseudoranges", "tx_id", 5,
     ["unknown transmitter id 'T9'", "'T1', 'T2', 'T3'"]),
    ("duplicate measurement", _set("pseudoranges", 4, "tx_id", "T1"), "pseudoranges", "tx_id",
     4, ["second measurement", "'T1'", "row 3"]),
    ("duplicate transmitter", _set("transmitters", 2, "tx_id", "T1"), "transmitters", "tx_id",
     2, ["appears twice"]),
    ("duplicate gnss", _set("gnss", 6, "sv_id", "E11"), "gnss", "sv_id", 6,
     ["second measurement"]),
    ("bad sv_id", _set("gnss", 2, "sv_id", "GPS5"), "gnss", "sv_id", 2, ["RINEX 3"]),
    ("negative sigma", _set("pseudoranges", 9, "sigma_m", -1.0), "pseudoranges", "sigma_m", 9,
     ["> 0"]),
    ("elevation", _set("gnss", 3, "el_deg", 95.0), "gnss", "el_deg", 3, ["[-90, 90]"]),
    ("ENU as ECEF", _set("transmitters", 0, "x_m", 200.0), "transmitters", "x_m", 0,
     ["local coordinates", "enu_to_ecef"]),
    ("quaternion", _set("truth", 30, "qw", 0.5), "truth", "qw", 30, ["norm"]),
    ("imu rate", _meta(imu_rate_hz=10.0), "imu", "t_s", None, ["imu_rate_hz"]),
    ("no version", _meta(format_version=_DEL), "meta", "format_version", None,
     ["format_version"]),
    ("future version", _meta(format_version=2), "meta", "format_version", None,
     ["not supported"]),
    ("wrong format", _meta(format="something"), "meta", "format", None, ["oaraim-recording"]),
    ("no origin", _meta(origin=_DEL), "meta", "origin", None, ["ENU"]),
    ("bad latitude", _meta(origin={"lat_deg": 95.0, "lon_deg": 0.0, "h_m": 0.0}), "meta",
     "origin.lat_deg", None, ["[-90, 90]"]),
    ("half GPS time", _meta(t0_gps_tow_s=_DEL), "meta", "t0_gps_tow_s", None, ["together"]),
    ("left-handed body", _meta(body_frame="FRU"), "meta", "body_frame", None, ["FLU"]),
    ("source", _meta(source={"kind": "dreamt"}), "meta", "source", None, ["synthesized"]),
]


@pytest.mark.parametrize("case", BAD, ids=[b[0] for b in BAD])
def test_loader_rejects_bad_files(rec, tmp_path, case):
    _, mutate, stem, column, row, words = case
    tables, meta = _tables(rec), json.loads(json.dumps(rec.meta))
    tables = {k: v.copy() for k, v in tables.items()}
    mutate(tables, meta)
    folder = _write_raw(tmp_path / "bad", meta, tables)
    with pytest.raises(RecordingError) as e:
        R.load_recording(folder)
    err, msg = e.value, str(e.value)
    assert isinstance(err, ValueError)
    expect_file = "meta.json" if stem == "meta" else stem
    assert expect_file in err.file and expect_file in msg
    assert err.column == column
    if column is not None:
        assert repr(column) in msg
    assert err.row == row
    if row is not None:
        assert f"row {row} " in msg
    for w in words:
        assert w in msg, (w, msg)


def test_loader_rejects_folder_level_problems(rec, tmp_path):
    with pytest.raises(RecordingError, match="not a folder"):
        R.load_recording(tmp_path / "nowhere")
    folder = R.write_recording(tmp_path / "d", rec, format="csv")
    rec.imu.to_parquet(folder / "imu.parquet", index=False)
    with pytest.raises(RecordingError, match="imu.parquet and imu.csv|imu.csv and imu.parquet"):
        R.load_recording(folder)
    (folder / "imu.parquet").unlink()
    (folder / "meta.json").write_text('{"format": "oaraim-recording",\n "format_version": 1,,}')
    with pytest.raises(RecordingError, match="line 2") as e:
        R.load_recording(folder)
    assert e.value.file.endswith("meta.json")
    (folder / "meta.json").unlink()
    with pytest.raises(RecordingError, match="meta.json: missing"):
        R.load_recording(folder)
    (folder / "meta.json").write_text(json.dumps(rec.meta))
    (folder / "truth.csv").write_text("")
    with pytest.raises(RecordingError, match="truth.csv: file line 1: the file is empty") as e:
        R.load_recording(folder)
    assert e.value.file.endswith("truth.csv")


@pytest.mark.parametrize("table, edit, message", [
    ("pseudoranges", lambda b: b[:-4], r"pseudoranges\.csv: file line \d+: the last line does "
     "not end with a line break: the file is truncated"),
    ("transmitters", lambda b: b.replace(b"carrier_b", b"carri\xe9r_b"),
     r"transmitters\.csv: file line 4: not UTF-8 text"),
    ("pseudoranges", lambda b: b.replace(b"T2", b'"T2', 1),
     r"pseudoranges\.csv: file line \d+: not CSV \(unexpected end of data\)"),
    ("pseudoranges", lambda b: b.replace(b"T2", b"T\x002", 1),
     r"pseudoranges\.csv: file line 3: a NUL character"),
    ("truth", lambda b: b.replace(b"\n", b",1\n", 3)[:],
     r"truth\.csv: file line 4: 13 fields where the header has 14"),
    ("transmitters", lambda b: b + b.split(b"\n")[1].replace(b"T1", b"T9") + b"\n",
     r"transmitters\.csv, column 'tx_id', row 3 \(file line 5\): transmitter 'T9' has the "
     r"position and clock group of 'T1' \(row 0\)"),
])
def test_csv_cut_short_garbled_or_duplicated_names_the_line(rec, tmp_path, table, edit, message):
    """A CSV table cut short lost (or truncated) its last row without a word, bytes
    that are not UTF-8 or a broken quote gave an error without a line, and a transmitter listed
    again under a new id counted as a second independent range. Each now names the file
    line."""
    folder = R.write_recording(tmp_path / "d", rec, format="csv")
    f = folder / f"{table}.csv"
    f.write_bytes(edit(f.read_bytes()))
    with pytest.raises(RecordingError, match=message):
        R.load_recording(folder)


def test_parquet_rows_counted_from_zero(rec, tmp_path):
    tables = {k: v.copy() for k, v in _tables(rec).items()}
    _set("truth", 40, "x_m", np.nan)(tables, None)
    tables["truth"]["x_m"] = tables["truth"]["x_m"].astype(float)
    _write_raw(tmp_path / "p", rec.meta, tables, fmt="parquet")
    with pytest.raises(RecordingError, match=r"truth\.parquet, column 'x_m', row 40 \(counted"):
        R.load_recording(tmp_path / "p")


def test_extra_columns_kept_and_near_misses_warned(rec, tmp_path):
    tables = {k: v.copy() for k, v in _tables(rec).items()}
    tables["imu"]["temperature_c"] = 21.5
    pr = tables["pseudoranges"].drop(columns=["sigma_m"])
    pr["sigma"] = 2.0
    tables["pseudoranges"] = pr
    _write_raw(tmp_path / "x", rec.meta, tables, fmt="parquet")
    with pytest.warns(R.RecordingWarning, match="'sigma'.*'sigma_m'"):
        r = R.load_recording(tmp_path / "x")
    assert (r.imu["temperature_c"] == 21.5).all() and "sigma" in r.pseudoranges
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        R.validate_recording(rec)


def test_public_exports():
    for name in ("Recording", "RecordingError", "load_recording", "write_recording",
                 "pseudorange_matrix", "gnss_matrix", "tower_clock_m"):
        assert getattr(geometry, name) is getattr(R, name)
        assert name in geometry.__all__
    assert "example_recording" in sim.__all__  # a synthesized recording: oaraim.sim


def test_csv_floats_round_trip_bit_exact(tmp_path):
    rng = np.random.default_rng(7)
    rows = [(0.1 * k, "ABC"[k % 3], v, 1.0 + abs(v) * 1e-9)
            for k, v in enumerate(rng.standard_normal(300) * 10.0 ** rng.integers(-8, 9, 300))]
    r = R.validate_recording(_hand_recording(rows))
    back = R.load_recording(R.write_recording(tmp_path / "f", r, format="csv"))
    pd.testing.assert_frame_equal(back.pseudoranges, r.pseudoranges, check_exact=True)


@pytest.mark.parametrize("dx_m, message", [
    (1e-4, r"transmitter 'T9' has a position 0\.0001 m from the position and clock group of "
           r"'T1' \(row 0\): closer than 1 m"),
    (0.9, r"transmitter 'T9' has a position 0\.9 m from the position and clock group of 'T1'"),
    (2.0, None),
])
def test_near_duplicate_transmitters_are_refused(rec, tmp_path, dx_m, message):
    """A transmitter listed again 0.1 mm from itself under a new id passed the exact duplicate
    check and counted as a second independent range. Transmitters of one clock group closer
    than 1 m (``readers.MIN_SEPARATION_M``) are one given twice; 2 m apart, two."""
    tables = {k: v.copy() for k, v in _tables(rec).items()}
    tx = tables["transmitters"]
    again = tx.iloc[[0]].copy()
    again["tx_id"] = "T9"
    again["x_m"] = again["x_m"] + dx_m
    tables["transmitters"] = pd.concat([tx, again], ignore_index=True)
    folder = tmp_path / "d"
    _write_raw(folder, rec.meta, tables)
    if message is None:
        assert "T9" in R.load_recording(folder).transmitters["tx_id"].tolist()
        return
    with pytest.raises(RecordingError, match=r"transmitters\.csv, column 'tx_id', row 3 "
                       r"\(file line 5\): " + message):
        R.load_recording(folder)
