"""Plain per-geometry NumPy/SciPy reference of the ARAIM / OARAIM MHSS solver.

The oracle of ``araim.protection_levels``, ``araim.solution_separation`` and
``araim.detect_and_exclude``, and the "NumPy reference" of the benchmark (DESIGN.md). One geometry
at a time, straight from seed 004 eqs. (8)-(16) with the corrections of DESIGN.md, written for
clarity and not for speed:

- fault modes are enumerated with ``itertools`` (grouping rule below), priors are products of
  event probabilities (eq. 17 as corrected);
- each fault-tolerant solution is an ordinary weighted least squares on the kept rows only, with
  the clock columns of constellations that have no kept source literally removed;
- each PL equation (14)/(16) is solved by bisection to 1e-6 m.

Fault-mode grouping (the project's documented rule). For a present constellation c (one with at
least one valid source) with valid sources S_c:

    P_none_c   = (1 - P_const,c) prod_{l in S_c} (1 - P_s,l)
    P_single_l = (1 - P_const,c) P_s,l prod_{l' in S_c, l' != l} (1 - P_s,l')   (|S_c| >= 2 only)
    P_whole_c  = 1 - P_none_c - sum_l P_single_l   (constellation event or >= 2 faulty sources;
                 = 1 - P_none_c when |S_c| = 1: single and whole coincide)
    P_f,c      = 1 - P_none_c

The order r is the smallest r in 1..R with P(more than r present constellations faulty) <=
P_thresh (constellations independent), else R. For k = 1..r and every set F of k present
constellations, the candidate modes are "whole F" (all sources of F excluded) and "resolved
(l, F)" for every a in F with |S_a| >= 2 and l in S_a (l and all sources of F minus a excluded):
each fault combination with exactly the constellations F faulty belongs to exactly one mode (the
lowest-index constellation of F in a single-source state is resolved, all others excluded whole).

All probabilities here are computed as sums of non-negative terms (no 1 - (1 - p) cancellation):
P(at least k faulty sources) from the exact Poisson-binomial distribution, and the probability
that more than r constellations are faulty by enumerating the faulty sets.
"""

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, special

OK, TOO_FEW_SOURCES, SINGULAR_GEOMETRY, NOT_CONVERGED, UNMONITORED_RISK = 0, 1, 2, 4, 5

#: a normal matrix is singular when its smallest eigenvalue is below this times its largest
#: diagonal entry (the spec: condition number above ~1e10)
SINGULAR_RTOL = 1e-10
#: a mode whose eigenvalue ratio lies within this factor of SINGULAR_RTOL (either side) is
#: "borderline": an implementation with a different but reasonable test (Cholesky pivots, another
#: tolerance) may call it either way, so comparisons treat such geometries separately
BORDERLINE_FACTOR = 1e3
#: a solution separation whose sigma_ss is below this times sigma_q^(0) is exactly zero (both the
#: separation and the threshold), e.g. the lone-SOP mode of Theorem 1: tau = 0 (DESIGN.md)
ZERO_SS_RTOL = 1e-9
#: bisection tolerance of the PL root, metres
PL_XTOL_M = 1e-6


def q_func(x):
    """Q(x) = P(N(0, 1) > x), accurate in the far tail."""
    return special.ndtr(-np.asarray(x, float))


def q_inv(p):
    """Q^-1(p)."""
    return -special.ndtri(p)


def poisson_binomial_pmf(p):
    """P(exactly k of the independent events with probabilities p occur), k = 0..len(p)."""
    pmf = np.zeros(len(p) + 1)
    pmf[0] = 1.0
    for pk in p:
        pmf[1:] = pmf[1:] * (1.0 - pk) + pmf[:-1] * pk
        pmf[0] *= 1.0 - pk
    return pmf


@dataclass
class Mode:
    """One candidate fault mode."""

    excluded: frozenset  # source indices hypothesised faulty
    prior: float
    kind: str  # "whole" or "resolved"
    constellations: tuple  # F, the faulty constellations it stands for
    source: int = -1  # the resolved source l (resolved modes)


