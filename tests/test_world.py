"""The simulated error world (``sim.measurement``: multipath, NLOS episodes, tower
clocks and the GNSS-period fit, the empirical filter sigma) and the Clopper-Pearson interval
(``mc.intervals``): closed forms by hand, statistics with fixed seeds (tolerances from the
sample counts), and the checks that make the drives' MI counts able to fail."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import errors, mc, sim
from oaraim.geometry import clocks
from oaraim.sim import measurement as m

# ----------------------------------------------------------------------------- closed forms


def test_gauss_markov_step_by_hand():
    """x' = phi x + sigma sqrt(1 - phi^2) n with phi = exp(-dt / tau): dt = tau ln 2 gives
    phi = 1/2, so x = 4, n = 1, sigma = 2 -> 2 + 2 sqrt(3/4) = 2 + sqrt(3)."""
    tau = 10.0
    x = m.gauss_markov_step(4.0, 1.0, 2.0, tau, tau * np.log(2.0))
    assert float(x) == pytest.approx(2.0 + np.sqrt(3.0), rel=1e-14)


def test_gauss_markov_stationary_variance_and_autocorrelation():
    """20,000 independent chains started stationary, stepped 50 times at dt = 1 s, tau = 10 s,
    sigma = 3 m: the variance stays sigma^2 and the covariance at lag 10 s is
    sigma^2 exp(-1). The sample variance of 20,000 normals has relative sd sqrt(2/20000) = 1 %:
    5 % is 5 sd; the lag covariance's sd is below sigma^2 / sqrt(20000) = 0.064 m^2: 0.3 m^2."""
    sigma, tau, n = 3.0, 10.0, 20_000
    key = jax.random.key(7)
    x0 = sigma * jax.random.normal(key, (n,))

    def body(x, k):
        x = m.gauss_markov_step(x, jax.random.normal(k, (n,)), sigma, tau, 1.0)
        return x, x

    _, xs = jax.lax.scan(body, x0, jax.random.split(jax.random.fold_in(key, 1), 50))
    xs = np.asarray(xs)
    assert np.var(xs[-1]) == pytest.approx(sigma**2, rel=0.05)
    cov10 = np.mean(xs[19] * xs[29])
    assert cov10 == pytest.approx(sigma**2 * np.exp(-1.0), abs=0.3)


def test_nlos_probabilities_by_hand():
    """rate 0.1 /s, duration 5 s, dt 1 s: p_on = 1 - e^-0.1, p_off = 1 - e^-0.2."""
    err = errors.ErrorModel(nlos_rate_per_s=0.1, nlos_duration_s=5.0)
    p_on, p_off = m.nlos_probabilities(err, 1.0)
    assert float(p_on) == pytest.approx(1 - np.exp(-0.1), rel=1e-14)
    assert float(p_off) == pytest.approx(1 - np.exp(-0.2), rel=1e-14)


def test_nlos_step_transitions():
    """Uniforms decide: an episode ends when u0 < p_off, a clear tower starts one when
    u1 < p_on, with bias nlos_bias_m times the exponential draw."""
    err = errors.ErrorModel(nlos_rate_per_s=0.1, nlos_duration_s=5.0, nlos_bias_m=10.0)
    state = jnp.array([7.0, 7.0, 0.0, 0.0])
    u = jnp.array([[0.01, 0.99, 0.5, 0.5], [0.5, 0.5, 0.01, 0.99]])
    out = m.nlos_step(state, u, jnp.full(4, 0.3), err, 1.0)
    np.testing.assert_array_equal(np.asarray(out), [0.0, 7.0, 3.0, 0.0])


def test_nlos_share_and_episode_length():
    """4,000 towers x 2,000 steps of 0.1 s (rate 0.02 /s, duration 5 s): the NLOS share is
    p_on / (p_on + p_off) = 0.0909 and the mean excess delay of the episodes the bias mean.
    The share's sd over 8e6 correlated samples (episodes of ~50 steps: ~1.6e5 independent) is
    about sqrt(0.09 * 0.91 / 1.6e5) = 7e-4: 0.006 is ~8 sd."""
    err = errors.ErrorModel(nlos_rate_per_s=0.02, nlos_duration_s=5.0, nlos_bias_m=10.0)
    n, dt = 4000, 0.1
    p_on, p_off = (float(v) for v in m.nlos_probabilities(err, dt))
    share = p_on / (p_on + p_off)

    def body(x, k):
        u = jax.random.uniform(k, (3, n))
        x = m.nlos_step(x, u[:2], -jnp.log1p(-u[2]), err, dt)
        return x, x

    _, xs = jax.lax.scan(body, jnp.zeros(n), jax.random.split(jax.random.key(3), 3000))
    xs = np.asarray(xs[1000:])  # after the 5 episode-lengths of burn-in
    assert np.mean(xs > 0) == pytest.approx(share, abs=0.006)
    assert np.mean(xs[xs > 0]) == pytest.approx(10.0, rel=0.1)


