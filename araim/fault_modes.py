"""Fault modes to monitor and their prior probabilities (seed 004 eq. 8, eq. 17, App. B).

Events are single sources (P_s) and constellations (P_const) (App. B), independent. Seed 004
monitors every combination of up to N simultaneous faults, N following from P_thresh (eq. 8),
as the ARAIM ADD does. With P_s^S up to 0.1 (seed 004 Fig. 4) that set explodes: with 8 SOPs the
probability of two SOP faults is 0.19, and monitoring every such pair, triple, ... of single
sources is combinatorial. We group, as the issue and DESIGN.md ask ("assign every fault
combination to exactly one monitored mode whose exclusion set contains it"):

**Group states.** Each present constellation c (>= 1 valid source) is in one of three states:
none (P_none_c = (1 - P_const,c) prod_l (1 - P_s,l)); exactly one source l faulty and no
constellation fault (P_single_l = (1 - P_const,c) P_s,l prod_{l' != l} (1 - P_s,l')); or
*whole*: the constellation event or two or more of its sources (P_whole_c, the rest). A
constellation with a single source has no separate single state: its one source and the
constellation are excluded alike, so the two states merge into whole.

**Order.** r is the smallest r >= 1 (at most ``max_order``) such that the probability that more
than r constellations are faulty is <= P_thresh (eq. 8, with constellations instead of events;
Poisson-binomial over the independent constellations).

**Modes.** For every set F of k <= r present constellations: the mode "F whole" (exclude all
their sources and drop their clock states) and, for every constellation a in F with >= 2
sources and every source l of a, the mode "l resolved, F - {a} whole". A fault combination
whose faulty constellations are F goes to exactly one of them: the lowest-index constellation of
F that is in a single-source state is resolved, all others are excluded whole. The prior of a
mode is the probability of the combinations assigned to it (exact, with the prod (1 - P)
factors, eq. 17 as corrected in DESIGN.md):

    prior(F whole)       = prod_{c in F} P_whole_c                prod_{c not in F} P_none_c
    prior(l, F - {a})    = P_single_l prod_{b in F, b < a} P_whole_b
                                      prod_{b in F, b > a} P_fault_b prod_{c not in F} P_none_c

with P_fault = 1 - P_none. So P(no fault) + sum of all priors of order <= r + P(more than r
constellations faulty) = 1 exactly, and P_not_monitored = P(more than r) + the priors of modes
that cannot be monitored (singular fault-tolerant subset). Order 1 is the ADD's single-fault
set (every source and every constellation); the grouping only shapes the higher orders, where it
bounds the number of modes by L C(C-1, r-1) + C(C, r) per order instead of C(L, r). Order the
constellations from the most to the least reliable (GPS 0, Galileo 1, then SOPs, the labels of
``geometry.sky``): the resolved source then comes from the most reliable faulty constellation.

Reference for the ungrouped rule: WG-C ARAIM TSG, Airborne Algorithm Description Document v3.0
(2017), section 2.3.2 (determination of the fault modes and P_not_monitored); Blanch et al.,
"Baseline Advanced RAIM User Algorithm and Possible Improvements", IEEE TAES 51(1), 2015.

The mode *template* below depends only on the static sizes (L sources, C constellation slots,
max order R); which modes are live, their exclusion sets and priors are computed per geometry,
so a batch with different constellation labels shares one compiled kernel.
"""

import itertools
from functools import cache
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.araim import linalg


class ModeTemplate(NamedTuple):
    """Static description of the candidate fault modes (all-in-view not included).

    source: (T,) int, the resolved source slot, or -1 for a whole-constellations mode.
    whole: (T, C) bool, for a whole mode the constellations excluded.
    other: (T, max(C - 1, 1)) bool, for a resolved mode the other constellations excluded,
      indexed among the C - 1 constellations different from the resolved source's own.
    order: (T,) int, number of faulty constellations the mode stands for.
    """

    source: np.ndarray
    whole: np.ndarray
    other: np.ndarray
    order: np.ndarray


@cache
def mode_template(n_sources: int, n_constellations: int, max_order: int) -> ModeTemplate:
    """Candidate modes, ordered by order, then resolved sources, then whole sets."""
    L, C = n_sources, n_constellations
    co = max(C - 1, 1)
    source, whole, other, order = [], [], [], []
    for k in range(1, min(max_order, C) + 1):
        for l in range(L):
            for rel in itertools.combinations(range(C - 1), k - 1):
                o = np.zeros(co, bool)
                o[list(rel)] = True
                source.append(l)
                whole.append(np.zeros(C, bool))
                other.append(o)
                order.append(k)
        for subset in itertools.combinations(range(C), k):
            w = np.zeros(C, bool)
            w[list(subset)] = True
            source.append(-1)
            whole.append(w)
            other.append(np.zeros(co, bool))
            order.append(k)
    return ModeTemplate(np.array(source, int), np.array(whole, bool).reshape(-1, C),
                        np.array(other, bool).reshape(-1, co), np.array(order, int))


