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

import functools
import itertools
from dataclasses import dataclass
from functools import cache
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Bool, Float, Int

from oaraim.araim import linalg
from oaraim.araim.event_sets import (
    event_tails,
    merge_equal_sets,
    pad_row,
    per_set,
    stored_sum,
    suffix_sums,
)


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
    """The per-constellation state probabilities of the module docstring ("Group states"),
    batch-last (``group_probabilities``)."""

    member: jax.Array
    """(L, C, B) bool: valid source l belongs to constellation c."""
    n_sources: jax.Array
    """(C, B) number of valid sources per constellation."""
    present: jax.Array
    """(C, B) bool: the constellation has at least one valid source."""
    p_none: jax.Array
    """(C, B) P_none_c, no fault in the constellation (1 for absent constellations)."""
    p_whole: jax.Array
    """(C, B) P_whole_c, the constellation event or >= 2 faulty sources (0 when absent)."""
    p_fault: jax.Array
    """(C, B) P_fault_c = 1 - P_none_c, computed without cancellation (0 when absent)."""
    p_single: jax.Array
    """(L, B) P_single_l, source l alone faulty (0 for padding and for constellations with
    one source)."""


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
    """The candidate fault modes of a batch of geometries: T template slots, which are live,
    what each excludes and its prior. Batch-last as the kernels build them (shapes below);
    ``fault_modes`` returns them batch-first, (..., T, L) and so on."""

    excluded: jax.Array
    """(T, L, B) bool: the sources the mode hypothesises faulty (valid ones only)."""
    excluded_constellation: jax.Array
    """(T, C, B) bool: the constellations it excludes whole (their clock states dropped)."""
    prior: jax.Array
    """(T, B) prior probability assigned to the mode (0 where not live)."""
    live: jax.Array
    """(T, B) bool: the mode is monitored at this geometry's order."""
    order: jax.Array
    """(B,) int: the order r, the most constellations (events) a live mode stands for."""
    p_beyond_order: jax.Array
    """(B,) P_NM before singular modes: grouped, P(more than r constellations faulty); event
    rules, the prior of every set not monitored."""
    p_no_fault: jax.Array
    """(B,) probability of no fault at all (no source or constellation event)."""
    needs_higher_order: jax.Array
    """(B,) bool: the convention would monitor a mode beyond the template order (kept in
    P_NM instead)."""


def fault_modes_batch_last(valid: Bool[ArrayLike, "L B"], constellation: Int[ArrayLike, "L B"],
                           p_sat: Float[ArrayLike, "L B"], p_const: Float[ArrayLike, "C B"],
                           p_thresh: float, max_order: int) -> FaultModes:
    """Live modes, exclusion sets and priors (static template), batch-last layout: valid,
    constellation, p_sat (L, B), p_const (C, B); ``FaultModes`` as its fields say."""
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
                      jnp.prod(gp.p_none, axis=0), p_beyond > p_thresh)


def to_batch_last(x, event_dims: int):
    """(..., e1..ek) -> (e1..ek, B) with the batch axes flattened."""
    batch = x.shape[:x.ndim - event_dims]
    x = x.reshape((-1,) + x.shape[x.ndim - event_dims:]) if batch else x[None]
    return jnp.moveaxis(x, 0, -1)


def to_batch_first(x, batch_shape):
    """(e1..ek, B) -> (batch..., e1..ek)."""
    x = jnp.moveaxis(x, -1, 0)
    return x.reshape(tuple(batch_shape) + x.shape[1:])


def fault_modes(valid, constellation, p_sat, p_const, p_thresh, max_order: int,
                rule=None) -> FaultModes:
    """Batch-first fault modes: valid, constellation, p_sat (..., L), p_const (..., C); returns
    arrays (..., T, L), (..., T, C), (..., T) and (...). ``p_thresh``: a float (the ``grouped``
    rule, ``fault_modes_batch_last``) or an ``IntegrityBudget``; ``rule``: a ``FaultModeRule``
    or its name (default ``grouped`` for a float p_thresh, else ``add-v4.2``)."""
    valid = jnp.asarray(valid, bool)
    batch = valid.shape[:-1]
    args = [to_batch_last(jnp.broadcast_to(jnp.asarray(x), valid.shape), 1)
            for x in (valid, constellation, p_sat)]
    pc = to_batch_last(jnp.broadcast_to(jnp.asarray(p_const, jnp.float64),
                                        batch + jnp.shape(p_const)[-1:]), 1)
    if isinstance(p_thresh, float | int):
        if rule is not None and fault_mode_rule(rule).events:
            raise ValueError("an event rule needs the IntegrityBudget (PHMI, P_THRES)")
        fm = fault_modes_batch_last(*args, pc, p_thresh, max_order)
    else:
        rule = fault_mode_rule(rule)
        fm = select_fault_modes(*args, pc, p_thresh, rule, check_order(rule, max_order))
    return FaultModes(*(to_batch_first(x, batch) for x in fm))


