"""Solution-separation integrity monitor of a Kalman filter bank (docs/filter-integrity.md).

The main filter uses every valid source; one sub-filter per candidate fault mode (the slots of
the ``FaultModeRule`` template, ``araim.fault_modes.select_fault_modes``) runs the same model
without the sources that mode hypothesises faulty. All K = 1 + T filters start from the same
prior and are propagated in one ``lax.scan``. Per epoch (Brenner 1996; Joerger and Pervan,
"Kalman filter-based integrity monitoring against sensor faults", J. Guidance, Control, and
Dynamics 36(2), 2013):

    separation        Delta_i = x_i - x_0             (position part, ENU)
    its covariance    P_ss,i = P_i - P_0              (both filters optimal for one model)
    sigma_ss,i,q      sqrt(max(P_ss,i,qq, 0))          (0 below ZERO_SEPARATION_RTOL sigma_0)
    threshold         T_i,q = K_fa,q sigma_ss,i,q      K_fa of seed 004 eq. (12)
    detection         |Delta_i,q| > T_i,q for a monitored mode i and a direction q
    PLs               seed 004 eqs. (14), (16) with sigma_i,q = sqrt(P_i,qq), b = 0,
                      solved by the snapshot MHSS root finder (``araim.mhss.root``)

The fault modes, their priors, the order and P_NM are those of the snapshot MHSS at the
epoch's valid sources (same rule, same budget), so a filter that forgets everything (huge
process noise) gives the snapshot MHSS of the epoch, and a static state with no process noise
after k epochs gives the snapshot MHSS of the k epochs' measurements stacked (both tested,
tests/test_filter_monitor.py).

Two banks: ``run_linear_monitor`` (a linear model x+ = Phi x + w, z = H x + v, information-form
measurement update, exact for a diffuse prior) and ``run_ekf_monitor`` (the LTE + IMU
error-state EKF of seed 000, ``araim.ekf``: the main filter is that EKF and every sub-filter
an error-state filter about its trajectory, so P_i - P_0 is the separation's covariance;
``linearisation='own'`` keeps the earlier bank of full EKFs, each about its own estimate, whose
separations have heavier tails than P_i - P_0 says: docs/filter-integrity.md).
``separation_monitor`` turns one epoch of a bank (means and covariances) into the PLs.
Nominal biases (b_nom of the snapshot) are not modelled: the bank's model must carry them
(Gauss-Markov states or an overbounding noise; docs/filter-integrity.md).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Array, Bool, Float, Real
from scipy import special

from oaraim.araim import ekf as _ekf
from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.fault_modes import (
    DEFAULT_RULE,
    FaultModeRule,
    FaultModes,
    check_order,
    event_template,
    fault_mode_rule,
    mode_template,
    select_fault_modes,
)
from oaraim.araim.mhss.projection import ZERO_SEPARATION_RTOL, Projection
from oaraim.araim.mhss.root import PL_ITERATIONS, pls_from_projection
from oaraim.araim.status import Status

__all__ = ["AugmentedBank", "BankOptions", "BankSources", "ErrorStates", "FilterMonitorEpoch",
           "LINEARISATIONS", "LinearModel", "augmented_bank", "dense_update", "ekf_bank_step",
           "ekf_bank_step_augmented", "epoch_modes_and_used", "exclusion_restart",
           "false_alert_factors", "linear_update", "n_bank_filters", "run_ekf_monitor",
           "run_linear_monitor", "separation_monitor"]

#: how the EKF bank linearises its sub-filters: 'main' (every sub-filter an error-state filter
#: about the main filter's trajectory: one mechanization, common Phi, Q_d and H; the separation
#: is linear in the innovations and P_i - P_0 its covariance, docs/filter-integrity.md) or 'own'
#: (every sub-filter a full EKF linearised at its own estimate; its separation carries the
#: filters' different second-order terms, which P_i - P_0 does not describe)
LINEARISATIONS = ("main", "own")


class BankSources(NamedTuple):
    """The sources' fault-mode inputs: ``constellation`` (L,) int labels 0..C-1, ``p_sat`` (L,)
    or (E, L) per-epoch priors P_s, ``p_const`` (C,) per-epoch priors P_const."""

    constellation: jax.Array
    p_sat: jax.Array
    p_const: jax.Array


class BankOptions(NamedTuple):
    """Static settings of a bank (hashable): the integrity ``budget``, the fault-mode
    ``max_order`` and convention ``fault_modes``, the PL root finder's ``iterations``,
    ``exclusion`` by restart (``exclusion_restart``) and the EKF bank's ``linearisation``
    (``LINEARISATIONS``; the linear bank has one)."""

    budget: IntegrityBudget
    max_order: int = 1
    fault_modes: str | FaultModeRule = DEFAULT_RULE
    iterations: int = PL_ITERATIONS
    exclusion: bool = False
    linearisation: str = "main"


def _check_linearisation(name):
    if name not in LINEARISATIONS:
        raise ValueError(f"linearisation must be one of {LINEARISATIONS}, got {name!r}")


class FilterMonitorEpoch(NamedTuple):
    """One epoch of the solution-separation filter monitor (leading axes: whatever the caller
    scans or vmaps over; K = 1 + T filters, filter 0 the main one)."""

    hpl_m: jax.Array
    """() HPL = sqrt(PL_E^2 + PL_N^2), seed 004 eq. (15); inf where status != OK."""
    vpl_m: jax.Array
    """() VPL, eq. (16); inf where status != OK (a ground vehicle reads the HPL only)."""
    emt_m: jax.Array
    """() effective monitor threshold (vertical, modes with prior >= P_EMT)."""
    pl_enu_m: jax.Array
    """(3,) PL_E, PL_N, PL_U."""
    position_m: jax.Array
    """(3,) the main filter's position (ENU of the filter's frame)."""
    separation_m: jax.Array
    """(K, 3) x_i - x_0 (position, ENU); 0 for i = 0."""
    sigma_m: jax.Array
    """(K, 3) sqrt(P_i,qq) of each filter's position."""
    sigma_ss_m: jax.Array
    """(K, 3) sqrt(P_i,qq - P_0,qq) where the mode is monitored, else 0."""
    threshold_m: jax.Array
    """(K, 3) T_i,q = K_fa,q sigma_ss,i,q where monitored, else 0."""
    test_ratio: jax.Array
    """() max over monitored modes and q with T_i,q > 0 of |Delta_i,q| / T_i,q (0 if none)."""
    alert: jax.Array
    """() bool: some monitored separation exceeds its threshold (test_ratio > 1)."""
    prior: jax.Array
    """(K,) P_f of the monitored modes, 0 otherwise (0 for i = 0)."""
    monitored: jax.Array
    """(K,) bool: the mode is live at this epoch (False for i = 0)."""
    n_modes: jax.Array
    """() N_f, the monitored modes."""
    p_not_monitored: jax.Array
    """() P_NM of eqs. (14), (16)."""
    status: jax.Array
    """() ``araim.Status`` (int8)."""
    excluded_sources: jax.Array
    """(L,) bool: the sources excluded so far (``exclusion=True`` of the banks; else none)."""


