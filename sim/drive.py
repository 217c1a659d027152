"""Monte Carlo drives: one simulated run of a ``sim.trajectory`` scenario through the
receiver's EKF-RAIM (seed 000 sections II-IV, seed 002).

``simulate_drive`` draws one run of the world (``sim.measurement.calibrate``: the GNSS period,
then ``sim.measurement.drive_epoch``: IMU noise and GM biases, receiver clock, the SOP errors of
the ``ErrorModel``, pseudoranges and the injected fault, from ``fold_in(key, epoch)``) inside a
``lax.scan`` over pseudorange epochs, so nothing of size runs x epochs is stored, feeds each
epoch to the receiver (``araim.ekf_raim.raim_update``, without and with exclusion side by side)
and returns per-run summaries; ``monte_carlo_drive`` vmaps it over runs.
"""

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from oaraim.araim import RaimConfig, RaimOptions
from oaraim.araim import ekf as _ekf
from oaraim.araim.ekf_raim import (
    InitialUncertainty,
    RaimEpoch,
    RaimTables,
    initial_covariance,
    raim_init,
    raim_tables,
    raim_update,
)
from oaraim.errors import ErrorModel, imu
from oaraim.geometry import clocks
from oaraim.sim import trajectory
from oaraim.sim.measurement import (
    EpochTowers,
    EpochTruth,
    ReceiverSensors,
    WorldState,
    calibrate,
    drive_epoch,
)


class DriveSummary(NamedTuple):
    """Per-run summaries; arrays of shape (2,) are [without exclusion, with exclusion].

    Times in s (inf: never); counts are integers; NEES/NIS are means over the epochs of the run
    (NIS over the valid towers before exclusion; ``nis_dof_mean`` its mean d = N_s);
    ``n_misleading`` counts the epochs with 2D error > HPL (misleading information);
    ``filter_sigma_m`` is the pseudorange sigma the filter used (the run's empirical estimate,
    or the one given), the same for both filters."""

    rmse_2d_m: jnp.ndarray
    max_2d_m: jnp.ndarray
    detection_time_s: jnp.ndarray
    n_false_alarms: jnp.ndarray
    n_detections_after_onset: jnp.ndarray
    n_correct_exclusions: jnp.ndarray
    n_wrong_exclusions: jnp.ndarray
    nees_mean: jnp.ndarray
    nis_mean: jnp.ndarray
    nis_dof_mean: jnp.ndarray
    hpl_max_m: jnp.ndarray
    n_alarms: jnp.ndarray
    n_misleading: jnp.ndarray
    filter_sigma_m: jnp.ndarray


class DriveTrace(NamedTuple):
    """Per-epoch traces of one run (for tests and plots), each (E, 2, ...); ``nees`` is
    (E / nees_every, 2), at the last epoch of each block."""

    t_s: jnp.ndarray
    err_2d_m: jnp.ndarray
    nees: jnp.ndarray
    raim: RaimEpoch


class DriveSetup(NamedTuple):
    """Everything static for a drive: truth arrays reshaped per epoch, the receiver's model
    (EKF parameters, initial covariance P0, RAIM tables) and the IMU spec of the world."""

    gyro: jnp.ndarray       # (E, n, 3) ideal interval-mean body rates
    accel: jnp.ndarray      # (E, n, 3)
    pos: jnp.ndarray        # (E + 1, 3) truth at epoch boundaries (index 0 = start)
    vel: jnp.ndarray
    quat: jnp.ndarray
    t_s: jnp.ndarray        # (E,) epoch times
    tower_clk_m: jnp.ndarray  # (E, L)
    towers: jnp.ndarray
    params: _ekf.EkfParams
    spec: imu.ImuSpec
    P0: jnp.ndarray
    tables: RaimTables
    operator: jnp.ndarray     # (L,) each tower's operator 0..L-1 (its common clock term)
    calib_t_s: jnp.ndarray    # (n_cal,) epochs of the GNSS period, the last at t = 0

    def sensors(self) -> ReceiverSensors:
        """The world's IMU (``spec``, the IMU step) and receiver clock PSDs, those of the
        receiver's model ``params``: what ``sim.measurement.drive_epoch`` draws from."""
        p = self.params
        return ReceiverSensors(self.spec, p.dt_s, p.s_wdt_s, p.s_wdtdot_per_s)


