"""EKF-based RAIM for LTE + IMU navigation (seed 000 section III, seed 002 exclusion steps 1-4).

Per pseudorange epoch k+1, after the EKF time update (``araim.ekf``):

1. Detection (seed 000 section III-A): NIS phi = nu^T S^-1 nu over the valid towers, compared with
   T_h(P_FA, d) of eq. (5). d = N_s by default (seed 002; the innovation has N_s components),
   d = N_s - 4 as the option ``dof_offset=4`` (seed 000's text). With 5 towers that option leaves
   d = 1 and the exclusion subsets d = 0: they cannot be tested, so exclusion fails there
   (``Status.EXCLUSION_FAILED``), as DESIGN.md warns.
2. Exclusion (seed 000 end of III-B; seed 002 steps 1-4): the N_s subsets of N_s - 1 towers are
   tested with the same prior; subset i's NIS is phi - (S^-1 nu)_i^2 / (S^-1)_ii (the Schur
   complement of removing row i, exact), against T_h(P_FA, d - 1). The subset that passes is fed
   to the navigation filter; if several pass, the one with the smallest NIS; if none passes, no
   measurement is excluded and the epoch carries ``EXCLUSION_FAILED``. Exclusion is decided
   afresh at every epoch.
3. Update with the used towers (Joseph form).
4. Xi recursion (seed 000 section III-B): Xi(k+1) = M(k+1) Xi(k) + K(k+1), M = (I - K H) Phi,
   restarted at Xi = K whenever the used set changes (DESIGN.md) and at the first epoch;
   slope_n = sqrt(Xi_{E,n}^2 + Xi_{N,n}^2) / sqrt((S^-1)_nn) (rows 4 and 5 of the seed, 1-based,
   are East and North in the ENU frame); HPL = max_n slope_n sqrt(lambda_min), with lambda_min the
   non-centrality giving P_MD at T_h (eq. 6, ``araim.chi2.noncentrality``) for the used set's d.
5. HAL alarm: HPL > HAL.

Failures are data: with d < 1 the threshold and lambda_min are inf, nothing is detected, HPL is
inf and the status is ``TOO_FEW_SOURCES``; never a NaN.

The drive runner ``simulate_drive`` synthesizes one Monte Carlo run of a ``geometry.trajectory``
scenario inside a ``lax.scan`` over pseudorange epochs (IMU noise, GM biases, receiver clock,
multipath, pseudoranges and the injected fault drawn from ``fold_in(key, epoch)``, so nothing of
size runs x epochs is stored), runs the EKF without and with exclusion side by side, and returns
per-run summaries; ``monte_carlo_drive`` vmaps it over runs.
"""

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.araim import ekf as _ekf
from oaraim.araim.chi2 import detection_threshold, noncentrality
from oaraim.araim.status import Status
from oaraim.geometry import clocks, imu, trajectory


class RaimConfig(NamedTuple):
    """Integrity parameters. Seeds 000/002 give no P_FA, P_MD or HAL: P_FA = 1e-5 and
    P_MD = 1e-3 per epoch are the repository's seed 001 defaults; HAL = 30 m is the horizontal
    alert limit of the same group's vehicle RAIM study (seed 001 Fig. 4)."""

    p_fa: float = 1e-5
    p_md: float = 1e-3
    hal_m: float = 30.0
    dof_offset: int = 0  # 0: d = N_s (seed 002, default); 4: d = N_s - 4 (seed 000)


class RaimTables(NamedTuple):
    """``threshold[d]`` = T_h(P_FA, d) (eq. 5), ``lambda_min[d]`` (eq. 6); index 0 = inf."""

    threshold: jnp.ndarray
    lambda_min: jnp.ndarray


def raim_tables(p_fa: float, p_md: float, max_dof: int) -> RaimTables:
    """Host-side tables for d = 0..max_dof (SciPy via ``araim.chi2``)."""
    th = np.full(max_dof + 1, np.inf)
    lam = np.full(max_dof + 1, np.inf)
    for d in range(1, max_dof + 1):
        th[d] = detection_threshold(p_fa, d)
        lam[d] = noncentrality(p_fa, p_md, d)
    return RaimTables(jnp.asarray(th), jnp.asarray(lam))


