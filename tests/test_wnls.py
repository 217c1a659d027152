"""Tests of araim.wnls: iterated weighted nonlinear least squares, seed 001 section 2.4.

Positions are compared in metres. Noise-free solves must land within 1e-6 m of the truth: the
pseudoranges are ~2e7 m, so float64 rounding alone is ~4e-9 m per range and Gauss-Newton
converges quadratically; 1e-6 m leaves a margin of ~100 over rounding and is still a thousand
times below any physically meaningful error. Compiled shapes are kept few: every batch is
(50, 12) or (2000, 12) sources, padded with ``valid``.
"""

import numpy as np
import pytest

from oaraim import araim
from oaraim.araim import Status
from oaraim.reference import wnls_reference

L = 12  # padded number of sources
B = 50  # epochs per small batch
RX_MDSCC = np.array([4849210.0, -360329.7, 4114920.0])  # seed 001 sec. 4.1, y corrected (DESIGN)
R_ORBIT = 6_371e3 + 20_200e3  # GPS altitude 20,200 km above a spherical Earth (radius 6371 km)


def _enu_basis(rx):
    """Local east, north, up unit vectors (geocentric) at an ECEF point."""
    lat = np.arctan2(rx[2], np.hypot(rx[0], rx[1]))
    lon = np.arctan2(rx[1], rx[0])
    east = np.array([-np.sin(lon), np.cos(lon), 0.0])
    north = np.array([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)])
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    return east, north, up


def _gps_sky(rng, shape, rx=RX_MDSCC, mask_deg=10.0):
    """ECEF satellite positions on the sphere of radius R_ORBIT seen from rx at random az/el."""
    az = rng.uniform(0.0, 2 * np.pi, shape)
    el = rng.uniform(np.deg2rad(mask_deg), 0.5 * np.pi, shape)
    e, n, u = _enu_basis(rx)
    los = (np.cos(el) * np.sin(az))[..., None] * e + (np.cos(el) * np.cos(az))[..., None] * n
    los = los + np.sin(el)[..., None] * u
    b = los @ rx  # |rx + t los| = R_ORBIT  =>  t^2 + 2 b t + |rx|^2 - R^2 = 0
    t = -b + np.sqrt(b**2 - (rx @ rx - R_ORBIT**2))
    return rx + t[..., None] * los


def _pseudoranges(rx, tx, clock_m):
    return np.linalg.norm(tx - np.asarray(rx)[..., None, :], axis=-1) + clock_m


def _no_nan(res):
    for name in res._fields:
        assert not np.any(np.isnan(np.asarray(getattr(res, name)))), name


# --------------------------------------------------------------------------- noise-free


def test_noise_free_gps_ecef_from_earth_centre():
    rng = np.random.default_rng(1)
    tx = _gps_sky(rng, (B, L))
    valid = np.arange(L) < 8  # 8 satellites, 4 padding rows
    clock = rng.uniform(-3e5, 3e5, B)  # up to 1 ms of receiver clock bias
    pr = _pseudoranges(RX_MDSCC, tx, clock[:, None])
    res = araim.wnls(pr, tx, 1.0, valid=valid)  # default x0: the Earth's centre, zero clock
    np.testing.assert_array_equal(res.status, Status.OK)
    np.testing.assert_array_equal(res.dof, 8 - 4)
    np.testing.assert_allclose(res.position_m, np.broadcast_to(RX_MDSCC, (B, 3)), rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.clock_m[:, 0], clock, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.residual_m, 0.0, rtol=0, atol=1e-6)
    assert np.all(np.asarray(res.last_step_m) < 1e-4)
    # the receiver really is at MDSCC, 40.4 N 4.25 W, on the Earth's surface
    assert np.linalg.norm(RX_MDSCC) == pytest.approx(6.37e6, rel=2e-3)