# --------------------------------------------------------------------------------------------
# Fault-mode conventions: the ADD's enumeration of independent events, and ours
# (docs/conformance.md).
# --------------------------------------------------------------------------------------------

#: the conventions ``FaultModeRule`` accepts, by name (docs/conformance.md)
CONVENTIONS = ("add-v4.2", "add-v3", "add-v3-consolidated", "blanch-2012", "grouped")
#: the highest order of the event conventions (pairs of events); ``grouped`` goes to 3
MAX_EVENT_ORDER = 2
#: source codes 2^l are exact in float64 up to this many sources (duplicate detection)
MAX_EVENT_SOURCES = 52


@dataclass(frozen=True)
class FaultModeRule:
    """Which fault modes are monitored and with which priors (a static configuration object).

    Events are each valid source (P_sat) and each present constellation (P_const), independent;
    the prior of a set E of events is exact, P0 prod_{e in E} P_e / (1 - P_e) with P0 the
    probability of no event. A mode excludes the union of the sources its events touch; modes
    with equal exclusion sets are one mode (priors summed, as MAAST's ``find_unique_subsets``).

    - ``add-v4.2`` (the current ADD, MAAST 2024 ``determine_subsets_v5``): enumerate the sets of
      up to max(order, 2) events, fold into each constellation mode every set inside that
      constellation whose prior is below ``fc_thres`` x the constellation's prior, monitor every
      set whose prior exceeds PHMI_V + PHMI_H, then the others by increasing number of sources
      out (ties in enumeration order) until P_NM <= P_THRES.
    - ``add-v3`` (ADD v3.0 / v3.1): sets of order 1, 2, ... in decreasing prior (ties in
      enumeration order) until P_NM <= P_THRES, no folding.
    - ``add-v3-consolidated``: ``add-v3`` after the folding of ``add-v4.2``.
    - ``blanch-2012`` (Blanch et al., ION GNSS 2012, Appendix J): satellites and constellations
      apart: every set of up to N_sat satellites and of up to N_const constellations, N_sat the
      smallest with P(more than N_sat satellite faults) <= ``sat_share`` x P_THRES and N_const
      with P(more than N_const constellation faults) <= (1 - ``sat_share``) x P_THRES; P_NM is
      the sum of the two tails; priors exact within each of the two families.
    - ``grouped``: the constellation-state grouping of this module's first part (seed 004's SOP
      studies, P_s up to 0.1): two faults in one constellation are that constellation whole.

    P_NM = 1 - P(no fault) - sum of the monitored priors: what the enumeration leaves out, the
    sets beyond the order, and (in the kernels) the priors of modes whose subset is singular.
    """

    name: str = "add-v4.2"
    fc_thres: float = 0.01
    sat_share: float = 0.5

    def __post_init__(self):
        if self.name not in CONVENTIONS:
            raise ValueError(f"fault_modes must be one of {', '.join(CONVENTIONS)}, "
                             f"got {self.name!r}")
        if not (0.0 <= float(self.fc_thres) < 1.0):
            raise ValueError(f"fc_thres must lie in [0, 1), got {self.fc_thres!r}")
        if not (0.0 < float(self.sat_share) < 1.0):
            raise ValueError(f"sat_share must lie in (0, 1), got {self.sat_share!r}")

    @property
    def events(self) -> bool:
        """The mode set is an enumeration of event sets (every convention but ``grouped``)."""
        return self.name != "grouped"

    @property
    def consolidated(self) -> bool:
        """The convention folds small sets into their constellation's mode (``add-v4.2``,
        ``add-v3-consolidated``)."""
        return self.name in ("add-v4.2", "add-v3-consolidated")

    @property
    def max_order(self) -> int:
        """The highest fault-mode order the convention enumerates: ``MAX_EVENT_ORDER`` (pairs
        of events) for the event rules, 3 for ``grouped``."""
        return MAX_EVENT_ORDER if self.events else 3