def test_common_clock_step_is_the_receiver_clock_model_and_zero_psd_is_safe():
    err = errors.ErrorModel()
    x = jnp.array([[1.0, 0.1], [2.0, -0.2]])
    w = jnp.array([[0.3, -1.2], [0.5, 0.7]])
    got = m.common_clock_step(x, w, err, 0.1)
    want = clocks.clock_step_normals(w, x, 0.1, err.clk_s_wdt_s, err.clk_s_wdtdot_per_s)
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12)
    still = m.common_clock_step(x, w, errors.ErrorModel.clean(), 0.1)
    np.testing.assert_allclose(np.asarray(still), [[1.01, 0.1], [1.98, -0.2]], rtol=1e-14)


def test_clock_fit_is_least_squares_with_a_mask():
    rng = np.random.default_rng(0)
    t = -np.arange(40)[::-1] * 1.0
    y = rng.normal(size=(40, 3)) + 2.0 + 0.05 * t[:, None]
    mask = t > -30.0
    fit, var = m.clock_fit(jnp.asarray(y), jnp.asarray(t), jnp.asarray(mask))
    for j in range(3):
        b, a = np.polyfit(t[mask], y[mask, j], 1)
        res = y[mask, j] - (a + b * t[mask])
        np.testing.assert_allclose(np.asarray(fit[j]), [a, b], rtol=1e-10)
        assert float(var[j]) == pytest.approx(res @ res / (mask.sum() - 2), rel=1e-10)
    fit0, var0 = m.clock_fit(jnp.asarray(y), jnp.asarray(t), jnp.zeros(40, bool))
    assert np.all(np.asarray(fit0) == 0.0) and np.all(np.isnan(np.asarray(var0)))


def test_clock_fit_slope_variance_of_white_noise():
    """A line through N = 120 samples of white noise (sigma 1, dt 1 s): the slope's variance is
    sigma^2 / sum (t - tbar)^2 = 12 / (N (N^2 - 1)) (the hand formula). 4,000 fits: the sample
    variance's relative sd is sqrt(2 / 4000) = 2.2 %; 10 % is 4.5 sd."""
    n, reps = 120, 4000
    t = jnp.asarray(-np.arange(n)[::-1] * 1.0)
    y = jax.random.normal(jax.random.key(11), (n, reps))
    fit, _ = m.clock_fit(y, t, jnp.ones(n, bool))
    want = 12.0 / (n * (n**2 - 1))
    assert float(np.var(np.asarray(fit[:, 1]))) == pytest.approx(want, rel=0.1)


# ------------------------------------------------------------------- calibration and sigma


def _setup(duration_s=20.0):
    return sim.drive_setup(sim.drive_seed000(), duration_s=duration_s)


def _calib(err, n=64, seed=0):
    setup = _setup()
    keys = jax.random.split(jax.random.key(seed), n)
    return jax.jit(jax.vmap(lambda k: sim.initial_draw(k, setup, err)))(keys)


def test_clean_world_has_no_calibration_and_the_filter_is_told_the_truth():
    d = _calib(errors.ErrorModel.clean(sigma_pr_m=2.0), n=4)
    assert np.all(np.asarray(d.world.clk_fit_m) == 0.0)
    assert np.all(np.isnan(np.asarray(d.sigma_empirical_m)))
    sig = jax.vmap(lambda dd: sim.drive.filter_sigma(dd, errors.ErrorModel.clean(2.0)))(d)
    np.testing.assert_array_equal(np.asarray(sig), 2.0)