@dataclass
class FaultModeSet:
    """The candidate fault modes of one geometry and the probabilities they are built from
    (the grouping rule of the module docstring, or ``event_fault_mode_set``'s events, which
    leaves the four probability dicts empty)."""

    present: list  # present constellation labels, ascending
    sources: dict  # c -> list of valid source indices
    p_none: dict  # c -> P_none_c
    p_single: dict  # l -> P_single_l (only for constellations with >= 2 sources)
    p_whole: dict  # c -> P_whole_c
    p_fault: dict  # c -> P_f,c = 1 - P_none_c
    order: int  # r, the most constellations (events) a monitored mode stands for
    p_no_fault: float  # prod_c P_none_c
    p_beyond_order: float  # P(more than r constellations faulty)
    modes: list = field(default_factory=list)  # Mode of every candidate, enumeration order


def _inputs(valid, constellation, p_sat, p_const):
    """The fault-mode inputs as arrays, the present constellations and their valid sources."""
    valid = np.asarray(valid, bool)
    constellation = np.asarray(constellation, int)
    present = sorted({int(c) for c in constellation[valid]})
    sources = {c: [int(l) for l in np.flatnonzero(valid & (constellation == c))] for c in present}
    return (valid, constellation, np.asarray(p_sat, float), np.asarray(p_const, float), present,
            sources)


def fault_mode_set(valid, constellation, p_sat, p_const, p_thresh, max_order):
    """Enumerate the candidate fault modes and their priors for one geometry."""
    valid, constellation, p_sat, p_const, present, sources = _inputs(valid, constellation,
                                                                     p_sat, p_const)

    p_none, p_single, p_whole, p_fault = {}, {}, {}, {}
    for c in present:
        pc = p_const[c]
        ps = p_sat[sources[c]]
        pmf = poisson_binomial_pmf(ps)
        p_none[c] = (1.0 - pc) * pmf[0]
        p_fault[c] = pc + (1.0 - pc) * pmf[1:].sum()  # = 1 - P_none_c
        if len(sources[c]) >= 2:
            for l in sources[c]:
                others = [m for m in sources[c] if m != l]
                p_single[l] = (1.0 - pc) * p_sat[l] * np.prod(1.0 - p_sat[others])
            p_whole[c] = pc + (1.0 - pc) * pmf[2:].sum()  # event, or >= 2 faulty sources
        else:
            p_whole[c] = p_fault[c]

    def p_more_than(r):
        total = 0.0
        for k in range(r + 1, len(present) + 1):
            for faulty in itertools.combinations(present, k):
                total += np.prod([p_fault[c] if c in faulty else p_none[c] for c in present])
        return total

    order = max_order
    for r in range(1, max_order + 1):
        if p_more_than(r) <= p_thresh:
            order = r
            break

    fm = FaultModeSet(present, sources, p_none, p_single, p_whole, p_fault, order,
                      float(np.prod([p_none[c] for c in present])), p_more_than(order))
    for k in range(1, order + 1):
        for F in itertools.combinations(present, k):
            rest = np.prod([p_none[c] for c in present if c not in F])
            excl = frozenset(l for c in F for l in sources[c])
            fm.modes.append(Mode(excl, float(np.prod([p_whole[c] for c in F]) * rest),
                                 "whole", F))
            for a in F:
                if len(sources[a]) < 2:
                    continue
                before = np.prod([p_whole[b] for b in F if b < a])
                after = np.prod([p_fault[b] for b in F if b > a])
                others = frozenset(l for b in F if b != a for l in sources[b])
                for l in sources[a]:
                    fm.modes.append(Mode(others | {l}, float(p_single[l] * before * after * rest),
                                         "resolved", F, l))
    return fm


EVENT_RULES = ("add-v4.2", "add-v3", "add-v3-consolidated", "blanch-2012")


def _rule_parts(rule):
    """(name, fc_thres, sat_share) of a rule name or of an object carrying them."""
    if isinstance(rule, str):
        return rule, 0.01, 0.5
    return rule.name, float(rule.fc_thres), float(rule.sat_share)