def test_noise_free_local_enu_towers_and_satellites():
    rng = np.random.default_rng(2)
    truth = np.column_stack([rng.uniform(-200, 200, (B, 2)), np.full(B, 1.5)])
    clock = rng.uniform(-1e3, 1e3, B)
    # 5 satellites: 2e7 m from the receiver along random lines of sight above 15 deg
    az = rng.uniform(0, 2 * np.pi, (B, 5))
    el = rng.uniform(np.deg2rad(15), 0.5 * np.pi, (B, 5))
    los = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)
    sats = truth[:, None, :] + 2e7 * los
    # 7 towers at 0 deg elevation (the receiver's height), uniform in area within 5 m .. 3 km
    d = np.sqrt(rng.uniform(5.0**2, 3000.0**2, (B, 7)))
    az_t = rng.uniform(0, 2 * np.pi, (B, 7))
    towers = truth[:, None, :] + np.stack([d * np.sin(az_t), d * np.cos(az_t), 0 * d], axis=-1)
    tx = np.concatenate([sats, towers], axis=1)
    pr = _pseudoranges(truth, tx, clock[:, None])
    res = araim.wnls(pr, tx, np.r_[[3.0] * 5, [1.5] * 7])
    np.testing.assert_array_equal(res.status, Status.OK)
    np.testing.assert_allclose(res.position_m, truth, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.clock_m[:, 0], clock, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(res.dof, L - 4)


# ------------------------------------------------------------------------------- noisy


@pytest.fixture(scope="module")
def noisy_epochs():
    rng = np.random.default_rng(3)
    tx = _gps_sky(rng, (B, L))
    n_valid = rng.integers(6, L + 1, B)
    valid = np.arange(L) < n_valid[:, None]
    sigma = rng.uniform(0.5, 5.0, (B, L))
    clock = rng.uniform(-3e5, 3e5, B)
    pr = _pseudoranges(RX_MDSCC, tx, clock[:, None]) + sigma * rng.standard_normal((B, L))
    return pr, tx, sigma, valid, araim.wnls(pr, tx, sigma, valid=valid)


def test_noisy_matches_reference(noisy_epochs):
    pr, tx, sigma, valid, res = noisy_epochs
    np.testing.assert_array_equal(res.status, Status.OK)
    for b in range(B):
        v = valid[b]
        ref = wnls_reference(pr[b][v], tx[b][v], sigma[b][v], np.zeros(4))
        np.testing.assert_allclose(res.position_m[b], ref[:3], rtol=0, atol=1e-6)
        np.testing.assert_allclose(res.clock_m[b, 0], ref[3], rtol=0, atol=1e-6)
        # covariance: (H^T W H)^-1 at the solution; 1e-9 relative (a 4x4 inverse of a matrix
        # with condition number ~1e3 at most for these skies)
        d = ref[:3] - tx[b][v]
        h = np.hstack([d / np.linalg.norm(d, axis=1)[:, None], np.ones((v.sum(), 1))])
        cov = np.linalg.inv(h.T @ (h / sigma[b][v, None] ** 2))
        np.testing.assert_allclose(res.covariance_m2[b], cov, rtol=1e-9, atol=1e-9 * cov.max())
    np.testing.assert_array_equal(res.dof, valid.sum(axis=1) - 4)


def test_residuals_and_wsse(noisy_epochs):
    pr, tx, sigma, valid, res = noisy_epochs
    x = np.asarray(res.position_m)
    predicted = _pseudoranges(x, tx, np.asarray(res.clock_m))
    resid = np.asarray(res.residual_m)
    np.testing.assert_allclose(resid[valid], (pr - predicted)[valid], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(resid[~valid], 0.0)
    # wsse = r^T W r with W = diag(1 / sigma^2) over the valid sources
    wsse = np.sum(np.where(valid, resid**2 / sigma**2, 0.0), axis=1)
    np.testing.assert_allclose(res.wsse, wsse, rtol=1e-12)
    assert np.all(np.asarray(res.wsse) > 0)


@pytest.mark.parametrize("heterogeneous", [False, True])
def test_wsse_is_chi_square(heterogeneous):
    """Mean WSSE over 2000 noisy epochs (9 sources, 1 clock) is dof = 9 - 4 = 5.

    Under H0 the WSSE of a linear(ised) WLS is chi-square with 5 dof: mean 5, variance 10. With
    satellites 2e7 m away and metre-level noise the linearisation error is ~1e-7 m, negligible.
    The mean of 2000 independent epochs has standard error sqrt(2 * 5 / 2000) = 0.071 and is
    normal to within a skewness of 0.03, so |mean - 5| < 3 SE fails for a correct solver with
    probability 0.27 % per seed; the seed is fixed, so the test is deterministic. A wrong
    weighting (1/sigma instead of 1/sigma^2, or no weights) moves the heterogeneous mean by
    far more than 3 SE; a wrong dof by 1 moves it by 14 SE.
    """
    n = 2000
    rng = np.random.default_rng(4 + heterogeneous)
    tx = _gps_sky(rng, (n, L))
    valid = np.zeros((n, L), bool)
    valid[:, :9] = True
    sigma = rng.uniform(0.3, 6.0, (n, L)) if heterogeneous else np.ones((n, L))
    pr = _pseudoranges(RX_MDSCC, tx, 100.0) + sigma * rng.standard_normal((n, L))
    res = araim.wnls(pr, tx, sigma, valid=valid)
    np.testing.assert_array_equal(res.status, Status.OK)
    np.testing.assert_array_equal(res.dof, 5)
    se = np.sqrt(2 * 5 / n)
    assert abs(float(np.mean(res.wsse)) - 5.0) < 3 * se, float(np.mean(res.wsse))


# ------------------------------------------------------------------------------ clocks


def _two_constellations(rng):
    """7 sources on clock 0 (GPS) and 5 on clock 1 (Galileo), distinct biases."""
    tx = _gps_sky(rng, (B, L))
    clock_index = np.r_[[0] * 7, [1] * 5]
    clocks = np.column_stack([rng.uniform(-3e5, 3e5, B), rng.uniform(-3e5, 3e5, B)])
    pr = _pseudoranges(RX_MDSCC, tx, np.take_along_axis(clocks, np.tile(clock_index, (B, 1)), 1))
    return tx, clock_index, clocks, pr


def test_two_clock_groups_recovered():
    tx, clock_index, clocks, pr = _two_constellations(np.random.default_rng(5))
    res = araim.wnls(pr, tx, 1.0, clock_index=clock_index, options=araim.WNLSOptions(n_clocks=2))
    np.testing.assert_array_equal(res.status, Status.OK)
    assert res.clock_m.shape == (B, 2)
    assert res.covariance_m2.shape == (B, 5, 5)
    np.testing.assert_allclose(res.position_m, np.broadcast_to(RX_MDSCC, (B, 3)), rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.clock_m, clocks, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(res.dof, L - 5)


def test_clock_group_without_valid_source():
    """A constellation with no valid source loses its clock column (DESIGN.md): its clock stays
    at the initial value, the solve is not singular and the dof counts one clock."""
    tx, clock_index, clocks, pr = _two_constellations(np.random.default_rng(6))
    valid = clock_index == 0  # every clock-1 source invalid
    res = araim.wnls(pr, tx, 1.0, valid=valid, clock_index=clock_index,
                     options=araim.WNLSOptions(n_clocks=2))
    np.testing.assert_array_equal(res.status, Status.OK)
    np.testing.assert_allclose(res.position_m, np.broadcast_to(RX_MDSCC, (B, 3)), rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.clock_m[:, 0], clocks[:, 0], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(res.clock_m[:, 1], 0.0)
    np.testing.assert_array_equal(res.dof, 7 - 4)
    assert np.all(np.isfinite(np.asarray(res.covariance_m2)[:, :4, :4]))
    # with an explicit initial clock for the empty group, that value is kept
    x0 = np.r_[0.0, 0.0, 0.0, 0.0, 77.0]
    res2 = araim.wnls(pr, tx, 1.0, x0, valid, clock_index, araim.WNLSOptions(n_clocks=2))
    np.testing.assert_array_equal(res2.status, Status.OK)
    np.testing.assert_array_equal(res2.clock_m[:, 1], 77.0)
    np.testing.assert_allclose(res2.position_m, res.position_m, rtol=0, atol=1e-6)
    # all sources on clock 0 (group 1 simply unused) behaves the same way
    res3 = araim.wnls(pr, tx, 1.0, valid=valid, clock_index=np.zeros(L, int),
                      options=araim.WNLSOptions(n_clocks=2))
    np.testing.assert_array_equal(res3.status, Status.OK)
    np.testing.assert_allclose(res3.position_m, res.position_m, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(res3.clock_m[:, 1], 0.0)


# ---------------------------------------------------------------------------- padding


def _padded(rng, junk_tx, junk_pr, junk_sigma):
    """8 real sources per epoch scattered among 12 rows; junk in the other 4."""
    n_real = 8
    tx = _gps_sky(rng, (B, n_real))
    sigma = rng.uniform(0.5, 5.0, (B, n_real))
    pr = _pseudoranges(RX_MDSCC, tx, 50.0) + sigma * rng.standard_normal((B, n_real))
    perm = np.argsort(rng.random((B, L)), axis=1)
    pos = np.sort(perm[:, :n_real], axis=1)  # where the real sources go, order kept
    valid = np.zeros((B, L), bool)
    np.put_along_axis(valid, pos, True, 1)
    tx_p, pr_p, sigma_p = np.empty((B, L, 3)), np.empty((B, L)), np.empty((B, L))
    tx_p[~valid], pr_p[~valid], sigma_p[~valid] = junk_tx, junk_pr, junk_sigma
    tx_p[valid], pr_p[valid], sigma_p[valid] = tx.reshape(-1, 3), pr.ravel(), sigma.ravel()
    return (pr, tx, sigma), (pr_p, tx_p, sigma_p, valid), pos


def _assert_padding_invariant(base, padded, pos):
    np.testing.assert_array_equal(padded.status, base.status)
    np.testing.assert_array_equal(padded.dof, base.dof)
    # metres: 1e-6 m, far above the ~1e-9 m rounding of a different summation order
    np.testing.assert_allclose(padded.position_m, base.position_m, rtol=0, atol=1e-6)
    np.testing.assert_allclose(padded.clock_m, base.clock_m, rtol=0, atol=1e-6)
    np.testing.assert_allclose(
        np.take_along_axis(np.asarray(padded.residual_m), pos, 1), base.residual_m, atol=1e-6
    )
    # residuals are differences of ~2e7 m numbers, each known to ~1e-8 m: WSSE (~1..20) agrees
    # to ~1e-8 relative
    np.testing.assert_allclose(padded.wsse, base.wsse, rtol=1e-6)
    np.testing.assert_allclose(padded.covariance_m2, base.covariance_m2, rtol=1e-9)


def test_padding_invariance_finite_junk():
    rng = np.random.default_rng(7)
    junk_tx = rng.uniform(-3e7, 3e7, (B * 4, 3))
    junk_tx[::5] = 0.0  # a transmitter at the frame origin (the initial guess): zero range
    junk_tx[1::5] = RX_MDSCC  # a transmitter at the receiver itself
    junk_sigma = rng.choice([0.0, -1.0, np.nan, np.inf, 1e-300], B * 4)  # sigma is ignored
    (pr, tx, sigma), (pr_p, tx_p, sigma_p, valid), pos = _padded(
        rng, junk_tx, rng.uniform(-1e8, 1e8, B * 4), junk_sigma
    )
    base = araim.wnls(pr, tx, sigma)
    padded = araim.wnls(pr_p, tx_p, sigma_p, valid=valid)
    np.testing.assert_array_equal(base.status, Status.OK)
    _assert_padding_invariant(base, padded, pos)
    np.testing.assert_array_equal(np.asarray(padded.residual_m)[~valid], 0.0)


@pytest.mark.parametrize("nan_in", ["tx", "pr", "both"])
def test_padding_invariance_nan_junk(nan_in):
    rng = np.random.default_rng(8)
    junk_tx = np.nan if nan_in in ("tx", "both") else 1e7
    junk_pr = np.nan if nan_in in ("pr", "both") else 2e7
    (pr, tx, sigma), (pr_p, tx_p, sigma_p, valid), pos = _padded(rng, junk_tx, junk_pr, 1.0)
    base = araim.wnls(pr, tx, sigma)
    padded = araim.wnls(pr_p, tx_p, sigma_p, valid=valid)
    _no_nan(padded)
    _assert_padding_invariant(base, padded, pos)


# --------------------------------------------------------------------- failures as data


def test_failures_are_data():
    rng = np.random.default_rng(9)
    tx = _gps_sky(rng, (B, L))
    pr = _pseudoranges(RX_MDSCC, tx, 10.0) + rng.standard_normal((B, L))
    valid = np.ones((B, L), bool)
    expected = np.full(B, Status.OK)
    valid[0:5, 3:] = False  # 3 sources for 4 states
    expected[0:5] = Status.TOO_FEW_SOURCES
    valid[5:8] = False  # nothing valid at all
    expected[5:8] = Status.TOO_FEW_SOURCES
    tx[8:14] = tx[8:14, :1]  # every transmitter at the same point: rank-1 normal matrix
    expected[8:14] = Status.SINGULAR_GEOMETRY
    valid[14:17, 4:] = False  # exactly 4 sources: a solution, no redundancy (dof 0), still OK
    res = araim.wnls(pr, tx, 1.0, valid=valid)
    _no_nan(res)
    np.testing.assert_array_equal(res.status, expected)
    assert np.all(np.isfinite(np.asarray(res.position_m)))
    assert np.all(np.isfinite(np.asarray(res.clock_m)))
    # dof = n_valid - 3 - (clock groups in use): with nothing valid no clock is in use
    n_valid = valid.sum(axis=1)
    np.testing.assert_array_equal(res.dof, n_valid - 3 - (n_valid > 0))
    singular = expected == Status.SINGULAR_GEOMETRY
    assert np.all(np.asarray(res.covariance_m2)[singular] == np.inf)
    # good epochs, including the dof-0 ones, are unaffected by their neighbours
    good = expected == Status.OK
    for b in np.flatnonzero(good):
        v = valid[b]
        ref = wnls_reference(pr[b][v], tx[b][v], 1.0, np.zeros(4))
        np.testing.assert_allclose(res.position_m[b], ref[:3], rtol=0, atol=1e-6)
    # the exactly-determined epochs fit their pseudoranges exactly
    np.testing.assert_allclose(res.wsse[14:17], 0.0, atol=1e-10)


def test_not_converged_with_one_iteration():
    rng = np.random.default_rng(10)
    tx = _gps_sky(rng, (B, L))
    pr = _pseudoranges(RX_MDSCC, tx, 1234.0)
    x0 = np.zeros((B, 4))  # the Earth's centre: 6400 km from the receiver
    x0[B // 2 :] = np.r_[RX_MDSCC, 1234.0]  # the exact solution: the step is zero
    res = araim.wnls(pr, tx, 1.0, x0, options=araim.WNLSOptions(n_iter=1))
    _no_nan(res)
    np.testing.assert_array_equal(res.status[: B // 2], Status.NOT_CONVERGED)
    assert np.all(np.asarray(res.last_step_m)[: B // 2] > 1e3)
    np.testing.assert_array_equal(res.status[B // 2 :], Status.OK)
    np.testing.assert_allclose(res.position_m[B // 2 :], x0[B // 2 :, :3], rtol=0, atol=1e-6)
    # the same epochs with the default 10 iterations converge
    res10 = araim.wnls(pr, tx, 1.0, x0)
    np.testing.assert_array_equal(res10.status, Status.OK)


# ------------------------------------------------------------------------- bad user input


@pytest.mark.parametrize("bad", [0.0, -1.0, np.nan, np.inf])
def test_bad_sigma_raises_naming_sigma(bad):
    rng = np.random.default_rng(11)
    tx = _gps_sky(rng, (B, L))
    pr = _pseudoranges(RX_MDSCC, tx, 0.0)
    sigma = np.ones((B, L))
    sigma[3, 5] = bad
    with pytest.raises(ValueError, match="sigma_m"):
        araim.wnls(pr, tx, sigma)
