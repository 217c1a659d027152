"""Monte Carlo drives through three integrity monitors side by side (docs/filter-integrity.md):
the solution-separation filter bank (``araim.run_ekf_monitor``'s step), seed 000's EKF with NIS
detection and the Xi-slope HPL (``araim.ekf_raim``, without exclusion), and the snapshot MHSS
of each epoch's pseudoranges (``araim.separation_kernel``, linearised at the main filter's
estimate).

One run: the GNSS period and the world of ``sim.drive`` (``initial_draw``, ``drive_epoch``),
an injected ``sim.faults.FaultScenario`` added to the pseudoranges, and per epoch every
monitor's horizontal position error (HPE, 2D), HPL and alert. The bank's main filter and the
Xi-slope filter are the same EKF on the same measurements (same estimate, two HPLs); the
snapshot has its own estimate. ``simulate_filter_drive`` returns per-run counts
(``FilterDriveSummary``) and, on request, per-epoch traces; vmap it over run keys.

The filters' pseudorange variance is sigma_f^2 (``sim.drive.filter_sigma``) plus, when the
world has Gauss-Markov multipath that the filter does not model, the overbound
``gm_inflation`` sigma_mp^2 (1 + rho) / (1 - rho), rho = exp(-T / tau) (the long-run variance
of the sampled GM process: the variance of any equal-weight average of n samples is at most
this over n; ``gm_overbound_variance``). The seed 000 EKF's own default is no inflation.
"""

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from oaraim import araim
from oaraim.araim import ekf as _ekf
from oaraim.araim.ekf_raim import raim_init, raim_update
from oaraim.errors import ErrorModel
from oaraim.sim.drive import DriveSetup, filter_sigma, initial_draw
from oaraim.sim.faults import FaultScenario, fault_profile_m
from oaraim.sim.measurement import EpochTowers, EpochTruth, drive_epoch

__all__ = ["DEFAULT_CONFIG", "MONITORS", "FilterDriveConfig", "FilterDriveSummary",
           "FilterDriveTrace", "SEPARATION_SIGMAS", "TOWER_STATES", "gm_overbound_variance",
           "simulate_filter_drive", "tower_error_states"]

#: the monitors compared, in the order of the summary's last axis
MONITORS = ("filter_ss", "ekf_xi_slope", "snapshot_mhss")
#: the k of ``FilterDriveSummary.n_sep_over`` (|Delta| > k sigma_ss)
SEPARATION_SIGMAS = (3.0, 4.0, 5.0)


class FilterDriveConfig(NamedTuple):
    """The integrity settings (static: hashable). ``p_sat`` per tower and ``p_const`` for the
    towers' one operator are per-epoch priors; ``budget`` the integrity and false-alert
    allocation; ``gm_inflation`` 1 adds the GM overbound to the filters' variance (0: no);
    ``linearisation`` how the bank's sub-filters are linearised
    (``araim.filter_monitor.LINEARISATIONS``); ``tower_states`` True augments the bank's
    filters with each tower's correlated-error states (``tower_error_states``: the world's
    multipath and clock deviation as Gauss-Markov states, the calibration line's error),
    exclusive with ``gm_inflation`` (the Xi-slope EKF and the snapshot keep the white model)."""

    budget: araim.IntegrityBudget = araim.BUDGET_SEED004_TABLE_I
    p_sat: float = 1e-5
    p_const: float = 1e-8
    fault_modes: str = "add-v4.2"
    max_order: int = 1
    hal_m: float = 30.0
    gm_inflation: float = 0.0
    linearisation: str = "main"
    tower_states: bool = False


#: the settings of ``simulate_filter_drive`` by default
DEFAULT_CONFIG = FilterDriveConfig()


class FilterDriveSummary(NamedTuple):
    """Per-run counts over the epochs evaluated; axis (3,) = ``MONITORS``. 'At risk' epochs are
    those at or after the fault's onset (every epoch of a fault-free run)."""

    n_epochs: jax.Array
    n_at_risk: jax.Array
    n_exceed: jax.Array
    """(3,) at-risk epochs with HPE > HPL."""
    n_misleading: jax.Array
    """(3,) at-risk epochs with HPE > HPL and no alert (hazardously misleading)."""
    n_false_alerts: jax.Array
    """(3,) alerts at epochs without a fault (before the onset; every epoch of a fault-free
    run)."""
    detection_delay_s: jax.Array
    """(3,) first alert at or after the onset minus the onset, s (inf: never)."""
    n_available: jax.Array
    """(3,) at-risk epochs with HPL <= HAL."""
    hpl_sum_m: jax.Array
    """(3,) sum of the finite HPLs over the at-risk epochs (mean = sum / n_finite)."""
    n_finite: jax.Array
    hpe_max_m: jax.Array
    """(3,) largest HPE over the at-risk epochs."""
    n_sep_tests: jax.Array
    """() separation tests (monitored mode and direction with sigma_ss > 0) at epochs without a
    fault: the samples of the normalized separation Delta / sigma_ss."""
    n_sep_over: jax.Array
    """(3,) of those, |Delta| > k sigma_ss for k = ``SEPARATION_SIGMAS`` (3, 4, 5): the tails of
    the normalized separation, 2 Q(k) if P_i - P_0 is its covariance."""


