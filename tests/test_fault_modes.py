"""Tests of the fault-mode grouping rule (araim.fault_modes; seed 004 eq. 8, eq. 17, App. B).

Rule (araim/fault_modes.py docstring, tests/reference_mhss.py): per present constellation the
states none / one source faulty / whole; order r from P(more than r constellations faulty) <=
P_thresh; modes "F whole" and "l resolved, F - {a} whole" for |F| <= r. Priors are compared by
exclusion set (unique per mode). Probability identities to 1e-12 (sums of ~100 terms <= 1 in
float64: rounding ~1e-15).
"""

import itertools

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from oaraim import araim
from oaraim import reference_mhss as ref
from oaraim.araim import Status
from oaraim.araim.fault_modes import fault_modes as _fault_modes_eager
from oaraim.errors import gnss_variances, sop_variances
from tests.test_mhss import grouped, random_cases

# these tests check the grouped convention (seed 004's SOP studies) against the grouped
# oracle; the ADD conventions are tested in test_conformance.py
protection_levels = grouped(araim.protection_levels)
solution_separation = grouped(araim.solution_separation)

P_THRESH = 6e-8  # Table I
#: jitted once per shape: eager dispatch of the mode template is slower than compiling it
fault_modes = jax.jit(_fault_modes_eager, static_argnums=(4, 5))


def _np(fm):
    return {k: np.asarray(getattr(fm, k)) for k in fm._fields}


def _priors(fm, i=None):
    """{excluded set: prior} of the live modes (geometry i of a batch, or unbatched)."""
    ex = fm["excluded"] if i is None else fm["excluded"][i]
    pr = fm["prior"] if i is None else fm["prior"][i]
    live = fm["live"] if i is None else fm["live"][i]
    out = {}
    for k in np.flatnonzero(live):
        key = frozenset(np.flatnonzero(ex[k]).tolist())
        assert key not in out, f"two live modes exclude {sorted(key)}"
        out[key] = float(pr[k])
    return out


# --------------------------------------------------------------------------- hand-computed toy


def _toy():
    """Constellation 0: sources 0, 1 with P_s 0.1, 0.2 and P_const 0.05; constellation 1: source
    2 with P_s 0.3 and P_const 0.1 (large values so that every term is visible)."""
    valid = np.ones(3, bool)
    const = np.array([0, 0, 1])
    p_sat = np.array([0.1, 0.2, 0.3])
    p_const = np.array([0.05, 0.1])
    return valid, const, p_sat, p_const


#   P_none_0 = 0.95 x 0.9 x 0.8 = 0.684          P_none_1 = 0.9 x 0.7 = 0.63
#   P_single_0 = 0.95 x 0.1 x 0.8 = 0.076        P_single_1 = 0.95 x 0.2 x 0.9 = 0.171
#   P_whole_0 = 1 - 0.684 - 0.076 - 0.171 = 0.069 (= 0.05 + 0.95 x 0.1 x 0.2)
#   P_whole_1 = P_fault_1 = 1 - 0.63 = 0.37 (one source: single and whole coincide)
#   P_fault_0 = 0.316; P(both faulty) = 0.316 x 0.37 = 0.11692 > P_thresh: order 2
TOY_ORDER_1 = {
    frozenset({0, 1}): 0.069 * 0.63,  # constellation 0 whole
    frozenset({0}): 0.076 * 0.63,  # source 0 alone
    frozenset({1}): 0.171 * 0.63,  # source 1 alone
    frozenset({2}): 0.37 * 0.684,  # constellation 1 (its one source)
}
TOY_ORDER_2 = {
    frozenset({0, 1, 2}): 0.069 * 0.37,  # both whole
    frozenset({0, 2}): 0.076 * 0.37,  # source 0 resolved (lowest index), constellation 1 whole
    frozenset({1, 2}): 0.171 * 0.37,
}
TOY_NO_FAULT = 0.684 * 0.63