@dataclass(frozen=True)
class ReferenceOptions:
    """The options of the oracle's functions (``araim.MHSSOptions``' counterpart, plus the
    singularity tolerance of its projector)."""

    max_order: int = 3
    """The fault-mode order (``grouped`` up to 3, the event conventions up to 2)."""
    fault_modes: object = "grouped"
    """"grouped" (``fault_mode_set``), a name of ``EVENT_RULES`` or an object with ``name``,
    ``fc_thres`` and ``sat_share`` (``event_fault_mode_set``)."""
    singular_rtol: float = SINGULAR_RTOL
    """Relative pivot tolerance below which a mode's normal matrix is singular."""
    position_optimization: object = None
    """None or an ``araim.PositionOptimization`` (``adjusted_estimator``)."""


def _options(options):
    """``options``, or the defaults for None."""
    return ReferenceOptions() if options is None else options


def event_fault_mode_set(valid, constellation, p_sat, p_const, budget, rule="add-v4.2",
                         max_order=2):
    """The event conventions of ``araim.FaultModeRule`` for one geometry, by enumeration.

    Events: every valid source and every present constellation. Every set E of up to R events
    (R = max(max_order, 2) when consolidating, else max_order) gets the exact prior
    P0 prod_{e in E} p_e / (1 - p_e); the folding, the selection and P_NM = 1 - P0 - sum of the
    monitored priors follow the rule's docstring literally (a sorted list walked until P_NM
    fits); selected sets of more than ``max_order`` events are not monitored (they stay in
    P_NM); selected sets with the same exclusion set are one mode, priors summed. ``rule``: a
    name of ``EVENT_RULES`` (fc_thres 0.01, sat_share 0.5) or an object with ``name``,
    ``fc_thres`` and ``sat_share`` (an ``araim.FaultModeRule``).
    """
    rule, fc_thres, sat_share = _rule_parts(rule)
    valid, constellation, p_sat, p_const, present, sources = _inputs(valid, constellation,
                                                                     p_sat, p_const)
    events = [("s", int(l)) for l in np.flatnonzero(valid)] + [("c", c) for c in present]
    p_ev = {e: (p_sat[e[1]] if e[0] == "s" else p_const[e[1]]) for e in events}

    def union(subset):
        out = set()
        for kind, i in subset:
            out |= {i} if kind == "s" else set(sources[i])
        return frozenset(out)

    def product(subset, family):
        p0 = np.prod([1.0 - p_ev[e] for e in family])
        return float(p0 * np.prod([p_ev[e] / (1.0 - p_ev[e]) for e in subset]))

    consolidated = rule in ("add-v4.2", "add-v3-consolidated")
    r_enum = max(max_order, 2) if consolidated else max_order
    # (subset, prior) in MAAST's enumeration order; a list entry per set
    listing = [(sub, product(sub, events)) for k in range(1, r_enum + 1)
               for sub in itertools.combinations(events, k)]
    if rule == "blanch-2012":
        sats = [e for e in events if e[0] == "s"]
        consts = [e for e in events if e[0] == "c"]

        def family_order(family, thr):
            pmf = poisson_binomial_pmf([p_ev[e] for e in family])
            for n in range(1, r_enum + 1):
                if pmf[n + 1:].sum() <= thr:
                    return n, float(pmf[n + 1:].sum())
            return r_enum, float(pmf[r_enum + 1:].sum())

        n_s, nm_s = family_order(sats, sat_share * budget.p_thresh)
        n_c, nm_c = family_order(consts, (1.0 - sat_share) * budget.p_thresh)
        selected = [(sub, product(sub, sats)) for k in range(1, n_s + 1)
                    for sub in itertools.combinations(sats, k)]
        selected += [(sub, product(sub, consts)) for k in range(1, n_c + 1)
                     for sub in itertools.combinations(consts, k)]
        p_nm = nm_s + nm_c
    else:
        if consolidated:
            for c in present:
                entry = next(i for i, (sub, _) in enumerate(listing) if sub == (("c", c),))
                base = listing[entry][1]
                inside = [i for i, (sub, pr) in enumerate(listing)
                          if i != entry and union(sub) and union(sub) <= set(sources[c])
                          and all(e[0] == "s" or e[1] == c for e in sub)
                          and pr < fc_thres * base]
                listing[entry] = (listing[entry][0],
                                  base + sum(listing[i][1] for i in inside))
                listing = [x for i, x in enumerate(listing) if i not in set(inside)]
        p0 = float(np.prod([1.0 - p for p in p_ev.values()]))
        if rule == "add-v4.2":
            phmi = budget.phmi_v + budget.phmi_h
            forced = [x for x in listing if x[1] > phmi]
            others = sorted([x for x in listing if x[1] <= phmi], key=lambda x: len(union(x[0])))
            p_nm = 1.0 - p0 - sum(pr for _, pr in forced)
            selected = list(forced)
        else:
            others = sorted(listing, key=lambda x: (len(x[0]), -x[1]))
            p_nm = 1.0 - p0
            selected = []
        for sub, pr in others:  # sorted() is stable: ties keep the enumeration order
            if p_nm <= budget.p_thresh:
                break
            selected.append((sub, pr))
            p_nm -= pr
    modes, order = {}, 0
    for sub, pr in selected:
        if len(sub) > max_order:
            p_nm += pr  # no slot for it: it stays unmonitored
            continue
        order = max(order, len(sub))
        excl = union(sub)
        modes[excl] = modes.get(excl, 0.0) + pr
    fm = FaultModeSet(present, sources, {}, {}, {}, {}, order,
                      float(np.prod([1.0 - p for p in p_ev.values()])), max(float(p_nm), 0.0))
    fm.modes = [Mode(excl, pr, "events", ()) for excl, pr in modes.items()]
    return fm