def _lookup(table, dof):
    """table[dof], inf for dof < 1 (fixed-shape gather)."""
    d = jnp.clip(dof, 0, table.shape[0] - 1)
    return jnp.where(dof >= 1, table[d], jnp.inf)


def nis_test(nu, s_inv, valid, tables: RaimTables, dof_offset):
    """NIS phi = nu^T S^-1 nu over the valid towers, its d, T_h(d) and the detection flag."""
    nu = jnp.where(valid, nu, 0.0)
    nis = nu @ s_inv @ nu
    dof = jnp.sum(valid) - dof_offset
    th = _lookup(tables.threshold, dof)
    return nis, dof, th, nis > th


def subset_nis(nis, nu, s_inv, valid):
    """NIS of each subset without tower i (seed 002 steps 1-2), inf for invalid i, (L,)."""
    w = s_inv @ jnp.where(valid, nu, 0.0)
    diag = jnp.diagonal(s_inv)
    return jnp.where(valid, nis - w**2 / jnp.where(valid, diag, 1.0), jnp.inf)


def select_exclusion(nis_sub, dof, valid, tables: RaimTables):
    """Seed 002 steps 3-4: index of the subset that passes its test (-1 if none), and whether
    none passed. Subsets with d - 1 < 1 cannot be tested and never pass."""
    th_sub = _lookup(tables.threshold, dof - 1)
    passes = valid & (dof - 1 >= 1) & (nis_sub <= th_sub)
    cand = jnp.where(passes, nis_sub, jnp.inf)
    best = jnp.argmin(cand)
    any_pass = jnp.any(passes)
    return jnp.where(any_pass, best, -1), ~any_pass


def xi_recursion(xi_prev, k, hu, phi, restart):
    """Xi(k+1) = (I - K H) Phi Xi(k) + K, or K on restart (seed 000 section III-B).
    ``hu`` is the (masked) H (L, 17) of the update."""
    y = phi @ xi_prev
    xi = y - k @ (hu @ y) + k
    return jnp.where(restart, k, xi)


def slopes_hpl(xi, s_inv, used, lambda_min):
    """slope_n (L,) (0 for unused towers), slope_max and HPL = slope_max sqrt(lambda_min)."""
    dr = jnp.sqrt(xi[3] ** 2 + xi[4] ** 2)
    diag = jnp.where(used, jnp.diagonal(s_inv), 1.0)
    slope = jnp.where(used, dr / jnp.sqrt(diag), 0.0)
    smax = jnp.max(slope)
    hpl = jnp.where(jnp.isfinite(lambda_min), smax * jnp.sqrt(jnp.where(
        jnp.isfinite(lambda_min), lambda_min, 0.0)), jnp.inf)
    return slope, smax, hpl


class RaimCarry(NamedTuple):
    """Filter state carried between epochs: EKF state, Xi (17, L), previous used set, first."""

    state: _ekf.EkfState
    xi: jnp.ndarray
    used_prev: jnp.ndarray
    first: jnp.ndarray


class RaimEpoch(NamedTuple):
    """Per-epoch outputs (scalars unless stated): NIS of all valid towers and its d, threshold,
    detected, excluded tower (-1 none), number used, HPL (m, inf when unavailable), HAL alarm,
    status (``araim.status.Status``), slopes (L,)."""

    nis: jnp.ndarray
    dof: jnp.ndarray
    threshold: jnp.ndarray
    detected: jnp.ndarray
    excluded: jnp.ndarray
    n_used: jnp.ndarray
    hpl_m: jnp.ndarray
    alarm: jnp.ndarray
    status: jnp.ndarray
    slopes: jnp.ndarray


def raim_init(state: _ekf.EkfState, n_towers: int) -> RaimCarry:
    return RaimCarry(state, jnp.zeros((_ekf.N_ERR, n_towers)), jnp.zeros(n_towers, bool),
                     jnp.asarray(True))