def n_bank_filters(n_sources: int, n_constellations: int, max_order: int = 1,
                   fault_modes=DEFAULT_RULE) -> int:
    """K = 1 + T: the main filter and one sub-filter per template slot of ``fault_modes`` at
    ``max_order`` for L sources and C constellation slots."""
    rule = fault_mode_rule(fault_modes)
    if rule.events:
        return 1 + event_template(n_sources, n_constellations, max_order).order.size
    return 1 + mode_template(n_sources, n_constellations, max_order).order.size


def false_alert_factors(n_modes, n_slots: int, budget: IntegrityBudget):
    """K_fa (3, ...) of seed 004 eq. (12) for N_f = ``n_modes`` (N_f = 0 read as 1):
    K_fa,H = Q^-1(P_FA_H / (4 N_f)), K_fa,V = Q^-1(P_FA_V / (2 N_f)), the budgets divided by
    ``n_es_cont``. The table over N_f = 0..n_slots is evaluated on the host, as the snapshot
    MHSS does (``araim.mhss.projection``), so both give the same bits."""
    nf = np.maximum(np.arange(n_slots + 1), 1)
    pfa_h, pfa_v = budget.p_fa_h / budget.n_es_cont, budget.p_fa_v / budget.n_es_cont
    k_h = jnp.take(jnp.asarray(-special.ndtri(pfa_h / (4.0 * nf))), n_modes)
    k_v = jnp.take(jnp.asarray(-special.ndtri(pfa_v / (2.0 * nf))), n_modes)
    return jnp.stack([k_h, k_h, k_v], axis=0)


