"""Fault detection and exclusion with measurements (seed 004 eq. 13 and section IV-B).

Given the residual vector y = z - z_hat of the all-in-view linearisation point (Section III-C),
the solution separations are Delta x^(i) = (S^(i) - S^(0)) y, the test coefficients
tau_i,q = |Delta x_q^(i)| / T_i,q (eq. 13), and a fault is detected when any tau exceeds 1 over
the monitored modes and the three directions.

Exclusion (our rule, after the ADD v3.0 section 2.6 exclusion function): every monitored fault
mode is a candidate; its kept sources become a new all-in-view set whose own fault modes,
thresholds and separations are recomputed with the same residual. Candidates whose own test
passes and whose PLs are available are acceptable; the one whose subset fits y best (smallest
weighted sum of squared residuals, weights C_int^-1) is chosen, and the PLs reported are those of
that subset. The ADD additionally inflates the PLs after exclusion for the probability of a wrong
exclusion; we do not (stated in the README).
"""

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Float, Real

from oaraim.araim import linalg
from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.fault_modes import DEFAULT_RULE, to_batch_first, to_batch_last
from oaraim.araim.mhss import (
    PL_ITERATIONS,
    MHSSOptions,
    MHSSResult,
    Sources,
    as_options,
    batch_last_inputs,
    check_options,
    kernel_options,
    pls_from_projection,
    prepare_inputs,
    project,
    required_order,
)
from oaraim.araim.status import Status
from oaraim.araim.validate import batch_source
from oaraim.batching import bucket, is_traced, jit_kernel, pad_rows, unpad


class Separation(NamedTuple):
    """The solution-separation test of ``solution_separation`` and ``separation_kernel``, per
    fault mode (axis K, mode 0 the all-in-view solution) and direction (east, north, up)."""

    separation_m: jax.Array
    """(..., K, 3) Delta x_q^(i), ENU (mode 0: zeros)."""
    threshold_m: jax.Array
    """(..., K, 3) T_i,q, eq. (12)."""
    tau: jax.Array
    """(..., K, 3) eq. (13); 0 where the mode is not monitored or T = separation = 0."""
    monitored: jax.Array
    """(..., K) bool: the mode is monitored."""
    excluded: jax.Array
    """(..., K, L) bool: sources hypothesised faulty per mode."""
    prior: jax.Array
    """(..., K) P_f^(i) of the monitored modes, 0 otherwise."""
    detected: jax.Array
    """(...) bool: any tau > 1."""
    position_m: jax.Array
    """(..., 3) all-in-view correction S^(0) y, ENU."""
    pl: MHSSResult
    """The all-in-view protection levels."""


class FDEResult(NamedTuple):
    """Detection and exclusion of ``detect_and_exclude`` and ``detect_and_exclude_kernel``."""

    detected: jax.Array
    """(...) bool: the all-in-view test failed."""
    excluded: jax.Array
    """(..., L) bool: sources excluded (none when nothing was detected)."""
    exclusion_mode: jax.Array
    """(...) index of the excluded mode (K axis), -1 if none."""
    tau: jax.Array
    """(..., K, 3) the all-in-view test coefficients."""
    position_m: jax.Array
    """(..., 3) correction of the solution kept (after exclusion), ENU."""
    pl: MHSSResult
    """PLs of the solution kept; status EXCLUSION_FAILED (inf) if no candidate passes."""
    status: jax.Array
    """(...) ``araim.Status`` of the solution kept."""


