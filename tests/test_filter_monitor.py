"""Tests of araim.filter_monitor: the solution-separation monitor of a Kalman filter bank.

The exactness checks cannot be tuned: a filter on a static state with no process noise is
recursive least squares, so after k epochs every filter of the bank equals the weighted least
squares of the k epochs' measurements stacked (its mode's sources removed at every epoch), and
the monitor's separations, thresholds and PLs equal the snapshot MHSS of those stacked
measurements (same modes, same budget); a filter that forgets everything (huge process noise)
equals the snapshot MHSS of each epoch. Tolerance 1e-6 m: both sides solve the same PL
equations with the same root finder, so what is left is float64 rounding of 5 x 5 systems
(conditioning ~1e3 here, differences seen ~1e-9 m) and, for the diffuse prior of 1e12 m^2 and
the process noise of 1e14 m^2, a prior information of 1e-12 / 1e-14 m^-2 against >= 1e-3 m^-2 of
the data (relative <= 1e-9 of a PL of < 100 m: <= 1e-7 m; 1e10 m^2 left 1.3e-6 m on a VPL of
96 m, whose vertical information is ~1e-2 m^-2).

Oracles: ``araim.protection_levels`` and ``araim.mhss.project`` (the snapshot MHSS) where the
stacked problem is one (a static receiver and towers: k rows of a tower are one row of
variance 1 / sum 1/sigma^2), and a plain NumPy stacked weighted least squares (below) with the
reference bisection of ``oaraim.reference_mhss`` where the geometry changes from epoch to epoch.
"""

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

from oaraim import araim, errors, geometry, readers
from oaraim import reference_mhss as ref
from oaraim.araim import Status
from oaraim.araim import filter_monitor as fmon
from oaraim.araim.fault_modes import FaultModeRule, fault_modes

L, C, E = 8, 2, 4
N = 3 + C
BUDGET = araim.BUDGET_SEED004_TABLE_I
RULE = "add-v4.2"
P_SAT = np.full(L, 1e-5)
P_CONST = np.array([1e-8, 1e-4])
CON = np.array([0, 0, 0, 0, 0, 1, 1, 1])
N_GEOMETRIES = 6
SOURCES = fmon.BankSources(CON, P_SAT, P_CONST)
OPTIONS = fmon.BankOptions(BUDGET, 1, RULE)


def _rows(rng, shape):
    az = rng.uniform(0.0, 2.0 * np.pi, shape)
    el = rng.uniform(np.radians(5.0), np.radians(75.0), shape)
    return np.asarray(geometry.geometry_rows(az, el))


def _design(g):
    """Measurement rows [g, one-hot clock] (..., L, N) of the state [E, N, U, clocks]."""
    return np.concatenate([g, np.broadcast_to(np.eye(C)[CON], g.shape[:-1] + (C,))], -1)


def _run(h, sig, z, q=0.0, valid=None):
    """The linear bank over the epochs of h (E, L, N): static state (Phi = I), process noise
    q I, diffuse prior 1e12 m^2."""
    e = h.shape[0]
    model = fmon.LinearModel(jnp.broadcast_to(jnp.eye(N), (e, N, N)),
                             jnp.broadcast_to(q * jnp.eye(N), (e, N, N)), jnp.asarray(h),
                             jnp.asarray(sig**2))
    valid = np.ones((e, L), bool) if valid is None else valid
    return fmon.run_linear_monitor(jnp.zeros(N), 1e12 * jnp.eye(N), model, jnp.asarray(z),
                                   jnp.asarray(valid), fmon.BankSources(CON, P_SAT, P_CONST),
                                   OPTIONS)[1]


