"""The entry points of the MHSS protection levels (seed 004 eqs. 8-16): the jit-safe kernel
``protection_levels_kernel`` on a ``Sources`` pytree, and the host function
``protection_levels`` (NumPy input, argument checks with clear errors, batch-size buckets,
host threads) over the same compiled kernel. The kernel composes ``project`` (fault modes and
projectors), ``pls_from_projection`` (the PL root finder) and, on request, the Blanch et al.
(2015) all-in-view estimator (``araim.position_opt``), tile by tile (``oaraim.batching``)."""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Float, Real

from oaraim.araim import linalg
from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.fault_modes import (
    select_fault_modes,
    to_batch_first,
    to_batch_last,
)
from oaraim.araim.mhss.inputs import (
    INPUT_RANGES,
    Sources,
    broadcast_batch,
    check_inputs,
    check_options,
    host_inputs,
    invalid_input_flags,
    prepare_inputs,
)
from oaraim.araim.mhss.options import MHSSOptions, as_options
from oaraim.araim.mhss.orders import higher_order_flags, required_order
from oaraim.araim.mhss.projection import (
    adjusted_projection,
    finish_projection,
    mode_solutions,
    position_rows,
    project,
)
from oaraim.araim.mhss.root import pls_from_projection
from oaraim.araim.status import Status
from oaraim.araim.validate import check_int
from oaraim.batching import (
    TILE,
    bucket,
    is_traced,
    jit_kernel,
    map_threads,
    map_tiles,
    pad_rows,
    slice_rows,
    unpad,
)

__all__ = ["MHSSResult", "batch_last_inputs", "kernel_cache_size", "kernel_options",
           "protection_levels",
           "protection_levels_kernel", "protection_levels_priors_kernel",
           "protection_levels_threaded"]


class MHSSResult(NamedTuple):
    """The protection levels of ``protection_levels`` and ``protection_levels_kernel``: every
    field has the batch shape of the inputs (``pl_enu_m`` one more axis of 3)."""

    hpl_m: jax.Array
    """(...) HPL, eq. (15); inf where status != OK."""
    vpl_m: jax.Array
    """(...) VPL, eq. (16); inf where status != OK."""
    emt_m: jax.Array
    """(...) effective monitor threshold (vertical), ADD."""
    sigma_acc_u_m: jax.Array
    """(...) vertical accuracy sigma of the all-in-view solution."""
    n_modes: jax.Array
    """(...) N_f: the monitored fault modes."""
    p_not_monitored: jax.Array
    """(...) P_NM of eqs. (14), (16)."""
    status: jax.Array
    """(...) ``araim.Status`` (int8)."""
    order: jax.Array
    """(...) the template order: number of simultaneous faults monitored."""
    pl_enu_m: jax.Array
    """(..., 3) PL_1, PL_2, PL_3 (east, north, up)."""
    position_adjusted: jax.Array
    """(...) bool: the PLs are those of the Blanch et al. (2015) estimator
    (``position_optimization``), not of the WLS one."""


def batch_last_inputs(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid):
    """The kernel's flat batch-first inputs, g (B, L, 3), the per-source arrays (B, L) and
    p_const (B, C), moved to the batch-last layout of ``project`` (the batch axis last)."""
    tl = to_batch_last
    return (tl(g, 2), tl(constellation, 1), tl(var_int, 1), tl(var_acc, 1), tl(b_nom, 1),
            tl(p_sat, 1), tl(p_const, 1), tl(valid, 1))


#: geometries of a tile that ``_optimized_position`` solves a second time in a compact
#: sub-batch; a tile with more triggered geometries solves the whole tile again
OPTIMIZED_SUBBATCH = 16