def design_matrix(g, constellation, kept):
    """(H, rows): H = [G, B] over the kept rows, one clock column per constellation that still
    has a kept source (the clocks of the others are literally removed)."""
    rows = np.flatnonzero(kept)
    cols = sorted({int(c) for c in constellation[rows]})
    h = np.zeros((len(rows), 3 + len(cols)))
    h[:, :3] = g[rows]
    for j, c in enumerate(cols):
        h[:, 3 + j] = constellation[rows] == c
    return h, rows


def wls_projector(g, constellation, kept, var_int, singular_rtol=SINGULAR_RTOL):
    """Full-state WLS of the kept rows: ((S, N^-1, H, rows) or None when singular, ratio).

    H = [G, B] over the kept rows, B with one column per constellation that still has a kept
    source; S = N^-1 H^T W (all state rows), N = H^T W H, W = diag(1 / var_int). ratio = the
    smallest eigenvalue of N over its largest diagonal entry (0 with fewer rows than states);
    singular: ratio <= singular_rtol.
    """
    h, rows = design_matrix(g, constellation, kept)
    if len(rows) < h.shape[1]:
        return None, 0.0
    w = np.diag(1.0 / var_int[rows])
    n = h.T @ w @ h
    ratio = float(np.linalg.eigvalsh(n).min() / np.diag(n).max())
    if ratio <= singular_rtol:
        return None, ratio
    n_inv = np.linalg.inv(n)
    return (n_inv @ h.T @ w, n_inv, h, rows), ratio


@dataclass
class ModeSolution:
    """The weighted least-squares solution of one fault mode (or the all-in-view one), seed 004
    eqs. (9)-(12), per axis east, north, up (m)."""

    mode: Mode | None  # None for the all-in-view solution
    s_pos: np.ndarray  # (3, L) position rows of S^(i), zero outside the kept rows
    sigma: np.ndarray  # (3,) eq. (9)
    bias: np.ndarray  # (3,) eq. (10)
    sigma_ss: np.ndarray = None  # (3,) eq. (11)
    threshold: np.ndarray = None  # (3,) eq. (12)