def _epoch_modes(valid, constellation, p_sat, p_const, budget, rule, max_order):
    """``select_fault_modes`` of one epoch (batch of one, batch-last inside)."""
    return select_fault_modes(valid[:, None], constellation[:, None], p_sat[:, None],
                              p_const[:, None], budget, rule, max_order)


def separation_monitor(x_pos: Float[ArrayLike, "K 3"], p_pos: Float[ArrayLike, "K 3 3"],
                       fm: FaultModes, budget: IntegrityBudget,
                       iterations: int = PL_ITERATIONS) -> FilterMonitorEpoch:
    """The monitor of one epoch from the bank's position estimates ``x_pos`` (K, 3), their
    covariances ``p_pos`` (K, 3, 3) (ENU, m, m^2; filter 0 the main one) and the epoch's fault
    modes ``fm`` (``select_fault_modes`` with a batch of one, T = K - 1 slots). Jit-safe; vmap
    it over drives. Returns ``FilterMonitorEpoch``."""
    K = x_pos.shape[0]
    var = jnp.diagonal(p_pos, axis1=-2, axis2=-1)  # (K, 3)
    finite = jnp.all(jnp.isfinite(var), axis=1) & jnp.all(jnp.isfinite(x_pos), axis=1)
    ok_var = finite & jnp.all(var > 0.0, axis=1)
    live = jnp.concatenate([jnp.zeros((1,), bool), fm.live[:, 0]])
    monitored = live & ok_var
    usable = monitored.at[0].set(ok_var[0])
    sigma = jnp.sqrt(jnp.where(usable[:, None], var, 1.0))
    ss2 = jnp.where(monitored[:, None], var - var[:1], 0.0)
    sigma_ss = jnp.sqrt(jnp.maximum(ss2, 0.0))
    sigma_ss = jnp.where(sigma_ss <= ZERO_SEPARATION_RTOL * sigma[:1], 0.0, sigma_ss)
    n_modes = jnp.sum(monitored)
    k_fa = false_alert_factors(n_modes, K - 1, budget)  # (3,)
    threshold = jnp.where(monitored[:, None], k_fa[None] * sigma_ss, 0.0)
    prior_all = jnp.concatenate([jnp.zeros((1,)), fm.prior[:, 0]])
    prior = jnp.where(monitored, prior_all, 0.0)
    p_nm = fm.p_beyond_order[0] + jnp.sum(jnp.where(live & ~ok_var, prior_all, 0.0))
    sep = jnp.where(usable[:, None], x_pos - x_pos[:1], 0.0)
    status = jnp.where(~ok_var[0], Status.SINGULAR_GEOMETRY,
                       jnp.where(p_nm > budget.p_thresh, Status.UNMONITORED_RISK, Status.OK))
    status = jnp.asarray(status, jnp.int8)
    b = lambda x: x[..., None]  # noqa: E731  (batch of one, last)
    pr = Projection(
        s_pos=None, sigma=b(sigma), bias=jnp.zeros((K, 3, 1)), sigma_ss=b(sigma_ss),
        threshold=b(threshold), monitored=b(monitored), prior=b(prior),
        excluded=jnp.concatenate([jnp.zeros_like(fm.excluded[:1]), fm.excluded]),
        n_modes=b(n_modes), p_not_monitored=b(p_nm), order=fm.order, status=b(status),
        sigma_acc_u=b(sigma[0, 2]))
    pl, status, emt = pls_from_projection(pr, budget, iterations)
    pl, status, emt = pl[:, 0], status[0], emt[0]
    ok = status == Status.OK
    pl_ok = jnp.where(ok, pl[:2], 0.0)
    hpl = jnp.where(ok, jnp.sqrt(pl_ok[0] ** 2 + pl_ok[1] ** 2), jnp.inf)
    # a zero threshold (sigma_ss = 0: the mode's separation has no variance, as for a source
    # no other source can check) tests nothing: tau = 0 as in the snapshot; the PL equation gives
    # such a mode no detection credit (its term is P_f Q(PL / sigma_i)). In an EKF bank the
    # separation there is linearisation noise, not a fault signature
    ratio = jnp.where(threshold > 0.0,
                      jnp.abs(sep) / jnp.where(threshold > 0.0, threshold, 1.0), 0.0)
    test = jnp.max(ratio)
    return FilterMonitorEpoch(
        hpl_m=hpl, vpl_m=pl[2], emt_m=emt, pl_enu_m=pl, position_m=x_pos[0], separation_m=sep,
        sigma_m=sigma, sigma_ss_m=sigma_ss, threshold_m=threshold, test_ratio=test,
        alert=test > 1.0, prior=prior, monitored=monitored, n_modes=n_modes,
        p_not_monitored=p_nm, status=status,
        excluded_sources=jnp.zeros(fm.excluded.shape[1], bool))


