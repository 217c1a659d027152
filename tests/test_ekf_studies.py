"""EKF-RAIM drive studies (seed000-ekf-raim, seed002-outlier) and the recording replay path."""

import dataclasses
import json
import re
from pathlib import Path

import jax
import numpy as np
import pytest

from oaraim import errors, mc, readers, sim
from oaraim.araim import ekf_replay
from oaraim.execute import run_study
from oaraim.registry import STUDIES

DUR_S = 30.0  # the first 30 s of the seed 000 drive: fault on tower 1 from 25 s


def _drive(tmp_path_factory, err):
    sc = sim.drive_seed000()
    key = mc.realization_keys(0, 0, 0, 1)[0]
    rec = sim.synthesize_recording(sc, key, err=err, duration_s=DUR_S)
    folder = tmp_path_factory.mktemp("drive") / "drive"
    readers.write_recording(folder, rec)
    loaded = readers.load_recording(folder)
    tr = ekf_replay.replay_ekf_raim(loaded)
    setup = sim.drive_setup(sc, duration_s=DUR_S)
    summ, direct = sim.simulate_drive(key, setup, err, traces=True)
    return sc, rec, folder, loaded, tr, jax.device_get(direct)


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """Run 0 of seed 0 in the clean world (white 2 m noise, the filter told the truth: the exact
    detection / exclusion expectations below hold only there): synthesized, written (Parquet),
    loaded, replayed; and the direct run."""
    return _drive(tmp_path_factory, errors.ErrorModel.clean())


@pytest.fixture(scope="module")
def world_drive(tmp_path_factory):
    """The same run in the default (realistic) error world."""
    return _drive(tmp_path_factory, errors.ErrorModel())