@dataclass
class Result:
    """What ``protection_levels_reference`` finds for one geometry; on a failure the levels are
    inf and ``status`` says why (the codes of ``araim.Status``)."""

    hpl_m: float  # horizontal protection level, hypot of the east and north PLs
    vpl_m: float  # vertical protection level, eq. (16)
    emt_m: float  # effect of monitor threshold: largest vertical threshold, prior >= P_EMT
    sigma_acc_u_m: float  # vertical accuracy sigma of the all-in-view solution (C_acc)
    n_modes: int  # N_f, the monitored modes
    p_not_monitored: float  # P_NM: beyond the order plus the singular modes' priors
    status: int  # OK, TOO_FEW_SOURCES, SINGULAR_GEOMETRY or UNMONITORED_RISK
    order: int  # the fault-mode order r
    pl_enu_m: np.ndarray  # (3,) the PL of each axis, eq. (14) east/north, (16) up
    fault_modes: FaultModeSet
    all_in_view: ModeSolution | None  # None when too few sources
    monitored: list  # ModeSolution of the monitorable modes, in enumeration order
    singular: list  # Mode of the candidate modes that are singular
    k_fa: np.ndarray  # (3,) false-alarm multipliers K_fa of eq. (12)
    borderline: bool = False  # some mode's (or the all-in-view) singularity test is borderline
    position_adjusted: bool = False  # PLs of the Blanch et al. (2015) estimator


def _solution(g, constellation, kept, var_int, b_nom, mode, singular_rtol):
    """(ModeSolution or None when singular, eigenvalue ratio of the normal matrix)."""
    out, ratio = wls_projector(g, constellation, kept, var_int, singular_rtol)
    if out is None:
        return None, ratio
    s, n_inv, _, rows = out
    s_pos = np.zeros((3, len(kept)))
    s_pos[:, rows] = s[:3]
    sigma = np.sqrt(np.diag(n_inv)[:3])
    bias = np.abs(s_pos) @ b_nom
    return ModeSolution(mode, s_pos, sigma, bias), ratio