def _case(seed, static, sigma_m=None):
    """Rows, sigmas (uniform 0.5-3 m, or ``sigma_m``), design matrices and measurements (with
    noise of those sigmas) of E epochs of L sources."""
    rng = np.random.default_rng(seed)
    g = _rows(rng, (L,)) if static else _rows(rng, (E, L))
    g = np.broadcast_to(g, (E, L, 3))
    sig = rng.uniform(0.5, 3.0, (E, L))
    if sigma_m is not None:
        sig = np.full_like(sig, sigma_m)
    h = _design(g)
    x = rng.normal(size=N) * 20.0
    z = np.einsum("eln,n->el", h, x) + sig * rng.normal(size=(E, L))
    return g, sig, h, z


@pytest.mark.parametrize("seed", range(N_GEOMETRIES))
def test_static_state_equals_snapshot_mhss_of_stacked_epochs(seed):
    g, sig, h, z = _case(seed, static=True)
    out = _run(h, sig, z)
    for k in range(E):
        w = np.sum(1.0 / sig[:k + 1] ** 2, 0)
        var = 1.0 / w                                   # k + 1 rows of a tower: one row
        z_eff = np.sum(z[:k + 1] / sig[:k + 1] ** 2, 0) * var
        snap = araim.protection_levels(araim.Sources(g[0], CON, var, var, np.zeros(L), P_SAT),
                                       P_CONST, BUDGET, araim.MHSSOptions(1, fault_modes=RULE))
        assert int(snap.status) == Status.OK == int(out.status[k])
        for ours, theirs in ((out.hpl_m, snap.hpl_m), (out.vpl_m, snap.vpl_m),
                             (out.emt_m, snap.emt_m)):
            assert abs(float(ours[k]) - float(theirs)) < 1e-6
        assert int(out.n_modes[k]) == int(snap.n_modes)
        assert float(out.p_not_monitored[k]) == pytest.approx(float(snap.p_not_monitored),
                                                              rel=1e-12)
        tl = lambda a: jnp.asarray(a)[..., None]  # noqa: E731  (batch of one, last)
        pr = araim.mhss.project(
            araim.Sources(tl(g[0]), tl(CON), tl(var), tl(var), tl(np.zeros(L)), tl(P_SAT),
                          tl(np.ones(L, bool))), tl(P_CONST), BUDGET,
            araim.MHSSOptions(1, fault_modes=FaultModeRule(RULE)))
        s_pos = np.asarray(pr.s_pos[..., 0])          # (K, 3, L)
        sep = (s_pos - s_pos[:1]) @ z_eff              # the snapshot's separations
        mon = np.asarray(pr.monitored[:, 0])
        np.testing.assert_array_equal(np.asarray(out.monitored[k]), mon)
        np.testing.assert_allclose(np.asarray(out.threshold_m[k]), pr.threshold[..., 0],
                                   rtol=0, atol=1e-6)
        np.testing.assert_allclose(np.asarray(out.sigma_ss_m[k]), pr.sigma_ss[..., 0],
                                   rtol=0, atol=1e-6)
        np.testing.assert_allclose(np.asarray(out.separation_m[k])[mon], sep[mon], atol=1e-6)
        np.testing.assert_allclose(np.asarray(out.sigma_m[k]), pr.sigma[..., 0], atol=1e-6)


def _stacked_wls(h, sig, z, keep):
    """Plain NumPy weighted least squares of the stacked rows ``keep`` (E, L) of h, z: the
    position estimate (3,) and covariance (3, 3); a clock with no kept row is dropped."""
    rows = h[keep]
    cols = np.flatnonzero(np.any(rows != 0.0, axis=0))
    a = rows[:, cols]
    w = 1.0 / sig[keep] ** 2
    cov = np.linalg.inv(a.T @ (w[:, None] * a))
    x = cov @ a.T @ (w * z[keep])
    return x[:3], cov[:3, :3]