def drive_setup(scenario: trajectory.Scenario, spec: imu.ImuSpec | None = None,
                init: InitialUncertainty | None = None, cfg: RaimConfig | None = None,
                duration_s: float | None = None, operator=None,
                calib_s: float = 300.0, calib_rate_hz: float = 1.0) -> DriveSetup:
    """Host-side preparation of ``simulate_drive`` (optionally truncated to ``duration_s``):
    the scenario's truth cut into pseudorange epochs, the tower clocks at the epochs, the EKF
    parameters of ``spec`` (default VN-100), P0 of ``init``, the RAIM tables of ``cfg``, the
    towers' operators (default: one operator, seed 000's AT&T) and the longest GNSS period
    ``calib_s`` an ``ErrorModel.calib_window_s`` may use, sampled at ``calib_rate_hz`` (its
    epochs are simulated in every run: 300 at the defaults)."""
    spec = imu.vn100() if spec is None else spec
    init = InitialUncertainty() if init is None else init
    cfg = RaimConfig() if cfg is None else cfg
    tr = scenario.traj
    dt = float(tr.t_s[1] - tr.t_s[0])
    n = int(round(1.0 / (scenario.meas_rate_hz * dt)))
    e = tr.gyro_rad_s.shape[0] // n
    if duration_s is not None:
        e = min(e, int(round(duration_s * scenario.meas_rate_hz)))
    k = e * n
    t_ep = tr.t_s[n:k + 1:n]
    l = scenario.towers_enu_m.shape[0]
    return DriveSetup(
        gyro=tr.gyro_rad_s[:k].reshape(e, n, 3), accel=tr.accel_m_s2[:k].reshape(e, n, 3),
        pos=tr.pos_m[:k + 1:n], vel=tr.vel_m_s[:k + 1:n], quat=tr.quat[:k + 1:n], t_s=t_ep,
        tower_clk_m=clocks.tower_clock_m(t_ep[:, None], scenario.tower_clk_bias0_s,
                                         scenario.tower_clk_drift),
        towers=scenario.towers_enu_m,
        params=_ekf.params_from_imu(spec, dt, tr.gravity_m_s2),
        spec=spec, P0=initial_covariance(spec, init),
        tables=raim_tables(cfg.p_fa, cfg.p_md, l),
        operator=jnp.zeros(l, int) if operator is None else jnp.asarray(operator, int),
        calib_t_s=-jnp.arange(max(int(round(calib_s * calib_rate_hz)), 2))[::-1]
        / calib_rate_hz)


def nees_of_state(state: _ekf.EkfState, q, r, v, bg, ba, clk):
    """Normalized estimation error squared of an EKF state against the truth (attitude
    quaternion ``q``, position ``r``, velocity ``v``, IMU biases, clock [c dt, c dt'])."""
    e = jnp.concatenate([_ekf.attitude_error(q, state.q), r - state.r, v - state.v,
                         bg - state.bg, ba - state.ba, clk - state.clk])
    chol = jnp.linalg.cholesky(state.P)
    y = jax.scipy.linalg.solve_triangular(chol, e, lower=True)
    return y @ y


class InitialDraw(NamedTuple):
    """The draws of a run's start: the key of the per-epoch draws, the world's initial error
    state (``WorldState``, after the GNSS period), the receiver's initial estimate (JPL
    quaternion (4,), position and velocity (3,) ENU), which is the truth minus an error drawn
    from N(0, P0), and the pseudorange sigma the receiver estimated from the GNSS period's
    fault-free data (nan when the world has no calibration window)."""

    epoch_key: jnp.ndarray
    world: WorldState
    quat_est: jnp.ndarray
    pos_est_m: jnp.ndarray
    vel_est_m_s: jnp.ndarray
    sigma_empirical_m: jnp.ndarray