class FilterDriveTrace(NamedTuple):
    """Per-epoch traces (E, ...) of one run."""

    t_s: jax.Array
    hpe_m: jax.Array
    """(E, 3) per monitor."""
    hpl_m: jax.Array
    """(E, 3)."""
    alert: jax.Array
    """(E, 3)."""
    fault_m: jax.Array
    """(E,) the injected bias on the faulty tower."""
    status: jax.Array
    """(E,) the filter monitor's Status."""
    test_ratio: jax.Array
    """(E,) the filter monitor's largest |separation| / threshold."""
    worst_mode: jax.Array
    """(E,) the bank filter (1..K-1) of that largest ratio (0: none monitored)."""
    monitor: araim.FilterMonitorEpoch | None = None
    """the bank's ``araim.FilterMonitorEpoch`` per epoch (leading axis E): positions,
    separations, sigma_ss, thresholds and HPL, what ``sim.filter_risk``'s conditional
    estimate reads."""
    p0_h_m2: jax.Array | None = None
    """(E, 2, 2) the main filter's horizontal position covariance, m^2."""
    truth_m: jax.Array | None = None
    """(E, 3) the true position (the frame of ``monitor.position_m``)."""


def gm_overbound_variance(sigma_m, tau_s, dt_s):
    """sigma^2 (1 + rho) / (1 - rho), rho = exp(-dt / tau): the long-run variance of a first-order
    Gauss-Markov process sampled every ``dt_s`` (module docstring)."""
    rho = jnp.exp(-dt_s / tau_s)
    return sigma_m**2 * (1.0 + rho) / (1.0 - rho)


#: the correlated-error states ``tower_error_states`` gives each tower, in this order: the
#: Gauss-Markov multipath, the Gauss-Markov clock deviation epsilon_n, the receiver's clock-fit
#: line at t (c = a + b t) and its slope b; the pseudorange's modelled error is mp + eps - c
TOWER_STATES = ("multipath_m", "clk_eps_m", "fit_line_m", "fit_slope_m_s")


def _exp_corr(sigma_m, tau_s, lag_s):
    """sigma^2 exp(-|lag| / tau): the autocovariance of a first-order Gauss-Markov process
    (0 where sigma is 0)."""
    return jnp.where(sigma_m > 0, sigma_m**2 * jnp.exp(-jnp.abs(lag_s) / tau_s), 0.0)


def tower_error_states(err: ErrorModel, calib_t_s, dt_s, sigma_white_m, n_towers: int):
    """The ``araim.filter_monitor.ErrorStates`` of the world ``err``'s tower errors, 4 per
    tower (``TOWER_STATES``), for a filter that knows the world's Gauss-Markov parameters.

    Per measurement interval ``dt_s``: mp <- rho_mp mp + w, eps <- rho_eps eps + w (exact GM
    steps, process variances sigma^2 (1 - rho^2)), c <- c + dt b, b <- b. The prior at t = 0
    is the exact joint covariance of (mp(0), eps(0), a, b) where (a, b) is the least-squares
    line the receiver fitted during the GNSS period (``sim.measurement.calibrate``: the samples
    ``calib_t_s`` within ``err.calib_window_s`` of t = 0) to y_k = mp(t_k) + eps(t_k) +
    white(``sigma_white_m``): with A = [1, t_k] and M = (A^T A)^-1 A^T, cov(a, b) = M C_y M^T
    and cov(mp(0), (a, b)) = M cov(y, mp(0)). The towers are independent (the operator's
    common clock, an OCXO whose drift is ~mm over the period, is absorbed by the receiver
    clock and left out). Fewer than 3 calibration samples: no fit, the line states zero."""
    t = jnp.asarray(calib_t_s, jnp.float64)
    m = (t > -err.calib_window_s).astype(jnp.float64)
    ok = jnp.sum(m) > 2
    a = jnp.stack([m, m * t], -1)
    ata = a.T @ a + jnp.where(ok, 0.0, 1.0) * jnp.eye(2)
    mm = jnp.where(ok, jnp.linalg.solve(ata, a.T), 0.0)
    lag = t[:, None] - t[None, :]
    c_y = (_exp_corr(err.mp_sigma_m, err.mp_tau_s, lag)
           + _exp_corr(err.clk_eps_sigma_m, err.clk_eps_tau_s, lag)
           + jnp.asarray(sigma_white_m, jnp.float64) ** 2 * jnp.eye(t.shape[0]))
    c_ab = mm @ c_y @ mm.T
    c_mp = mm @ _exp_corr(err.mp_sigma_m, err.mp_tau_s, t)
    c_eps = mm @ _exp_corr(err.clk_eps_sigma_m, err.clk_eps_tau_s, t)
    p4 = jnp.zeros((4, 4))
    p4 = p4.at[0, 0].set(err.mp_sigma_m**2).at[1, 1].set(err.clk_eps_sigma_m**2)
    p4 = p4.at[2:, 2:].set(c_ab).at[0, 2:].set(c_mp).at[2:, 0].set(c_mp)
    p4 = p4.at[1, 2:].set(c_eps).at[2:, 1].set(c_eps)
    rho_mp = jnp.exp(-dt_s / err.mp_tau_s)
    rho_eps = jnp.exp(-dt_s / err.clk_eps_tau_s)
    phi4 = jnp.diag(jnp.stack([rho_mp, rho_eps, 1.0, 1.0])).at[2, 3].set(dt_s)
    q4 = jnp.diag(jnp.stack([err.mp_sigma_m**2 * (1.0 - rho_mp**2),
                             err.clk_eps_sigma_m**2 * (1.0 - rho_eps**2), 0.0, 0.0]))
    eye = jnp.eye(n_towers)
    h = jnp.kron(eye, jnp.array([[1.0, 1.0, -1.0, 0.0]]))
    return araim.filter_monitor.ErrorStates(jnp.kron(eye, phi4), jnp.kron(eye, q4), h,
                                            jnp.kron(eye, p4))