def exclusion_restart(bank, out: FilterMonitorEpoch, fm, excluded_sources, enabled):
    """Exclusion by restart (Brenner 1996's bank, the restart variant): where ``enabled`` and
    the epoch alerts, the sub-filter whose separation exceeds its threshold the most (largest
    max_q |Delta_i,q| / T_i,q) becomes the main filter, its mode's sources are excluded from
    then on, and every filter of the bank restarts as a copy of it (state and covariance), so
    the new sub-filters (that mode's exclusion plus each other mode's) begin with zero
    separation. Returns (bank, excluded sources (L,), the epoch's output with them).
    ``enabled`` False (static): nothing is done (no select over the bank)."""
    if enabled is False:
        return bank, excluded_sources, out._replace(excluded_sources=excluded_sources)
    thr = out.threshold_m
    ratio = jnp.max(jnp.where(thr > 0.0, jnp.abs(out.separation_m)
                              / jnp.where(thr > 0.0, thr, 1.0), 0.0), axis=1)
    best = jnp.argmax(ratio)
    do = enabled & out.alert
    sets = jnp.concatenate([jnp.zeros_like(fm.excluded[:1, :, 0]), fm.excluded[:, :, 0]])
    excluded_sources = excluded_sources | (do & sets[best])
    bank = jax.tree.map(lambda a: jnp.where(do, jnp.broadcast_to(a[best], a.shape), a), bank)
    return bank, excluded_sources, out._replace(excluded_sources=excluded_sources)


def epoch_modes_and_used(valid, constellation, p_sat, p_const, budget, rule, max_order):
    """The epoch's fault modes and each filter's used sources (K, L): filter 0 every valid
    source, filter i the valid sources slot i does not exclude."""
    fm = _epoch_modes(valid, constellation, p_sat, p_const, budget, rule, max_order)
    used = jnp.concatenate([valid[None], valid[None] & ~fm.excluded[:, :, 0]], axis=0)
    return fm, used


# ------------------------------------------------------------------------------------------
# A linear model


class LinearModel(NamedTuple):
    """x_{k} = Phi_k x_{k-1} + w_k, w_k ~ N(0, Q_k); z_k = H_k x_k + v_k, v_k ~ N(0, diag(R_k)).
    The first three states are the position (east, north, up, m). Each field carries a leading
    epoch axis E (``run_linear_monitor`` scans over it)."""

    phi: jax.Array
    """(E, n, n) transition over the interval ending at epoch k."""
    q: jax.Array
    """(E, n, n) process noise covariance of that interval."""
    h: jax.Array
    """(E, L, n) measurement rows."""
    r_var: jax.Array
    """(E, L) measurement variances, m^2."""


def _spd_inv(a):
    """Inverse of a small SPD matrix by Cholesky (symmetrized)."""
    c = jax.scipy.linalg.cho_factor(a, lower=True)
    inv = jax.scipy.linalg.cho_solve(c, jnp.eye(a.shape[-1], dtype=a.dtype))
    return 0.5 * (inv + inv.T)