def initial_draw(key, setup: DriveSetup, err: ErrorModel | None = None) -> InitialDraw:
    """Split a run's key into (initial error, initial IMU biases, per-epoch draws), draw the
    initial estimate error ~ N(0, P0) (its clock part is the true receiver clock: the filter
    starts at 0), the stationary IMU biases and the GNSS period of ``err`` (default the
    realistic world; ``sim.measurement.calibrate``: the SOP errors at t = 0, the receiver's
    tower-clock fit and its empirical sigma). Shared by ``simulate_drive`` and
    ``sim.recordings.synthesize_recording``, so a synthesized recording is that run."""
    err = ErrorModel() if err is None else err
    k_init, k_bias, k_scan = jax.random.split(key, 3)
    d0 = jnp.sqrt(jnp.diagonal(setup.P0)) * jax.random.normal(k_init, (_ekf.N_ERR,))
    bg0, ba0 = imu.initial_biases(k_bias, setup.spec)
    q_est0 = _ekf.quat_multiply(_ekf.error_quat(-d0[_ekf.TH]), setup.quat[0])
    n_t = setup.towers.shape[0]
    world = WorldState(bg0, ba0, d0[_ekf.CLK], jnp.zeros(n_t), jnp.zeros(n_t), jnp.zeros(n_t),
                       jnp.zeros((n_t, 2)), jnp.zeros((n_t, 2)))
    world, sig = calibrate(key, world, err, setup.operator, setup.calib_t_s)
    return InitialDraw(k_scan, world, q_est0, setup.pos[0] - d0[_ekf.POS],
                       setup.vel[0] - d0[_ekf.VEL], sig)


def filter_sigma(d: InitialDraw, err: ErrorModel, filter_sigma_pr_m=0.0):
    """The pseudorange sigma the receiver's filter uses: ``filter_sigma_pr_m`` when > 0, else
    the run's empirical estimate from the GNSS period (seed 000 IV-A: "determined
    empirically"), else, in a world without calibration window (``ErrorModel.clean()``), the
    truth's ``sigma_pr_m`` (the pre-issue-25 behaviour: the filter is told the truth)."""
    emp = jnp.where(jnp.isfinite(d.sigma_empirical_m), d.sigma_empirical_m, err.sigma_pr_m)
    return jnp.where(filter_sigma_pr_m > 0, filter_sigma_pr_m, emp)