def _optimized_position(pr, pl, status, emt, args, budget, iterations, opt):
    """MAAST's use of the Blanch et al. (2015) estimator (``usr_vhpl_araim.m``): tried where
    the baseline is computed, sigma_acc,U < its limit and VPL, HPL or EMT exceeds its target;
    kept (PLs, EMT and sigma_acc together) where its VPL or HPL is lower. Returns (pl,
    status, emt, sigma_acc_u, adjusted).

    The second solve runs only where a tile has triggered geometries (``lax.switch``): on
    up to ``OPTIMIZED_SUBBATCH`` of them gathered into a compact sub-batch (a world map
    triggers on ~0-1 % of its geometries, so most tiles that trigger at all hold one or
    two), else on the whole tile. Every step is elementwise along the batch, so a geometry
    gets the same bits either way (tested on tiles of 64; XLA may round the lanes past the
    last full vector of a batch differently, so a batch of at most ``OPTIMIZED_SUBBATCH``
    geometries is always solved whole)."""
    ok = status == Status.OK
    hpl = jnp.sqrt(pl[0] ** 2 + pl[1] ** 2)
    if opt.keep == "always":
        trigger = ok
    else:
        trigger = ok & (pr.sigma_acc_u < opt.sigma_acc_max_m[2]) & (
            (pl[2] > opt.vpl_target_m) | (hpl > opt.hpl_target_m) | (emt > opt.emt_target_m))
    n_batch = trigger.shape[-1]

    def rows(pr):
        """S^(i) built inside the branch that reads it (``project(lazy_rows=True)``), from
        the whole tile's pieces: the same bits as building it for every tile."""
        return pr._replace(s_pos=position_rows(pr), rows=None)

    def solve(pr, pl, emt, args, trigger):
        """The adjusted PLs where triggered and better, on batch-last arrays of any batch."""
        hpl = jnp.sqrt(pl[0] ** 2 + pl[1] ** 2)
        pr2 = adjusted_projection(pr, args[2], args[3], args[4], args[7], budget, opt)
        pr2 = pr2._replace(status=jnp.where(trigger, pr2.status, Status.NOT_CONVERGED)
                           .astype(pr2.status.dtype))  # untriggered: not solved
        pl2, status2, emt2 = pls_from_projection(pr2, budget, iterations)
        hpl2 = jnp.sqrt(pl2[0] ** 2 + pl2[1] ** 2)
        take = trigger & (status2 == Status.OK)
        if opt.keep == "lower":
            take = take & ((pl2[2] < pl[2]) | (hpl2 < hpl))
        return (jnp.where(take[None], pl2, pl), jnp.where(take, emt2, emt),
                jnp.where(take, pr2.sigma_acc_u, pr.sigma_acc_u), take)

    def whole(_):
        return solve(rows(pr), pl, emt, args, trigger)

    def compact(_):
        idx = jnp.nonzero(trigger, size=OPTIMIZED_SUBBATCH, fill_value=n_batch)[0]
        pick = lambda x: jnp.take(x, idx, axis=-1, mode="clip")  # noqa: E731
        sub = solve(jax.tree.map(pick, rows(pr)), pick(pl), pick(emt), [pick(a) for a in args],
                    pick(trigger) & (idx < n_batch))
        put = lambda full, part: full.at[..., idx].set(part, mode="drop")  # noqa: E731
        return tuple(put(f, x) for f, x in zip(
            (pl, emt, pr.sigma_acc_u, jnp.zeros_like(trigger)), sub, strict=True))

    def baseline(_):
        return pl, emt, pr.sigma_acc_u, jnp.zeros_like(trigger)

    n_trig = jnp.sum(trigger)
    # (a batch no larger than the sub-batch solves itself: its bits are those of its own
    # shape, whose last lanes XLA may round differently from a full vector)
    few = n_trig <= OPTIMIZED_SUBBATCH if n_batch > OPTIMIZED_SUBBATCH else False
    branch = jnp.where(n_trig == 0, 0, jnp.where(few, 1, 2))
    pl, emt, sigma_acc_u, take = jax.lax.switch(branch, (baseline, compact, whole), None)
    return pl, status, emt, sigma_acc_u, take


