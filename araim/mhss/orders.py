"""Fault-mode orders of the MHSS protection levels: the smallest template order (most
simultaneous faults a monitored mode stands for) that the fault-mode convention needs for a
batch (``required_order``), and per geometry whether a higher one is needed
(``higher_order_flags``, the kernel's one-dispatch version of that test)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Bool, Float, Int

from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.fault_modes import (
    FaultModeRule,
    event_modes_batch_last,
    fault_mode_rule,
    faulty_constellation_tail,
    group_probabilities,
    to_batch_last,
)
from oaraim.batching import TILE, map_tiles

__all__ = ["MAX_AUTO_ORDER", "higher_order_flags", "required_order"]

#: ``max_order=None`` picks the smallest order meeting P_thresh over the batch, up to this
MAX_AUTO_ORDER = 3



def required_order(valid: Bool[ArrayLike, "*batch L"], constellation: Int[ArrayLike, "*batch L"],
                   p_sat: Float[ArrayLike, "*batch L"], p_const: Float[ArrayLike, "*batch C"],
                   budget: IntegrityBudget | float, cap: int = MAX_AUTO_ORDER,
                   fault_modes: str | FaultModeRule | None = None) -> int:
    """Smallest template order meeting the convention for every geometry of the batch, at most
    ``cap``; valid, constellation, p_sat (..., L) and p_const (..., C), batch first.
    ``grouped``: the number of simultaneously faulty constellations r with P(more than r) <=
    P_thresh (``budget`` may then be P_thresh alone); event conventions
    (``budget`` an ``IntegrityBudget``): the smallest order at which no geometry would monitor
    a set beyond it (at most 2)."""
    if isinstance(budget, IntegrityBudget):
        rule = fault_mode_rule(fault_modes)
        p_thresh = budget.p_thresh
    else:
        rule = fault_mode_rule("grouped" if fault_modes is None else fault_modes)
        p_thresh = float(budget)
        if rule.events:
            raise ValueError(f"fault_modes={rule.name!r} needs the IntegrityBudget, "
                             "not P_thresh alone")
    if valid.size == 0:
        return 1
    if rule.events:
        r_max = max(1, min(cap, rule.max_order))
        try:
            for r in range(1, r_max):
                if not bool(_needs_higher_order(valid, constellation, p_sat, p_const, budget,
                                                rule, r)):
                    return r
        except jax.errors.TracerArrayConversionError:
            raise ValueError("max_order=None needs concrete probabilities; under jit pass "
                             "max_order (e.g. 1)") from None
        return r_max
    r_max = max(1, min(cap, p_const.shape[-1]))
    try:
        worst = np.asarray(_worst_tails(valid, constellation, p_sat, p_const, r_max))
    except jax.errors.TracerArrayConversionError:
        raise ValueError("max_order=None needs concrete probabilities; under jit pass "
                         "max_order (e.g. 1 for the Table I GPS budget)") from None
    for r in range(1, r_max + 1):
        if worst[r - 1] <= p_thresh:  # NaN never is
            return r
    return r_max


def _needs_flat(valid, constellation, p_sat, p_const, budget, rule, order):
    fm = event_modes_batch_last(to_batch_last(valid, 1), to_batch_last(constellation, 1),
                                to_batch_last(p_sat, 1), to_batch_last(p_const, 1), budget,
                                rule, order, full=True)
    return fm.needs_higher_order | (fm.p_beyond_order > budget.p_thresh)


def higher_order_flags(valid, constellation, p_sat, p_const, budget, rule, order):
    """(B,) bool, batch-last inputs: True where a geometry needs a template above ``order``,
    by exactly the test of ``required_order`` (so the batch's required order is ``order``
    where no geometry is flagged); False everywhere when ``required_order`` could not pick
    a higher one (its cap, the convention's order, the constellation count)."""
    B = valid.shape[-1]
    if rule.events:
        if min(MAX_AUTO_ORDER, rule.max_order) <= order:
            return jnp.zeros((B,), bool)
        fm = event_modes_batch_last(valid, constellation, p_sat, p_const, budget, rule, order,
                                    full=True)
        return fm.needs_higher_order | (fm.p_beyond_order > budget.p_thresh)
    if min(MAX_AUTO_ORDER, p_const.shape[0]) <= order:
        return jnp.zeros((B,), bool)
    gp = group_probabilities(valid, constellation, p_sat, p_const)
    return ~(faulty_constellation_tail(gp.p_fault, order)[order - 1] <= budget.p_thresh)


@functools.partial(jax.jit, static_argnames=("budget", "rule", "order"))
def _needs_higher_order(valid, constellation, p_sat, p_const, budget, rule, order):
    """Whether any geometry of the batch needs a template above ``order`` (event rules)."""
    batch = valid.shape[:-1]
    flags = map_tiles(functools.partial(_needs_flat, budget=budget, rule=rule, order=order),
                      (valid, constellation, p_sat, p_const), batch, tile=4 * TILE)
    return jnp.any(flags)


def _tails_flat(valid, constellation, p_sat, p_const, r_max):
    """P(more than r constellations faulty), r = 1..r_max, per geometry: (B, r_max)."""
    gp = group_probabilities(to_batch_last(valid, 1), to_batch_last(constellation, 1),
                             to_batch_last(p_sat, 1), to_batch_last(p_const, 1))
    return jnp.moveaxis(faulty_constellation_tail(gp.p_fault, r_max), 0, -1)


@functools.partial(jax.jit, static_argnames="r_max")
def _worst_tails(valid, constellation, p_sat, p_const, r_max):
    """The batch's largest ``_tails_flat`` per order, (r_max,): one compiled program in tiles
    (docs/benchmarks.md)."""
    batch = valid.shape[:-1]
    tails = map_tiles(functools.partial(_tails_flat, r_max=r_max),
                      (valid, constellation, p_sat, p_const), batch, tile=16 * TILE)
    return jnp.max(tails.reshape(-1, r_max), axis=0)