# Internal layout (kernels): per-source arrays (L, B), per-constellation (C, B), per-mode (T, B)
# and (T, L, B), with one flattened batch axis B LAST, so that every operation is elementwise
# over the batch and XLA vectorises it (batch-first arrays with a short source axis last ran
# about 3x slower; DESIGN.md performance notes). Public wrappers take and return batch-first.


class GroupProbabilities(NamedTuple):
    member: jax.Array  # (L, C, B) valid source l belongs to constellation c
    n_sources: jax.Array  # (C, B) valid sources per constellation
    present: jax.Array  # (C, B)
    p_none: jax.Array  # (C, B) 1 for absent constellations
    p_whole: jax.Array  # (C, B) 0 for absent constellations
    p_fault: jax.Array  # (C, B) 1 - p_none, computed without cancellation
    p_single: jax.Array  # (L, B) 0 for padding and for constellations with one source


def group_probabilities(valid, constellation, p_sat, p_const) -> GroupProbabilities:
    """Per-constellation state probabilities (module docstring), stable for tiny P.

    Batch-last: valid, constellation, p_sat (L, B); p_const (C, B).
    """
    C = p_const.shape[0]
    member = valid[:, None, :] & (constellation[:, None, :] == jnp.arange(C)[None, :, None])
    p = jnp.where(member, p_sat[:, None, :], 0.0)  # (L, C, B)
    # Poisson-binomial recursion over sources: P(0), P(1), P(>= 2) faulty sources, all sums
    # of non-negative terms (no 1 - (1 - x) cancellation for P ~ 1e-9).
    p0 = jnp.ones(p.shape[1:])
    p1 = jnp.zeros_like(p0)
    p2 = jnp.zeros_like(p0)
    for l in range(p.shape[0]):
        pl = p[l]
        p2 = p2 + p1 * pl
        p1 = p1 * (1.0 - pl) + p0 * pl
        p0 = p0 * (1.0 - pl)
    # stored once: left alone, XLA fused the 3 x L-step recursion into every element of the
    # (L, C, B) consumers below (measured: 5 % of the whole MHSS kernel)
    p0, p1, p2 = (linalg.materialize(x) for x in (p0, p1, p2))
    n_sources = jnp.sum(member, axis=0)
    present = n_sources > 0
    pc = jnp.where(present, p_const, 0.0)
    p_none = (1.0 - pc) * p0
    p_fault = jnp.where(present, pc + (1.0 - pc) * (p1 + p2), 0.0)
    p_whole = jnp.where(present, pc + (1.0 - pc) * jnp.where(n_sources == 1, p1 + p2, p2), 0.0)
    # P_single_l = (1 - P_const) P_s,l prod_{l' != l} (1 - P_s,l')
    #            = (1 - P_const) p0 P_s,l / (1 - P_s,l)
    own = jnp.sum(jnp.where(member, ((1.0 - pc) * p0)[None], 0.0), axis=1)
    big = jnp.any(member & (n_sources >= 2)[None], axis=1)
    ps = jnp.where(valid, p_sat, 0.0)
    p_single = jnp.where(big, own * ps / (1.0 - ps), 0.0)
    return GroupProbabilities(member, n_sources, present, p_none, p_whole, p_fault, p_single)


def faulty_constellation_tail(p_fault, max_order: int):
    """P(more than k constellations faulty) for k = 1 .. max_order: (max_order, B) from
    p_fault (C, B)."""
    C = p_fault.shape[0]
    zero = jnp.zeros(p_fault.shape[1:])
    dist = [zero + 1.0] + [zero] * C
    for c in range(C):
        q = p_fault[c]
        dist = [dist[0] * (1 - q)] + [dist[k] * (1 - q) + dist[k - 1] * q for k in range(1, C + 1)]
    tails = []
    for k in range(1, max_order + 1):
        t = zero
        for j in range(k + 1, C + 1):
            t = t + dist[j]
        tails.append(t)
    return jnp.stack(tails, axis=0)


class FaultModes(NamedTuple):
    excluded: jax.Array  # (T, L, B) bool: sources hypothesised faulty (valid ones only)
    excluded_constellation: jax.Array  # (T, C, B) bool: constellations excluded whole
    prior: jax.Array  # (T, B) prior probability assigned to the mode (0 where not live)
    live: jax.Array  # (T, B) bool: monitored at this geometry's order
    order: jax.Array  # (B,) int: the order r
    p_beyond_order: jax.Array  # (B,) P(more than r constellations faulty)
    p_no_fault: jax.Array  # (B,)


