"""Scenario synthesis: trajectories, IMU error model, clocks (sim.trajectory, errors.imu)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import expm

from oaraim import geometry
from oaraim.araim import ekf
from oaraim.constants import C_M_S
from oaraim.errors import imu
from oaraim.geometry import clocks
from oaraim.sim import measurement, trajectory


@pytest.fixture(scope="module")
def scenarios():
    return {name: f() for name, f in trajectory.SCENARIOS.items()}


def test_scenarios_match_the_seeds(scenarios):
    s0, s2, s4 = scenarios["seed000-drive"], scenarios["seed002-drive"], scenarios["seed004-uav"]
    assert s0.traj.length_m == pytest.approx(1350.0, abs=0.5)       # seed 000 abstract
    assert s2.traj.length_m == pytest.approx(1400.0, abs=0.5)       # seed 002 poster
    assert s4.traj.length_m == pytest.approx(815.0, abs=0.5)        # seed 004 section VII-A
    assert float(s4.traj.t_s[-1]) == pytest.approx(220.0, abs=0.01)
    assert [s.towers_enu_m.shape[0] for s in (s0, s2, s4)] == [5, 5, 11]
    assert (s0.fault_onset_s, s2.fault_onset_s, s0.fault_tower) == (25.0, 95.0, 0)
    assert float(s2.traj.t_s[-1]) > 95.0
    for s in (s0, s2, s4):
        assert s.traj.gyro_rad_s.shape[0] == s.traj.t_s.shape[0] - 1
        assert np.all(np.isfinite(np.asarray(s.traj.accel_m_s2)))


def test_normal_gravity_somigliana():
    # NIMA TR8350.2: 9.7803253359 at the equator, 9.8321849378 at the poles
    assert geometry.normal_gravity_mps2(0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert geometry.normal_gravity_mps2(np.pi / 2) == pytest.approx(9.8321849378, abs=1e-9)


def test_level_body_frame(scenarios):
    tr = scenarios["seed000-drive"].traj
    c = np.asarray(ekf.quat_to_dcm(tr.quat))           # G -> body
    v_body = np.einsum("kij,kj->ki", c, np.asarray(tr.vel_m_s))
    moving = np.linalg.norm(np.asarray(tr.vel_m_s), axis=-1) > 0.5
    # the velocity is along body x (front), nothing along y (left) or z (up)
    assert np.abs(v_body[moving, 1:]).max() < 1e-9
    assert np.all(v_body[moving, 0] > 0)
    # on flat ground the mean specific force along body z is g exactly
    g = scenarios["seed000-drive"].notes["gravity_m_s2"]
    np.testing.assert_allclose(np.asarray(tr.accel_m_s2[:, 2]), g, atol=1e-12)
    # a left turn (positive yaw rate) has a positive (leftward) lateral specific force
    left = np.asarray(tr.gyro_rad_s[:, 2]) > 0.1
    assert np.all(np.asarray(tr.accel_m_s2[left, 1]) > 0)


@pytest.mark.parametrize("name", ["seed000-drive", "seed004-uav"])
def test_kinematics_integrate_back(scenarios, name):
    """Strapdown integration of the ideal IMU (specific force + gravity, body rates) from the
    true initial state reproduces the truth: position within 1 cm over the whole route (the
    mechanization's midpoint-attitude and trapezoid errors are O(dt^2); measured 0.35 mm for the
    drive)."""
    s = scenarios[name]
    tr = s.traj
    p = ekf.params_from_imu(imu.vn100(), 0.01, tr.gravity_m_s2)

    @jax.jit
    def run(g, a):
        def body(nom, ga):
            new, _ = ekf.mechanize(*nom, ga[0], ga[1], p)
            return new, new[1]
        nom0 = (tr.quat[0], tr.pos_m[0], tr.vel_m_s[0], jnp.zeros(3), jnp.zeros(3))
        return jax.lax.scan(body, nom0, (g, a))

    (q, r, v, _, _), pos = run(tr.gyro_rad_s, tr.accel_m_s2)
    err = np.linalg.norm(np.asarray(pos) - np.asarray(tr.pos_m[1:]), axis=-1)
    assert err.max() < 0.01
    assert np.linalg.norm(np.asarray(v - tr.vel_m_s[-1])) < 1e-4
    assert np.abs(np.asarray(ekf.attitude_error(tr.quat[-1], q))).max() < 1e-9


def test_imu_white_noise_statistics():
    """Per-sample sigma = density / sqrt(dt); the sample std of n draws has relative standard
    error 1 / sqrt(2 n): with n = 3 x 40000 per sensor, 5 sigma is 1.3 %."""
    spec = imu.vn100()._replace(gyro_bias_sigma_rad_s=0.0, accel_bias_sigma_m_s2=0.0)
    n, dt = 40000, 0.01
    zeros = jnp.zeros((n, 3))
    gm, am, _, _ = imu.simulate_imu(jax.random.key(3), zeros, zeros, spec, dt)
    tol = 5.0 / np.sqrt(2 * 3 * n)
    assert np.std(np.asarray(gm)) == pytest.approx(imu.VN100_GYRO_NOISE / np.sqrt(dt), rel=tol)
    assert np.std(np.asarray(am)) == pytest.approx(imu.VN100_ACCEL_NOISE / np.sqrt(dt), rel=tol)
    assert abs(np.mean(np.asarray(gm))) < 5 * imu.VN100_GYRO_NOISE / np.sqrt(dt) / np.sqrt(3 * n)


def test_gauss_markov_bias_statistics():
    """Stationary variance and lag correlation exp(-dt/tau) of the GM bias, over 2000 independent
    runs of 100 steps with tau = 0.5 s (tolerances ~5 standard errors)."""
    spec = imu.ImuSpec(0.0, 0.0, 1e-3, 2e-2, 0.5, 0.5)
    zeros = jnp.zeros((100, 3))
    keys = jax.random.split(jax.random.key(5), 2000)
    _, _, bg, ba = jax.vmap(lambda k: imu.simulate_imu(k, zeros, zeros, spec, 0.01))(keys)
    bg, ba = np.asarray(bg), np.asarray(ba)
    n = bg.shape[0] * 3
    assert np.std(bg[:, -1]) == pytest.approx(1e-3, rel=5 / np.sqrt(2 * n))
    assert np.std(ba[:, -1]) == pytest.approx(2e-2, rel=5 / np.sqrt(2 * n))
    rho = np.mean(bg[:, -1] * bg[:, -51]) / np.mean(bg[:, -1] ** 2)
    assert rho == pytest.approx(np.exp(-0.5 / 0.5), abs=5 / np.sqrt(n))


def test_gm_allan_peak_is_the_datasheet_bias_instability():
    """The GM sigma is chosen so that its Allan-deviation peak is the in-run bias stability:
    check the closed form peak and an overlapping Allan deviation of a simulated series
    (tau = 1 s, 2000 s of data: ~1000 clusters at the peak, ~5 % estimator spread)."""
    tau = 1.0
    sigma = imu.gm_sigma_from_bias_instability(1.0, tau)
    grid = np.logspace(-1, 2, 3001)
    assert imu.gm_allan_deviation(sigma, tau, grid).max() == pytest.approx(1.0, rel=1e-6)
    n, dt = 200_000, 0.01
    _, _, b, _ = imu.simulate_imu(jax.random.key(7), jnp.zeros((n, 3)), jnp.zeros((n, 3)),
                                  imu.ImuSpec(0.0, 0.0, sigma, 1.0, tau, tau), dt,
                                  bg0=jnp.zeros(3))
    x = np.asarray(b)[:, 0]
    m = int(round(1.89 * tau / dt))
    c = np.concatenate([[0.0], np.cumsum(x)])
    avg = (c[m:] - c[:-m]) / m
    adev = np.sqrt(0.5 * np.mean((avg[m:] - avg[:-m]) ** 2))
    assert adev == pytest.approx(1.0, rel=0.15)


def test_vn100_datasheet_values():
    spec = imu.vn100()
    assert spec.gyro_noise_rad_s_sqrt_hz == pytest.approx(0.0035 * np.pi / 180)
    assert spec.accel_noise_m_s2_sqrt_hz == pytest.approx(0.14e-3 * 9.80665)
    peak_g = imu.gm_allan_deviation(spec.gyro_bias_sigma_rad_s, spec.gyro_bias_tau_s,
                                    np.logspace(0, 4, 4001)).max()
    assert peak_g == pytest.approx(10 * np.pi / 180 / 3600, rel=1e-4)


def test_qclk_closed_form_and_van_loan():
    """Seed 000 eq. 1 with the symmetric off-diagonal (DESIGN.md), against Van Loan's method."""
    t = 0.1
    q = np.asarray(clocks.clock_process_noise(t))
    s0, s1 = clocks.S_WDT_OCXO_S, clocks.S_WDTDOT_OCXO_PER_S
    c2 = C_M_S**2
    expect = c2 * np.array([[s0 * t + s1 * t**3 / 3, s1 * t**2 / 2], [s1 * t**2 / 2, s1 * t]])
    np.testing.assert_allclose(q, expect, rtol=1e-14)
    assert q[0, 1] == q[1, 0]
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    qc = np.diag([c2 * s0, c2 * s1])
    vl = expm(np.block([[-a, qc], [np.zeros((2, 2)), a.T]]) * t)
    np.testing.assert_allclose(vl[2:, 2:].T @ vl[:2, 2:], expect, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(clocks.clock_transition(t)), [[1, t], [0, 1]])