def solve_pl(prior_fault_free, sigma0, bias0, priors, sigmas, offsets, rhs):
    """Bisection root of  2 Q((PL - b0)/s0) + sum_i p_i Q((PL - offset_i)/s_i) = rhs."""
    def risk(pl):
        total = prior_fault_free * q_func((pl - bias0) / sigma0)
        if len(priors):
            total += np.sum(priors * q_func((pl - offsets) / sigmas))
        return total

    lo, hi = 0.0, 1.0
    assert risk(lo) > rhs  # 2 Q(-b0/s0) >= 1 > rhs
    while risk(hi) > rhs:
        lo, hi = hi, 2.0 * hi
        if hi > 1e12:
            raise RuntimeError("no PL bracket")
    while hi - lo > PL_XTOL_M:
        mid = 0.5 * (lo + hi)
        if risk(mid) > rhs:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def protection_levels_reference(sources, p_const, budget, options=None):
    """Seed 004 eqs. (8)-(16) for ONE geometry; arguments as ``araim.protection_levels`` without
    batch axes: ``sources`` the seven fields of an ``araim.Sources`` in its order (g (L, 3),
    constellation, var_int, var_acc, b_nom, p_sat, valid (L,) or None; any sequence: this
    module imports nothing of the package), p_const (C,). ``options``: ``ReferenceOptions``
    (None: the defaults): ``fault_modes`` "grouped" (``fault_mode_set``) or one of
    ``EVENT_RULES`` (``event_fault_mode_set``, max_order at most 2); ``position_optimization``
    None or an ``araim.PositionOptimization`` (``adjusted_estimator``; the result's
    ``position_adjusted`` says whether its PLs are the adjusted estimator's)."""
    g, constellation, var_int, var_acc, b_nom, p_sat, valid = sources
    options = _options(options)
    max_order, fault_modes = options.max_order, options.fault_modes
    singular_rtol, position_optimization = options.singular_rtol, options.position_optimization
    g = np.asarray(g, float)
    L = g.shape[0]
    valid = np.ones(L, bool) if valid is None else np.asarray(valid, bool)
    constellation = np.asarray(constellation, int)
    var_int = np.where(valid, np.asarray(var_int, float), 1.0)
    var_acc = np.where(valid, np.asarray(var_acc, float), 1.0)
    b_nom = np.where(valid, np.asarray(b_nom, float), 0.0)
    g = np.where(valid[:, None], g, 0.0)

    if isinstance(fault_modes, str) and fault_modes == "grouped":
        fm = fault_mode_set(valid, constellation, p_sat, p_const, budget.p_thresh, max_order)
    else:
        fm = event_fault_mode_set(valid, constellation, p_sat, p_const, budget, fault_modes,
                                  max_order)
    inf3 = np.full(3, np.inf)

    lo, hi = singular_rtol / BORDERLINE_FACTOR, singular_rtol * BORDERLINE_FACTOR
    borderline = False

    def failed(status, p_nm=np.nan, n_modes=0, aiv=None, monitored=(), singular=()):
        return Result(np.inf, np.inf, np.inf, np.inf, n_modes, p_nm, status, fm.order, inf3, fm,
                      aiv, list(monitored), list(singular), np.full(3, np.nan), borderline)

    if valid.sum() < 3 + len(fm.present) + 1:
        return failed(TOO_FEW_SOURCES)
    aiv, ratio = _solution(g, constellation, valid, var_int, b_nom, None, singular_rtol)
    borderline = lo <= ratio <= hi
    if aiv is None:
        return failed(SINGULAR_GEOMETRY)

    monitored, singular = [], []
    for mode in fm.modes:
        kept = valid.copy()
        kept[list(mode.excluded)] = False
        sol, ratio = _solution(g, constellation, kept, var_int, b_nom, mode, singular_rtol)
        borderline |= lo <= ratio <= hi
        if sol is None:
            singular.append(mode)
        else:
            diff = sol.s_pos - aiv.s_pos
            sol.sigma_ss = np.sqrt((diff**2) @ var_acc)
            sol.sigma_ss[sol.sigma_ss <= ZERO_SS_RTOL * aiv.sigma] = 0.0
            monitored.append(sol)
    n_f = len(monitored)
    p_nm = fm.p_beyond_order + sum(m.prior for m in singular)
    if p_nm > budget.p_thresh:
        return failed(UNMONITORED_RISK, p_nm, n_f, aiv, monitored, singular)

    pfa_h, pfa_v = budget.p_fa_h / budget.n_es_cont, budget.p_fa_v / budget.n_es_cont
    k_fa = np.array([q_inv(pfa_h / (4 * n_f)), q_inv(pfa_h / (4 * n_f)),
                     q_inv(pfa_v / (2 * n_f))]) if n_f else np.zeros(3)
    for sol in monitored:
        sol.threshold = k_fa * sol.sigma_ss

    res = _levels(aiv, monitored, k_fa, p_nm, var_acc, budget)
    res = Result(*res[:4], n_f, float(p_nm), OK, fm.order, res[4], fm, aiv, monitored,
                 singular, k_fa, borderline)
    opt = position_optimization
    if opt is None:
        return res
    triggered = opt.keep == "always" or (res.sigma_acc_u_m < opt.sigma_acc_max_m[2] and (
        res.vpl_m > opt.vpl_target_m or res.hpl_m > opt.hpl_target_m
        or res.emt_m > opt.emt_target_m))
    if not triggered:
        return res
    aiv2, monitored2 = adjusted_estimator(aiv, monitored, var_int, var_acc, b_nom, k_fa, opt)
    adj = _levels(aiv2, monitored2, k_fa, p_nm, var_acc, budget)
    if opt.keep == "lower" and not (adj[1] < res.vpl_m or adj[0] < res.hpl_m):
        return res
    return Result(*adj[:4], n_f, float(p_nm), OK, fm.order, adj[4], fm, aiv2, monitored2, singular,
                  k_fa, borderline, position_adjusted=True)


def _levels(aiv, monitored, k_fa, p_nm, var_acc, budget):
    """(HPL, VPL, EMT, sigma_acc_U, PL_ENU) of an all-in-view solution and its monitored modes
    (thresholds set)."""
    scale = (1.0 - p_nm / (budget.phmi_v + budget.phmi_h)) / budget.n_es_int
    rhs = np.array([budget.phmi_h / 2, budget.phmi_h / 2, budget.phmi_v]) * scale
    priors = np.array([m.mode.prior for m in monitored])
    pl = np.zeros(3)
    for q in range(3):
        pl[q] = solve_pl(
            2.0, aiv.sigma[q], aiv.bias[q], priors,
            np.array([m.sigma[q] for m in monitored]),
            np.array([m.threshold[q] + m.bias[q] for m in monitored]), rhs[q])
    emt = max([m.threshold[2] for m in monitored if m.mode.prior >= budget.p_emt], default=0.0)
    sigma_acc_u = float(np.sqrt(aiv.s_pos[2] ** 2 @ var_acc))
    return float(np.hypot(pl[0], pl[1])), float(pl[2]), float(emt), sigma_acc_u, pl