def linear_update(x, p, h, z, r_var, used):
    """Kalman measurement update in information form (one filter): P+ = (P^-1 + H^T W H)^-1,
    x+ = x + P+ H^T W (z - H x), W = diag(1 / R) on the used rows, 0 elsewhere. Algebraically
    the covariance-form update; exact where P is diffuse (a prior of 1e12 m^2 adds 1e-12 to the
    information instead of subtracting nearly equal numbers)."""
    w = jnp.where(used, 1.0 / jnp.where(used, r_var, 1.0), 0.0)
    info = _spd_inv(p) + (h * w[:, None]).T @ h
    p_new = _spd_inv(info)
    nu = jnp.where(used, z - h @ x, 0.0)
    return x + p_new @ (h.T @ (w * nu)), p_new


def _bank_setup(shape, sources: BankSources, options: BankOptions):
    """(rule, max_order, constellation, p_sat (E, L), p_const, K) of a bank over ``shape`` =
    (E, L) epochs and sources."""
    rule = fault_mode_rule(options.fault_modes)
    max_order = check_order(rule, options.max_order)
    E, L = shape
    p_const = jnp.asarray(sources.p_const, jnp.float64)
    K = n_bank_filters(L, p_const.shape[-1], max_order, rule)
    p_sat = jnp.broadcast_to(jnp.asarray(sources.p_sat, jnp.float64), (E, L))
    return rule, max_order, jnp.asarray(sources.constellation), p_sat, p_const, K


def run_linear_monitor(x0: Real[ArrayLike, " n"], p0: Real[ArrayLike, "n n"],
                       model: LinearModel, z: Real[ArrayLike, "E L"],
                       valid: Bool[ArrayLike, "E L"], sources: BankSources,
                       options: BankOptions
                       ) -> tuple[tuple[Float[Array, "K n"], Float[Array, "K n n"]],
                                  FilterMonitorEpoch]:
    """The filter bank on a linear model over E epochs (one ``lax.scan``).

    ``x0`` (n,), ``p0`` (n, n): the common prior of every filter; ``z``, ``valid`` (E, L);
    ``sources`` (``BankSources``: labels, P_s (E, L) or (L,), P_const (C,)); ``options``
    (``BankOptions``, static; its ``linearisation`` is not used). Per epoch: predict every
    filter (x <- Phi x, P <- Phi P Phi^T + Q), update filter i with its used sources
    (``linear_update``), then ``separation_monitor``; ``options.exclusion`` then
    ``exclusion_restart`` (the excluded sources are not valid afterwards). Returns (final
    (x (K, n), P (K, n, n)), ``FilterMonitorEpoch`` stacked over epochs)."""
    budget, iterations, exclusion = options.budget, options.iterations, options.exclusion
    rule, max_order, constellation, p_sat, p_const, K = _bank_setup(z.shape, sources, options)
    E, L = z.shape
    xs = jnp.broadcast_to(jnp.asarray(x0, jnp.float64), (K,) + x0.shape)
    ps = jnp.broadcast_to(jnp.asarray(p0, jnp.float64), (K,) + p0.shape)

    def body(carry, inp):
        x, p, gone = carry
        phi, q, h, r_var, zz, vv, ps_e = inp
        fm, used = epoch_modes_and_used(vv & ~gone, constellation, ps_e, p_const, budget, rule,
                                        max_order)
        x = x @ phi.T
        p = phi @ p @ phi.T + q
        x, p = jax.vmap(linear_update, in_axes=(0, 0, None, None, None, 0))(x, p, h, zz, r_var,
                                                                          used)
        out = separation_monitor(x[:, :3], p[:, :3, :3], fm, budget, iterations)
        (x, p), gone, out = exclusion_restart((x, p), out, fm, gone, exclusion)
        return (x, p, gone), out

    (x, p, _), out = jax.lax.scan(body, (xs, ps, jnp.zeros(L, bool)), (
        model.phi, model.q, model.h, model.r_var, z, jnp.asarray(valid, bool), p_sat))
    return (x, p), out


# ------------------------------------------------------------------------------------------
# The seed 000 LTE + IMU error-state EKF