@pytest.mark.parametrize("seed", range(N_GEOMETRIES))
def test_static_state_moving_geometry_equals_stacked_least_squares(seed):
    g, sig, h, z = _case(100 + seed, static=False)
    out = _run(h, sig, z)
    fm = fault_modes(np.ones(L, bool), CON, P_SAT, P_CONST, BUDGET, 1, RULE)
    excluded = np.asarray(fm.excluded)                 # (T, L), the same at every epoch
    for k in range(E):
        kept = np.zeros((E, L), bool)
        kept[:k + 1] = True
        x0, p0 = _stacked_wls(h, sig, z, kept)
        mon = np.asarray(out.monitored[k])
        n_f = int(mon.sum())
        k_h = -special.ndtri(BUDGET.p_fa_h / (4 * n_f))
        k_v = -special.ndtri(BUDGET.p_fa_v / (2 * n_f))
        np.testing.assert_allclose(out.position_m[k], x0, atol=1e-6)
        terms = [[], [], []]
        for t in np.flatnonzero(mon[1:]):
            xi, pi = _stacked_wls(h, sig, z, kept & ~excluded[t][None])
            sig_ss = np.sqrt(np.diag(pi - p0))
            thr = np.array([k_h, k_h, k_v]) * sig_ss
            np.testing.assert_allclose(out.separation_m[k, t + 1], xi - x0, atol=1e-6)
            np.testing.assert_allclose(out.sigma_ss_m[k, t + 1], sig_ss, atol=1e-6)
            np.testing.assert_allclose(out.threshold_m[k, t + 1], thr, atol=1e-6)
            for q in range(3):
                terms[q].append((float(out.prior[k, t + 1]), np.sqrt(pi[q, q]), thr[q]))
        # the PLs against the reference bisection (PL_XTOL 1e-6 m) on the oracle's sigmas:
        # the root finder returns a PL at most 1e-3 m above the root (araim.mhss.root)
        scale = 1.0 - float(out.p_not_monitored[k]) / (BUDGET.phmi_v + BUDGET.phmi_h)
        rhs = [0.5 * BUDGET.phmi_h * scale] * 2 + [BUDGET.phmi_v * scale]
        pls = [ref.solve_pl(2.0, np.sqrt(p0[q, q]), 0.0, np.array([a for a, _, _ in terms[q]]),
                            np.array([s for _, s, _ in terms[q]]),
                            np.array([o for _, _, o in terms[q]]), rhs[q]) for q in range(3)]
        assert 0.0 <= float(out.pl_enu_m[k, 0]) - pls[0] < 2e-3
        assert 0.0 <= float(out.vpl_m[k]) - pls[2] < 2e-3
        assert float(out.hpl_m[k]) == pytest.approx(np.hypot(*out.pl_enu_m[k, :2]), abs=1e-12)


@pytest.mark.parametrize("seed", range(N_GEOMETRIES))
def test_huge_process_noise_equals_snapshot_mhss_of_each_epoch(seed):
    g, sig, h, z = _case(200 + seed, static=False)
    out = _run(h, sig, z, q=1e14)
    for k in range(E):
        snap = araim.protection_levels(araim.Sources(g[k], CON, sig[k] ** 2, sig[k] ** 2,
                                                     np.zeros(L), P_SAT), P_CONST, BUDGET,
                                       araim.MHSSOptions(1, fault_modes=RULE))
        assert abs(float(out.hpl_m[k]) - float(snap.hpl_m)) < 1e-6
        assert abs(float(out.vpl_m[k]) - float(snap.vpl_m)) < 1e-6
        assert abs(float(out.emt_m[k]) - float(snap.emt_m)) < 1e-6