@pytest.mark.parametrize("max_order", [1, 2])
def test_toy_priors_by_hand(max_order):
    valid, const, p_sat, p_const = _toy()
    want = dict(TOY_ORDER_1)
    if max_order == 2:
        want.update(TOY_ORDER_2)
    beyond = 0.316 * 0.37 if max_order == 1 else 0.0
    fm = _np(fault_modes(valid, const, p_sat, p_const, P_THRESH, max_order))
    got = _priors(fm)
    assert set(got) == set(want)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-13), sorted(k)
    assert int(fm["order"]) == max_order  # order 1 does not meet P_thresh: r = R
    assert float(fm["p_no_fault"]) == pytest.approx(TOY_NO_FAULT, rel=1e-13)
    assert float(fm["p_beyond_order"]) == pytest.approx(beyond, rel=1e-13, abs=1e-300)
    assert sum(want.values()) + TOY_NO_FAULT + beyond == pytest.approx(1.0, abs=1e-14)
    o = ref.fault_mode_set(valid, const, p_sat, p_const, P_THRESH, max_order)
    assert {m.excluded: m.prior for m in o.modes} == pytest.approx(want, rel=1e-13)
    assert o.p_beyond_order == pytest.approx(beyond, rel=1e-13, abs=1e-300)


def test_toy_three_constellations_lowest_index_resolved():
    """Three constellations of two sources each, order 3: the mode that resolves source l of
    constellation a while F - {a} is faulty carries prod_{b < a} P_whole_b prod_{b > a}
    P_fault_b (the lowest-index single-source constellation is the resolved one); enumerate
    every fault combination by brute force and check that each lands in exactly one mode."""
    valid = np.ones(6, bool)
    const = np.array([0, 0, 1, 1, 2, 2])
    p_sat = np.array([0.1, 0.2, 0.15, 0.05, 0.3, 0.25])
    p_const = np.array([0.02, 0.04, 0.06])
    fm = _np(fault_modes(valid, const, p_sat, p_const, P_THRESH, 3))
    got = _priors(fm)
    # brute force over the 2^9 event combinations (6 sources + 3 constellation events)
    want = {}
    no_fault = 0.0
    for events in itertools.product([0, 1], repeat=9):
        p = np.prod([(q if e else 1 - q) for e, q in zip(events, [*p_sat, *p_const],
                                                          strict=True)])
        state = {}  # constellation -> "none" | ("single", l) | "whole"
        for c in range(3):
            faulty = [l for l in range(6) if const[l] == c and events[l]]
            if events[6 + c] or len(faulty) >= 2:
                state[c] = "whole"
            elif faulty:
                state[c] = ("single", faulty[0])
            else:
                state[c] = "none"
        if all(s == "none" for s in state.values()):
            no_fault += p
            continue
        singles = [c for c in range(3) if isinstance(state[c], tuple)]
        excluded = set()
        for c in range(3):
            if state[c] == "none":
                continue
            if singles and c == singles[0]:
                excluded.add(state[c][1])  # the lowest-index single is resolved
            else:
                excluded |= {l for l in range(6) if const[l] == c}
        key = frozenset(excluded)
        want[key] = want.get(key, 0.0) + p
    assert set(got) == set(want)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-12), sorted(k)
    assert float(fm["p_no_fault"]) == pytest.approx(no_fault, rel=1e-13)
    assert float(fm["p_beyond_order"]) == 0.0
    assert sum(got.values()) + no_fault == pytest.approx(1.0, abs=1e-13)


_probs = st.floats(0.0, 0.5, allow_nan=False, allow_subnormal=False)


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(labels=st.lists(st.integers(0, 2), min_size=6, max_size=6),
       valid=st.lists(st.booleans(), min_size=6, max_size=6),
       p_sat=st.lists(_probs, min_size=6, max_size=6),
       p_const=st.lists(_probs, min_size=3, max_size=3),
       max_order=st.integers(1, 3))
def test_grouping_matches_oracle_property(labels, valid, p_sat, p_const, max_order):
    """Any labels, validity and probabilities (6 sources, 3 constellation slots, some absent):
    the live modes, their priors, the order, P(no fault) and P(beyond r) equal the oracle's, and
    priors + P(no fault) + P(beyond r) = 1."""
    valid, labels = np.array(valid), np.array(labels)
    p_sat, p_const = np.array(p_sat), np.array(p_const)
    fm = _np(fault_modes(valid, labels, p_sat, p_const, P_THRESH, max_order))
    o = ref.fault_mode_set(valid, labels, p_sat, p_const, P_THRESH, max_order)
    got = _priors(fm)
    want = {m.excluded: m.prior for m in o.modes}
    assert set(got) == set(want)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-12, abs=1e-300), sorted(k)
    assert int(fm["order"]) == o.order
    assert float(fm["p_no_fault"]) == pytest.approx(o.p_no_fault, rel=1e-12, abs=1e-300)
    assert float(fm["p_beyond_order"]) == pytest.approx(o.p_beyond_order, rel=1e-12, abs=1e-300)
    total = sum(got.values()) + float(fm["p_no_fault"]) + float(fm["p_beyond_order"])
    assert total == pytest.approx(1.0, abs=1e-12)