def _offsets(states: _ekf.EkfState):
    """delta_i (K, 17): each filter's nominal state minus filter 0's in the error-state
    coordinates (attitude: theta with q_i = dq(theta) (x) q_0, the others additive)."""
    th = jax.vmap(_ekf.attitude_error, (0, None))(states.q, states.q[0])
    return jnp.concatenate([th, states.r - states.r[0], states.v - states.v[0],
                            states.bg - states.bg[0], states.ba - states.ba[0],
                            states.clk - states.clk[0]], axis=-1)


def _about(main: _ekf.EkfState, delta, p) -> _ekf.EkfState:
    """The bank (K leading) whose filter i is ``main`` with the offset ``delta`` (K, 17) injected
    and covariance ``p`` (K, 17, 17); filter 0 is ``main`` itself, bit for bit."""
    q = _ekf.quat_multiply(_ekf.error_quat(delta[:, _ekf.TH]), main.q[None])
    q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
    bank = _ekf.EkfState(q, main.r + delta[:, _ekf.POS], main.v + delta[:, _ekf.VEL],
                         main.bg + delta[:, _ekf.BG], main.ba + delta[:, _ekf.BA],
                         main.clk + delta[:, _ekf.CLK], p)
    return jax.tree.map(lambda b, m: b.at[0].set(m), bank, main)


def _bank_step_main(states: _ekf.EkfState, inputs: _ekf.EkfInputs, used, tx_pos, params):
    """Every sub-filter an error-state filter about the main filter's trajectory (module
    docstring of ``LINEARISATIONS``): the main filter is the seed 000 EKF (``ekf_step``'s
    operations); sub-filter i carries its offset delta_i from the main nominal state, predicted
    with the main interval's Phi (delta_i <- Phi delta_i, P_i <- Phi P_i Phi^T + Q_d) and
    updated with the main filter's innovations nu = z - h(x_0) and rows H:
    delta_i <- delta_i + K_i (nu - H delta_i); the main's correction dx_0 then moves the
    reference, delta_i <- delta_i - dx_0."""
    main = jax.tree.map(lambda a: a[0], states)
    delta = _offsets(states)
    main, phi, qd = _ekf.ekf_propagate(main, inputs.gyro, inputs.accel, params)
    delta = delta @ phi.T
    p = phi @ states.P @ phi.T + qd
    p = 0.5 * (p + jnp.swapaxes(p, -1, -2))
    z_hat, u = _ekf.pseudorange_model(main.r, main.clk, tx_pos, inputs.tx_clk_m)
    r_var = jnp.broadcast_to(jnp.asarray(inputs.sigma_m, jnp.float64) ** 2, z_hat.shape)
    nu = inputs.z - z_hat
    dx0, p0, _ = _ekf.error_state_update(main.P, nu, u, r_var, used[0])
    main = _ekf.inject(main, dx0, p0)
    nu_i = nu[None] - (delta[:, _ekf.POS] @ u.T + delta[:, 15:16])
    dx, p, _ = jax.vmap(_ekf.error_state_update, in_axes=(0, 0, None, None, 0))(
        p, nu_i, u, r_var, used)
    return _about(main, delta + dx - dx0[None], p)


def ekf_bank_step(states: _ekf.EkfState, inputs: _ekf.EkfInputs, used, tx_pos, params,
                  linearisation: str = "main"):
    """Predict and update every EKF of the bank (leading axis K of ``states`` and ``used``
    (K, L); ``inputs`` one epoch's ``araim.ekf.EkfInputs``, its ``valid`` not read: ``used``
    says what each filter uses; ``tx_pos`` (L, 3); ``params`` ``araim.ekf.EkfParams``).
    Filter 0, the main one, is the seed 000 EKF (``araim.ekf.ekf_step``) either way;
    ``linearisation`` (``LINEARISATIONS``, static) 'main': the sub-filters are error-state
    filters about the main filter's trajectory (``_bank_step_main``); 'own': each a full EKF
    with its own nominal state, linearised at its own estimate. Returns the new states."""
    _check_linearisation(linearisation)
    if linearisation == "main":
        return _bank_step_main(states, inputs, used, tx_pos, params)

    def one(st, u):
        st, _ = _ekf.ekf_step(st, inputs._replace(valid=u), tx_pos, params)
        return st

    return jax.vmap(one)(states, used)