def _result(pr, pl, status, emt, sigma_acc_u, adjusted):
    """The batch-first ``MHSSResult`` of a batch-last projection and its PLs (3, B)."""
    ok = status == Status.OK
    # the HPL of the finite PLs, inf where not OK: the same values, and no inf / inf = NaN in
    # its derivative there (docs/gradients.md)
    pl_ok = jnp.where(ok[None], pl[:2], 0.0)
    hpl = jnp.where(ok, jnp.sqrt(pl_ok[0] ** 2 + pl_ok[1] ** 2), jnp.inf)
    out = MHSSResult(
        hpl_m=hpl, vpl_m=pl[2], emt_m=emt,
        sigma_acc_u_m=jnp.where(ok, sigma_acc_u, jnp.inf), n_modes=pr.n_modes,
        p_not_monitored=pr.p_not_monitored, status=status, order=pr.order, pl_enu_m=pl,
        position_adjusted=adjusted)
    return MHSSResult(*(to_batch_first(x, x.shape[-1:]) for x in out))


def _protection_levels_flat(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid,
                            budget, options, input_flags=False, order_flags=False):
    """One flat batch (B, ...) in and out; batch-last inside; ``options`` checked, with an
    int order. ``input_flags``: returns (MHSSResult, ``invalid_input_flags``);
    ``order_flags`` (with ``input_flags``) also ``higher_order_flags``: (MHSSResult, input
    flags, order flags)."""
    args = batch_last_inputs(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid)
    more = higher_order_flags(args[7], args[1], args[5], args[6], budget, options.fault_modes,
                              options.max_order) if order_flags else None
    opt = options.position_optimization
    pr = project(Sources(*args[:6], args[7]), args[6], budget, options,
                 lazy_rows=opt is not None)
    flags = pr.invalid_input
    pl, status, emt = pls_from_projection(pr, budget, options.iterations)
    sigma_acc_u = pr.sigma_acc_u
    adjusted = jnp.zeros_like(status, dtype=bool)
    if opt is not None:
        pl, status, emt, sigma_acc_u, adjusted = _optimized_position(
            pr._replace(invalid_input=None), pl, status, emt, args, budget, options.iterations,
            opt)
    out = _result(pr, pl, status, emt, sigma_acc_u, adjusted)
    if order_flags:
        return out, flags, more
    return (out, flags) if input_flags else out


def _protection_levels(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid,
                       budget, options, input_flags=False, order_flags=False):
    """Batch-first in and out, every argument broadcast to g's batch shape; evaluated in
    cache-sized tiles (``oaraim.batching``). ``input_flags`` also returns ``invalid_input_flags``
    (the host's range checks, computed where the kernel reads its inputs anyway)."""
    arrays, batch = broadcast_batch(g, constellation, var_int, var_acc, b_nom, p_sat, p_const,
                                    valid)

    def kernel(*xs):
        return _protection_levels_flat(*xs, budget, options, input_flags, order_flags)

    return map_tiles(kernel, arrays, batch)


_STATIC = ("budget", "options", "input_flags", "order_flags")
_protection_levels_jit = jit_kernel(_protection_levels, static_argnames=_STATIC)


def _protection_levels_part(start, *args, size, budget, options, input_flags=False,
                            order_flags=False):
    """``_protection_levels`` on rows [start, start + size) of flat arrays, sliced inside the
    program (``oaraim.batching.map_threads``'s ``part_fn``)."""
    return _protection_levels(*slice_rows(args, start, size), budget, options, input_flags,
                              order_flags)


_protection_levels_part_jit = jit_kernel(_protection_levels_part,
                                         static_argnames=("size",) + _STATIC)


def kernel_cache_size():
    """How many programs the host wrapper's kernel (``protection_levels`` on a whole batch) has
    compiled in this process: one per batch-size bucket (``oaraim.batching.bucket``) and static
    setting. Tests use it to check that arbitrary batch sizes share the bucket programs."""
    return _protection_levels_jit.jitted._cache_size()


def _kernel(sources, p_const, budget, options):
    return _protection_levels(*sources[:6], p_const, sources.valid, budget, options)


_kernel_jit = jit_kernel(_kernel, static_argnames=("budget", "options"))


def kernel_options(budget: IntegrityBudget, options: MHSSOptions) -> MHSSOptions:
    """The static arguments of a kernel checked before any tracing (ValueError naming the
    field): the budget an ``IntegrityBudget``, the options in canonical form with an int
    ``max_order`` (``MHSSOptions.checked``)."""
    options = as_options(options)
    check_options(budget, options.all_in_view_weighting)
    return options.checked(need_order=True)