@partial(jax.jit, static_argnames=("traces", "nees_every"))
def simulate_drive(key, setup: DriveSetup, err: ErrorModel | None = None, filter_sigma_pr_m=0.0,
                   hal_m=30.0, dof_offset=0, traces=False, nees_every=10):
    """One Monte Carlo run of a drive in the error world ``err`` (default ``ErrorModel()``, the
    realistic world; ``ErrorModel.clean()`` the white-noise one); returns ``DriveSummary``
    (and ``DriveTrace`` if ``traces``). vmap over ``key`` for many runs
    (``monte_carlo_drive``). Every numeric argument and every field of ``err`` is traced (one
    compilation serves fault-free and faulty runs, both d options, any world). The filter's
    pseudorange sigma is ``filter_sigma`` (empirical unless ``filter_sigma_pr_m`` > 0).

    The run covers the whole epochs of the setup rounded down to a multiple of ``nees_every``;
    NEES (a 17 x 17 Cholesky solve, the costliest single step) is evaluated at the last epoch of
    each block of ``nees_every`` epochs (1 Hz at the default 10 Hz pseudorange rate); every other
    quantity at every epoch."""
    err = ErrorModel() if err is None else err
    fault_tower, fault_onset_s = err.fault_tower, err.fault_onset_s
    p = setup.params
    n_t = setup.towers.shape[0]
    d = initial_draw(key, setup, err)
    sigma_f = filter_sigma(d, err, filter_sigma_pr_m)
    est0 = _ekf.ekf_init(d.quat_est, d.pos_est_m, d.vel_est_m_s, jnp.zeros(3), jnp.zeros(3),
                         jnp.zeros(2), setup.P0)
    carry_f = raim_init(est0, n_t)
    carry_f = jax.tree.map(lambda x: jnp.stack([x, x]), carry_f)
    exclude = jnp.array([False, True])

    def body(c, inp):
        world, filt = c
        e, g_true, a_true, t_e, pos_e, vel_e, q_e, tclk = inp
        world, m = drive_epoch(jax.random.fold_in(d.epoch_key, e), world,
                               EpochTruth(g_true, a_true, t_e, pos_e),
                               EpochTowers(setup.towers, tclk, setup.operator), err,
                               setup.sensors())
        valid = jnp.ones(n_t, bool)

        def one_filter(cf, excl):
            prior, phi = _ekf.ekf_predict(cf.state, m.gyro_rad_s, m.accel_m_s2, p)
            cf, out = raim_update(cf, prior, phi, _ekf.EkfInputs(
                m.gyro_rad_s, m.accel_m_s2, m.pseudorange_m, valid, tclk, sigma_f),
                setup.towers, RaimOptions(setup.tables, dof_offset, excl, hal_m))
            err2d = jnp.linalg.norm(cf.state.r[:2] - pos_e[:2])
            return cf, (err2d, out)

        filt, (err2d, out) = jax.vmap(one_filter)(filt, exclude)
        return (world, filt), (err2d, out)

    def block(c, xs_blk):
        # nees_every epochs, then the NEES of both filters at the block's last epoch
        c, (err2d, out) = jax.lax.scan(body, c, xs_blk)
        w, filt = c
        _, _, t_e, pos_e, vel_e, q_e, _ = xs_blk[1:]
        nees = jax.vmap(lambda st: nees_of_state(st, q_e[-1], pos_e[-1], vel_e[-1],
                                                 w.gyro_bias_rad_s, w.accel_bias_m_s2,
                                                 w.rx_clock_m))(filt.state)
        return c, (err2d, out, nees)

    n_ep = setup.t_s.shape[0] // nees_every * nees_every
    e_idx = jnp.arange(n_ep)
    xs = (e_idx, setup.gyro[:n_ep], setup.accel[:n_ep], setup.t_s[:n_ep], setup.pos[1:n_ep + 1],
          setup.vel[1:n_ep + 1], setup.quat[1:n_ep + 1], setup.tower_clk_m[:n_ep])
    xs = jax.tree.map(lambda x: x.reshape((n_ep // nees_every, nees_every) + x.shape[1:]), xs)
    _, (err2d, out, nees) = jax.lax.scan(block, (d.world, carry_f), xs)
    flat = lambda x: x.reshape((n_ep,) + x.shape[2:])  # noqa: E731
    err2d, out = flat(err2d), jax.tree.map(flat, out)
    t = setup.t_s[:n_ep, None]
    after = t >= fault_onset_s
    det = out.detected
    big = jnp.inf
    summary = DriveSummary(
        rmse_2d_m=jnp.sqrt(jnp.mean(err2d**2, 0)),
        max_2d_m=jnp.max(err2d, 0),
        detection_time_s=jnp.min(jnp.where(det & after, t, big), 0),
        n_false_alarms=jnp.sum(det & ~after, 0),
        n_detections_after_onset=jnp.sum(det & after, 0),
        n_correct_exclusions=jnp.sum(after & (out.excluded == fault_tower), 0),
        n_wrong_exclusions=jnp.sum((out.excluded >= 0) & ~(after & (out.excluded == fault_tower)),
                                   0),
        nees_mean=jnp.mean(nees, 0),
        nis_mean=jnp.mean(out.nis, 0),
        nis_dof_mean=jnp.mean(out.dof.astype(jnp.float64), 0),
        hpl_max_m=jnp.max(out.hpl_m, 0),
        n_alarms=jnp.sum(out.alarm, 0),
        n_misleading=jnp.sum(err2d > out.hpl_m, 0),
        filter_sigma_m=jnp.full(2, sigma_f),
    )
    if traces:
        return summary, DriveTrace(setup.t_s[:n_ep], err2d, nees, out)
    return summary


def monte_carlo_drive(keys, setup: DriveSetup, **kw):
    """``simulate_drive`` vmapped over run keys; summaries with a leading runs axis."""
    return jax.vmap(lambda k: simulate_drive(k, setup, **kw))(keys)