def _separation_flat(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, y,
                     budget, max_order, weighting, iterations, fault_modes=DEFAULT_RULE):
    args = batch_last_inputs(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid)
    pr = project(Sources(*args[:6], args[7]), args[6], budget,
                 MHSSOptions(max_order, weighting, fault_modes, None, iterations))
    yl = to_batch_last(y, 1)  # (L, B)
    y_ok = jnp.isfinite(yl) | ~args[7]
    # a non-finite residual of a valid source: nothing claimed (no detection, no exclusion)
    pr = pr._replace(status=jnp.where(jnp.all(y_ok, axis=0), pr.status, Status.INVALID_INPUT)
                     .astype(pr.status.dtype))
    yl = jnp.where(args[7] & y_ok, yl, 0.0)
    shift = jnp.sum(pr.s_pos * yl[None, None], axis=2)  # (K, 3, B)
    sep = jnp.where(pr.monitored[:, None], shift - shift[:1], 0.0)
    sep = jnp.where(pr.threshold > 0, sep, 0.0)  # zero threshold = zero separation (Thm 1)
    tau = jnp.where(pr.threshold > 0, jnp.abs(sep) / jnp.where(pr.threshold > 0,
                                                              pr.threshold, 1.0), 0.0)
    detected = jnp.any(tau > 1.0, axis=(0, 1)) & (pr.status == Status.OK)
    pl, status, emt = pls_from_projection(pr, budget, iterations)
    ok = status == Status.OK
    res = MHSSResult(jnp.sqrt(pl[0] ** 2 + pl[1] ** 2), pl[2], emt,
                     jnp.where(ok, pr.sigma_acc_u, jnp.inf), pr.n_modes, pr.p_not_monitored,
                     status, pr.order, pl, jnp.zeros_like(detected))
    b = (g.shape[0],)
    return Separation(
        to_batch_first(sep, b), to_batch_first(pr.threshold, b), to_batch_first(tau, b),
        to_batch_first(pr.monitored, b), to_batch_first(pr.excluded, b),
        to_batch_first(pr.prior, b), detected, to_batch_first(shift[0], b),
        MHSSResult(*(to_batch_first(x, b) for x in res)))


def _flatten(arrays, batch):
    """The arrays with their batch axes ``batch`` flattened into one."""
    return [x.reshape((-1,) + x.shape[len(batch):]) for x in arrays]


_STATIC = ("budget", "max_order", "weighting", "iterations", "fault_modes")


@partial(jit_kernel, static_argnames=_STATIC)
def _separation(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, y, budget,
                max_order, weighting="int", iterations=PL_ITERATIONS, fault_modes=DEFAULT_RULE):
    batch = g.shape[:-2]
    out = _separation_flat(*_flatten((g, constellation, var_int, var_acc, b_nom, p_sat, p_const,
                                      valid, y), batch), budget, max_order, weighting, iterations,
                           fault_modes)
    return jax.tree.map(lambda x: x.reshape(batch + x.shape[1:]), out)


def weighted_sse(g, constellation, var_int, valid, y, n_constellations):
    """Weighted sum of squared residuals (weights C_int^-1) of the least-squares fit of y on the
    valid rows, one clock per constellation: the score by which ``detect_and_exclude`` picks
    among acceptable candidate subsets. JAX, batch first: g (..., L, 3), the others (..., L),
    ``n_constellations`` static; inf where the fit is singular."""
    C = n_constellations
    g = jnp.where(valid[..., None], g, 0.0)
    w = linalg.inverse_variance_weights(jnp.sqrt(jnp.where(valid, var_int, 1.0)), valid)
    y = jnp.where(valid, y, 0.0)
    member = valid[..., :, None] & (constellation[..., :, None] == jnp.arange(C))
    cols = [g[..., 0], g[..., 1], g[..., 2]] + [member[..., c].astype(g.dtype) for c in range(C)]
    n = linalg.normal_entries(cols, w)
    for c in range(C):
        n[3 + c][3 + c] = n[3 + c][3 + c] + jnp.where(jnp.any(member[..., c], axis=-1), 0.0, 1.0)
    lower, ok = linalg.cholesky(n)
    x = linalg.cholesky_solve(lower, [jnp.sum(w * c * y, axis=-1) for c in cols])
    r = y - sum(x[a][..., None] * cols[a] for a in range(len(cols)))
    return jnp.where(ok, jnp.sum(w * r**2, axis=-1), jnp.inf)