#: the default convention of the kernels: the current ADD
DEFAULT_RULE = FaultModeRule()


def fault_mode_rule(x: str | FaultModeRule | None) -> FaultModeRule:
    """A ``FaultModeRule`` from itself or its name (None: the default, ``add-v4.2``)."""
    if x is None:
        return DEFAULT_RULE
    if isinstance(x, FaultModeRule):
        return x
    if isinstance(x, str):
        return FaultModeRule(x)
    raise ValueError(f"fault_modes must be a name ({', '.join(CONVENTIONS)}) or an "
                     f"araim.FaultModeRule, got {x!r}")


class EventTemplate(NamedTuple):
    """Static event sets of order <= R: ``sources`` (T, 2) source slots (-1: none) and
    ``constellations`` (T, 2) constellation slots (-1: none), in MAAST's enumeration order
    (``itertools.combinations`` over the events [sources 0..L-1, constellations 0..C-1])."""

    sources: np.ndarray
    constellations: np.ndarray
    order: np.ndarray
    """(T,) int: the number of events in each set."""


@cache
def event_template(n_sources: int, n_constellations: int, order: int) -> EventTemplate:
    """Every set of 1..``order`` events over ``n_sources`` sources and ``n_constellations``
    constellations, in MAAST's enumeration order (cached per size)."""
    L, C = n_sources, n_constellations
    src, con, k_of = [], [], []
    for k in range(1, order + 1):
        for ev in itertools.combinations(range(L + C), k):
            s = [e for e in ev if e < L]
            c = [e - L for e in ev if e >= L]
            src.append(s + [-1] * (MAX_EVENT_ORDER - len(s)))
            con.append(c + [-1] * (MAX_EVENT_ORDER - len(c)))
            k_of.append(k)
    return EventTemplate(np.array(src, int).reshape(-1, MAX_EVENT_ORDER),
                         np.array(con, int).reshape(-1, MAX_EVENT_ORDER), np.array(k_of, int))


def template_source(rule: FaultModeRule, n_sources: int, n_constellations: int,
                    max_order: int) -> np.ndarray:
    """(T,) per candidate mode of the kernel: its first source slot, -1 for a mode that excludes
    whole constellations only (the kernels' fast paths); the first L modes are the single
    sources in both template families."""
    if not rule.events:
        return np.asarray(mode_template(n_sources, n_constellations, max_order).source)
    return event_template(n_sources, n_constellations, max_order).sources[:, 0]


_usum, _uany, _umax, _umin, _uprod = (linalg.sum_axis, linalg.any_axis, linalg.max_axis,
                                      linalg.min_axis, linalg.prod_axis)


@cache
def _event_indices(n_sources: int, n_constellations: int, order: int):
    """Static description of ``event_template``'s sets for gathers: the two source slots and
    the two constellation slots of each set (E, 2) with the sentinels L and C for "none", the
    number of sources named (E,), the order (E,) and the index of each constellation's own
    mode (C,)."""
    tpl = event_template(n_sources, n_constellations, order)
    L, C = n_sources, n_constellations
    src = np.where(tpl.sources >= 0, tpl.sources, L)
    con = np.where(tpl.constellations >= 0, tpl.constellations, C)
    n_src = np.sum(tpl.sources >= 0, axis=1)
    own = np.array([int(np.flatnonzero((n_src == 0) & (tpl.constellations[:, 0] == c)
                                       & (tpl.constellations[:, 1] < 0))[0])
                    for c in range(C)], int)
    return src, con, n_src, tpl.order, own