# --------------------------------------------------------------------------- identities


def test_priors_no_fault_and_unmonitored_sum_to_one():
    """On the random L = 28 GPS + SOP set (orders 1..3, P_s^S up to 0.1): sum of live priors +
    P(no fault) + P(more than r constellations faulty) = 1 within 1e-12, and the priors equal
    the oracle's, mode by mode (1e-9 relative)."""
    n = 400
    case, _ = random_cases(20261125, n)
    fm = _np(fault_modes(case["valid"], case["constellation"], case["p_sat"], case["p_const"],
                         P_THRESH, 3))
    total = np.sum(fm["prior"] * fm["live"], axis=-1) + fm["p_no_fault"] + fm["p_beyond_order"]
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-12)
    assert np.all(fm["prior"][~fm["live"]] == 0.0)
    for i in range(0, n, 4):
        o = ref.fault_mode_set(case["valid"][i], case["constellation"][i], case["p_sat"][i],
                               case["p_const"][i], P_THRESH, 3)
        got = _priors(fm, i)
        want = {m.excluded: m.prior for m in o.modes}
        assert set(got) == set(want), i
        for k, v in want.items():
            assert got[k] == pytest.approx(v, rel=1e-9, abs=1e-300), (i, sorted(k))
        assert int(fm["order"][i]) == o.order
        assert fm["p_no_fault"][i] == pytest.approx(o.p_no_fault, rel=1e-12)
        assert fm["p_beyond_order"][i] == pytest.approx(o.p_beyond_order, rel=1e-9, abs=1e-300)
        assert o.p_no_fault + sum(want.values()) + o.p_beyond_order == pytest.approx(1, abs=1e-12)


def test_public_api_probabilities_close():
    """Through araim.solution_separation: the monitored priors + P_not_monitored + P(no fault)
    (computed independently) = 1 within 1e-12 on every geometry with status OK or 5."""
    n = 128  # the shape of test_fde.py's separation test: one compilation for both
    case, _ = random_cases(20261125, n)
    sep = solution_separation(araim.Sources(case["g"], case["constellation"], case["var_int"],
                                            case["var_acc"], case["b_nom"], case["p_sat"],
                                            case["valid"]), case["p_const"],
                              araim.BUDGET_SEED004_TABLE_I, np.zeros((n, 28)), araim.MHSSOptions(3))
    prior = np.asarray(sep.prior) * np.asarray(sep.monitored)
    status = np.asarray(sep.pl.status)
    checked = 0
    for i in range(n):
        if status[i] not in (Status.OK, Status.UNMONITORED_RISK):
            continue
        o = ref.fault_mode_set(case["valid"][i], case["constellation"][i], case["p_sat"][i],
                               case["p_const"][i], P_THRESH, 3)
        total = prior[i].sum() + float(np.asarray(sep.pl.p_not_monitored)[i]) + o.p_no_fault
        assert total == pytest.approx(1.0, abs=1e-12), i
        checked += 1
    assert checked > 50


# --------------------------------------------------------------------------- mode counts


def _gps9_sops(n_sop, p_s_sop):
    """9 GPS satellites (fixed sky above 10 deg) + n_sop SOPs in one constellation on a ring at
    elevations spread from -10 to +20 deg (so SOP-only subsets are nonsingular), Table I; padded
    to 17 rows (one compiled shape). Returns the argument tuple and valid."""
    az_g = np.deg2rad([10, 50, 95, 140, 185, 220, 260, 300, 340])
    el_g = np.deg2rad([15, 62, 33, 25, 48, 80, 20, 38, 55])
    az_s = np.deg2rad(np.linspace(0, 360, n_sop, endpoint=False) + 7)
    el_s = np.deg2rad(np.linspace(-10, 20, n_sop))
    az, el = np.r_[az_g, az_s], np.r_[el_g, el_s]
    g = np.stack([-np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), -np.sin(el)], axis=-1)
    vi, va = (np.asarray(x).copy() for x in gnss_variances(el, 1.0))
    vi[9:], va[9:] = (float(x) for x in sop_variances(3.0))
    const = np.r_[np.zeros(9, int), np.ones(n_sop, int)]
    b_nom = np.r_[np.full(9, 0.75), np.zeros(n_sop)]
    p_sat = np.r_[np.full(9, 1e-5), np.full(n_sop, p_s_sop)]
    pad = 17 - 9 - n_sop
    g = np.vstack([g, np.zeros((pad, 3))])
    const, vi, va, b_nom, p_sat = (np.r_[x, np.full(pad, f, x.dtype)] for x, f in (
        (const, 1), (vi, 1.0), (va, 1.0), (b_nom, 0.0), (p_sat, 0.5)))
    return (g, const, vi, va, b_nom, p_sat, np.array([1e-8, 1e-4])), np.arange(17) < 9 + n_sop


