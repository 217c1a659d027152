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
           "FilterDriveTrace", "SEPARATION_SIGMAS", "gm_overbound_variance",
           "simulate_filter_drive"]

#: the monitors compared, in the order of the summary's last axis
MONITORS = ("filter_ss", "ekf_xi_slope", "snapshot_mhss")
#: the k of ``FilterDriveSummary.n_sep_over`` (|Delta| > k sigma_ss)
SEPARATION_SIGMAS = (3.0, 4.0, 5.0)


class FilterDriveConfig(NamedTuple):
    """The integrity settings (static: hashable). ``p_sat`` per tower and ``p_const`` for the
    towers' one operator are per-epoch priors; ``budget`` the integrity and false-alert
    allocation; ``gm_inflation`` 1 adds the GM overbound to the filters' variance (0: no);
    ``linearisation`` how the bank's sub-filters are linearised
    (``araim.filter_monitor.LINEARISATIONS``)."""

    budget: araim.IntegrityBudget = araim.BUDGET_SEED004_TABLE_I
    p_sat: float = 1e-5
    p_const: float = 1e-8
    fault_modes: str = "add-v4.2"
    max_order: int = 1
    hal_m: float = 30.0
    gm_inflation: float = 0.0
    linearisation: str = "main"


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


def gm_overbound_variance(sigma_m, tau_s, dt_s):
    """sigma^2 (1 + rho) / (1 - rho), rho = exp(-dt / tau): the long-run variance of a first-order
    Gauss-Markov process sampled every ``dt_s`` (module docstring)."""
    rho = jnp.exp(-dt_s / tau_s)
    return sigma_m**2 * (1.0 + rho) / (1.0 - rho)


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
    K = araim.filter_monitor.n_bank_filters(n_t, 1, cfg.max_order, rule)
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
        fm, used = araim.filter_monitor.epoch_modes_and_used(valid, con, p_sat, p_const,
                                                             cfg.budget, rule, cfg.max_order)
        bank = araim.filter_monitor.ekf_bank_step(
            bank, _ekf.EkfInputs(m.gyro_rad_s, m.accel_m_s2, z, valid, tclk, sig_f), used,
            setup.towers, p, cfg.linearisation)
        ss = araim.separation_monitor(bank.r, bank.P[:, _ekf.POS, _ekf.POS], fm, cfg.budget)
        # seed 000's NIS + Xi-slope HPL on the same EKF (no exclusion)
        prior, phi = _ekf.ekf_predict(xi.state, m.gyro_rad_s, m.accel_m_s2, p)
        xi, ro = raim_update(xi, prior, phi, _ekf.EkfInputs(None, None, z, valid, tclk, sig_f),
                             setup.towers, araim.RaimOptions(setup.tables, 0, False, cfg.hal_m))
        # the snapshot MHSS of this epoch, linearised at the main filter's estimate
        z_hat, u = _ekf.pseudorange_model(bank.r[0], bank.clk[0], setup.towers, tclk)
        src = araim.Sources(u, con, jnp.full(n_t, var_f), jnp.full(n_t, var_f),
                            jnp.zeros(n_t), p_sat, valid)
        sn = araim.separation_kernel(src, p_const, cfg.budget, z - z_hat,
                                     araim.MHSSOptions(cfg.max_order, fault_modes=rule))
        pos_snap = bank.r[0] + sn.position_m
        hpe = jnp.stack([jnp.linalg.norm(bank.r[0, :2] - pos_e[:2]),
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
        return (world, bank, xi), (hpe, hpl, alert, bias[jnp.clip(fault.source, 0)], ss.status,
                                   ss.test_ratio, jnp.argmax(ratio), jnp.sum(tests), n_over)

    n_ep = setup.t_s.shape[0]
    xs = (jnp.arange(n_ep), setup.gyro, setup.accel, setup.t_s, setup.pos[1:n_ep + 1],
          setup.tower_clk_m)
    _, (hpe, hpl, alert, fb, st, tr, wm, n_tests, n_over) = jax.lax.scan(
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
        return summary, FilterDriveTrace(setup.t_s, hpe, hpl, alert, fb, st, tr, wm)
    return summary