def test_clock_step_covariance():
    """One exact step from zero over 20000 runs: sample covariance = Q_clk (5 standard errors)."""
    t = 0.1
    keys = jax.random.split(jax.random.key(11), 20000)
    x = np.asarray(jax.vmap(lambda k: clocks.clock_step(k, jnp.zeros(2), t))(keys))
    q = np.asarray(clocks.clock_process_noise(t))
    cov = np.cov(x.T)
    tol = 5 / np.sqrt(20000 / 2)
    assert cov[0, 0] == pytest.approx(q[0, 0], rel=tol)
    assert cov[1, 1] == pytest.approx(q[1, 1], rel=tol)
    rho = q[0, 1] / np.sqrt(q[0, 0] * q[1, 1])
    assert cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]) == pytest.approx(rho, abs=5 / np.sqrt(20000))


def test_tower_clock_polynomial_and_fault():
    c = np.asarray(clocks.tower_clock_m(2.0, jnp.array([1e-6, -2e-6]), jnp.array([1e-8, 0.0])))
    np.testing.assert_allclose(c, C_M_S * np.array([1e-6 + 2e-8, -2e-6]))
    f = np.asarray(measurement.fault_bias_m(jnp.array([24.9, 25.0]), 25.0, 30.0, 0, 3))
    np.testing.assert_array_equal(f, [[0, 0, 0], [30, 0, 0]])