def raim_update(carry: RaimCarry, state_prior, phi, z, valid, tx_pos, tx_clk_m, sigma_m,
                tables: RaimTables, dof_offset, exclude, hal_m):
    """Detection, exclusion, update, Xi and HPL for one epoch (steps 1-5 of the module doc).

    ``state_prior``/``phi`` come from ``ekf_predict``; ``exclude`` (bool, may be traced) turns
    exclusion on. Returns ``(new carry, RaimEpoch)``.
    """
    z_hat, u = _ekf.pseudorange_model(state_prior.r, state_prior.clk, tx_pos, tx_clk_m)
    r_var = jnp.broadcast_to(jnp.asarray(sigma_m, jnp.float64) ** 2, z_hat.shape)
    nu = z - z_hat
    _, s_inv = _ekf.innovation_covariance(state_prior.P, u, r_var, valid)
    nis, dof, th, detected = nis_test(nu, s_inv, valid, tables, dof_offset)
    nis_sub = subset_nis(nis, nu, s_inv, valid)
    idx, none_pass = select_exclusion(nis_sub, dof, valid, tables)
    do_excl = exclude & detected & (idx >= 0)
    excluded = jnp.where(do_excl, idx, -1)
    used = valid & (jnp.arange(valid.shape[0]) != excluded)
    s_inv_used = _ekf.remove_from_inverse(s_inv, excluded)
    state, info = _ekf.kalman_update(state_prior, nu, u, r_var, used, s_inv_used)
    restart = carry.first | jnp.any(used != carry.used_prev)
    xi = xi_recursion(carry.xi, info.K, info.H, phi, restart)
    dof_used = info.n_used - dof_offset
    lam = _lookup(tables.lambda_min, dof_used)
    slope, _, hpl = slopes_hpl(xi, info.S_inv, used, lam)
    status = jnp.where(dof_used < 1, Status.TOO_FEW_SOURCES,
                       jnp.where(exclude & detected & none_pass, Status.EXCLUSION_FAILED,
                                 Status.OK)).astype(jnp.int32)
    out = RaimEpoch(nis, dof, th, detected, excluded.astype(jnp.int32), info.n_used, hpl,
                    hpl > hal_m, status, slope)
    return RaimCarry(state, xi, used, jnp.asarray(False)), out


def run_ekf_raim(state0, gyro, accel, z, valid, tx_pos, tx_clk_m, sigma_m, params,
                 tables: RaimTables, dof_offset=0, exclude=True, hal_m=30.0):
    """EKF + RAIM over E epochs of recorded data (lax.scan). ``gyro``/``accel`` (E, n, 3),
    ``z``/``valid``/``tx_clk_m`` (E, L). Returns (final carry, (EkfOutput-like position r (E, 3),
    RaimEpoch stacked))."""
    carry0 = raim_init(state0, tx_pos.shape[0])

    def body(carry, inp):
        g, a, zz, vv, tc = inp
        prior, phi = _ekf.ekf_predict(carry.state, g, a, params)
        carry, out = raim_update(carry, prior, phi, zz, vv, tx_pos, tc, sigma_m, tables,
                                 dof_offset, exclude, hal_m)
        return carry, (carry.state.r, out)

    return jax.lax.scan(body, carry0, (gyro, accel, z, valid, tx_clk_m))


# ------------------------------------------------------------------------------------------
# Monte Carlo drive


class InitialUncertainty(NamedTuple):
    """1-sigma of the initial error, what the GNSS period of seed 000 section IV-A leaves
    (our choices; the seed gives none): attitude roll/pitch/yaw (rad), position (m), velocity
    (m/s), clock bias (m) and drift (m/s). The biases start at their GM stationary sigma."""

    att_rad: tuple = (np.deg2rad(0.1), np.deg2rad(0.1), np.deg2rad(0.5))
    pos_m: float = 0.5
    vel_m_s: float = 0.05
    clk_m: float = 1.0
    clk_drift_m_s: float = 0.1


