"""Error-state EKF (araim.ekf) and EKF-based RAIM (araim.ekf_raim), seed 000 sections II-III."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats
from scipy.linalg import expm

from oaraim import errors, sim
from oaraim.araim import ekf, ekf_raim
from oaraim.araim.chi2 import detection_threshold, noncentrality
from oaraim.araim.status import Status
from oaraim.errors import imu

# ----------------------------------------------------------------------------------------
# A plain linear Kalman filter in NumPy (the reference)


def van_loan(a, qc, t):
    """Phi = e^{AT} and Q_d = int e^{As} Qc e^{A^T s} ds by Van Loan's matrix exponential."""
    n = a.shape[0]
    m = expm(np.block([[-a, qc], [np.zeros((n, n)), a.T]]) * t)
    phi = m[n:, n:].T
    return phi, phi @ m[:n, n:]


def linear_kf(x0, p0, a, b, qc, t, zs, h, r, used):
    """x <- Phi x + Gamma (constant input b over T), P <- Phi P Phi^T + Q_d; Joseph update with
    the used rows of H. Returns the posterior states and covariances per epoch."""
    n = a.shape[0]
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = a, b
    e = expm(aug * t)
    phi, gam = e[:n, :n], e[:n, n]
    _, qd = van_loan(a, qc, t)
    x, p = x0.copy(), p0.copy()
    xs, ps = [], []
    for z in zs:
        x = phi @ x + gam
        p = phi @ p @ phi.T + qd
        hu, zu, ru = h[used], z[used], np.diag(r[used])
        s = hu @ p @ hu.T + ru
        k = p @ hu.T @ np.linalg.inv(s)
        x = x + k @ (zu - hu @ x)
        ikh = np.eye(n) - k @ hu
        p = ikh @ p @ ikh.T + k @ ru @ k.T
        xs.append(x.copy())
        ps.append(p.copy())
    return np.array(xs), np.array(ps)