@partial(jit_kernel, static_argnames=_STATIC)
def _detect_and_exclude(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, y,
                        budget, max_order, weighting="int", iterations=PL_ITERATIONS,
                        fault_modes=DEFAULT_RULE):
    top = _separation(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, y,
                      budget, max_order, weighting, iterations, fault_modes)
    # candidate subsets: one per mode (axis K moved to the front as a batch axis)
    keep = valid[..., None, :] & ~top.excluded  # (..., K, L)
    cand_valid = jnp.moveaxis(keep, -2, 0)  # (K, ..., L)
    k = cand_valid.shape[0]

    def bc(x):
        return jnp.broadcast_to(x, (k,) + x.shape)

    sub = _separation(bc(g), bc(constellation), bc(var_int), bc(var_acc), bc(b_nom), bc(p_sat),
                      bc(p_const), cand_valid, bc(y), budget, max_order, weighting, iterations,
                      fault_modes)
    wsse = weighted_sse(bc(g), bc(constellation), bc(var_int), cand_valid, bc(y), p_const.shape[-1])
    candidate = jnp.moveaxis(top.monitored, -1, 0)  # (K, ...)
    acceptable = candidate & ~sub.detected & (sub.pl.status == Status.OK)
    score = jnp.where(acceptable, wsse, jnp.inf)
    best = jnp.argmin(score, axis=0)  # (...)
    found = jnp.any(acceptable, axis=0)

    def pick(x):  # x: (K, ..., rest) -> (..., rest)
        idx = best.reshape((1,) + best.shape + (1,) * (x.ndim - 1 - best.ndim))
        return jnp.take_along_axis(x, idx, axis=0)[0]

    detected = top.detected
    chosen_pl = jax.tree.map(pick, sub.pl)
    failed_pl = jax.tree.map(lambda a: a, chosen_pl)._replace(
        hpl_m=jnp.full(best.shape, jnp.inf), vpl_m=jnp.full(best.shape, jnp.inf),
        emt_m=jnp.full(best.shape, jnp.inf), sigma_acc_u_m=jnp.full(best.shape, jnp.inf),
        pl_enu_m=jnp.full(best.shape + (3,), jnp.inf),
        status=jnp.full(best.shape, Status.EXCLUSION_FAILED, jnp.int8))

    def select(a_excl, a_fail, a_top):
        d = detected.reshape(detected.shape + (1,) * (a_top.ndim - detected.ndim))
        f = found.reshape(found.shape + (1,) * (a_top.ndim - found.ndim))
        return jnp.where(d, jnp.where(f, a_excl, a_fail), a_top)

    pl = jax.tree.map(select, chosen_pl, failed_pl, top.pl)
    excluded = jnp.where((detected & found)[..., None], pick(jnp.moveaxis(
        top.excluded, -2, 0)), False)
    position = select(pick(sub.position_m), jnp.full(top.position_m.shape, jnp.nan),
                      top.position_m)
    position = jnp.where(jnp.isnan(position), jnp.inf, position)
    position = jnp.where((top.pl.status == Status.INVALID_INPUT)[..., None], jnp.inf, position)
    mode = jnp.where(detected & found, best, -1)
    return FDEResult(detected, excluded, mode, top.tau, position, pl, pl.status)


def _kernel_args(sources, p_const, budget, options):
    """The arrays and static arguments of the public kernels, checked (ValueError before any
    tracing)."""
    options = kernel_options(budget, options)
    s = Sources(*sources).filled()
    args = (s.g, s.constellation, s.var_int_m2, s.var_acc_m2, s.b_nom_m, s.p_sat, p_const,
            s.valid)
    return args, _static(budget, options)


def _static(budget, options):
    """The private kernels' static arguments from a checked ``MHSSOptions`` with an order."""
    if options.position_optimization is not None:
        raise ValueError("solution separation and exclusion use the weighted least-squares "
                         "all-in-view estimate: MHSSOptions(position_optimization=None)")
    return dict(budget=budget, max_order=options.max_order,
                weighting=options.all_in_view_weighting, iterations=options.iterations,
                fault_modes=options.fault_modes)


def separation_kernel(sources: Sources, p_const: Float[ArrayLike, "*#batch C"],
                      budget: IntegrityBudget, residual_m: Float[ArrayLike, "*#batch L"],
                      options: MHSSOptions) -> Separation:
    """The solution-separation test of ``solution_separation`` as a pure JAX function:
    callable inside ``jax.jit`` and ``jax.vmap`` (inline there), jitted on its own otherwise.

    Args:
      sources: ``araim.mhss.Sources`` of batch shape (...) and L sources.
      p_const: (..., C) P_const per constellation.
      budget: ``IntegrityBudget`` (static).
      residual_m: (..., L) y = z - z_hat at the all-in-view linearisation point (metres).
      options: ``MHSSOptions`` (static) with an int ``max_order``; no
        ``position_optimization``.

    Returns:
      ``Separation``. A non-finite residual or an unusable input of a valid source gives
      ``pl.status`` INVALID_INPUT (no detection); nothing raises inside the trace.
    """
    args, static = _kernel_args(sources, p_const, budget, options)
    return _separation(*args, residual_m, **static)