def event_modes_batch_last(valid, constellation, p_sat, p_const, budget, rule: FaultModeRule,
                           max_order: int, full=False) -> FaultModes:
    """The monitored modes of an event convention (``FaultModeRule``), batch-last.

    The kernel computes the geometry of the T event sets of order <= ``max_order`` (the slots);
    priors, folding and selection run over the E sets of order <= R_enum (max(max_order, 2)
    for the consolidated conventions, ``max_order`` otherwise), so a set beyond the slots stays
    in P_NM. The selection is decided for the slots: P_NM before slot i (what the sorted walk
    has left when it reaches i) is P(more than R_enum events) plus the candidates not before i,
    written as comparisons of keys, no sort; the sets beyond the slots all come after every slot
    of the same or a smaller key, so they enter as a few sums. ``full``: also decide whether
    the walk would monitor a set beyond the slots (``needs_higher_order``, for the host's
    ``required_order``), else that field is False.
    """
    L, C = valid.shape[0], p_const.shape[0]
    if L > MAX_EVENT_SOURCES:
        raise ValueError(f"fault_modes={rule.name!r} handles at most {MAX_EVENT_SOURCES} "
                         f"sources per geometry, got {L}")
    r_enum = max(max_order, MAX_EVENT_ORDER) if rule.consolidated else max_order
    src, con, n_src, order_t, own = _event_indices(L, C, r_enum)
    T = event_template(L, C, max_order).order.size  # slots: the first T sets
    E = order_t.size
    dtype = p_sat.dtype
    s0, s1, c0, c1 = src[:, 0], src[:, 1], con[:, 0], con[:, 1]

    lab = jnp.where(valid, constellation, -1)
    labpad = pad_row(lab, -1)
    member = lab[:, None, :] == jnp.arange(C)[None, :, None]  # (L, C, B), valid sources only
    n_c = _usum(member.astype(jnp.int32), 0)  # (C, B)
    present = n_c > 0
    ps = jnp.where(valid, p_sat, 0.0)
    pc = jnp.where(present, p_const, 0.0)
    # (the per-set arrays are buffers, written block by block: ``per_set``)
    ev_ok = jnp.concatenate([valid, present], axis=0)  # (N, B): the events, sources first
    exists = per_set(ev_ok, ev_ok, ev_ok, jnp.logical_and, r_enum)

    def priors(p_s, p_c):
        """Exact priors P0 prod p / (1 - p) of every set (E, B), as products (no logarithm:
        an exponential per set was a fifth of the kernel): P0 r_i for an event, (P0 r_i) r_j
        for a pair."""
        p0 = _uprod(1.0 - p_s, 0) * _uprod(1.0 - p_c, 0)
        r = jnp.concatenate([p_s / (1.0 - p_s), p_c / (1.0 - p_c)], axis=0)  # (N, B)
        a = linalg.materialize(p0[None] * r)
        return linalg.materialize(jnp.where(exists, per_set(a, a, r, jnp.multiply, r_enum),
                                            0.0))

    full_flag = jnp.zeros(valid.shape[1:], bool)
    if rule.name == "blanch-2012":
        # two families; a set mixing sources and constellations is not a mode there
        is_c = jnp.asarray(n_src == 0)[:, None]
        mixed = jnp.asarray((n_src > 0) & (c0 < C))[:, None]
        prior = jnp.where(is_c, priors(jnp.zeros_like(ps), pc), priors(ps, jnp.zeros_like(pc)))
        dist_s, tail_s = event_tails(ps, r_enum)
        dist_c, tail_c = event_tails(pc, r_enum)

        def family_order(dist, tail, thr):
            tails, above = [], tail  # P(more than k), k = r_enum .. 1
            for k in range(r_enum, 0, -1):
                tails.insert(0, above)
                above = above + dist[k]
            ok = jnp.stack([t <= thr for t in tails])
            n = jnp.where(jnp.any(ok, axis=0), jnp.argmax(ok, axis=0) + 1, r_enum)
            return n, jnp.choose(n - 1, tails, mode="clip")

        n_s, nm_s = family_order(dist_s, tail_s, rule.sat_share * budget.p_thresh)
        n_co, nm_c = family_order(dist_c, tail_c, (1.0 - rule.sat_share) * budget.p_thresh)
        k_t = jnp.asarray(order_t)[:, None]
        selected = exists & ~mixed & jnp.where(is_c, k_t <= n_co[None], k_t <= n_s[None])
        p_beyond = nm_s + nm_c + _usum(jnp.where(selected[T:], prior[T:], 0.0), 0)
        full_flag = (n_s > max_order) | (n_co > max_order)
        sel = selected[:T]
    else:
        prior = priors(ps, pc)
        _, tail = event_tails(jnp.concatenate([ps, pc], axis=0), r_enum)
        cand = exists
        if rule.consolidated:
            # fold every set inside one constellation c (its sources all in c, its
            # constellation, if any, c itself; not c's own mode) with prior below fc_thres x
            # prior(c) into c's mode (MAAST determine_subsets_v5, one pass per constellation)
            fold, mass = [], []
            for c in range(C):
                # inside c: its sources (one at least) all in c, its constellation, if any, c
                # (sources come first, so the first event of a pair is a source)
                own_c = jnp.concatenate([lab == c, jnp.broadcast_to(
                    jnp.asarray(np.arange(C) == c)[:, None], (C,) + lab.shape[1:])], axis=0)
                first = own_c.at[L:].set(False)
                inside = per_set(first, first, own_c, jnp.logical_and, r_enum) & exists
                f = inside & (prior < rule.fc_thres * prior[own[c]][None])
                fold.append(f)
                mass.append(stored_sum(jnp.where(f, prior, 0.0)))
            for c in range(C):  # the constellation modes' rows only
                prior = jax.lax.dynamic_update_slice_in_dim(
                    prior, (prior[own[c]] + mass[c])[None], int(own[c]), axis=0)
            cand = exists & ~functools.reduce(jnp.logical_or, fold)
        cp = linalg.materialize(jnp.where(cand, prior, 0.0))
        idx = np.arange(E)
        if rule.name == "add-v4.2":
            # sources out: named sources + the constellations' sources - those counted twice
            # an event puts 1 or n_c sources out; a pair the sum, less a source inside the
            # pair's constellation
            out = jnp.concatenate([jnp.ones_like(n_c[:1]).repeat(L, 0), n_c], axis=0)
            con_of = np.concatenate([np.full(L, -2), np.arange(C)])  # -2: no label equals it

            def pair_out(i):
                both = out[i][None] + out[i + 1:]
                if i >= L:
                    return both
                return both - (lab[i][None] == jnp.asarray(con_of[i + 1:])[:, None])

            n_out = linalg.materialize(per_set(out, None, None, None, r_enum, pair_out))
            forced = cand & (prior > budget.phmi_v + budget.phmi_h)
            other = linalg.materialize(jnp.where(forced, 0.0, cp))
            ni = n_out[:T]
            if max_order == 1:
                # order-1 slots: the L singles (1 source out) come first in index order, then
                # the C constellation modes by n_c; a reverse running sum for the singles and
                # C x C comparisons for the constellations instead of T x T. The sets beyond
                # the slots (E > T: the pairs the folding enumerates) are later in the
                # enumeration, so they come after a slot when they have as many sources out
                # or more: all of them after a single, those with n_out >= n_c after c
                # (every row stored: stacked unstored, each row's chain of up to E terms was
                # recomputed inside one scalar loop over the stack, 60 % of the selection)
                run, rows = linalg.materialize(tail + stored_sum(other[L:])), [None] * L
                for l in range(L - 1, -1, -1):
                    run = linalg.materialize(run + other[l])
                    rows[l] = run
                for c in range(C):
                    r = tail
                    for d in range(C):
                        after = (n_c[d] > n_c[c]) | ((n_c[d] == n_c[c]) & (d >= c))
                        r = r + jnp.where(after, other[L + d], 0.0)
                    r = stored_sum(jnp.where(n_out[T:] >= n_c[c][None], other[T:], 0.0), r)
                    rows.append(linalg.materialize(r))
                suffix = jnp.stack(rows)
            else:  # E == T: every set is a slot
                suffix = suffix_sums(tail, ni, n_out, other, idx[:T])
            sel = forced[:T] | (cand[:T] & (suffix > budget.p_thresh))
            if full and E > T:
                # the first unforced set beyond the slots in the walk's order: the walk
                # reaches it with the most P_NM left of them all
                key = jnp.where(cand[T:] & ~forced[T:], n_out[T:] * E + idx[T:, None], jnp.inf)
                first = _umin(key, 0)
                ahead = jnp.where(n_out * E + idx[:, None] >= first[None], other, 0.0)
                full_flag = _uany(forced[T:], 0) | (
                    jnp.isfinite(first) & (tail + _usum(ahead, 0) > budget.p_thresh))
        else:  # add-v3, add-v3-consolidated: order, then decreasing prior, then index
            k = order_t
            ci = cp[:T]
            higher = {o: _usum(cp[k > o], 0) for o in sorted(set(k[:T].tolist()))}
            suffix = tail[None] + jnp.stack([higher[o] for o in k[:T].tolist()])
            for j in range(T):  # same order: decreasing prior, ties in enumeration order
                same = jnp.asarray(k[:T] == k[j])[:, None]
                cj = cp[j][None]
                after = same & ((cj < ci) | ((cj == ci) & jnp.asarray(idx[:T] <= j)[:, None]))
                suffix = suffix + jnp.where(after, cj, 0.0)
            sel = cand[:T] & (suffix > budget.p_thresh)
            if full and E > T:
                # the walk reaches the sets beyond the slots (all of a higher order) with
                # the tail and their own mass left
                full_flag = _uany(cand[T:], 0) & (tail + _usum(cp[T:], 0) > budget.p_thresh)
        p_beyond = (tail + _usum(jnp.where(cand[:T] & ~sel, prior[:T], 0.0), 0)
                    + stored_sum(cp[T:]))
    sel = linalg.materialize(sel)

    # the slots: exclusion sets, duplicates merged into the first selected one
    t0, t1, k0, k1 = s0[:T], s1[:T], c0[:T], c1[:T]
    lidx = np.arange(L)[None, :, None]
    excluded = valid[None] & ((lidx == t0[:, None, None]) | (lidx == t1[:, None, None])
                              | (lab[None] == k0[:, None, None]) | (lab[None] == k1[:, None, None]))
    pr = prior[:T]
    if max_order == 1:
        # order-1 slots: a constellation mode duplicates a single only when the constellation
        # has that one source; it then joins the (earlier) single
        lone = member & (n_c == 1)[None]  # (L, C, B)
        sel_s, sel_c = sel[:L], sel[L:T]
        dup_c = sel_c & _uany(lone & sel_s[:, None], 0)
        gain = _usum(jnp.where(lone & sel_c[None], pr[L:T][None], 0.0), 1)  # (L, B)
        live = sel & jnp.concatenate([jnp.ones((L,) + sel.shape[1:], bool), ~dup_c], axis=0)
        merged = pr + jnp.concatenate([jnp.where(sel_s, gain, 0.0), jnp.zeros_like(pr[L:T])],
                                      axis=0)
    else:
        # equal exclusion sets by their codes sum_l 2^l (exact in float64 for L <= 52)
        two = 2.0 ** np.arange(L)
        code_c = pad_row(_usum(jnp.where(member, jnp.asarray(two, dtype)[:, None, None], 0.0), 0),
                      0.0)
        code = code_c[k0] + code_c[k1]
        for s in (t0, t1):  # a named source not inside a named constellation
            ls = labpad[s]
            named = jnp.asarray(s < L)[:, None] & pad_row(valid, False)[s]
            inside = (ls == jnp.asarray(k0)[:, None]) | (ls == jnp.asarray(k1)[:, None])
            code = code + jnp.where(named & ~inside, jnp.asarray(two[np.minimum(s, L - 1)],
                                                                 dtype)[:, None], 0.0)
        code = linalg.materialize(code)
        dup, merged = merge_equal_sets(code, sel, pr)
        live = sel & ~dup
    prior_out = jnp.where(live, merged, 0.0)
    excl_c = jnp.asarray((np.arange(C)[None] == k0[:, None]) | (np.arange(C)[None] == k1[:, None])
                         )[:, :, None] & present[None]  # (T, C, B)
    order = _umax(jnp.where(live, jnp.asarray(order_t[:T])[:, None], 0), 0)
    p0 = jnp.prod(1.0 - ps, axis=0) * jnp.prod(1.0 - pc, axis=0)
    return FaultModes(excluded, excl_c, prior_out, live, order, p_beyond, p0, full_flag)


def select_fault_modes(valid, constellation, p_sat, p_const, budget, rule: FaultModeRule,
                       max_order: int) -> FaultModes:
    """The kernels' fault modes under ``rule``, batch-last: (L, B) inputs, p_const (C, B)."""
    if rule.events:
        return event_modes_batch_last(valid, constellation, p_sat, p_const, budget, rule,
                                      max_order)
    return fault_modes_batch_last(valid, constellation, p_sat, p_const, budget.p_thresh,
                                  max_order)


def check_order(rule: FaultModeRule, max_order: int) -> int:
    """``max_order`` within what ``rule`` enumerates, or a ValueError naming both."""
    if max_order > rule.max_order:
        raise ValueError(f"max_order={max_order} is above what fault_modes={rule.name!r} "
                         f"enumerates ({rule.max_order}); use max_order <= {rule.max_order} "
                         "or fault_modes='grouped'")
    return max_order