def protection_levels_kernel(sources: Sources, p_const: Float[ArrayLike, "*#batch C"],
                             budget: IntegrityBudget, options: MHSSOptions) -> MHSSResult:
    """The MHSS protection levels as a pure JAX function: callable inside ``jax.jit`` and
    ``jax.vmap`` (there it runs inline in the caller's trace), and jitted on its own when
    called with concrete arrays. The same kernel ``protection_levels`` runs, without the host
    wrapper's NumPy conversion, threads, batch-size buckets and argument checks.

    Args:
      sources: ``Sources`` (line-of-sight rows, clock-group index, C_int and C_acc diagonals,
        b_nom, P_sat, valid), batch shape (...) and L sources.
      p_const: (..., C) P_const per constellation (clock group).
      budget: ``IntegrityBudget`` (static: hashable, part of the compiled program).
      options: ``MHSSOptions`` (static) with an int ``max_order`` (``required_order`` picks
        it from concrete probabilities); geometries needing more get status
        UNMONITORED_RISK.

    Returns:
      ``MHSSResult`` with the batch shape of ``sources``. Failures are data: a geometry with
      an unusable input of a valid source (non-unit row, variance <= 0, bias < 0, probability
      outside [0, 1), label outside 0..C-1) gets ``Status.INVALID_INPUT`` and infinite PLs;
      too few sources, a singular geometry or unmonitored risk their own status. Only a
      malformed static argument raises (ValueError, before tracing the arrays).
    """
    return _kernel_jit(Sources(*sources).filled(), p_const, budget=budget,
                       options=kernel_options(budget, options))



def _priors_flat(g, constellation, var_int, var_acc, b_nom, valid, p_sat, p_const, budget,
                 options):
    """One flat batch: the geometry arrays (B, ...) and the prior sets p_sat (B, P, L),
    p_const (B, P, C); returns the ``MHSSResult`` fields as (B, P, ...). The mode solutions
    once, then one loop step per prior set (``jax.lax.map``: each set is computed by the same
    loop body, so a set's results do not depend on how many sets there are or where it
    stands)."""
    tl = to_batch_last
    g, constellation, var_int, var_acc, b_nom, valid = (
        linalg.materialize(x) for x in (tl(g, 2), tl(constellation, 1), tl(var_int, 1),
                                        tl(var_acc, 1), tl(b_nom, 1), tl(valid, 1)))
    p_sat, p_const = linalg.materialize(tl(p_sat, 2)), linalg.materialize(tl(p_const, 2))
    C = p_const.shape[1]
    fault_modes, max_order = options.fault_modes, options.max_order
    # the template's exclusions do not depend on the probabilities: those of the first set
    excluded = select_fault_modes(valid, constellation, p_sat[0], p_const[0], budget,
                                  fault_modes, max_order).excluded
    modes = mode_solutions(Sources(g, constellation, var_int, var_acc, b_nom, None, valid),
                           excluded, C, options)

    def one(priors):
        ps, pc = priors
        flags = linalg.materialize(invalid_input_flags(g, constellation, var_int, var_acc,
                                                       b_nom, ps, valid, C))
        fm = select_fault_modes(valid, constellation, ps, pc, budget, fault_modes, max_order)
        pr = finish_projection(fm, modes, budget, flags)
        pl, status, emt = pls_from_projection(pr, budget, options.iterations)
        return _result(pr, pl, status, emt, pr.sigma_acc_u, jnp.zeros_like(status, bool))

    out = jax.lax.map(one, (p_sat, p_const))  # (P, B, ...)
    return MHSSResult(*(jnp.moveaxis(x, 0, 1) for x in out))