def run_ekf_monitor(state0: _ekf.EkfState, inputs: _ekf.EkfInputs,
                    tx_pos: Float[ArrayLike, "L 3"], params: _ekf.EkfParams,
                    sources: BankSources, options: BankOptions
                    ) -> tuple[_ekf.EkfState, FilterMonitorEpoch]:
    """The filter bank on the seed 000 EKF over E epochs (one ``lax.scan``); ``inputs``
    (``araim.ekf.EkfInputs`` stacked over E epochs: ``gyro``, ``accel`` (E, n, 3); ``z``,
    ``valid``, ``tx_clk_m`` (E, L); ``sigma_m`` scalar, (L,) or (E, L)), ``tx_pos`` (L, 3), the
    towers' operator labels and priors ``sources`` (``BankSources``), ``options``
    (``BankOptions``, static: budget, order, convention, exclusion by restart, linearisation).
    Every filter starts from ``state0``. Returns (final bank states, ``FilterMonitorEpoch``
    stacked over epochs); the position is ENU in the filter's frame G."""
    budget, iterations, exclusion = options.budget, options.iterations, options.exclusion
    _check_linearisation(options.linearisation)
    z = inputs.z
    rule, max_order, constellation, p_sat, p_const, K = _bank_setup(z.shape, sources, options)
    E, L = z.shape
    sigma = jnp.broadcast_to(jnp.asarray(inputs.sigma_m, jnp.float64), (E, L))
    bank0 = jax.tree.map(lambda a: jnp.broadcast_to(a, (K,) + a.shape), state0)

    def body(carry, inp):
        bank, gone = carry
        g, a, zz, vv, tc, ps_e, sg = inp
        fm, used = epoch_modes_and_used(vv & ~gone, constellation, ps_e, p_const, budget, rule,
                                        max_order)
        bank = ekf_bank_step(bank, _ekf.EkfInputs(g, a, zz, vv, tc, sg), used, tx_pos, params,
                             options.linearisation)
        out = separation_monitor(bank.r, bank.P[:, _ekf.POS, _ekf.POS], fm, budget, iterations)
        bank, gone, out = exclusion_restart(bank, out, fm, gone, exclusion)
        return (bank, gone), out

    (bank, _), out = jax.lax.scan(body, (bank0, jnp.zeros(L, bool)), (
        inputs.gyro, inputs.accel, z, jnp.asarray(inputs.valid, bool), inputs.tx_clk_m, p_sat,
        sigma))
    return bank, out


# ------------------------------------------------------------------------------------------
# The EKF bank with correlated measurement-error states


class ErrorStates(NamedTuple):
    """m additive states of the pseudorange errors appended to the EKF's 17 (a Gauss-Markov
    multipath or clock deviation, a calibration's residual line, ...): per measurement interval
    x_a <- ``phi`` x_a + w, w ~ N(0, ``q``) ((m, m) each), and each pseudorange's modelled error
    ``h`` x_a (``h`` (L, m)); ``p0`` (m, m) their prior covariance (uncorrelated with the 17).
    The caller builds them for its world (``sim.filter_drive.tower_error_states``)."""

    phi: jax.Array
    q: jax.Array
    h: jax.Array
    p0: jax.Array


class AugmentedBank(NamedTuple):
    """A bank whose filters carry ``ErrorStates``: ``ekf`` the EKF states (K leading, ``P``
    (K, 17 + m, 17 + m) over the error state [seed 000's 17, the m error states]), ``x_a``
    (K, m) the error states' estimates."""

    ekf: _ekf.EkfState
    x_a: jax.Array


def augmented_bank(state0: _ekf.EkfState, errs: ErrorStates, n_filters: int) -> AugmentedBank:
    """The bank of ``n_filters`` filters at ``state0`` (P (17, 17)) with the error states at
    zero and their prior ``errs.p0`` (block diagonal with state0's P)."""
    m = errs.p0.shape[-1]
    p = jnp.zeros((_ekf.N_ERR + m,) * 2).at[:_ekf.N_ERR, :_ekf.N_ERR].set(state0.P)
    p = p.at[_ekf.N_ERR:, _ekf.N_ERR:].set(errs.p0)
    st = state0._replace(P=p)
    bank = jax.tree.map(lambda a: jnp.broadcast_to(a, (n_filters,) + a.shape), st)
    return AugmentedBank(bank, jnp.zeros((n_filters, m)))