def fault_modes_batch_last(valid, constellation, p_sat, p_const, p_thresh, max_order: int):
    """Live modes, exclusion sets and priors (static template), batch-last layout."""
    C = p_const.shape[0]
    L = valid.shape[0]
    tpl = mode_template(L, C, max_order)
    gp = group_probabilities(valid, constellation, p_sat, p_const)
    R = min(max_order, C)
    tails = faulty_constellation_tail(gp.p_fault, R)  # (R, B)
    ok = tails <= p_thresh
    order = jnp.where(jnp.any(ok, axis=0), jnp.argmax(ok, axis=0) + 1, R)
    p_beyond = jnp.take_along_axis(tails, (order - 1)[None], axis=0)[0]

    src = np.asarray(tpl.source)
    resolved = jnp.asarray(src >= 0)[:, None]  # (T, 1)
    srci = np.maximum(src, 0)
    lab = jnp.clip(constellation, 0, C - 1)
    a = lab[srci]  # (T, B) constellation of each mode's resolved source
    cidx = jnp.arange(C)[None, :, None]
    rel = jnp.clip(cidx - (cidx > a[:, None, :]), 0, max(C - 2, 0))  # (T, C, B)
    # Small static axes: selects over them instead of gathers (take_along_axis over the batch
    # was most of this function's time on CPU)
    tpl_other = np.asarray(tpl.other)
    other = jnp.zeros(rel.shape, bool)
    for j in range(tpl_other.shape[1]):
        other = other | (jnp.asarray(tpl_other[:, j])[:, None, None] & (rel == j))
    other = other & (cidx != a[:, None, :])
    excl_c = jnp.where(resolved[:, :, None], other, jnp.asarray(tpl.whole)[:, :, None])

    all_present = jnp.all(~excl_c | gp.present[None], axis=1)  # (T, B)
    n_a = sum(jnp.where(a == c, gp.n_sources[c][None], 0) for c in range(C))
    src_ok = valid[srci] & (n_a >= 2)
    live = (all_present & jnp.where(resolved, src_ok, True)
            & (jnp.asarray(tpl.order)[:, None] <= order[None]))

    pn, pw, pf = (x[None] for x in (gp.p_none, gp.p_whole, gp.p_fault))
    before = cidx < a[:, None, :]
    own = cidx == a[:, None, :]
    factor_resolved = jnp.where(excl_c, jnp.where(before, pw, pf), jnp.where(own, 1.0, pn))
    factor_whole = jnp.where(excl_c, pw, pn)
    prod = jnp.prod(jnp.where(resolved[:, :, None], factor_resolved, factor_whole), axis=1)
    prior = jnp.where(live, jnp.where(resolved, gp.p_single[srci], 1.0) * prod, 0.0)

    # excluded[t, l] = the constellation of l is excluded whole in t, or l is t's source
    member_excl = jnp.zeros((excl_c.shape[0],) + lab.shape, bool)  # (T, L, B)
    for c in range(C):
        member_excl = member_excl | (excl_c[:, c][:, None] & (lab == c)[None])
    is_src = jnp.asarray(np.arange(L)[None, :] == src[:, None])[:, :, None]
    excluded = valid[None] & (member_excl | is_src)
    return FaultModes(excluded, excl_c, prior, live, order, p_beyond,
                      jnp.prod(gp.p_none, axis=0))


def to_batch_last(x, event_dims: int):
    """(..., e1..ek) -> (e1..ek, B) with the batch axes flattened."""
    batch = x.shape[:x.ndim - event_dims]
    x = x.reshape((-1,) + x.shape[x.ndim - event_dims:]) if batch else x[None]
    return jnp.moveaxis(x, 0, -1)


def to_batch_first(x, batch_shape):
    """(e1..ek, B) -> (batch..., e1..ek)."""
    x = jnp.moveaxis(x, -1, 0)
    return x.reshape(tuple(batch_shape) + x.shape[1:])


def fault_modes(valid, constellation, p_sat, p_const, p_thresh, max_order: int) -> FaultModes:
    """Batch-first ``fault_modes_batch_last``: valid, constellation, p_sat (..., L), p_const
    (..., C); returns arrays (..., T, L), (..., T, C), (..., T) and (...)."""
    valid = jnp.asarray(valid, bool)
    batch = valid.shape[:-1]
    args = [to_batch_last(jnp.broadcast_to(jnp.asarray(x), valid.shape), 1)
            for x in (valid, constellation, p_sat)]
    pc = to_batch_last(jnp.broadcast_to(jnp.asarray(p_const, jnp.float64),
                                        batch + jnp.shape(p_const)[-1:]), 1)
    fm = fault_modes_batch_last(*args, pc, p_thresh, max_order)
    return FaultModes(*(to_batch_first(x, batch) for x in fm))