@functools.partial(jit_kernel, static_argnames=("budget", "options"))
def _priors_kernel(sources, p_const, budget, options):
    g = sources.g
    batch, (L, C) = g.shape[:-2], (g.shape[-2], p_const.shape[-1])
    n_sets = sources.p_sat.shape[0]
    geo = [jnp.broadcast_to(x, batch + s) for x, s in (
        (g, (L, 3)), (sources.constellation, (L,)), (sources.var_int_m2, (L,)),
        (sources.var_acc_m2, (L,)), (sources.b_nom_m, (L,)), (sources.valid, (L,)))]
    # the set axis after the batch axes, so that the tiles (oaraim.batching) cut the batch
    sets = [jnp.moveaxis(jnp.broadcast_to(x, (n_sets,) + batch + s), 0, len(batch))
            for x, s in ((sources.p_sat, (L,)), (p_const, (C,)))]

    def kernel(*xs):
        return _priors_flat(*xs, budget, options)

    out = map_tiles(kernel, geo + sets, batch)  # (..., P, ...)
    return MHSSResult(*(jnp.moveaxis(x, len(batch), 0) for x in out))


def protection_levels_priors_kernel(sources: Sources, p_const: Float[ArrayLike, "P *#batch C"],
                                    budget: IntegrityBudget,
                                    options: MHSSOptions) -> MHSSResult:
    """``protection_levels_kernel`` under P sets of prior probabilities over the same
    geometries: ``sources.p_sat`` (P, ..., L) and ``p_const`` (P, ..., C) carry the sets on a
    leading axis, the other fields the batch shape (...). The fault-tolerant solutions
    (eqs. 8-11: the projections, sigmas, biases and separations) do not depend on the priors
    and are computed once per geometry; each set then gets its live modes, thresholds (eq. 12,
    N_f depends on the live modes), P_NM and PLs. For sweeps over P_s or P_const (seed 004
    Figs. 3 and 4): ~2x faster per set than one call per set (docs/benchmarks.md). Every set
    uses the template of order ``options.max_order``; results equal
    ``protection_levels_kernel``'s set by set to rounding (tested). Jit-safe, failures as data
    as in ``protection_levels_kernel``; no ``position_optimization``.

    Returns:
      ``MHSSResult`` with shape (P, ...) (``pl_enu_m`` (P, ..., 3)).
    """
    options = kernel_options(budget, options)
    if options.position_optimization is not None:
        raise ValueError("protection_levels_priors_kernel has no position_optimization: use "
                         "MHSSOptions(position_optimization=None)")
    sources = Sources(*sources).filled()
    if jnp.ndim(sources.p_sat) != jnp.ndim(sources.g) or jnp.ndim(p_const) < 2:
        raise ValueError("protection_levels_priors_kernel takes the prior sets on a leading "
                         "axis: p_sat (P, ..., L) with g (..., L, 3), and p_const (P, ..., C)")
    return _priors_kernel(sources, p_const, budget=budget, options=options)