def test_empirical_sigma_is_estimated_not_copied():
    """White noise only (sigma 1.7 m), a 120 s GNSS period at 1 Hz, 5 towers: the estimate is
    the pooled residual sd of 5 x 118 dof, whose relative sd is 1 / sqrt(2 * 590) = 2.9 %. Each
    run's estimate differs from the truth (it is estimated), and their mean over 64 runs lies
    within 1.5 % (4 sd of the mean) of 1.7 m. With the default multipath and NLOS added, the
    estimate grows."""
    white = errors.ErrorModel(sigma_pr_m=1.7, mp_sigma_m=0.0, nlos_rate_per_s=0.0,
                           clk_eps_sigma_m=0.0, clk_s_wdt_s=0.0, clk_s_wdtdot_per_s=0.0)
    s = np.asarray(_calib(white).sigma_empirical_m)
    assert np.all(s != 1.7) and np.std(s) == pytest.approx(1.7 * 0.029, rel=0.3)
    assert np.mean(s) == pytest.approx(1.7, rel=0.015)
    s_world = np.asarray(_calib(errors.ErrorModel(sigma_pr_m=1.7)).sigma_empirical_m)
    assert np.median(s_world) > 1.7 * 1.1


def test_fit_residual_grows_after_the_gnss_period():
    """Seed 000 II-D: the tower clocks are fitted while GNSS is available; after that the
    error of the fitted slope makes the residual grow linearly. With a pure white-noise world
    the fit error at t is e_a + e_b (t - tbar): its sd at t = 0 and t = 300 s follows the LS
    variances sigma^2 (1/N + (t - tbar)^2 / Sxx) (hand formula, 64 runs x 5 towers:
    relative sd of the variance sqrt(2 / 320) = 8 %, 30 % tolerance)."""
    white = errors.ErrorModel(sigma_pr_m=2.0, mp_sigma_m=0.0, nlos_rate_per_s=0.0,
                           clk_eps_sigma_m=0.0, clk_s_wdt_s=0.0, clk_s_wdtdot_per_s=0.0,
                           calib_window_s=120.0)
    fit = np.asarray(_calib(white).world.clk_fit_m).reshape(-1, 2)
    n = 120
    tb = -(n - 1) / 2.0
    sxx = n * (n**2 - 1) / 12.0
    for t in (0.0, 300.0):
        want = 4.0 * (1.0 / n + (t - tb) ** 2 / sxx)
        assert np.var(fit[:, 0] + fit[:, 1] * t) == pytest.approx(want, rel=0.3)


def test_sop_errors_are_reproducible_from_the_key():
    d1 = _calib(errors.ErrorModel(), n=2, seed=5)
    d2 = _calib(errors.ErrorModel(), n=2, seed=5)
    np.testing.assert_array_equal(np.asarray(d1.world.clk_fit_m), np.asarray(d2.world.clk_fit_m))
    np.testing.assert_array_equal(np.asarray(d1.sigma_empirical_m),
                                  np.asarray(d2.sigma_empirical_m))


# --------------------------------------------------------------------- Clopper-Pearson


def test_clopper_pearson_by_hand():
    """k = 0: upper = 1 - (alpha/2)^(1/n); k = n: lower = (alpha/2)^(1/n); k = 1, n = 1:
    (0.025, 1)."""
    assert mc.clopper_pearson(0, 10) == pytest.approx((0.0, 1 - 0.025 ** 0.1), rel=1e-12)
    assert mc.clopper_pearson(10, 10) == pytest.approx((0.025 ** 0.1, 1.0), rel=1e-12)
    assert mc.clopper_pearson(1, 1) == pytest.approx((0.025, 1.0), rel=1e-12)
    r = mc.rate_with_interval(3, 100)
    assert r["rate"] == 0.03 and r["ci_low"] < 0.03 < r["ci_high"]
    with pytest.raises(ValueError, match="0 <= k <= n"):
        mc.clopper_pearson(5, 3)
    with pytest.raises(ValueError, match="confidence"):
        mc.clopper_pearson(1, 3, confidence=1.0)


def test_clopper_pearson_coverage():
    """Exact coverage >= 95 % at p = 0.1, n = 50: the sum of the binomial pmf over the k
    whose interval contains p (computed, not sampled)."""
    from scipy import stats
    n, p = 50, 0.1
    k = np.arange(n + 1)
    lo, hi = mc.clopper_pearson(k, np.full(n + 1, n))
    cover = stats.binom.pmf(k, n, p)[(lo <= p) & (p <= hi)].sum()
    assert 0.95 <= cover < 1.0


