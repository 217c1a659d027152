"""The filter-integrity study and its simulated pieces (sim.faults, sim.filter_drive).

The study's integrity check must be able to fail: with the filters told a pseudorange sigma a
fifth of the truth's (``sigma_scale=0.2``) their PLs are far too small and the fault-free rate
of HPE > HPL without alert (thousands of epochs against an allocation of 1e-7) exceeds the
allocation; at the default the filter bank passes on the same runs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import sim
from oaraim.registry import STUDIES


def test_fault_profile_by_hand():
    f = sim.FaultScenario(jnp.asarray(2), jnp.asarray(10.0), jnp.asarray(5.0), jnp.asarray(0.5))
    b = np.asarray(sim.fault_profile_m(jnp.array([9.9, 10.0, 14.0]), f, 4))
    np.testing.assert_allclose(b, [[0, 0, 0, 0], [0, 0, 5.0, 0], [0, 0, 7.0, 0]])
    assert not np.any(np.asarray(sim.fault_profile_m(jnp.arange(5.0), sim.no_fault(), 3)))


def test_draw_faults_ranges():
    f = sim.draw_faults(jax.random.key(0), 2000, 5, "ramp", (10.0, 20.0), (0.01, 1.0))
    src, on, step, slope = (np.asarray(x) for x in f)
    assert set(np.unique(src)) == set(range(5))
    assert on.min() >= 10.0 and on.max() <= 20.0 and not step.any()
    assert slope.min() >= 0.01 and slope.max() <= 1.0
    # log-uniform: half the slopes below the geometric mean 0.1 (2000 draws: +-3.4 sigma = 0.04)
    assert abs(np.mean(slope < 0.1) - 0.5) < 0.04
    with pytest.raises(ValueError, match="step' or 'ramp"):
        sim.draw_faults(jax.random.key(0), 2, 5, "spike", (0, 1), (1, 2))


@pytest.fixture(scope="module")
def study_runs():
    study = STUDIES["filter-integrity"]
    out = {}
    for scale in (1.0, 0.2):
        params = study.validate({"duration_s": 20.0, "sigma_scale": scale})
        out[scale] = study.run(params, 16, 0, None)
    params = study.validate({"duration_s": 20.0, "linearisation": "own", "conditional": "no"})
    out["own"] = study.run(params, 16, 0, None)
    return out


def test_fault_free_separations_follow_their_claimed_covariance(study_runs):
    """The false-alert check that can fail. Fault-free, every separation Delta_i,q of the bank
    should be N(0, (P_i - P_0)_qq); the alert threshold is K_fa ~ 5.7 of its sigma. In 16 runs of
    20 s (48 runs over the three scenarios' fault-free epochs: ~1e5 monitored tests) a Gaussian
    exceeds 5 sigma with probability <= 1e5 x 5.7e-7 = 0.06 (union bound), so no test may; and
    no alert is raised. The bank whose sub-filters linearise about their own estimates (the
    earlier bank) fails the same check on the same runs: its tower-4 sub-filter's separation
    reaches 5.4 sigma in the first seconds (docs/filter-integrity.md, the false-alert cause)."""
    tails = {k: study_runs[k].metrics["separation_tails"] for k in (1.0, "own")}
    assert tails[1.0]["5"]["trials"] > 50_000
    assert tails[1.0]["5"]["count"] == 0
    assert tails["own"]["5"]["count"] > 0
    fa = study_runs[1.0].metrics["filter_ss_false_alerts"]
    assert fa["count"] == 0 and fa["verdict"].startswith("consistent")
    # the bulk matches the Gaussian too: 3 sigma within a factor 2 of 2 Q(3) = 2.7e-3
    t3 = tails[1.0]["3"]
    assert 0.5 < t3["rate"] / t3["gaussian"] < 2.0


def test_check_passes_at_default_and_fails_with_an_injected_model_error(study_runs):
    good, bad = study_runs[1.0], study_runs[0.2]
    assert good.metrics["integrity_check"]["passed"]
    assert not bad.metrics["integrity_check"]["passed"]
    ff = bad.metrics["scenarios"]["fault-free"]["filter_ss"]
    assert ff["verdict"] == "exceeds the allocation"
    assert ff["hmi_per_epoch"]["ci_low"] > 1e-3


def test_uav_flight_bank(study_runs):
    """The seed 004 UAV flight beside the drive (16 runs per scenario, 240 epochs): the bank of
    the seed004-uav option (grouped modes at order 2: 87 filters for 8 GPS satellites and 11
    towers of 3 operators), no misleading epoch and no alert without a fault, finite HPLs near
    the seed004-uav option's 6.7 m, faults detected."""
    u = study_runs[1.0].metrics["uav"]
    assert u["filters"] == 87 and u["max_order"] == 2 and u["passed"]
    for scen in ("fault-free", "step", "ramp"):
        d = u["scenarios"][scen]
        assert d["hmi_per_epoch"]["count"] == 0 and d["false_alerts"]["count"] == 0
        assert 5.0 < d["mean_hpl_m"] < 9.0
    assert u["scenarios"]["step"]["detected_runs_pct"] > 25.0


def test_conditional_estimate_beside_the_crude_counts(study_runs):
    """The conditional estimate (docs/filter-integrity.md, "The conditional risk estimate") on
    the same runs: at the default no scenario's crude check at 0.3 HPL flags the model, and
    every estimate lies inside its allocation and below the crude counts' upper bound, on the
    drive and on the UAV flight; with the filters told a fifth of the sigma the crude check
    flags the drive's model and the conditional check fails (it can fail)."""
    m = study_runs[1.0].metrics
    for cond, crude in ((m["conditional"], m["scenarios"]),
                        (m["uav"]["conditional"], m["uav"]["scenarios"])):
        assert cond["passed"]
        for scen in ("fault-free", "step", "ramp"):
            d = cond["scenarios"][scen]
            assert not d["validation"]["flagged"] and d["validation"]["expected"] > 1, d
            assert 0.0 < d["rate"] <= d["ci_high"] < d["allocation"], d
            c = crude[scen]
            c = c["filter_ss"] if "filter_ss" in c else c
            assert d["ci_high"] < c["hmi_per_epoch"]["ci_high"]
    assert m["conditional"]["check_passed"]
    bad = study_runs[0.2].metrics["conditional"]
    assert bad["scenarios"]["fault-free"]["validation"]["flagged"]
    assert not bad["check_passed"]


def test_bank_main_filter_is_the_xi_slope_filter(study_runs):
    """The bank's main EKF and the NIS/Xi-slope EKF see the same measurements: same HPE."""
    ds = study_runs[1.0].dataset
    hpe = ds["trace_hpe_m"].values
    np.testing.assert_allclose(hpe[..., 0], hpe[..., 1], atol=1e-9)
    assert np.all(ds["n_at_risk"].values[0] == ds["n_epochs"].values[0])  # fault-free: all


def test_ramp_detected_earlier_by_the_bank(study_runs):
    """20 s runs, ramps from 2-12 s: the filter bank detects in at least as many runs as the NIS
    test (seed 000's test waits for the innovation, the bank sees the drift)."""
    r = study_runs[1.0].metrics["scenarios"]["ramp"]
    assert r["filter_ss"]["detected_runs_pct"] >= r["ekf_xi_slope"]["detected_runs_pct"]


def test_seed_drive_study_monitor_option_adds_rows_and_changes_none():
    """``--set monitor=filter-ss-overbound`` on seed000-ekf-raim: the seed's own rows are those
    of the default run, bit for bit, and three rows of the filter monitors follow (30 s of the
    drive, 16 runs, no sensitivity runs)."""
    study = STUDIES["seed000-ekf-raim"]
    base = {"duration_s": "30", "sens_mp_sigma_m": "0"}
    a = study.run(study.validate(base), 16, 0, None)
    b = study.run(study.validate({**base, "monitor": "filter-ss-overbound"}), 16, 0, None)
    assert b.rows[:len(a.rows)] == a.rows
    extra = b.rows[len(a.rows):]
    assert len(extra) == 3 and "filter solution separation" in extra[0]["quantity"]
    assert "filter_ss" not in a.metrics and set(b.metrics["filter_ss"]) == {
        "filter_ss", "ekf_xi_slope", "snapshot_mhss"}
    with pytest.raises(ValueError, match="monitor must be one of"):
        study.validate({"monitor": "bank"})


def test_uav_study_monitor_option_adds_rows_and_changes_none(shared_data):
    """``--set monitor=filter-ss`` on seed004-uav (120 epochs, no exclusion replay): the
    paper's rows are the default run's, and the constant-velocity filter bank on GPS + all
    SOPs adds two rows with a finite HPL at every epoch."""
    study = STUDIES["seed004-uav"]
    base = {"n_epochs": "120", "exclusion": "false"}
    a = study.run(study.validate(base), 120, 0, None)
    b = study.run(study.validate({**base, "monitor": "filter-ss"}), 120, 0, None)
    assert b.rows[:len(a.rows)] == a.rows
    assert len(b.rows) == len(a.rows) + 2
    fs = b.metrics["filter_ss"]
    assert fs["finite_hpl_epochs"] == 120 and fs["status_counts"] == {0: 120}
    assert 0.0 < fs["mean_hpl_m"] < 100.0