def test_benchmark_configuration_has_15_modes():
    """9 GPS + 4 SOPs in one SOP constellation, Table I, P_s^S = 1e-4 (the issue's benchmark):
    order 1, 13 single-source modes + 2 constellation modes, all 15 monitorable."""
    args, valid = _gps9_sops(4, 1e-4)
    fm = _np(fault_modes(valid, args[1], args[5], args[6], P_THRESH, 3))
    assert int(fm["order"]) == 1 and int(fm["live"].sum()) == 15
    res = protection_levels(araim.Sources(*args[:6], valid), args[6], araim.BUDGET_SEED004_TABLE_I,
                            araim.MHSSOptions(3))
    assert int(res.order) == 1 and int(res.n_modes) == 15 and int(res.status) == Status.OK
    o = ref.protection_levels_reference(araim.Sources(*args[:6], valid), args[6],
                                        araim.BUDGET_SEED004_TABLE_I,
                                        ref.ReferenceOptions(max_order=3))
    assert o.n_modes == 15 and not o.singular
    assert float(res.hpl_m) == pytest.approx(o.hpl_m, abs=2e-3)


def test_high_sop_fault_probability_needs_order_2():
    """9 GPS + 8 SOPs with P_s^S = 0.1: P(SOP constellation faulty) ~ 0.57, P(GPS and SOP) ~ 5e-5
    > P_thresh: order 2. Candidates: 17 singles + 2 wholes (order 1), and for the pair: both
    whole, 9 GPS sources resolved with the SOPs whole, 8 SOPs resolved with GPS whole: 37. The
    pair-whole mode excludes everything (singular): 36 monitorable."""
    args, valid = _gps9_sops(8, 0.1)
    fm = _np(fault_modes(valid, args[1], args[5], args[6], P_THRESH, 3))
    assert int(fm["order"]) == 2 and int(fm["live"].sum()) == 37
    res = protection_levels(araim.Sources(*args[:6], valid), args[6], araim.BUDGET_SEED004_TABLE_I,
                            araim.MHSSOptions(3))
    assert int(res.order) == 2 and int(res.n_modes) == 36
    o = ref.protection_levels_reference(araim.Sources(*args[:6], valid), args[6],
                                        araim.BUDGET_SEED004_TABLE_I,
                                        ref.ReferenceOptions(max_order=3))
    assert o.order == 2 and len(o.fault_modes.modes) == 37 and o.n_modes == 36
    assert [m.constellations for m in o.singular] == [(0, 1)]
    assert int(res.status) == o.status
    if o.status == ref.OK:
        assert float(res.hpl_m) == pytest.approx(o.hpl_m, abs=2e-3)
        assert float(res.vpl_m) == pytest.approx(o.vpl_m, abs=2e-3)


def test_single_source_constellation_has_no_separate_single_mode():
    """A constellation with one valid source contributes one mode (whole = its source), with
    prior 1 - P_none; a padding row of that constellation changes nothing."""
    valid = np.array([True] * 6 + [True, False])
    const = np.array([0] * 6 + [1, 1])
    p_sat = np.array([1e-5] * 6 + [1e-3, 0.5])
    p_const = np.array([1e-8, 1e-4])
    fm = _np(fault_modes(valid, const, p_sat, p_const, P_THRESH, 1))
    got = _priors(fm)
    p_none_gps = (1 - 1e-8) * (1 - 1e-5) ** 6
    assert got[frozenset({6})] == pytest.approx((1 - (1 - 1e-4) * (1 - 1e-3)) * p_none_gps,
                                                rel=1e-12)
    assert len(got) == 6 + 1 + 1  # 6 GPS singles, GPS whole, the lone source
