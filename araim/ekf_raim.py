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

The simulated drives that run this monitor (``simulate_drive``, ``monte_carlo_drive``) live in
``oaraim.sim.drive``; here is only what the receiver computes.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Array, Float

from oaraim.araim import ekf as _ekf
from oaraim.araim.chi2 import detection_threshold, noncentrality
from oaraim.araim.status import Status
from oaraim.errors import imu


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
    """The carry of the first epoch: ``state``, Xi = 0, no previous used set, first = True."""
    return RaimCarry(state, jnp.zeros((_ekf.N_ERR, n_towers)), jnp.zeros(n_towers, bool),
                     jnp.asarray(True))


class RaimOptions(NamedTuple):
    """What ``raim_update`` and ``run_ekf_raim`` test with: the ``tables`` of ``raim_tables``,
    the ``dof_offset`` (0: d = N_s, seed 002; 4: d = N_s - 4, seed 000), ``exclude`` (bool, may
    be traced: exclusion on) and the alert limit ``hal_m`` (m)."""

    tables: RaimTables
    dof_offset: int = 0
    exclude: bool = True
    hal_m: float = 30.0


def raim_update(carry: RaimCarry, state_prior, phi, inputs: _ekf.EkfInputs, tx_pos,
                options: RaimOptions):
    """Detection, exclusion, update, Xi and HPL for one epoch (steps 1-5 of the module doc).

    ``state_prior``/``phi`` come from ``ekf_predict``; ``inputs`` the epoch's
    ``araim.ekf.EkfInputs`` (its ``z``, ``valid``, ``tx_clk_m``, ``sigma_m``; the IMU samples
    are not read); ``tx_pos`` (L, 3); ``options`` the tables, dof offset, exclusion switch and
    HAL. Returns ``(new carry, RaimEpoch)``.
    """
    z, valid, tx_clk_m, sigma_m = inputs.z, inputs.valid, inputs.tx_clk_m, inputs.sigma_m
    tables, dof_offset, exclude, hal_m = options
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


def run_ekf_raim(state0: _ekf.EkfState, inputs: _ekf.EkfInputs,
                 tx_pos: Float[ArrayLike, "L 3"], params: _ekf.EkfParams, options: RaimOptions
                 ) -> tuple[RaimCarry, tuple[Float[Array, "E 3"], RaimEpoch]]:
    """EKF + RAIM over E epochs of recorded data (lax.scan). ``inputs``: ``araim.ekf.EkfInputs``
    stacked over E epochs (``gyro``/``accel`` (E, n, 3), ``z``/``valid``/``tx_clk_m`` (E, L),
    ``sigma_m`` scalar, (L,) or (E, L)); ``options``: ``RaimOptions``. Returns (final carry,
    (EkfOutput-like position r (E, 3), RaimEpoch stacked))."""
    carry0 = raim_init(state0, tx_pos.shape[0])
    sigma = jnp.broadcast_to(jnp.asarray(inputs.sigma_m, jnp.float64), inputs.z.shape)

    def body(carry, inp):
        prior, phi = _ekf.ekf_predict(carry.state, inp.gyro, inp.accel, params)
        carry, out = raim_update(carry, prior, phi, inp, tx_pos, options)
        return carry, (carry.state.r, out)

    return jax.lax.scan(body, carry0, inputs._replace(sigma_m=sigma))


# ------------------------------------------------------------------------------------------
# The receiver's initial uncertainty


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
    """The EKF's initial covariance P0 (17 x 17, diagonal): ``init``'s sigmas and the IMU
    biases at their stationary GM sigma of ``spec``."""
    sd = np.concatenate([np.asarray(init.att_rad, float), np.full(3, init.pos_m),
                         np.full(3, init.vel_m_s), np.full(3, spec.gyro_bias_sigma_rad_s),
                         np.full(3, spec.accel_bias_sigma_m_s2),
                         [init.clk_m, init.clk_drift_m_s]])
    return jnp.diag(jnp.asarray(sd**2))