def test_ekf_equals_linear_kalman_filter():
    """With a level, non-rotating IMU, zero attitude/gyro uncertainty and random-walk biases
    (1/tau = 0), the EKF's model is linear in [r, v, b_a, clock]: the EKF (100 Hz mechanization,
    10 Hz covariance via the Taylor series, pseudorange-type rows [0, u^T, 0, 1, 0] with fixed
    u, one padded tower) must equal the NumPy KF (matrix exponentials, Van Loan) to 1e-9."""
    rng = np.random.default_rng(1)
    g = np.array([0.0, 0.0, -9.8])
    f = np.array([0.3, -0.2, 9.8])                    # constant specific force
    spec = imu.ImuSpec(0.0, 1.4e-3, 0.0, 4e-4, np.inf, np.inf)
    p = ekf.params_from_imu(spec, 0.01, g)._replace(accel_bias_psd=1e-8, gyro_bias_psd=0.0)
    n_sub, n_ep, t = 10, 40, 0.1
    u = rng.normal(size=(5, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    used = np.array([True, True, True, True, False])   # the last tower is padding
    sig = np.array([1.5, 2.0, 2.5, 3.0, 1.0])
    # full linear state x = [theta, r, v, bg, ba, clk] (17) with theta = bg = 0 throughout
    a = np.asarray(ekf.error_dynamics(jnp.zeros(3), jnp.eye(3), jnp.zeros((3, 3)), p))
    b = np.zeros(17)
    b[6:9] = f + g
    qc = np.diag(np.asarray(ekf.continuous_noise(p)))
    h = np.asarray(ekf.jacobian_rows(jnp.asarray(u)))
    x_true0 = np.concatenate([np.zeros(3), [10.0, -5.0, 1.0], [8.0, 2.0, 0.0], np.zeros(3),
                              [0.02, -0.01, 0.03], [3.0, 0.2]])
    p0 = np.diag(np.concatenate([np.zeros(3), np.full(3, 0.25), np.full(3, 0.01), np.zeros(3),
                                 np.full(3, 1.6e-7), [1.0, 0.01]]))
    x_est0 = x_true0 + np.sqrt(np.diag(p0)) * rng.normal(size=17)
    zs = np.array([h @ (x_true0 + k) for k in rng.normal(size=(n_ep, 17))])
    zs[:, 4] = 1e6                                        # junk on the padded tower
    xs_ref, ps_ref = linear_kf(x_est0, p0, a, b, qc, t, zs, h, sig**2, used)

    st = ekf.ekf_init([0, 0, 0, 1.0], x_est0[3:6], x_est0[6:9], x_est0[9:12], x_est0[12:15],
                      x_est0[15:17], p0)
    gyro = jnp.zeros((n_sub, 3))
    accel = jnp.tile(jnp.asarray(f), (n_sub, 1))

    @jax.jit
    def step(st, z):
        st, _ = ekf.ekf_predict(st, gyro, accel, p)
        nu = z - (jnp.asarray(u) @ st.r + st.clk[0])
        return ekf.kalman_update(st, nu, jnp.asarray(u), jnp.asarray(sig**2),
                                 jnp.asarray(used))[0]

    for e in range(n_ep):
        st = step(st, jnp.asarray(zs[e]))
        x = np.concatenate([np.zeros(3), st.r, st.v, st.bg, st.ba, st.clk])
        np.testing.assert_allclose(x, xs_ref[e], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(np.asarray(st.P), ps_ref[e], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.asarray(st.q), [0, 0, 0, 1.0], atol=1e-15)


def test_block_transition_equals_dense_series():
    rng = np.random.default_rng(2)
    p = ekf.params_from_imu(imu.vn100(), 0.01, [0, 0, -9.8])
    q = rng.normal(size=4)
    ct = ekf.quat_to_dcm(jnp.asarray(q / np.linalg.norm(q))).T
    w = jnp.asarray(rng.normal(size=3) * 0.5)
    ca = ct @ ekf.skew(jnp.asarray(rng.normal(size=3) + [0, 0, 9.8]))
    phi, qd = ekf.transition_and_noise(w, ct, ca, p, 0.1)
    a = ekf.error_dynamics(w, ct, ca, p)
    np.testing.assert_allclose(phi, ekf.transition_matrix(a, 0.1), atol=1e-15)
    qd_dense = ekf.discrete_process_noise(a, ekf.continuous_noise(p), 0.1)
    np.testing.assert_allclose(qd, qd_dense, rtol=1e-12, atol=1e-24)
    # against the exact exponential: the Taylor remainder is bounded by |AT|^4 / 4! e^|AT|
    phi_ex, qd_ex = van_loan(np.asarray(a), np.diag(np.asarray(ekf.continuous_noise(p))), 0.1)
    nrm = np.linalg.norm(np.asarray(a) * 0.1, 2)
    assert np.abs(np.asarray(phi) - phi_ex).max() < nrm**4 / 24 * np.exp(nrm)
    np.testing.assert_allclose(np.asarray(qd)[15:, 15:], qd_ex[15:, 15:], rtol=1e-12)


def test_quaternion_conventions():
    rng = np.random.default_rng(3)
    q1, q2 = (jnp.asarray(v / np.linalg.norm(v)) for v in rng.normal(size=(2, 4)))
    np.testing.assert_allclose(ekf.quat_to_dcm(ekf.quat_multiply(q1, q2)),
                               ekf.quat_to_dcm(q1) @ ekf.quat_to_dcm(q2), atol=1e-14)
    c = np.asarray(ekf.quat_to_dcm(q1))
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(c) == pytest.approx(1.0)
    th = jnp.array([0.01, -0.02, 0.015])
    np.testing.assert_allclose(ekf.attitude_error(ekf.quat_multiply(ekf.error_quat(th), q1), q1),
                               th, atol=1e-6)
    # eq. 2 to first order: C(dq) = I - [theta x]
    np.testing.assert_allclose(ekf.quat_to_dcm(ekf.error_quat(th)),
                               np.eye(3) - np.asarray(ekf.skew(th)), atol=5e-4)


def test_pseudorange_jacobian_matches_autodiff():
    r = jnp.array([12.0, -40.0, 1.5])
    clk = jnp.array([3.0, 0.1])
    tx = jnp.array([[900.0, 1400.0, 25.0], [-1900.0, 600.0, 35.0], [300.0, -1500.0, 28.0]])
    tc = jnp.array([1.0, -2.0, 0.5])
    _, u = ekf.pseudorange_model(r, clk, tx, tc)
    h = np.asarray(ekf.jacobian_rows(u))
    jr = jax.jacfwd(lambda rr: ekf.pseudorange_model(rr, clk, tx, tc)[0])(r)
    jc = jax.jacfwd(lambda cc: ekf.pseudorange_model(r, cc, tx, tc)[0])(clk)
    np.testing.assert_allclose(h[:, 3:6], jr, atol=1e-14)
    np.testing.assert_allclose(h[:, 15:17], jc, atol=1e-14)
    assert np.all(h[:, :3] == 0) and np.all(h[:, 6:15] == 0)


def _random_state(rng):
    m = rng.normal(size=(17, 17))
    p = m @ m.T / 17 + np.eye(17) * 0.1
    return ekf.ekf_init([0, 0, 0, 1.0], [1.0, 2, 0], [5.0, 0, 0], np.zeros(3), np.zeros(3),
                        [0.5, 0.0], p)


def test_update_padding_and_joseph_form():
    rng = np.random.default_rng(4)
    st = _random_state(rng)
    u = rng.normal(size=(6, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    nu = rng.normal(size=6)
    rv = rng.uniform(1, 4, 6)
    used = np.array([True, True, False, True, True, True])
    s1, i1 = ekf.kalman_update(st, jnp.asarray(nu), jnp.asarray(u), jnp.asarray(rv),
                               jnp.asarray(used))
    keep = np.flatnonzero(used)
    s2, i2 = ekf.kalman_update(st, jnp.asarray(nu[keep]), jnp.asarray(u[keep]),
                               jnp.asarray(rv[keep]), jnp.ones(5, bool))
    for a, b in zip(s1, s2, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)
    assert float(i1.nis) == pytest.approx(float(i2.nis), rel=1e-12)
    # Joseph product form with the used rows, in NumPy
    p = np.asarray(st.P)
    h = np.asarray(ekf.jacobian_rows(jnp.asarray(u)))[keep]
    k = np.asarray(i2.K)
    ikh = np.eye(17) - k @ h
    np.testing.assert_allclose(s2.P, ikh @ p @ ikh.T + k @ np.diag(rv[keep]) @ k.T,
                               rtol=1e-10, atol=1e-13)


def test_small_inverses():
    rng = np.random.default_rng(5)
    m = rng.normal(size=(7, 7))
    s = m @ m.T + np.eye(7)
    np.testing.assert_allclose(ekf.spd_inverse(jnp.asarray(s)), np.linalg.inv(s), rtol=1e-10,
                               atol=1e-13)
    d = np.asarray(ekf.remove_from_inverse(jnp.asarray(np.linalg.inv(s)), 2))
    keep = [0, 1, 3, 4, 5, 6]
    np.testing.assert_allclose(d[np.ix_(keep, keep)], np.linalg.inv(s[np.ix_(keep, keep)]),
                               rtol=1e-10, atol=1e-13)
    np.testing.assert_array_equal(d[2], np.eye(7)[2])
    np.testing.assert_array_equal(ekf.remove_from_inverse(jnp.asarray(s), -1), s)


# ----------------------------------------------------------------------------------------
# RAIM pieces on hand cases


def test_tables_and_subset_nis():
    tab = ekf_raim.raim_tables(1e-5, 1e-3, 6)
    assert np.isinf(tab.threshold[0]) and np.isinf(tab.lambda_min[0])
    for d in (1, 5, 6):
        assert float(tab.threshold[d]) == pytest.approx(detection_threshold(1e-5, d))
        assert float(tab.lambda_min[d]) == pytest.approx(noncentrality(1e-5, 1e-3, d))
    rng = np.random.default_rng(6)
    m = rng.normal(size=(5, 5))
    s = m @ m.T + np.eye(5)
    nu = rng.normal(size=5)
    si = np.linalg.inv(s)
    valid = np.array([True] * 5)
    nis, dof, th, det = ekf_raim.nis_test(jnp.asarray(nu), jnp.asarray(si), jnp.asarray(valid),
                                          tab, 0)
    assert float(nis) == pytest.approx(nu @ si @ nu) and int(dof) == 5
    sub = np.asarray(ekf_raim.subset_nis(nis, jnp.asarray(nu), jnp.asarray(si),
                                         jnp.asarray(valid)))
    for i in range(5):
        k = [j for j in range(5) if j != i]
        assert sub[i] == pytest.approx(nu[k] @ np.linalg.inv(s[np.ix_(k, k)]) @ nu[k])
    # d = N_s - 4 with 5 towers: subsets have d = 0 and cannot pass (exclusion fails)
    idx, none = ekf_raim.select_exclusion(jnp.asarray(sub), jnp.asarray(1), jnp.asarray(valid),
                                          tab)
    assert int(idx) == -1 and bool(none)


def test_xi_recursion_and_hpl_against_numpy():
    """Xi on a tiny random case equals the direct response of the error recursion
    e(k+1) = (I - K H) Phi e(k) + K u to a constant bias u from the restart on; slopes and HPL
    follow seed 000 section III-B."""
    rng = np.random.default_rng(7)
    n_ep, l = 6, 4
    phis = [np.eye(17) + 0.05 * rng.normal(size=(17, 17)) for _ in range(n_ep)]
    ks = [0.1 * rng.normal(size=(17, l)) for _ in range(n_ep)]
    hs = [rng.normal(size=(l, 17)) for _ in range(n_ep)]
    xi = jnp.zeros((17, l))
    for e in range(n_ep):
        xi = ekf_raim.xi_recursion(xi, jnp.asarray(ks[e]), jnp.asarray(hs[e]),
                                   jnp.asarray(phis[e]), jnp.asarray(e == 0))
    bias = rng.normal(size=l)
    err = ks[0] @ bias
    for e in range(1, n_ep):
        err = (np.eye(17) - ks[e] @ hs[e]) @ phis[e] @ err + ks[e] @ bias
    np.testing.assert_allclose(np.asarray(xi) @ bias, err, rtol=1e-12, atol=1e-14)
    # restart resets to K
    xi_r = ekf_raim.xi_recursion(xi, jnp.asarray(ks[0]), jnp.asarray(hs[0]),
                                 jnp.asarray(phis[0]), jnp.asarray(True))
    np.testing.assert_array_equal(xi_r, ks[0])
    m = rng.normal(size=(l, l))
    si = np.linalg.inv(m @ m.T + np.eye(l))
    used = np.array([True, True, False, True])
    lam = 30.0
    slope, smax, hpl = ekf_raim.slopes_hpl(xi, jnp.asarray(si), jnp.asarray(used),
                                           jnp.asarray(lam))
    x = np.asarray(xi)
    ref = np.sqrt(x[3] ** 2 + x[4] ** 2) / np.sqrt(np.diag(si))
    ref[~used] = 0.0
    np.testing.assert_allclose(slope, ref, rtol=1e-12)
    assert float(hpl) == pytest.approx(ref.max() * np.sqrt(lam))
    _, _, hpl_inf = ekf_raim.slopes_hpl(xi, jnp.asarray(si), jnp.asarray(used),
                                        jnp.asarray(np.inf))
    assert np.isinf(float(hpl_inf))


# ----------------------------------------------------------------------------------------
# Monte Carlo over the synthetic seed 000 drive (one compilation serves all cases below)

N_RUNS = 64
DURATION_S = 30.0


@pytest.fixture(scope="module")
def drive():
    setup = sim.drive_setup(sim.drive_seed000(), duration_s=DURATION_S)
    keys = jax.random.split(jax.random.key(2024), N_RUNS)
    # the clean world (white 2 m noise, the filter told the truth's sigma): the consistency
    # checks below hold only there; the realistic world is tests/test_world.py's
    run = jax.jit(jax.vmap(lambda k, b, off: sim.simulate_drive(
        k, setup, errors.ErrorModel.clean(fault_bias_m=b, fault_onset_s=25.0), dof_offset=off,
        traces=True),
        in_axes=(0, None, None)))
    return setup, keys, run


@pytest.fixture(scope="module")
def fault_free(drive):
    _, keys, run = drive
    return run(keys, 0.0, 0)


def test_nis_nees_consistency(fault_free):
    """64 fault-free runs of the first 30 s of the drive, 5 towers, 10 Hz.

    Per epoch, the run-average of NIS is chi2(5 N) / N and of NEES chi2(17 N) / N exactly for a
    consistent linear-Gaussian filter, because the runs are independent; Bar-Shalom et al. (2001,
    section 5.4) expect ~95 % of the epochs inside the two-sided 95 % bounds: we require 85 % (NIS,
    300 epochs) and 90 % (NEES, 30 samples at 1 Hz). Innovations are also independent in time,
    so the grand mean of NIS over runs and epochs is chi2(5 N E) / (N E): it must lie inside its
    two-sided 95 % bounds."""
    _, tr = fault_free
    nis = np.asarray(tr.raim.nis[:, :, 0])
    nees = np.asarray(tr.nees[:, :, 0])
    n, e = nis.shape
    lo, hi = stats.chi2.ppf([0.025, 0.975], 5 * n) / n
    m = nis.mean(0)
    assert np.mean((m > lo) & (m < hi)) >= 0.85
    lo, hi = stats.chi2.ppf([0.025, 0.975], 5 * n * e) / (n * e)
    assert lo < nis.mean() < hi
    lo, hi = stats.chi2.ppf([0.025, 0.975], 17 * n) / n
    m = nees.mean(0)
    assert np.mean((m > lo) & (m < hi)) >= 0.9
    # no fault: both filters identical unless a (rare) false alarm excluded something
    assert np.all(np.isfinite(np.asarray(tr.raim.hpl_m)))


def test_fault_detected_and_tower1_excluded(drive, fault_free):
    _, keys, run = drive
    summ, tr = run(keys, 30.0, 0)
    t = np.asarray(tr.t_s[0])
    after = t >= 25.0
    det = np.asarray(tr.raim.detected[:, :, 1])
    exc = np.asarray(tr.raim.excluded[:, :, 1])
    # detected at the first epoch after the onset in every run, tower 1 (index 0) excluded
    np.testing.assert_allclose(np.asarray(summ.detection_time_s[:, 1]), t[after][0])
    assert np.mean(exc[:, after] == 0) > 0.99
    assert np.all(exc[:, ~after] <= 0) and np.mean(det[:, ~after]) < 1e-3
    # the filter without exclusion absorbs the bias; the one with exclusion does not
    err = np.asarray(tr.err_2d_m)
    assert err[:, after, 1].mean() < err[:, after, 0].mean() / 3
    assert np.all(np.asarray(tr.raim.status[:, after, 1]) == Status.OK)
    # fault-free runs give the same results for both filters outside false alarms
    _, ff = fault_free
    same = np.asarray(ff.raim.excluded[:, :, 1]) < 0
    assert np.mean(same) > 0.99


def test_dof_option_n_minus_4(drive):
    """d = N_s - 4 (seed 000's text): with 5 towers d = 1; detection works, the 4-tower subsets
    have d = 0 and cannot be tested, so exclusion fails (status) and nothing is excluded."""
    setup, keys, run = drive
    _, tr = run(keys[:N_RUNS], 30.0, 4)
    t = np.asarray(tr.t_s[0])
    after = t >= 25.0
    assert np.all(np.asarray(tr.raim.dof) == 1)
    np.testing.assert_allclose(np.asarray(tr.raim.threshold[0, 0, 0]),
                               detection_threshold(1e-5, 1))
    assert np.mean(np.asarray(tr.raim.detected[:, after, 1])) > 0.99
    assert np.all(np.asarray(tr.raim.excluded) == -1)
    st = np.asarray(tr.raim.status[:, after, 1])
    assert np.mean(st == Status.EXCLUSION_FAILED) > 0.99
    assert np.all(np.isfinite(np.asarray(tr.raim.hpl_m)))


def test_too_few_towers_gives_inf_and_status():
    """Two towers with d = N_s - 4 < 1: no threshold, HPL = inf, TOO_FEW_SOURCES, no NaN."""
    rng = np.random.default_rng(8)
    st = _random_state(rng)
    tab = ekf_raim.raim_tables(1e-5, 1e-3, 5)
    carry = ekf_raim.raim_init(st, 5)
    valid = jnp.array([True, True, False, False, False])
    tx = jnp.asarray(rng.normal(size=(5, 3)) * 1000)
    inputs = ekf.EkfInputs(None, None, jnp.full(5, 1500.0), valid, jnp.zeros(5), 2.0)
    _, out = ekf_raim.raim_update(carry, st, jnp.eye(17), inputs, tx,
                                  ekf_raim.RaimOptions(tab, 4, True, 30.0))
    assert np.isinf(float(out.hpl_m)) and np.isinf(float(out.threshold))
    assert int(out.status) == Status.TOO_FEW_SOURCES and not bool(out.detected)
    assert bool(out.alarm)
    assert not np.any(np.isnan(np.asarray(out.slopes)))
