"""Tests of araim.filter_risk (the filter bank's conditional integrity risk) and of its use on
the seed 004 UAV flight's linear bank (studies/seed004_uav/filter_mc.py).

Three oracles: hand-derived closed forms (a Rayleigh tail, a one-dimensional Gaussian, the
static least-squares bank whose separation and error are independent by construction); SciPy's
adaptive quadrature and normal CDF (a NumPy/SciPy reference of the Gaussian probabilities);
and crude Monte Carlo where it resolves the event (the HPL scaled by c < 1), fixed seeds,
tolerances from the sample counts. The check can fail: with the filters told a fifth of the
true sigma the crude counts leave the estimate's interval (tested).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, special, stats

from oaraim import mc, sim
from oaraim.araim import filter_risk as fr


def _outside_reference(cov, mean, radius):
    """P(|x| > R), x ~ N(mean, cov), by SciPy's adaptive 2-D quadrature in polar coordinates
    over r > R (the outside directly, no 1 - inside)."""
    ci = np.linalg.inv(cov)
    norm = 1.0 / (2.0 * np.pi * np.sqrt(np.linalg.det(cov)))

    def f(r, t):
        d = np.array([r * np.cos(t), r * np.sin(t)]) - mean
        return norm * np.exp(-0.5 * d @ ci @ d) * r

    top = radius + np.linalg.norm(mean) + 40.0 * np.sqrt(np.linalg.eigvalsh(cov).max())
    return integrate.dblquad(f, 0.0, 2.0 * np.pi, radius, top, epsabs=0.0, epsrel=1e-11)[0]


def test_outside_circle_matches_scipy_quadrature():
    """Random covariances (condition numbers up to ~1e3), means and radii, and one small
    radius, probabilities from 0.9 down to 1e-17: the quadrature (64 nodes) equals SciPy's
    adaptive one to 1e-9 relative (seen ~1e-11)."""
    rng = np.random.default_rng(1)
    got, seen = [], []
    for _ in range(10):
        a = rng.normal(size=(2, 2))
        cov = a @ a.T + rng.uniform(0.001, 0.3) * np.eye(2)
        mean = rng.normal(size=2) * 3.0
        radius = rng.uniform(1.0, 12.0)
        got.append(float(fr.outside_circle_probability(cov, mean, radius)))
        seen.append(_outside_reference(cov, mean, radius))
    cov, mean = np.array([[2.0, 0.7], [0.7, 0.5]]), np.array([0.3, -0.2])
    got.append(float(fr.outside_circle_probability(cov, mean, 0.5)))
    seen.append(_outside_reference(cov, mean, 0.5))
    got, seen = np.array(got), np.array(seen)
    assert seen.min() < 1e-16 and seen.max() > 0.5
    np.testing.assert_allclose(got, seen, rtol=1e-9, atol=0.0)


def test_outside_circle_closed_forms():
    """Hand-derived: zero mean, isotropic sigma: P = exp(-R^2 / (2 sigma^2)) (Rayleigh);
    isotropic with a mean: the noncentral chi-square tail with 2 degrees of freedom; a
    covariance of rank one (sigma along one axis, 0 along the other): Q((R - m)/sigma) +
    Q((R + m)/sigma) with m the mean along it, when the other mean is 0; an infinite radius
    (a PL not computable) 0, a zero radius 1."""
    s, r = 1.3, 5.0
    np.testing.assert_allclose(float(fr.outside_circle_probability(s**2 * np.eye(2),
                                                                    np.zeros(2), r)),
                               np.exp(-r**2 / (2 * s**2)), rtol=1e-12)
    for rr in (5.0, 12.0):
        m = np.array([1.0, 2.0])
        np.testing.assert_allclose(
            float(fr.outside_circle_probability(s**2 * np.eye(2), m, rr)),
            stats.ncx2.sf(rr**2 / s**2, 2, m @ m / s**2), rtol=1e-9)
    th = 0.4
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    cov = rot @ np.diag([4.0, 0.0]) @ rot.T
    for m in (0.0, 3.0, 9.0):
        want = special.ndtr(-(6.0 - m) / 2.0) + special.ndtr(-(6.0 + m) / 2.0)
        got = float(fr.outside_circle_probability(cov, rot @ np.array([m, 0.0]), 6.0))
        np.testing.assert_allclose(got, want, rtol=1e-6)
    assert float(fr.outside_circle_probability(np.eye(2), np.ones(2), np.inf)) == 0.0
    assert float(fr.outside_circle_probability(np.eye(2), np.ones(2), 0.0)) == 1.0


def test_inside_interval_matches_scipy():
    """P(|X| <= T), X ~ N(mu, sigma^2), against scipy.stats.norm's tails Q((|mu| - T)/sigma)
    - Q((|mu| + T)/sigma), also far in the tail (|mu| >> T, 1e-65, where a difference of
    CDFs near 1 would lose every digit); sigma = 0 the indicator."""
    mu = np.array([0.0, 1.0, -3.0, 20.0, -40.0, 5.0])
    sig = np.array([1.0, 0.5, 2.0, 1.0, 3.0, 0.0])
    t = np.array([2.0, 0.1, 1.0, 3.0, 4.0, 6.0])
    got = np.asarray(fr.inside_interval_probability(mu, sig, t))
    ok = sig > 0
    a = np.abs(mu[ok])
    want = stats.norm.sf(a - t[ok], 0.0, sig[ok]) - stats.norm.sf(a + t[ok], 0.0, sig[ok])
    np.testing.assert_allclose(got[ok], want, rtol=1e-9, atol=1e-300)
    assert got[3] < 1e-30 and got[3] > 0
    assert got[~ok][0] == 1.0


def test_no_alert_factor_is_the_minimum_over_all_tests():
    """The no-alert factor of eq. (1), computed at the test of largest (|mu| - T) / sigma_ss
    only, equals the minimum over every test (T > 0) of SciPy's
    P(|Delta| <= T) (200 random epochs of 12 filters, some tests off, means up to 8 sigma);
    the mode and direction it reports are where that minimum is."""
    rng = np.random.default_rng(4)
    e, k = 200, 12
    sig = rng.uniform(0.1, 3.0, (e, k, 3))
    thr = np.where(rng.uniform(size=(e, k, 3)) < 0.8, 5.0 * sig, 0.0)
    thr[:, 0] = 0.0
    mu = rng.normal(size=(e, k, 3)) * 8.0 * sig
    er = fr.epoch_risk_bound(np.broadcast_to(np.eye(2), (e, 2, 2)), np.zeros((e, 2)),
                             np.full(e, 3.0), mu, sig, thr)
    a = np.abs(mu)
    p_in = stats.norm.sf(a - thr, 0.0, sig) - stats.norm.sf(a + thr, 0.0, sig)
    p_in = np.where(thr > 0, p_in, 1.0).reshape(e, -1)
    np.testing.assert_allclose(np.asarray(er.p_no_alert), p_in.min(1), rtol=1e-9, atol=1e-300)
    at = np.asarray(er.mode) * 3 + np.asarray(er.direction)
    np.testing.assert_allclose(p_in[np.arange(e), at], p_in.min(1), rtol=1e-9, atol=1e-300)


def test_static_least_squares_bank_matches_crude_count():
    """Hand-derived bank: a static 2-D position from 5 ranges (white, unit variances), the main
    solution all five, the sub-solution without source 0, a bias f on source 0. Then e_0 =
    S_0 (v + f), Delta = (S_1 - S_0)(v + f), P_1 - P_0 their covariance, r_1 = 0 (the
    snapshot form of the claim). The event {|e_0| > R} and {|Delta_q| <= T_q} for the q eq.
    (1) picks has probability eq. (1) exactly, the product of the two factors (independence);
    200,000 draws resolve it within 4 standard errors."""
    rng = np.random.default_rng(7)
    az = np.deg2rad([10.0, 80.0, 150.0, 220.0, 300.0])
    g = np.stack([np.cos(az), np.sin(az)], 1)
    s0 = np.linalg.solve(g.T @ g, g.T)
    g1 = g[1:]
    s1 = np.zeros_like(s0)
    s1[:, 1:] = np.linalg.solve(g1.T @ g1, g1.T)
    p0, p1 = s0 @ s0.T, s1 @ s1.T
    f = np.array([2.5, 0, 0, 0, 0])
    r0, r1 = s0 @ f, s1 @ f
    assert np.allclose(r1, 0.0)
    sig_ss = np.sqrt(np.diag(p1 - p0))
    thr = 2.0 * sig_ss
    radius = 2.2
    pad = lambda x: np.concatenate([x, [0.0]])  # noqa: E731  (an up direction that tests nothing)
    er = fr.epoch_risk_bound(p0, r0, radius, np.stack([np.zeros(3), pad(r1 - r0)]),
                             np.stack([np.zeros(3), pad(sig_ss)]),
                             np.stack([np.zeros(3), pad(thr)]))
    assert int(er.mode) == 1
    q = int(er.direction)
    n = 200_000
    v = rng.normal(size=(n, 5)) + f
    e0, d = v @ s0.T, v @ (s1 - s0).T
    hit = (np.linalg.norm(e0, axis=1) > radius) & (np.abs(d[:, q]) <= thr[q])
    p = float(er.p_hmi_bound)
    assert 1e-3 < p < 0.2
    se = np.sqrt(p * (1 - p) / n)
    assert abs(hit.mean() - p) < 4.0 * se, (hit.mean(), p, se)
    # the factors alone, from the same draws
    assert abs(np.mean(np.linalg.norm(e0, axis=1) > radius) - float(er.p_outside)) < 4e-3


def test_log_uniform_nodes_and_weighted_mean():
    """The log-uniform quadrature integrates E[m] = (hi - lo) / ln(hi / lo) and E[1/m]; the
    weighted mean of an importance sample: weights 1 give the plain mean and ESS n; a proposal
    N(1, 1) for E_{N(0, 1)}[x^2] = 1 recovers it within 4 standard errors."""
    m, w = fr.log_uniform_nodes(3.0, 60.0, 24)
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-14)
    np.testing.assert_allclose(w @ m, 57.0 / np.log(20.0), rtol=1e-12)
    np.testing.assert_allclose(w @ (1 / m), (1 / 3 - 1 / 60) / np.log(20.0), rtol=1e-12)
    x = np.arange(10.0)
    e = fr.weighted_mean(x)
    assert e.mean == 4.5 and e.ess == 10.0
    rng = np.random.default_rng(3)
    y = rng.normal(1.0, 1.0, 20_000)
    lw = stats.norm.logpdf(y) - stats.norm.logpdf(y, 1.0)
    e = fr.weighted_mean(y**2, lw)
    assert abs(e.mean - 1.0) < 4 * e.std_error and e.ess < 20_000
    with pytest.raises(ValueError, match="log_uniform_nodes needs"):
        fr.log_uniform_nodes(0.0, 1.0)
    with pytest.raises(ValueError, match="at least 2 draws"):
        fr.weighted_mean([1.0])


# ------------------------------------------------------------------------------------------
# The UAV flight's linear bank (80 epochs over the 220 s flight: the tests' size)

UAV_EPOCHS = 80


@pytest.fixture(scope="module")
def uav():
    from oaraim.studies.seed004_uav import filter_mc
    return filter_mc, filter_mc.uav_setup(UAV_EPOCHS)


def test_uav_response_and_covariance_are_the_banks(uav):
    """The main covariance is the bank's (its east and north variances equal sigma_m^2 of
    the bank's own output to 1e-9 relative); the fault response is linear in the magnitude
    (a step of 7 m is 7 x the unit step's); the sub-filter whose mode excludes the faulty
    source does not move (r_s = 0 to 1e-9 m: it never uses the source)."""
    fm, st = uav
    p0 = np.asarray(fm.main_covariance(st))
    j = int(np.flatnonzero(st.faultable)[3])
    unit = sim.FaultScenario(jnp.asarray(j), jnp.asarray(60.0), jnp.asarray(1.0),
                             jnp.asarray(0.0))
    out1 = fm.fault_response(st, unit)
    out7 = fm.fault_response(st, unit._replace(step_m=jnp.asarray(7.0)))
    np.testing.assert_allclose(np.asarray(out1.sigma_m[:, 0, :2]) ** 2,
                               np.diagonal(p0, axis1=1, axis2=2), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(out7.position_m), 7.0 * np.asarray(out1.position_m),
                               rtol=1e-9, atol=1e-9)
    r = np.asarray(out1.position_m)[:, None] + np.asarray(out1.separation_m)  # (E, K, 3)
    moved = np.max(np.abs(r), axis=(0, 2))
    assert moved[0] > 0.05
    assert np.sum(moved < 1e-9) >= 1
    assert np.all(np.asarray(out1.position_m)[np.asarray(st.t_s) < 60.0] == 0.0)


def test_uav_magnitude_quadrature_converged(uav):
    """MAGNITUDE_NODES (48) Gauss-Legendre nodes in log m give the magnitude average of 384
    nodes to 1e-4 relative (one source and onset of a step 3-60 m: the integrand peaks over
    ~0.1 in ln m; 24 nodes were 1 % off)."""
    fm, st = uav
    cand = np.flatnonzero(st.faultable)
    a = fm.conditional_risk(st, "step", cand[5:6], [80.0], (3.0, 60.0))
    b = fm.conditional_risk(st, "step", cand[5:6], [80.0], (3.0, 60.0), n_nodes=384)
    assert b.sum_risk[0] > 0
    np.testing.assert_allclose(a.sum_risk, b.sum_risk, rtol=1e-4)


def _validate(fm, st, scen, n, hpl_fraction, sigma_scale):
    keys = mc.realization_keys(11, 0, 0, n)
    cand = np.flatnonzero(st.faultable)
    if scen == "fault-free":
        f = jax.tree.map(lambda x: jnp.broadcast_to(x, (n,)), sim.no_fault())
    else:
        f = sim.draw_faults(jax.random.PRNGKey(5), n, cand.size, "step", (22.0, 132.0),
                            (3.0, 60.0))
        f = f._replace(source=jnp.asarray(cand)[f.source])
    fn = jax.jit(jax.vmap(lambda k, fl: fm.validation_counts(k, st, fl, hpl_fraction,
                                                             sigma_scale)))
    ob, ex, hmi = fn(keys, f)[:3]
    return fr.crude_check(ob, ex, hmi, hpl_fraction)


@pytest.mark.parametrize("scen", ["fault-free", "step"])
def test_uav_estimate_agrees_with_crude_count(uav, scen):
    """Where crude Monte Carlo resolves the event (HPL x 0.3: tens of epochs of 32 runs), the
    crude count of eq. (1)'s event equals the summed probabilities within CRUDE_CHECK_Z
    standard errors (the runs' spread), and the no-alert event it bounds is not more
    frequent."""
    fm, st = uav
    v = _validate(fm, st, scen, 32, 0.3, 1.0)
    assert v["expected"] > 10, v
    assert not v["flagged"], v
    assert v["hmi_at_fraction"] <= v["observed"]


def test_uav_validation_flags_a_wrong_model(uav):
    """The filters told a fifth of the true sigma (the study's sigma_scale=0.2): eq. (1) uses
    the filter's covariance, which the crude counts contradict; the validation flags it."""
    fm, st = uav
    v = _validate(fm, st, "fault-free", 16, 0.3, 0.2)
    assert v["flagged"] and v["observed"] > 10 * v["expected"], v


def test_uav_importance_estimate_matches_grid(uav):
    """The importance-sampled step risk (16 draws after the pilot) equals the average over
    every faultable source and 3 onsets (the prior's stratified grid) within 4 of its
    standard errors, and the plain draws' weights are 1 (log weight 0)."""
    fm, st = uav
    onset, size = (22.0, 132.0), (3.0, 60.0)
    est = fm.importance_risk(st, "step", onset, size, 16, jax.random.PRNGKey(2))
    cand = np.flatnonzero(st.faultable)
    ons = onset[0] + (np.arange(3) + 0.5) / 3 * (onset[1] - onset[0])
    grid = fm.conditional_risk(st, "step", np.repeat(cand, 3), np.tile(ons, cand.size), size)
    assert np.all(grid.log_weight == 0.0)
    ref = grid.sum_risk.mean() / fm.onset_nodes(st.t_s, onset)
    assert est["rate"] > 0 and est["std_error"] > 0
    assert abs(est["rate"] - ref) < 4.0 * est["std_error"] + 0.05 * ref, (est, ref)
    assert est["worst"] >= est["rate"]


# ------------------------------------------------------------------------------------------
# The seed 000 drive's EKF bank (the first 30 s: the tests' size)


@pytest.fixture(scope="module")
def drive():
    from oaraim import errors
    from oaraim.studies import filter_integrity_conditional as fic
    setup = sim.drive_setup(sim.drive_seed000(), duration_s=30.0)
    err = errors.ErrorModel.clean(sigma_pr_m=2.0, fault_onset_s=np.inf, fault_bias_m=0.0)
    return fic, fic.DriveCase(setup, err, sim.FilterDriveConfig(), 2.0)


def test_drive_response_is_first_order_linear(drive):
    """The traces' new fields are the bank's (the monitor's HPL is the trace's, P_0,HH's
    diagonal sigma_m^2); the response (a faulted minus a fault-free run, the same key) is
    linear in the magnitude between 0.3 m and 3 m to 0.2 % of the horizontal response (seen
    0.07 %; the up, which eq. (1) does not use, to 2 %: seen 1 %; the EKF's second-order
    terms), and the sub-filter without the faulty tower moves by at most 3 % of
    the main filter's response (the first-order cross term of the fault and the noise-level
    offset through the main filter's Phi and H: ~1 % measured, not the 0 of the linear
    bank)."""
    fic, case = drive
    key = mc.realization_keys(0, 0, 0, 1)[0]
    _, tr = sim.simulate_filter_drive(key, case.setup, case.err, sim.no_fault(), case.cfg,
                                      2.0, traces=True)
    np.testing.assert_array_equal(np.asarray(tr.monitor.hpl_m), np.asarray(tr.hpl_m[:, 0]))
    np.testing.assert_allclose(np.diagonal(np.asarray(tr.p0_h_m2), axis1=1, axis2=2),
                               np.asarray(tr.monitor.sigma_m[:, 0, :2]) ** 2, rtol=1e-12)
    r = {}
    for m in (0.3, 3.0):
        f = sim.FaultScenario(jnp.asarray(1), jnp.asarray(10.0), jnp.asarray(m),
                              jnp.asarray(0.0))
        r[m] = sim.filter_risk.drive_response(key, case.setup, case.err, f, case.cfg, 2.0)
    a, b = np.asarray(r[0.3].r0_m) / 0.3, np.asarray(r[3.0].r0_m) / 3.0
    assert np.abs(b[:, :2]).max() > 0.1
    assert np.abs(a - b)[:, :2].max() < 2e-3 * np.abs(b[:, :2]).max()
    assert np.abs(a - b).max() < 2e-2 * np.abs(b).max()
    rs = np.asarray(r[3.0].r0_m)[:, None] + np.asarray(r[3.0].separation_mean_m)
    assert np.abs(rs[:, 2]).max() < 0.03 * np.abs(np.asarray(r[3.0].r0_m)).max()


@pytest.mark.parametrize("scen,sigma_f,flag", [("fault-free", 2.0, False), ("step", 2.0, False),
                                               ("fault-free", 0.4, True)])
def test_drive_crude_check(drive, scen, sigma_f, flag):
    """The crude check at 0.3 HPL on 16 runs of the drive: the filters told the truth, eq.
    (1)'s event is counted as often as its probabilities sum to (within CRUDE_CHECK_Z of the
    runs' spread); told a fifth of the sigma (0.4 m for 2 m), the check flags the model."""
    fic, case = drive
    case = case._replace(sigma_f=sigma_f)
    n = 16
    keys = mc.realization_keys(3, 0, 0, n)
    if scen == "fault-free":
        f = jax.tree.map(lambda x: jnp.broadcast_to(x, (n,)), sim.no_fault())
    else:
        f = sim.draw_faults(jax.random.PRNGKey(5), n, 5, "step", (3.0, 18.0), (3.0, 60.0))
    v = fr.crude_check(*fic.drive_validation(case, keys, f)[:3], fic.HPL_FRACTION)
    assert v["flagged"] == flag, v
    if not flag:
        assert v["expected"] > 5, v
        assert v["hmi_at_fraction"] <= v["observed"]