def test_padding_changes_nothing():
    g, sig, h, z = _case(7, static=False)
    out = _run(h, sig, z)
    # a ninth tower, never valid, with garbage rows and measurements
    rng = np.random.default_rng(9)
    global L, CON, P_SAT
    saved = L, CON, P_SAT
    try:
        L, CON, P_SAT = L + 1, np.append(CON, 1), np.append(P_SAT, 1e-5)
        h9 = np.concatenate([h, rng.normal(size=(E, 1, N))], 1)
        z9 = np.concatenate([z, rng.normal(size=(E, 1)) * 1e3], 1)
        s9 = np.concatenate([sig, np.ones((E, 1))], 1)
        valid = np.ones((E, L), bool)
        valid[:, -1] = False
        out9 = _run(h9, s9, z9, valid=valid)
    finally:
        L, CON, P_SAT = saved
    np.testing.assert_allclose(out9.hpl_m, out.hpl_m, atol=1e-9)
    np.testing.assert_allclose(out9.vpl_m, out.vpl_m, atol=1e-9)
    np.testing.assert_allclose(out9.position_m, out.position_m, atol=1e-9)


def test_false_alert_factors_closed_form():
    k = fmon.false_alert_factors(jnp.asarray(9), 10, BUDGET)
    assert float(k[0]) == pytest.approx(-special.ndtri(BUDGET.p_fa_h / 36.0), rel=1e-14)
    assert float(k[2]) == pytest.approx(-special.ndtri(BUDGET.p_fa_v / 18.0), rel=1e-14)


def test_fault_on_one_tower_is_detected_and_its_subfilter_separates():
    """A 40 m step on tower 2 from epoch 2 (static state, no process noise, the filter's sigma
    the truth's): no alert before the onset, alerts from it on, and the sub-filter without
    tower 2 (slot 1 + 2) is among the modes whose separation exceeds its threshold (the largest
    ratio need not be its own: with 8 sources of 0.5 m the other modes' separations also move)."""
    g, sig, h, z = _case(11, static=False, sigma_m=0.5)
    z = z.copy()
    z[2:, 2] += 40.0
    out = _run(h, sig, z)
    assert not np.asarray(out.alert)[:2].any() and np.asarray(out.alert)[2:].all()
    ratio = np.abs(np.asarray(out.separation_m[-1])) / np.where(
        np.asarray(out.threshold_m[-1]) > 0, out.threshold_m[-1], np.inf)
    assert ratio[1 + 2].max() > 1.0


def test_exclusion_restart_makes_the_fault_free_subfilter_the_main_one():
    """The step of the test above with ``exclusion=True``: at the first alert the sub-filter
    without tower 2 (which never used it) becomes the main filter and tower 2 is excluded from
    then on, so the main filter at the last epoch is the stacked least squares of the 4 epochs
    without tower 2 (1e-6 m), and the bank restarted from it stops alerting."""
    g, sig, h, z = _case(11, static=False, sigma_m=0.5)
    z = z.copy()
    z[2:, 2] += 40.0
    e = h.shape[0]
    model = fmon.LinearModel(jnp.broadcast_to(jnp.eye(N), (e, N, N)), jnp.zeros((e, N, N)),
                             jnp.asarray(h), jnp.asarray(sig**2))
    run = lambda excl: fmon.run_linear_monitor(  # noqa: E731
        jnp.zeros(N), 1e12 * jnp.eye(N), model, jnp.asarray(z), jnp.ones((e, L), bool),
        SOURCES, OPTIONS._replace(exclusion=excl))[1]
    out, plain = run(True), run(False)
    first = int(np.argmax(np.asarray(plain.alert)))
    assert bool(plain.alert[first]) and first >= 2
    gone = np.asarray(out.excluded_sources)
    assert not gone[:first].any() and np.all(gone[first:] == (np.arange(L) == 2))
    kept = np.ones((E, L), bool)
    kept[:, 2] = False
    x_ref, _ = _stacked_wls(h, sig, z, kept)
    np.testing.assert_allclose(out.position_m[-1], x_ref, atol=1e-6)
    assert np.linalg.norm(plain.position_m[-1] - x_ref) > 1.0   # without: the fault is in
    assert not np.asarray(out.alert)[first + 1:].any()
    assert not np.asarray(plain.excluded_sources).any()


def test_bank_size_matches_template():
    assert fmon.n_bank_filters(L, C, 1, RULE) == 1 + L + C
    assert fmon.n_bank_filters(L, C, 1, "grouped") == 1 + L + C


