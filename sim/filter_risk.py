"""The drive's filter bank risk by conditional Monte Carlo (docs/filter-integrity.md, "The
conditional risk estimate"): ``araim.filter_risk`` eq. (1) on ``simulate_filter_drive``.

The EKF bank is linear in the measurement errors to first order about the main filter's
trajectory. A fault's response r_i (each filter's deterministic error) is the difference of a
faulted and a fault-free run with the same key (the same world, the same noise): that
difference carries the bank's linearisation of the fault, which a bank run on the fault alone
could not. The magnitude enters linearly to first order, so one faulted run at a reference
magnitude m_ref serves every magnitude of the quadrature (r(m) = (m / m_ref) r(m_ref);
``drive_linearity`` measures how far from linear the bank is). The HPL, thresholds and P_0 are
the faulted run's (they move with the linearisation point, to second order in the error).
"""

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from oaraim import araim
from oaraim.errors import ErrorModel
from oaraim.sim.drive import DriveSetup
from oaraim.sim.faults import FaultScenario, no_fault
from oaraim.sim.filter_drive import DEFAULT_CONFIG, FilterDriveConfig, simulate_filter_drive

__all__ = ["DriveResponse", "drive_epoch_risks", "drive_response", "drive_validation_counts"]


class DriveResponse(NamedTuple):
    """One drive's fault response (E epochs, K filters)."""

    r0_m: jax.Array
    """(E, 3) the main filter's position, faulted minus fault-free run."""
    separation_mean_m: jax.Array
    """(E, K, 3) the separations, faulted minus fault-free run: r_i - r_0."""
    p0_h_m2: jax.Array
    """(E, 2, 2) the faulted run's main horizontal covariance."""
    hpl_m: jax.Array
    """(E,) the faulted run's HPL."""
    sigma_ss_m: jax.Array
    """(E, K, 3)."""
    threshold_m: jax.Array
    """(E, K, 3)."""
    error_m: jax.Array
    """(E, 3) the faulted run's main filter error (estimate - truth)."""
    separation_m: jax.Array
    """(E, K, 3) the faulted run's separations."""
    alert: jax.Array
    """(E,) the faulted run's alerts."""


@partial(jax.jit, static_argnames=("cfg",))
def drive_response(key, setup: DriveSetup, err: ErrorModel, fault: FaultScenario,
                   cfg: FilterDriveConfig = DEFAULT_CONFIG, filter_sigma_pr_m=0.0):
    """``DriveResponse`` of ``fault`` on the drive of ``key`` (``simulate_filter_drive``'s
    arguments; two runs, faulted and fault-free)."""
    _, tf = simulate_filter_drive(key, setup, err, fault, cfg, filter_sigma_pr_m, traces=True)
    _, t0 = simulate_filter_drive(key, setup, err, no_fault(), cfg, filter_sigma_pr_m,
                                  traces=True)
    return _response(tf, t0.monitor)


def _response(tf, m0):
    mf = tf.monitor
    return DriveResponse(mf.position_m - m0.position_m, mf.separation_m - m0.separation_m,
                         tf.p0_h_m2, mf.hpl_m, mf.sigma_ss_m, mf.threshold_m,
                         mf.position_m - tf.truth_m, mf.separation_m, mf.alert)


def drive_epoch_risks(resp: DriveResponse, scale, hpl_fraction=1.0):
    """Eq. (1) at every epoch with the response scaled by each of ``scale`` (G,) (m / m_ref)
    against ``hpl_fraction`` x HPL. Jit-safe; returns ``araim.filter_risk.EpochRisk`` (G, E)."""
    g = jnp.asarray(scale, jnp.float64)[:, None]
    return araim.epoch_risk_bound(
        resp.p0_h_m2[None], g[..., None] * resp.r0_m[None, :, :2],
        hpl_fraction * resp.hpl_m[None], g[..., None, None] * resp.separation_mean_m[None],
        resp.sigma_ss_m[None], resp.threshold_m[None])


def drive_validation_counts(resp: DriveResponse, t_s, fault: FaultScenario, hpl_fraction):
    """The crude check of eq. (1) on the faulted run of ``resp`` (as the UAV flight's
    ``validation_counts``): per at-risk epoch B_k = {|e_0,H| > c HPL} and {|Delta_i*,q*| <=
    T_i*,q*}, counted and its probability summed, and {|e_0,H| > c HPL and no alert}; and
    eq. (1) itself (c = 1) on the run, summed and its largest value. Returns (observed B,
    expected B, observed HMI at c, at-risk epochs, sum of P(A_k), largest P(A_k))."""
    er = jax.tree.map(lambda a: a[0], drive_epoch_risks(resp, jnp.ones(1), hpl_fraction))
    e0 = jnp.linalg.norm(resp.error_m[:, :2], axis=-1)
    outside = e0 > hpl_fraction * resp.hpl_m
    idx = jnp.arange(e0.shape[0])
    d = resp.separation_m[idx, er.mode, er.direction]
    t = resp.threshold_m[idx, er.mode, er.direction]
    quiet = jnp.where(t > 0.0, jnp.abs(d) <= t, True)
    risk = jnp.asarray(t_s) >= jnp.where(fault.source >= 0, fault.onset_s, -jnp.inf)
    p1 = jnp.where(risk, drive_epoch_risks(resp, jnp.ones(1)).p_hmi_bound[0], 0.0)
    return (jnp.sum(outside & quiet & risk), jnp.sum(jnp.where(risk, er.p_hmi_bound, 0.0)),
            jnp.sum(outside & ~resp.alert & risk), jnp.sum(risk), jnp.sum(p1), jnp.max(p1))