def adjusted_estimator(aiv, monitored, var_int, var_acc, b_nom, k_fa, opt):
    """Blanch et al. (2015) (``araim.position_opt``), per axis q: the all-in-view row moved
    toward the row of the monitored mode (prior >= opt.prior_min) with the largest sigma_q, by
    the largest t in [0, 1] at which its accuracy sigma stays at most sigma_acc_max_q - 1e-5 m
    (found by bracketing the convex sigma_acc(t)^2 with brentq, not by the quadratic formula).
    Returns the new all-in-view ModeSolution and copies of the monitored ones with separations
    and thresholds from it."""
    rows = aiv.s_pos.copy()
    for q in range(3):
        cands = [m for m in monitored if m.mode.prior >= opt.prior_min]
        if not cands:
            continue
        weak = max(cands, key=lambda m: m.sigma[q])
        d = weak.s_pos[q] - aiv.s_pos[q]
        limit2 = (opt.sigma_acc_max_m[q] - 1e-5) ** 2

        def excess(t, q=q, d=d, limit2=limit2):
            return float((aiv.s_pos[q] + t * d) ** 2 @ var_acc) - limit2

        if excess(0.0) >= 0 or not np.any(d):
            t = 0.0
        elif excess(1.0) <= 0:
            t = 1.0
        else:
            t = optimize.brentq(excess, 0.0, 1.0, xtol=1e-15, rtol=1e-15)
        rows[q] = aiv.s_pos[q] + t * d
    aiv2 = ModeSolution(None, rows, np.sqrt(rows**2 @ var_int), np.abs(rows) @ b_nom)
    out = []
    for m in monitored:
        ss = np.sqrt((m.s_pos - rows) ** 2 @ var_acc)
        ss[ss <= ZERO_SS_RTOL * aiv2.sigma] = 0.0
        out.append(ModeSolution(m.mode, m.s_pos, m.sigma, m.bias, ss, k_fa * ss))
    return aiv2, out


def pl_equation(res, budget, q, pl):
    """Left-hand side and right-hand side of eq. (14) (q = 0, 1) or (16) (q = 2) at ``pl`` for an
    OK result of ``protection_levels_reference``."""
    aiv = res.all_in_view
    lhs = 2.0 * q_func((pl - aiv.bias[q]) / aiv.sigma[q])
    for m in res.monitored:
        lhs += m.mode.prior * q_func((pl - m.threshold[q] - m.bias[q]) / m.sigma[q])
    scale = (1.0 - res.p_not_monitored / (budget.phmi_v + budget.phmi_h)) / budget.n_es_int
    rhs = (budget.phmi_h / 2.0 if q < 2 else budget.phmi_v) * scale
    return float(lhs), float(rhs)


@dataclass
class Separation:
    """Eq. (13) for one geometry and residual vector: the solution separations of the
    monitored modes, their test statistics and whether any exceeds its threshold."""

    result: Result  # the protection levels of the same geometry
    separation: np.ndarray  # (N_f, 3) ((S^(i) - S^(0)) y)_q of the monitored modes
    tau: np.ndarray  # (N_f, 3) eq. (13)
    detected: bool  # some tau > 1
    excluded: list  # frozensets, the excluded sources of each monitored mode