@pytest.mark.parametrize("which", ["drive", "world_drive"])
def test_recording_round_trip_replays_the_direct_simulation(which, request):
    """The synthesized recording, written and loaded back, replays to the run that
    ``simulate_drive`` computes from the same key: same detections and exclusions, NIS and 2D
    errors equal to 1e-6. Not bit-identical because the recording stores ECEF (towers, truth)
    and the replay converts back to ENU (~1e-9 m of rounding), and the epoch grid is rebuilt
    from the stored time stamps. NB: this relies on ``synthesize_recording`` drawing the same
    normals as ``simulate_drive`` (key split in 3, fold_in per epoch, one normal vector per
    epoch in the order IMU, clock, multipath, pseudorange, and the GNSS period and named
    streams of the error world); change both together. Both worlds: the realistic one's
    pseudoranges carry the run's empirical sigma, which the replay reads from the table."""
    _, rec, _, _, tr, direct = request.getfixturevalue(which)
    n = direct.t_s.shape[0]
    assert n == 300 and tr.t_s.shape == (300,)
    np.testing.assert_allclose(tr.t_s, np.asarray(direct.t_s), atol=1e-9)
    np.testing.assert_array_equal(tr.detected, np.asarray(direct.raim.detected).T)
    np.testing.assert_array_equal(tr.excluded, np.asarray(direct.raim.excluded).T)
    np.testing.assert_allclose(tr.nis, np.asarray(direct.raim.nis).T, rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(tr.err_2d_m, np.asarray(direct.err_2d_m).T, atol=1e-6)
    np.testing.assert_allclose(tr.hpl_m, np.asarray(direct.raim.hpl_m).T, rtol=1e-7)
    assert rec.pseudoranges["sigma_m"].iloc[0] == rec.meta["source"]["parameters"][
        "filter_sigma_pr_m"]


def test_in_memory_and_loaded_recordings_replay_identically(drive):
    """Parquet stores float64 exactly: the loaded recording replays bit for bit like the one in
    memory."""
    _, rec, _, _, tr, _ = drive
    tr_mem = ekf_replay.replay_ekf_raim(rec)
    np.testing.assert_array_equal(tr_mem.err_2d_m, tr.err_2d_m)
    np.testing.assert_array_equal(tr_mem.nis, tr.nis)


def test_fault_detected_and_tower_1_excluded(drive):
    _, _, _, _, tr, _ = drive
    s = ekf_replay.trace_summary(tr, 25.0, 0)
    w, wo = s["with_exclusion"], s["without_exclusion"]
    assert w["first_detection_s"] == pytest.approx(25.0)
    assert w["detections_before_onset"] == 0
    after = tr.t_s >= 25.0 - 1e-9
    assert np.all(tr.excluded[1][after] == 0)  # tower 1 (index 0) at every faulty epoch
    assert np.all(tr.excluded[1][~after] == -1) and np.all(tr.excluded[0] == -1)
    assert w["exclusions_by_tower"]["T1"] == int(after.sum())
    # exclusion removes the fault's effect: the error stays at the noise level
    e_after = tr.err_2d_m[:, after]
    assert e_after[1].max() < 2.0 < e_after[0].max()
    assert wo["rmse_2d_m"] > w["rmse_2d_m"]


def test_initial_state_from_truth_and_refusal_without(drive):
    """Without meta.json's initial_state the replay starts from the truth at t0 (the filter
    then works as well: same exclusions, errors at the noise level); without truth too it
    refuses with a message naming the three ways."""
    _, rec, _, _, tr, _ = drive
    meta = {k: v for k, v in rec.meta.items() if k != "initial_state"}
    rec_t = dataclasses.replace(rec, meta=meta)
    tr_t = ekf_replay.replay_ekf_raim(rec_t)
    assert tr_t.init_source == "truth at t0"
    assert tr_t.err_2d_m[1].max() < 2.0
    assert np.array_equal(tr_t.excluded[1], tr.excluded[1])
    with pytest.raises(ValueError, match="initial_state"):
        ekf_replay.replay_ekf_raim(dataclasses.replace(rec_t, truth=None))


def test_replay_rejects_epochs_off_the_imu_grid(drive):
    _, rec, _, _, _, _ = drive
    pr = rec.pseudoranges.copy()
    pr["t_s"] = pr["t_s"] + 0.004
    with pytest.raises(ValueError, match="IMU time stamp"):
        ekf_replay.replay_ekf_raim(dataclasses.replace(rec, pseudoranges=pr))


def test_missing_epochs_become_prediction_only(drive):
    """A gap in the pseudoranges (epochs 100-109 dropped) is kept on the grid with no valid
    tower: those epochs predict only (no detection, HPL unavailable)."""
    _, rec, _, _, tr, _ = drive
    t = np.unique(rec.pseudoranges["t_s"])
    drop = np.isin(rec.pseudoranges["t_s"], t[100:110])
    tr_g = ekf_replay.replay_ekf_raim(dataclasses.replace(
        rec, pseudoranges=rec.pseudoranges[~drop].reset_index(drop=True)))
    assert tr_g.t_s.shape == tr.t_s.shape
    assert np.all(tr_g.n_valid[100:110] == 0) and np.all(tr_g.n_valid[:100] == 5)
    assert not tr_g.detected[:, 100:110].any() and np.all(np.isinf(tr_g.hpl_m[:, 100:110]))
    np.testing.assert_array_equal(tr_g.err_2d_m[:, :100], tr.err_2d_m[:, :100])


def test_study_defaults_are_the_realistic_world_and_the_scenario_fault():
    """The studies' default world is ``sim.ErrorModel()`` (the realistic one) with
    the scenario's fault, except the parameters a study calibrated (``calibrated``: seed 000's
    fault size and multipath, fitted to its RMSEs by ``oaraim calibrate``) and the world
    parameters it chose on its own evidence (``chosen``: seed 000's NLOS rate 0)."""
    from oaraim.studies.common.ekf_drive import world_of
    for name, sc in (("seed000-ekf-raim", sim.drive_seed000()),
                     ("seed002-outlier", sim.drive_seed002())):
        study = STUDIES[name]
        p = study.validate({})
        assert p["world"] == "realistic" and p["filter_sigma_pr_m"] == 0.0
        want = errors.ErrorModel(fault_tower=sc.fault_tower, fault_onset_s=sc.fault_onset_s,
                              fault_bias_m=sc.fault_bias_m)._replace(
            **study.calibrated, **{k: v for k, (v, _) in study.chosen.items()})
        assert world_of(p) == want
        assert {k: p[k] for k in study.calibrated} == study.calibrated
        assert all(p[k] == v for k, (v, _) in study.chosen.items())
        assert p["fault_tower"] == sc.fault_tower + 1
        assert sc.towers_enu_m.shape[0] == 5
        clean = world_of(STUDIES[name].validate({"world": "clean"}))
        assert clean.calib_window_s == 0.0 and clean.nlos_rate_per_s == 0.0


def test_bad_recording_folder_is_a_clear_error(tmp_path):
    study = STUDIES["seed000-ekf-raim"]
    with pytest.raises(ValueError, match="is not a folder"):
        study.validate({"recording": str(tmp_path / "nope")})
    with pytest.raises(ValueError, match="no meta.json"):
        study.validate({"recording": str(tmp_path)})
    (tmp_path / "meta.json").write_text("{not json")
    with pytest.raises(readers.RecordingError, match="meta.json"):
        run_study("seed000-ekf-raim", realizations=1, out=tmp_path / "out",
                  sets=[f"recording={tmp_path}"], show_progress=False)


def test_study_replays_a_user_recording(drive, tmp_path):
    """--set recording=PATH: the single-drive part replays the folder, the Monte Carlo is
    skipped and says so; figures are drawn from data.zarr."""
    _, _, folder, _, tr, _ = drive
    summary, sdir, figures, _ = run_study("seed000-ekf-raim", realizations=2, out=tmp_path,
                                          sets=[f"recording={folder}"], show_progress=False)
    assert summary["metrics"]["monte_carlo"].startswith("skipped")
    rm = summary["metrics"]["single_drive"]["with_exclusion"]["rmse_2d_m"]
    assert rm == pytest.approx(float(np.sqrt(np.mean(tr.err_2d_m[1] ** 2))), rel=1e-12)
    assert len(figures) == 3 and all((sdir / f.split("/")[-1]).is_file() for f in figures)


def test_seed002_tiny_run_rows(tmp_path):
    summary, sdir, figures, _ = run_study("seed002-outlier", realizations=3, out=tmp_path,
                                          sets=["duration_s=100"], show_progress=False)
    pub = {r["published"] for r in summary["rows"]}
    assert {8.2, 4.8, 42.0, 20.4, 11.6, 43.3, 95.0} <= pub
    mcm = summary["metrics"]["monte_carlo"]
    assert mcm["runs"] == 3 and set(mcm) >= {"nominal", "multipath"}
    assert mcm["nominal"]["detection_rate"] == 1.0
    det = next(r for r in summary["rows"] if r["quantity"].startswith("first detection"))
    assert det["reproduced"] == pytest.approx(95.0)
    prov = json.loads((sdir / "provenance.json").read_text())
    assert prov["realizations"] == 3
    assert len(figures) == 4
    # the calibration's six targets are the six Monte Carlo median rows, one row each
    for t in STUDIES["seed002-outlier"].calibration.targets:
        hits = [r for r in summary["rows"] if re.search(t.pattern, r["quantity"])]
        assert len(hits) == 1 and "Monte Carlo median" in hits[0]["quantity"], t.pattern


def test_seed002_defaults_are_its_calibrated_fit():
    """Seed 002's outlier size and multipath sigma are the values of its declared fit (``oaraim
    calibrate seed002-outlier``, 200 runs: 30.25 m and 2.065 m; docs/calibration.md), its NLOS
    episodes the world's rate (not fitted: the six numbers leave it loose); the committed
    results were run at those defaults, and their six Monte Carlo medians are within 15 % of
    the poster's numbers."""
    study = STUDIES["seed002-outlier"]
    p = study.validate({})
    assert study.calibrated == {"fault_bias_m": 30.3, "mp_sigma_m": 2.07}
    assert p["fault_bias_m"] == 30.3 and p["mp_sigma_m"] == 2.07
    assert p["nlos_rate_per_s"] == errors.ErrorModel().nlos_rate_per_s
    cal = study.calibration
    assert [f.name for f in cal.free] == list(study.calibrated)
    assert all(f.low < p[f.name] < f.high for f in cal.free)
    assert cal.realizations == study.default_realizations and len(cal.targets) == 6
    folder = Path(__file__).resolve().parents[1] / "results" / study.name
    if not (folder / "summary.json").is_file():
        pytest.skip("no committed results beside the tests")
    prov = json.loads((folder / "provenance.json").read_text())
    assert {k: prov["parameters"][k] for k in study.calibrated} == study.calibrated
    rows = json.loads((folder / "summary.json").read_text())["rows"]
    for t in cal.targets:
        (row,) = [r for r in rows if re.search(t.pattern, r["quantity"])]
        assert abs(row["reproduced"] / row["published"] - 1) < 0.15, row