def initial_covariance(spec: imu.ImuSpec, init: InitialUncertainty):
    sd = np.concatenate([np.asarray(init.att_rad, float), np.full(3, init.pos_m),
                         np.full(3, init.vel_m_s), np.full(3, spec.gyro_bias_sigma_rad_s),
                         np.full(3, spec.accel_bias_sigma_m_s2),
                         [init.clk_m, init.clk_drift_m_s]])
    return jnp.diag(jnp.asarray(sd**2))


class DriveSummary(NamedTuple):
    """Per-run summaries; arrays of shape (2,) are [without exclusion, with exclusion].

    Times in s (inf: never); counts are integers; NEES/NIS are means over the epochs of the run
    (NIS over the valid towers before exclusion; ``nis_dof_mean`` its mean d = N_s)."""

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


class DriveTrace(NamedTuple):
    """Per-epoch traces of one run (for tests and plots), each (E, 2, ...); ``nees`` is
    (E / nees_every, 2), at the last epoch of each block."""

    t_s: jnp.ndarray
    err_2d_m: jnp.ndarray
    nees: jnp.ndarray
    raim: RaimEpoch


class DriveSetup(NamedTuple):
    """Everything static for a drive: truth arrays reshaped per epoch, model, tables."""

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


def drive_setup(scenario: trajectory.Scenario, spec: imu.ImuSpec | None = None,
                init: InitialUncertainty | None = None, cfg: RaimConfig | None = None,
                duration_s: float | None = None) -> DriveSetup:
    """Host-side preparation of ``simulate_drive`` (optionally truncated to ``duration_s``)."""
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
        tables=raim_tables(cfg.p_fa, cfg.p_md, l))


def _nees(state: _ekf.EkfState, q, r, v, bg, ba, clk):
    e = jnp.concatenate([_ekf.attitude_error(q, state.q), r - state.r, v - state.v,
                         bg - state.bg, ba - state.ba, clk - state.clk])
    chol = jnp.linalg.cholesky(state.P)
    y = jax.scipy.linalg.solve_triangular(chol, e, lower=True)
    return y @ y