def test_replay_of_a_recorded_drive_main_filter_is_the_ekf(tmp_path):
    """A synthesized seed 000 drive (clean world, 30 s, 30 m fault on tower 1 from 25 s),
    written and loaded as a recording: the bank's main filter is the replay's EKF without
    exclusion (same preparation, initial state and updates: positions equal to 1e-6 m), every
    epoch has a finite HPL, and the bank alerts after the onset, not before; with exclusion
    (by restart) the faulty tower goes."""
    from oaraim import mc, sim
    from oaraim.araim import ekf_replay

    sc = sim.drive_seed000()
    rec = sim.synthesize_recording(sc, mc.realization_keys(0, 0, 0, 1)[0],
                                   err=errors.ErrorModel.clean(), duration_s=30.0)
    readers.write_recording(tmp_path / "drive", rec)
    loaded = readers.load_recording(tmp_path / "drive")
    ref_tr = ekf_replay.replay_ekf_raim(loaded)
    fr = ekf_replay.replay_filter_monitor(loaded)
    np.testing.assert_allclose(fr.monitor.position_m, ref_tr.position_enu_m[0], atol=1e-6)
    assert np.all(fr.monitor.status == Status.OK) and np.all(np.isfinite(fr.monitor.hpl_m))
    after = fr.t_s >= 25.0
    assert fr.monitor.alert[after].mean() > 0.9 and not fr.monitor.alert[~after].any()
    assert np.all(np.isfinite(fr.err_2d_m))
    # exclusion by restart: tower 1 (index 0) out from the first alert on, the error after the
    # onset smaller than the unexcluded bank's (which absorbs the 30 m bias)
    fx = ekf_replay.replay_filter_monitor(loaded, ekf_replay.FilterReplayConfig(exclusion=True))
    gone = fx.monitor.excluded_sources
    assert not gone[~after].any() and np.all(gone[-1] == (np.arange(gone.shape[1]) == 0))
    assert fx.err_2d_m[after].mean() < fr.err_2d_m[after].mean() / 2


def test_gradient_of_the_filter_hpl_matches_finite_differences():
    """Reverse mode through the bank's scan and the PL root finder's implicit derivative: the
    last epoch's HPL with respect to the azimuths of two sources at two epochs equals central
    differences (step 1e-6 rad: truncation ~1e-12, rounding ~1e-16 x 50 m / 1e-6 = 5e-9 m/rad;
    compared to 1e-6 relative + 1e-7 m/rad)."""
    import jax

    rng = np.random.default_rng(3)
    az = rng.uniform(0.0, 2.0 * np.pi, (E, L))
    el = rng.uniform(np.radians(5.0), np.radians(70.0), (E, L))
    sig = rng.uniform(0.5, 3.0, (E, L))

    def hpl(a):
        h = jnp.concatenate([geometry.geometry_rows(a, el),
                             jnp.broadcast_to(jnp.eye(C)[CON], (E, L, C))], -1)
        model = fmon.LinearModel(jnp.broadcast_to(jnp.eye(N), (E, N, N)), jnp.zeros((E, N, N)),
                                 h, jnp.asarray(sig**2))
        return fmon.run_linear_monitor(jnp.zeros(N), 1e12 * jnp.eye(N), model,
                                       jnp.zeros((E, L)), jnp.ones((E, L), bool), SOURCES,
                                       OPTIONS)[1].hpl_m[-1]

    grad = np.asarray(jax.grad(hpl)(jnp.asarray(az)))
    for e, l_ in ((2, 3), (0, 6)):
        d = np.zeros_like(az)
        d[e, l_] = 1e-6
        fd = (float(hpl(jnp.asarray(az + d))) - float(hpl(jnp.asarray(az - d)))) / 2e-6
        assert grad[e, l_] == pytest.approx(fd, rel=1e-6, abs=1e-7)