def protection_levels(sources: Sources, p_const: Real[ArrayLike, "*#batch C"],
                      budget: IntegrityBudget, options: MHSSOptions | None = None, *,
                      threads: int | None = None) -> MHSSResult:
    """ARAIM / OARAIM protection levels by multiple-hypothesis solution separation.

    Seed 004 eqs. (8)-(16) with the corrections of DESIGN.md. Takes VARIANCES (the ADD's C_int
    and C_acc diagonals, m^2), unlike ``slope_hpl`` which takes standard deviations.

    Args:
      sources: ``Sources``: the geometry rows g (..., L, 3) (``geometry.geometry_rows``, ENU
        line-of-sight convention), the integer clock-group labels 0..C-1 (GPS 0, Galileo 1,
        SOP constellations after them), the C_int and C_acc diagonals (``araim.error_models``),
        b_nom and P_s per source and ``valid`` (None: every source), each (..., L) or
        broadcasting to it (NumPy or JAX arrays, scalars).
      p_const: P_const per constellation (..., C).
      budget: ``IntegrityBudget`` (e.g. ``BUDGET_SEED004_TABLE_I``).
      options: ``MHSSOptions`` (None: the defaults): the fault-mode convention, the template
        order (None picks the smallest the convention needs over the batch), the all-in-view
        weighting and the all-in-view estimator (``position_adjusted`` says where MAAST's
        Blanch et al. (2015) estimator was kept).
      threads: host threads over which a large batch is split (default
        ``oaraim.batching.default_threads()``: ``OARAIM_THREADS`` or 2); results do not depend
        on it.

    Returns:
      ``MHSSResult``; every PL is inf where status != OK, never NaN.
    """
    options = as_options(options)
    check_options(budget, options.all_in_view_weighting)
    options = options.checked()
    if threads is not None:
        threads = check_int("threads", threads, 1)
    s = Sources(*sources)
    arrays = (s.g, s.constellation, s.var_int_m2, s.var_acc_m2, s.b_nom_m, s.p_sat, p_const,
              s.valid)
    if is_traced(arrays):
        return _protection_levels_traced(s, p_const, budget, options)
    flat, batch = host_inputs(*arrays)
    n = flat[0].shape[0]
    flat = pad_rows(flat, bucket(n))
    res = None
    rule = options.fault_modes
    if options.max_order is None and flat[0].shape[0] <= TILE:
        # one dispatch for a small batch: the kernel at order 1 also says, by the test of
        # required_order, whether any geometry needs more (then the batch runs again there)
        res, flags, more = _protection_levels_jit.jitted(
            *flat, budget=budget, options=options._replace(max_order=1), input_flags=True,
            order_flags=True)
        options = options._replace(max_order=2 if bool(np.any(np.asarray(more))) else 1)
        if options.max_order > 1:
            res = None
            options = options._replace(max_order=required_order(
                flat[7], flat[1], flat[5], flat[6], budget, fault_modes=rule))
    elif options.max_order is None:
        options = options._replace(max_order=required_order(flat[7], flat[1], flat[5],
                                                            flat[6], budget, fault_modes=rule))
    if res is None:
        res, flags = _threaded(flat, budget, options, threads)
    if bool(np.any(np.asarray(flags))):  # name the argument, batch index and source
        x = [a[:n].reshape(batch + a.shape[1:]) for a in flat]
        check_inputs(dict(zip(INPUT_RANGES, x[2:6], strict=True)), x[6], x[1], x[7],
                      x[6].shape[-1], g=x[0])
        raise AssertionError("the kernel's input flags and the host checks disagree")
    return unpad(res, batch, n)


def _protection_levels_traced(sources, p_const, budget, options):
    """``protection_levels`` inside a caller's trace: the kernel inline, failures as data
    (INVALID_INPUT), no host checks; ``max_order`` must be given unless the probabilities are
    concrete."""
    s, p_const = prepare_inputs(sources, p_const, check_sources=False)
    if options.max_order is None:
        options = options._replace(max_order=required_order(
            s.valid, s.constellation, s.p_sat, p_const, budget,
            fault_modes=options.fault_modes))
    res, _ = _threaded([*s[:6], p_const, s.valid], budget, options)
    return res


def _threaded(args, budget, options, threads=None):
    """(MHSSResult, ``invalid_input_flags``) of the jitted kernel on flat arrays ``args``
    (g, labels, var_int, var_acc, b_nom, p_sat, p_const, valid), large batches split over
    host threads (``oaraim.batching.map_threads``: bit-identical to one call, ~1.9x faster on
    2 cores); ``options`` checked, with an int order."""
    static = dict(budget=budget, options=options, input_flags=True)

    def fn(*xs):
        return _protection_levels_jit(*xs, **static)

    def part_fn(start, size, *xs):
        return _protection_levels_part_jit(start, *xs, size=size, **static)

    return map_threads(fn, args, args[0].shape[:-2], threads, part_fn=part_fn)


def protection_levels_threaded(sources: Sources, p_const: Float[ArrayLike, "*#batch C"],
                               budget: IntegrityBudget, options: MHSSOptions, *,
                               threads: int | None = None) -> MHSSResult:
    """The host wrapper's jitted kernel on sources already broadcast and checked
    (``prepare_inputs``), large batches split over host threads (bit-identical to one call,
    ~1.9x faster on 2 cores); ``options`` with an int ``max_order``. No host checks: an
    unusable input gives status INVALID_INPUT."""
    options = kernel_options(budget, options)
    s = Sources(*sources).filled()
    return _threaded([*s[:6], p_const, s.valid], budget, options, threads)[0]