def detect_and_exclude_kernel(sources: Sources, p_const: Float[ArrayLike, "*#batch C"],
                              budget: IntegrityBudget,
                              residual_m: Float[ArrayLike, "*#batch L"],
                              options: MHSSOptions) -> FDEResult:
    """Detection and exclusion of ``detect_and_exclude`` as a pure JAX function, arguments as
    ``separation_kernel``. Returns ``FDEResult``; failures as data (EXCLUSION_FAILED,
    INVALID_INPUT with infinite PLs and position), never raised inside the trace."""
    args, static = _kernel_args(sources, p_const, budget, options)
    return _detect_and_exclude(*args, residual_m, **static)


def checked_inputs(sources: Sources, p_const, budget: IntegrityBudget,
                   options: MHSSOptions | None) -> tuple[Sources, jax.Array, MHSSOptions]:
    """The receiver's inputs broadcast and checked (``prepare_inputs``), the budget and the
    options checked, and the static order (``required_order`` when None): (sources,
    p_const, options with an int ``max_order``)."""
    options = as_options(options)
    check_options(budget, options.all_in_view_weighting)
    options = options.checked()
    s, p_const = prepare_inputs(sources, p_const)
    if options.max_order is None:
        options = options._replace(max_order=required_order(
            s.valid, s.constellation, s.p_sat, p_const, budget,
            fault_modes=options.fault_modes))
    return s, p_const, options


def _public(fn, sources, p_const, budget, residual_m, options):
    s, p_const, options = checked_inputs(sources, p_const, budget, options)
    args = (*s[:6], p_const, s.valid)
    y = jnp.broadcast_to(jnp.asarray(residual_m, jnp.float64), args[0].shape[:-1])
    try:
        bad = ~np.isfinite(np.asarray(y)) & np.asarray(args[7])
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        bad = None  # traced: the kernel reports INVALID_INPUT
    if bad is not None and bad.any():
        raise ValueError(f"residual_m of a valid source is not finite at {batch_source(bad)}: "
                         f"{float(np.asarray(y)[bad][0])!r} (mark the source invalid or drop "
                         "the epoch)")
    static = _static(budget, options)
    if bad is None or is_traced(args):
        return fn(*args, y, **static)
    # padded to a bucket size (oaraim.batching.bucket): a handful of compiled shapes
    batch = args[0].shape[:-2]
    n = int(np.prod(batch, dtype=np.int64))
    flat = [np.asarray(x).reshape((n,) + x.shape[len(batch):]) for x in (*args, y)]
    return unpad(fn(*pad_rows(flat, bucket(n)), **static), batch, n)


def solution_separation(sources: Sources, p_const: Real[ArrayLike, "*#batch C"],
                        budget: IntegrityBudget, residual_m: Real[ArrayLike, "*#batch #L"],
                        options: MHSSOptions | None = None) -> Separation:
    """Solution-separation statistics and detection (seed 004 eqs. 9-13) for measured residuals.

    Arguments as ``protection_levels`` (``options`` without ``position_optimization``) plus
    ``residual_m`` (..., L): y = z - z_hat at the all-in-view linearisation point (metres).
    Returns ``Separation``: per mode and direction the separation, threshold and tau;
    ``detected`` is any tau > 1.
    """
    return _public(_separation, sources, p_const, budget, residual_m, options)


def detect_and_exclude(sources: Sources, p_const: Real[ArrayLike, "*#batch C"],
                       budget: IntegrityBudget, residual_m: Real[ArrayLike, "*#batch #L"],
                       options: MHSSOptions | None = None) -> FDEResult:
    """Detection, then exclusion over the monitored fault modes (module docstring).

    Returns ``FDEResult``: ``excluded`` marks the sources removed, ``pl`` the PLs of the solution
    kept (all-in-view when nothing was detected), ``position_m`` its ENU correction S y.
    Arguments as ``solution_separation`` (every candidate subset uses the same options).
    """
    return _public(_detect_and_exclude, sources, p_const, budget, residual_m, options)