@partial(jax.jit, static_argnames=("cfg", "traces"))
def simulate_filter_drive(key, setup: DriveSetup, err: ErrorModel, fault: FaultScenario,
                          cfg: FilterDriveConfig = DEFAULT_CONFIG, filter_sigma_pr_m=0.0,
                          traces=False):
    """One run of the drive of ``setup`` in the world ``err`` (its own constant fault as set
    there; pass ``fault_onset_s=inf`` for none) with ``fault`` added; returns
    ``FilterDriveSummary`` (and ``FilterDriveTrace`` if ``traces``)."""
    p = setup.params
    n_t = setup.towers.shape[0]
    d = initial_draw(key, setup, err)
    sigma_f = filter_sigma(d, err, filter_sigma_pr_m)
    dt_meas = setup.gyro.shape[1] * p.dt_s
    var_f = sigma_f**2 + cfg.gm_inflation * jnp.where(
        err.mp_sigma_m > 0, gm_overbound_variance(err.mp_sigma_m, err.mp_tau_s, dt_meas), 0.0)
    sig_f = jnp.sqrt(var_f)
    est0 = _ekf.ekf_init(d.quat_est, d.pos_est_m, d.vel_est_m_s, jnp.zeros(3), jnp.zeros(3),
                         jnp.zeros(2), setup.P0)
    rule = araim.FaultModeRule(cfg.fault_modes)
    fmon = araim.filter_monitor
    K = fmon.n_bank_filters(n_t, 1, cfg.max_order, rule)
    if cfg.tower_states:
        if cfg.gm_inflation:
            raise ValueError("FilterDriveConfig: tower_states models the Gauss-Markov errors; "
                             "set gm_inflation=0 (the overbound would count them twice)")
        errs = tower_error_states(err, setup.calib_t_s, dt_meas, sig_f, n_t)
        bank0 = fmon.augmented_bank(est0, errs, K)
    else:
        bank0 = jax.tree.map(lambda a: jnp.broadcast_to(a, (K,) + a.shape), est0)
    xi0 = raim_init(est0, n_t)
    con = jnp.zeros(n_t, int)
    p_sat = jnp.full(n_t, cfg.p_sat)
    p_const = jnp.full(1, cfg.p_const)
    valid = jnp.ones(n_t, bool)

    def body(c, inp):
        world, bank, xi = c
        e, g_true, a_true, t_e, pos_e, tclk = inp
        world, m = drive_epoch(jax.random.fold_in(d.epoch_key, e), world,
                               EpochTruth(g_true, a_true, t_e, pos_e),
                               EpochTowers(setup.towers, tclk, setup.operator), err,
                               setup.sensors())
        bias = fault_profile_m(t_e, fault, n_t)
        z = m.pseudorange_m + bias
        # the solution-separation bank
        fm, used = fmon.epoch_modes_and_used(valid, con, p_sat, p_const, cfg.budget, rule,
                                             cfg.max_order)
        inputs = _ekf.EkfInputs(m.gyro_rad_s, m.accel_m_s2, z, valid, tclk, sig_f)
        if cfg.tower_states:
            bank = fmon.ekf_bank_step_augmented(bank, inputs, used, setup.towers, p, errs)
            filters = bank.ekf
        else:
            bank = fmon.ekf_bank_step(bank, inputs, used, setup.towers, p, cfg.linearisation)
            filters = bank
        ss = araim.separation_monitor(filters.r, filters.P[:, _ekf.POS, _ekf.POS], fm,
                                      cfg.budget)
        # seed 000's NIS + Xi-slope HPL on the same EKF (no exclusion)
        prior, phi = _ekf.ekf_predict(xi.state, m.gyro_rad_s, m.accel_m_s2, p)
        xi, ro = raim_update(xi, prior, phi, _ekf.EkfInputs(None, None, z, valid, tclk, sig_f),
                             setup.towers, araim.RaimOptions(setup.tables, 0, False, cfg.hal_m))
        # the snapshot MHSS of this epoch, linearised at the main filter's estimate
        z_hat, u = _ekf.pseudorange_model(filters.r[0], filters.clk[0], setup.towers, tclk)
        src = araim.Sources(u, con, jnp.full(n_t, var_f), jnp.full(n_t, var_f),
                            jnp.zeros(n_t), p_sat, valid)
        sn = araim.separation_kernel(src, p_const, cfg.budget, z - z_hat,
                                     araim.MHSSOptions(cfg.max_order, fault_modes=rule))
        pos_snap = filters.r[0] + sn.position_m
        hpe = jnp.stack([jnp.linalg.norm(filters.r[0, :2] - pos_e[:2]),
                         jnp.linalg.norm(xi.state.r[:2] - pos_e[:2]),
                         jnp.linalg.norm(pos_snap[:2] - pos_e[:2])])
        hpl = jnp.stack([ss.hpl_m, ro.hpl_m, sn.pl.hpl_m])
        alert = jnp.stack([ss.alert, ro.detected, sn.detected])
        thr = ss.threshold_m
        ratio = jnp.max(jnp.where(thr > 0, jnp.abs(ss.separation_m) / jnp.where(thr > 0, thr, 1.0),
                                  0.0), axis=1)
        sss = ss.sigma_ss_m
        zabs = jnp.where(sss > 0, jnp.abs(ss.separation_m) / jnp.where(sss > 0, sss, 1.0), 0.0)
        tests = ss.monitored[:, None] & (sss > 0)
        n_over = jnp.stack([jnp.sum(tests & (zabs > k)) for k in SEPARATION_SIGMAS])
        # the bank's own epoch, for the conditional estimate (sim.filter_risk): traces only
        extra = (ss, filters.P[0][_ekf.POS, _ekf.POS][:2, :2], pos_e) if traces else ()
        return (world, bank, xi), (hpe, hpl, alert, bias[jnp.clip(fault.source, 0)], ss.status,
                                   ss.test_ratio, jnp.argmax(ratio), jnp.sum(tests), n_over,
                                   extra)

    n_ep = setup.t_s.shape[0]
    xs = (jnp.arange(n_ep), setup.gyro, setup.accel, setup.t_s, setup.pos[1:n_ep + 1],
          setup.tower_clk_m)
    _, (hpe, hpl, alert, fb, st, tr, wm, n_tests, n_over, extra) = jax.lax.scan(
        body, (d.world, bank0, xi0), xs)
    t = setup.t_s[:, None]
    risk = t >= jnp.where(fault.source >= 0, fault.onset_s, -jnp.inf)
    faulted = risk & (fault.source >= 0)
    exceed = hpe > hpl
    fin = jnp.isfinite(hpl)
    first = jnp.min(jnp.where(alert & risk, t, jnp.inf), 0)
    summary = FilterDriveSummary(
        n_epochs=jnp.asarray(n_ep), n_at_risk=jnp.sum(risk[:, 0]),
        n_exceed=jnp.sum(exceed & risk, 0), n_misleading=jnp.sum(exceed & ~alert & risk, 0),
        n_false_alerts=jnp.sum(alert & ~faulted, 0),
        detection_delay_s=jnp.where(fault.source >= 0, first - fault.onset_s, jnp.inf),
        n_available=jnp.sum((hpl <= cfg.hal_m) & risk, 0),
        hpl_sum_m=jnp.sum(jnp.where(fin & risk, hpl, 0.0), 0), n_finite=jnp.sum(fin & risk, 0),
        hpe_max_m=jnp.max(jnp.where(risk, hpe, 0.0), 0),
        n_sep_tests=jnp.sum(jnp.where(faulted[:, 0], 0, n_tests)),
        n_sep_over=jnp.sum(jnp.where(faulted[:, :1], 0, n_over), 0))
    if traces:
        return summary, FilterDriveTrace(setup.t_s, hpe, hpl, alert, fb, st, tr, wm, *extra)
    return summary