@partial(jax.jit, static_argnames=("traces", "nees_every"))
def simulate_drive(key, setup: DriveSetup, sigma_pr_m=2.0, mp_sigma_m=0.0, mp_tau_s=5.0,
                   fault_tower=0, fault_onset_s=25.0, fault_bias_m=30.0, hal_m=30.0,
                   dof_offset=0, traces=False, nees_every=10):
    """One Monte Carlo run of a drive; returns ``DriveSummary`` (and ``DriveTrace`` if
    ``traces``). vmap over ``key`` for many runs (``monte_carlo_drive``). Every numeric argument
    is traced (one compilation serves fault-free and faulty runs, both d options).

    The run covers the whole epochs of the setup rounded down to a multiple of ``nees_every``;
    NEES (a 17 x 17 Cholesky solve, the costliest single step) is evaluated at the last epoch of
    each block of ``nees_every`` epochs (1 Hz at the default 10 Hz pseudorange rate); every other
    quantity at every epoch."""
    sp, p = setup.spec, setup.params
    n_t = setup.towers.shape[0]
    dt_meas = setup.gyro.shape[1] * p.dt_s
    k_init, k_bias, k_scan = jax.random.split(key, 3)
    # initial truth and estimate: error ~ N(0, P0); biases start at their stationary draw
    d0 = jnp.sqrt(jnp.diagonal(setup.P0)) * jax.random.normal(k_init, (_ekf.N_ERR,))
    bg0, ba0 = imu.initial_biases(k_bias, sp)
    clk0 = d0[_ekf.CLK]
    q_true0 = setup.quat[0]
    q_est0 = _ekf.quat_multiply(_ekf.error_quat(-d0[_ekf.TH]), q_true0)
    est0 = _ekf.ekf_init(q_est0, setup.pos[0] - d0[_ekf.POS], setup.vel[0] - d0[_ekf.VEL],
                         jnp.zeros(3), jnp.zeros(3), jnp.zeros(2), setup.P0)
    carry_f = raim_init(est0, n_t)
    carry_f = jax.tree.map(lambda x: jnp.stack([x, x]), carry_f)
    exclude = jnp.array([False, True])
    mp0 = jnp.zeros(n_t)

    def body(c, inp):
        truth, filt = c
        bg, ba, clk, mp = truth
        e, g_true, a_true, t_e, pos_e, vel_e, q_e, tclk = inp
        ke = jax.random.fold_in(k_scan, e)
        n_sub = g_true.shape[0]
        w = jax.random.normal(ke, (n_sub * 12 + 2 + 2 * n_t,))
        w_imu = w[:n_sub * 12].reshape(n_sub, 12)
        w_clk = w[n_sub * 12:n_sub * 12 + 2]
        w_mp = w[n_sub * 12 + 2:n_sub * 12 + 2 + n_t]
        w_pr = w[n_sub * 12 + 2 + n_t:]

        def imu_step(b, x):
            # a scan, not an unrolled loop: unrolled, XLA fused the whole bias chain into every
            # sample's fusion (quadratic recomputation, ~15 % of the run time)
            wj, gt, at = x
            gj, aj, bgj, baj = imu.imu_sample_normals(wj, gt, at, b[0], b[1], sp, p.dt_s)
            return (bgj, baj), (gj, aj)

        (bg, ba), (gm, am) = jax.lax.scan(imu_step, (bg, ba), (w_imu, g_true, a_true))
        clk = clocks.clock_step_normals(w_clk, clk, dt_meas, p.s_wdt_s, p.s_wdtdot_per_s)
        phi_mp = jnp.exp(-dt_meas / mp_tau_s)
        mp = phi_mp * mp + mp_sigma_m * jnp.sqrt(1.0 - phi_mp**2) * w_mp
        bias = mp + trajectory.fault_bias_m(t_e, fault_onset_s, fault_bias_m, fault_tower, n_t)
        z = (trajectory.pseudorange_true(pos_e, setup.towers, clk[0], tclk) + bias
             + sigma_pr_m * w_pr)
        valid = jnp.ones(n_t, bool)

        def one_filter(cf, excl):
            prior, phi = _ekf.ekf_predict(cf.state, gm, am, p)
            cf, out = raim_update(cf, prior, phi, z, valid, setup.towers, tclk, sigma_pr_m,
                                  setup.tables, dof_offset, excl, hal_m)
            err2d = jnp.linalg.norm(cf.state.r[:2] - pos_e[:2])
            return cf, (err2d, out)

        filt, (err2d, out) = jax.vmap(one_filter)(filt, exclude)
        return ((bg, ba, clk, mp), filt), (err2d, out)

    def block(c, xs_blk):
        # nees_every epochs, then the NEES of both filters at the block's last epoch
        c, (err2d, out) = jax.lax.scan(body, c, xs_blk)
        (bg, ba, clk, _), filt = c
        _, _, t_e, pos_e, vel_e, q_e, _ = xs_blk[1:]
        nees = jax.vmap(lambda st: _nees(st, q_e[-1], pos_e[-1], vel_e[-1], bg, ba, clk))(
            filt.state)
        return c, (err2d, out, nees)

    n_ep = setup.t_s.shape[0] // nees_every * nees_every
    e_idx = jnp.arange(n_ep)
    xs = (e_idx, setup.gyro[:n_ep], setup.accel[:n_ep], setup.t_s[:n_ep], setup.pos[1:n_ep + 1],
          setup.vel[1:n_ep + 1], setup.quat[1:n_ep + 1], setup.tower_clk_m[:n_ep])
    xs = jax.tree.map(lambda x: x.reshape((n_ep // nees_every, nees_every) + x.shape[1:]), xs)
    _, (err2d, out, nees) = jax.lax.scan(block, ((bg0, ba0, clk0, mp0), carry_f), xs)
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
    )
    if traces:
        return summary, DriveTrace(setup.t_s[:n_ep], err2d, nees, out)
    return summary


def monte_carlo_drive(keys, setup: DriveSetup, **kw):
    """``simulate_drive`` vmapped over run keys; summaries with a leading runs axis."""
    return jax.vmap(lambda k: simulate_drive(k, setup, **kw))(keys)