def solution_separation_reference(sources, p_const, budget, residual, options=None):
    """Eq. (13) for one geometry and residual vector y (L,): separations, tau and detection.
    Arguments as ``protection_levels_reference`` plus the residual."""
    valid = sources[6]
    res = protection_levels_reference(sources, p_const, budget, options)
    y = np.asarray(residual, float)
    if valid is not None:
        y = np.where(np.asarray(valid, bool), y, 0.0)
    if res.status not in (OK, UNMONITORED_RISK) or not res.monitored:
        return Separation(res, np.zeros((0, 3)), np.zeros((0, 3)), False, [])
    if res.status != OK:  # thresholds need K_fa, which needs N_f only
        n_f = res.n_modes
        pfa_h, pfa_v = budget.p_fa_h / budget.n_es_cont, budget.p_fa_v / budget.n_es_cont
        k_fa = np.array([q_inv(pfa_h / (4 * n_f)), q_inv(pfa_h / (4 * n_f)),
                         q_inv(pfa_v / (2 * n_f))])
        for sol in res.monitored:
            sol.threshold = k_fa * sol.sigma_ss
    sep = np.array([(m.s_pos - res.all_in_view.s_pos) @ y for m in res.monitored])
    thr = np.array([m.threshold for m in res.monitored])
    zero = thr == 0.0
    sep[zero] = 0.0  # a separation with zero variance is identically zero (Theorem 1)
    tau = np.where(zero, 0.0, np.abs(sep) / np.where(zero, 1.0, thr))
    return Separation(res, sep, tau, bool(np.any(tau > 1.0)),
                      [m.mode.excluded for m in res.monitored])


@dataclass
class FDE:
    """Detection and exclusion for one geometry (``detect_and_exclude_reference``)."""

    detected: bool  # the all-in-view solution separation test fired
    excluded: np.ndarray  # (L,) bool, sources excluded
    pl: Result  # the result after exclusion (all-in-view when nothing was detected)
    status: int | None  # None: exclusion failed (the implementation picks the code)
    candidates: list  # (excluded set, acceptable, weighted SSE) of every candidate tried


def weighted_sse(g, constellation, kept, var_int, y):
    """sum_l w_l (y_l - (H dx)_l)^2 over the kept rows, dx the full-state WLS solution."""
    (s, _, h, rows), _ = wls_projector(g, constellation, kept, var_int)
    dx = s @ y[rows]
    r = y[rows] - h @ dx
    return float(np.sum(r**2 / var_int[rows]))


def detect_and_exclude_reference(sources, p_const, budget, residual, options=None):
    """Detection and exclusion for one geometry: re-test every monitorable mode's subset with the
    same residual; among the subsets that pass with status OK keep the smallest weighted SSE.
    Arguments as ``solution_separation_reference``."""
    g, constellation, var_int, var_acc, b_nom, p_sat, valid = sources
    L = np.asarray(g).shape[0]
    valid = np.ones(L, bool) if valid is None else np.asarray(valid, bool)
    y = np.where(valid, np.asarray(residual, float), 0.0)

    def with_valid(v):
        return (g, constellation, var_int, var_acc, b_nom, p_sat, v)

    sep = solution_separation_reference(with_valid(valid), p_const, budget, y, options)
    if not sep.detected:
        return FDE(False, np.zeros(L, bool), sep.result, sep.result.status, [])
    g_clean = np.where(valid[:, None], np.asarray(g, float), 0.0)
    vi = np.where(valid, np.asarray(var_int, float), 1.0)
    candidates, best = [], None
    for excl in sep.excluded:
        sub_valid = valid.copy()
        sub_valid[list(excl)] = False
        sub = solution_separation_reference(with_valid(sub_valid), p_const, budget, y, options)
        ok = sub.result.status == OK and not sub.detected
        sse = weighted_sse(g_clean, np.asarray(constellation, int), sub_valid, vi, y) if ok \
            else np.inf
        candidates.append((excl, ok, sse))
        if ok and (best is None or sse < best[2]):
            best = (sub_valid, sub.result, sse)
    if best is None:  # exclusion failed: no PL (the status code is the implementation's choice)
        res = sep.result
        failed = Result(np.inf, np.inf, np.inf, np.inf, res.n_modes, res.p_not_monitored, None,
                        res.order, np.full(3, np.inf), res.fault_modes, res.all_in_view,
                        res.monitored, res.singular, res.k_fa, res.borderline)
        return FDE(True, np.zeros(L, bool), failed, None, candidates)
    sub_valid, res, _ = best
    return FDE(True, valid & ~sub_valid, res, res.status, candidates)