# ------------------------------------------------- integrity checks that can fail (item 6)


@pytest.fixture(scope="module")
def mi_runs():
    """16 runs of the first 60 s of the seed 000 drive, no fault, both filters: the clean
    world, the clean world plus an error outside the PL's model (a Gauss-Markov bias of
    4 sigma = 8 m, tau 30 s, on every tower: the filter assumes white 2 m noise), and the
    default realistic world. One compilation (every world field is traced)."""
    setup = sim.drive_setup(sim.drive_seed000(), duration_s=60.0)
    keys = jax.random.split(jax.random.key(25), 16)
    run = jax.jit(jax.vmap(lambda k, e: sim.simulate_drive(k, setup, e), in_axes=(0, None)))
    no_fault = dict(fault_onset_s=np.inf, fault_bias_m=0.0)
    worlds = {"clean": errors.ErrorModel.clean(**no_fault),
              "unmodelled": errors.ErrorModel.clean(mp_sigma_m=8.0, mp_tau_s=30.0, **no_fault),
              "realistic": errors.ErrorModel(**no_fault)}
    return {k: jax.device_get(run(keys, w)) for k, w in worlds.items()}


def test_mi_count_can_fail(mi_runs):
    """HPE > HPL (MI) is rare when the filter's model is the truth (clean world: 2 of the
    19,200 filter-epochs here) and common once an error outside that model is injected: the
    MI check of the drive studies is not true by construction. The runs are independent, so
    the share of runs with any MI has an exact Clopper-Pearson interval: the injected world's
    lies above the clean world's."""
    clean = np.asarray(mi_runs["clean"].n_misleading)
    bad = np.asarray(mi_runs["unmodelled"].n_misleading)
    print("MI epochs clean", clean.sum(0), "unmodelled", bad.sum(0))
    assert bad.sum() > 20 * max(clean.sum(), 1)
    r_bad = mc.rate_with_interval(np.sum(bad[:, 1] > 0), bad.shape[0])
    r_clean = mc.rate_with_interval(np.sum(clean[:, 1] > 0), clean.shape[0])
    assert r_bad["ci_low"] > r_clean["rate"]


def test_realistic_world_is_harsher_than_the_clean_one(mi_runs):
    """The realistic world's filter is not told the truth: more NIS alarms and larger errors
    than the clean world's, with the empirical sigma of each run > 0."""
    cl, rw = mi_runs["clean"], mi_runs["realistic"]
    assert np.median(np.asarray(rw.rmse_2d_m)[:, 0]) > np.median(np.asarray(cl.rmse_2d_m)[:, 0])
    assert np.all(np.asarray(rw.filter_sigma_m) > 0)
    assert np.sum(np.asarray(rw.n_false_alarms)) > np.sum(np.asarray(cl.n_false_alarms))


def test_gnss_errors_variance_adds_up():
    """``sim.gnss_errors`` at one elevation (30 deg) over 4,000 satellites (stationary start):
    the variance is the sum of its terms, (2/3 URA)^2 + b_nom^2 / 3 (uniform) + sigma_tropo^2 +
    sigma_iono^2 + (scale x iono-free x sigma_MP)^2 + (iono-free x sigma_noise)^2, by the ADD
    formulas of errors. Relative sd of the sample variance sqrt(2 / 4000) = 2.2 %
    (the uniform term changes it little): 10 % is > 4 sd."""
    from oaraim import errors as em
    gm = errors.GnssErrorModel(sigma_iono_m=0.4)
    el = jnp.full((3, 4000), np.deg2rad(30.0))
    e = np.asarray(sim.gnss_errors(jax.random.key(4), jnp.array([0.0, 1.0, 2.0]), el, 1.0, gm))
    iff = em.iono_free_factor()
    want = ((2 / 3) ** 2 + 0.75**2 / 3 + float(em.sigma_tropo_m(el[0, 0])) ** 2 + 0.4**2
            + (2.0 * iff * float(em.sigma_multipath_m(el[0, 0]))) ** 2
            + (iff * float(em.sigma_noise_m(el[0, 0]))) ** 2)
    assert np.var(e[2]) == pytest.approx(want, rel=0.1)
    # time-correlated: consecutive epochs 1 s apart are strongly correlated (URE, troposphere)
    assert np.corrcoef(e[1], e[2])[0, 1] > 0.3