def _block_diag(a, b):
    n, m = a.shape[-1], b.shape[-1]
    out = jnp.zeros((n + m, n + m), jnp.result_type(a, b))
    return out.at[:n, :n].set(a).at[n:, n:].set(b)


def dense_update(P: Float[ArrayLike, "n n"], nu: Float[ArrayLike, " L"],
                 h: Float[ArrayLike, "L n"], r_var: Float[ArrayLike, " L"],
                 used: Bool[ArrayLike, " L"]) -> tuple[Float[Array, " n"], Float[Array, "n n"]]:
    """Kalman update of an error state with dense rows ``h`` (L, n) (masked by ``used`` (L,)),
    innovations ``nu`` (L,) and variances ``r_var`` (L,); the Joseph form expanded as in
    ``araim.ekf.kalman_update``. Returns (dx (n,), P+ (n, n))."""
    hu = h * used[:, None]
    pht = P @ hu.T
    s = hu @ pht + jnp.diag(jnp.where(used, r_var, 1.0))
    s_inv = _ekf.spd_inverse(0.5 * (s + s.T))
    k = pht @ s_inv
    dx = k @ jnp.where(used, nu, 0.0)
    p = P + jnp.concatenate([k @ s - pht, -k], 1) @ jnp.concatenate([k, pht], 1).T
    return dx, 0.5 * (p + p.T)


def ekf_bank_step_augmented(bank: AugmentedBank, inputs: _ekf.EkfInputs,
                            used: Bool[ArrayLike, "K L"], tx_pos: Float[ArrayLike, "L 3"],
                            params: _ekf.EkfParams, errs: ErrorStates) -> AugmentedBank:
    """``ekf_bank_step`` (sub-filters about the main filter's trajectory) for filters whose
    error state carries ``errs``: the main filter predicts z = range + clock - tx clock +
    ``errs.h`` x_a and updates the 17 + m states; each sub-filter's offset delta_i (17 + m) is
    propagated with the block-diagonal Phi and updated with the main innovations, as in
    ``ekf_bank_step``. Returns the new bank."""
    n17 = _ekf.N_ERR
    main = jax.tree.map(lambda a: a[0], bank.ekf)
    delta = jnp.concatenate([_offsets(bank.ekf), bank.x_a - bank.x_a[0]], -1)
    main, phi17, qd17 = _ekf.ekf_propagate(main._replace(P=main.P[:n17, :n17]), inputs.gyro,
                                           inputs.accel, params)
    phi = _block_diag(phi17, errs.phi)
    delta = delta @ phi.T
    p = phi @ bank.ekf.P @ phi.T + _block_diag(qd17, errs.q)
    p = 0.5 * (p + jnp.swapaxes(p, -1, -2))
    x_a0 = errs.phi @ bank.x_a[0]
    z_hat, u = _ekf.pseudorange_model(main.r, main.clk, tx_pos, inputs.tx_clk_m)
    nu = inputs.z - (z_hat + errs.h @ x_a0)
    h = jnp.concatenate([_ekf.jacobian_rows(u), errs.h], 1)
    r_var = jnp.broadcast_to(jnp.asarray(inputs.sigma_m, jnp.float64) ** 2, z_hat.shape)
    dx0, p0 = dense_update(p[0], nu, h, r_var, used[0])
    main = _ekf.inject(main, dx0[:n17], p0)
    x_a0 = x_a0 + dx0[n17:]
    dx, p = jax.vmap(dense_update, in_axes=(0, 0, None, None, 0))(
        p, nu[None] - delta @ h.T, h, r_var, used)
    delta = delta + dx - dx0[None]
    x_a = (x_a0[None] + delta[:, n17:]).at[0].set(x_a0)
    return AugmentedBank(_about(main, delta[:, :n17], p), x_a)
