"""ARAIM conformance: the published worked examples, each under the convention its source uses
(docs/conformance.md), and the event conventions of ``araim.FaultModeRule`` against the NumPy
oracle's independent enumeration (``oaraim.reference_mhss.event_fault_mode_set``).

Tolerances. The ADD (v3.0 section 2.5) computes every PL to within TOL_PL = 5e-2 m from above
(the bisection returns the upper end of its bracket) and prints it to 0.1 m; a conformant PL root
x therefore prints a value P with x - 0.05 <= P <= x + 0.05 + TOL_PL (for the HPL, the sum of
two such per-axis PLs, x + 0.05 + sqrt(2) TOL_PL). Our kernel returns the root to 1e-4 m.
Intermediate values printed to 1e-4 are met to 5e-5 plus the rounding of the inputs (C_int and
C_acc are printed to 1e-4 m^2): 2e-4. sigma_acc is printed to 0.01 m: 0.005.
"""

import itertools
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import araim
from oaraim import reference_mhss as ref
from oaraim.araim import Status
from oaraim.araim import availability as av
from oaraim.araim.fault_modes import CONVENTIONS, FaultModeRule, fault_mode_rule, fault_modes
from oaraim.araim.mhss import required_order
from oaraim.errors import gnss_variances, sop_variances

#: WG-C ARAIM TSG, Reference Airborne Algorithm Description Document v3.0 (2019), Appendix D
#: (numerical example, also EU-US Cooperation on Satellite Navigation WG-C, ARAIM Technical
#: Subgroup Milestone 3 Report (2016), Annex A.IX; the same geometry is Blanch et al. 2012,
#: Appendix J): ENU line-of-sight rows (the first three columns of G), 5 GPS then 5 Galileo
ADD_ROWS = np.array([
    [0.0225, 0.9951, -0.0966], [0.6750, -0.6900, -0.2612], [0.0723, -0.6601, -0.7477],
    [-0.9398, 0.2553, -0.2269], [-0.5907, -0.7539, -0.2877], [-0.3236, -0.0354, -0.9455],
    [-0.6748, 0.4356, -0.5957], [0.0938, -0.7004, -0.7075], [0.5571, 0.3088, -0.7709],
    [0.6622, 0.6958, -0.2780]])
#: C_int and C_acc diagonals, m^2 (sigma_URA 0.75 m, sigma_URE 0.5 m, ADD error models)
ADD_C_INT = np.array([3.8865, 1.4377, 0.8604, 1.6383, 1.3229, 0.8434, 0.8963, 0.8669, 0.8573,
                      1.3616])
ADD_C_ACC = np.array([3.5740, 1.1252, 0.5479, 1.3258, 1.0104, 0.5309, 0.5838, 0.5544, 0.5448,
                      1.0491])
ADD_CONST = np.array([0] * 5 + [1] * 5)
ADD_B_NOM_M = 0.5
ADD_P_CONST = np.array([1e-4, 1e-4])
#: the ADD's TOL_PL (v3.0 Table 1 of constants) and the printed precisions
TOL_PL_M = 0.05
PRINT_PL_M = 0.05  # half of 0.1 m
INTERMEDIATE_TOL = 2e-4
SIGMA_ACC_TOL_M = 0.005


def add_example(p_sat, rule, max_order=None, budget=araim.BUDGET_LPV200):
    L = ADD_ROWS.shape[0]
    args = (ADD_ROWS, ADD_CONST, ADD_C_INT, ADD_C_ACC, np.full(L, ADD_B_NOM_M),
            np.full(L, p_sat), ADD_P_CONST)
    a = [x[None] for x in args]
    res = araim.protection_levels(araim.Sources(*a[:6]), a[6], budget,
                                  araim.MHSSOptions(max_order, fault_modes=rule))
    oracle = ref.protection_levels_reference(araim.Sources(*args[:6]), args[6], budget,
                                             ref.ReferenceOptions(max_order=max_order or 2,
                                                                  fault_modes=rule))
    return {k: np.asarray(v)[0] for k, v in res._asdict().items()}, oracle


def assert_printed_pl(root_m, published_m, axes=1):
    """A PL root x printed as P by a TOL_PL bisection from above (module docstring)."""
    assert root_m - PRINT_PL_M <= published_m <= root_m + PRINT_PL_M + np.sqrt(axes) * TOL_PL_M, (
        root_m, published_m)


def test_add_v3_appendix_d_worked_example():
    """ADD v3.0 Appendix D (P_sat = 1e-5, P_const = 1e-4, b_nom 0.5 m, LPV-200 allocation):
    N_fault modes 12, K_fa,3 = 5.1083, per constellation mode sigma_3 = 2.5760 / 2.5577 m,
    sigma_ss,3 = 1.5307 / 1.5292 m, b_3 = 2.8935 / 2.0875 m; VPL 19.2 m, HPL 14.5 m,
    EMT 7.8 m, sigma_v,acc 1.47 m."""
    res, oracle = add_example(1e-5, "add-v3")
    assert res["status"] == Status.OK and res["n_modes"] == 12 and res["order"] == 1
    assert oracle.k_fa[2] == pytest.approx(5.1083, abs=INTERMEDIATE_TOL)
    # the probability of no fault monitored, by hand: all pairs of the 12 events at first order
    p, pc = 1e-5, 1e-4
    assert res["p_not_monitored"] == pytest.approx(45 * p * p + 20 * p * pc + pc * pc, rel=1e-3)
    whole = {frozenset(range(5)): (2.5760, 1.5307, 2.8935),
             frozenset(range(5, 10)): (2.5577, 1.5292, 2.0875)}
    for m in oracle.monitored:
        if m.mode.excluded in whole:
            np.testing.assert_allclose([m.sigma[2], m.sigma_ss[2], m.bias[2]],
                                       whole.pop(m.mode.excluded), atol=INTERMEDIATE_TOL)
    assert not whole
    assert_printed_pl(res["vpl_m"], 19.2)
    assert_printed_pl(res["hpl_m"], 14.5, axes=2)
    assert res["emt_m"] == pytest.approx(7.8, abs=PRINT_PL_M)
    assert res["sigma_acc_u_m"] == pytest.approx(1.47, abs=SIGMA_ACC_TOL_M)
    for key in ("vpl_m", "hpl_m", "emt_m"):
        assert res[key] == pytest.approx(getattr(oracle, key), abs=2e-3)


_fault_modes = jax.jit(fault_modes, static_argnums=(4, 5, 6))


def add_fault_modes(p_sat, rule, max_order=1):
    """The fault modes alone (no geometry) of the Appendix D example under ``rule``."""
    L = ADD_ROWS.shape[0]
    fm = _fault_modes(np.ones((1, L), bool), ADD_CONST[None], np.full((1, L), p_sat),
                      ADD_P_CONST[None], araim.BUDGET_LPV200, max_order, fault_mode_rule(rule))
    return {k: np.asarray(v)[0] for k, v in fm._asdict().items()}


def test_add_v3_appendix_d_other_conventions_miss_it():
    """The same example under the consolidating conventions folds the sat + own-constellation
    pairs and the pairs inside a constellation into the constellation modes: P_NM 2.25e-8 by
    hand (3.45e-8 - 10 P_sat P_const - 2 C(5, 2) P_sat^2), VPL 19.10 m, outside the ADD's
    printed 19.2 (what the issue measured before the conventions existed)."""
    p, pc = 1e-5, 1e-4
    folded = 45 * p * p + 20 * p * pc + pc * pc - 10 * p * pc - 20 * p * p
    for rule in ("add-v3-consolidated", "add-v4.2"):
        assert add_fault_modes(p, rule)["p_beyond_order"] == pytest.approx(folded, rel=1e-3)
    res, _ = add_example(p, "add-v4.2", max_order=1)
    assert res["p_not_monitored"] == pytest.approx(folded, rel=1e-3)
    assert res["vpl_m"] < 19.2 - PRINT_PL_M


def test_emt_counts_modes_at_or_above_p_emt_with_exact_priors():
    """ADD: the EMT is the largest vertical threshold over the modes whose prior is >= P_EMT.
    With exact priors a satellite mode is P_sat prod (1 - P_other) < P_sat = 1e-5 and a
    constellation mode P_const prod (1 - P_other) = 9.998e-5 < P_const: at P_EMT = 1e-5 only
    the constellation modes count (EMT 7.8 m, Appendix D; the satellites' thresholds are lower
    here, at most 7.51 m, so counting them would not change it) and at P_EMT = P_const = 1e-4
    none does (EMT 0: the equality case)."""
    res, oracle = add_example(1e-5, "add-v3")
    priors = {len(m.mode.excluded): m.mode.prior for m in oracle.monitored}
    assert priors[1] < 1e-5 and 9.99e-5 < priors[5] < 1e-4
    t_whole = max(m.threshold[2] for m in oracle.monitored if len(m.mode.excluded) == 5)
    assert res["emt_m"] == pytest.approx(t_whole, abs=1e-9)
    budget = araim.IntegrityBudget(9.8e-8, 2e-9, 3.9e-6, 9e-8, 8e-8, p_emt=1e-4)
    assert add_example(1e-5, "add-v3", budget=budget)[0]["emt_m"] == 0.0


def test_blanch_2012_appendix_j_worked_example():
    """Blanch et al., "Advanced RAIM user algorithm description: integrity support message
    processing, fault detection, exclusion, and protection level calculation", ION GNSS 2012,
    Appendix J: the Appendix D geometry with P_sat = 1e-4, P_const = 1e-4, separate thresholds
    P_sat,thres = P_const,thres = 4e-8 (half of P_THRES each): N_sat,max 2, N_const,max 1, 57
    modes, K_fa,3 = Q^-1(3.9e-6 / 2 / 57) = 5.3953; VPL 19.7 m, HPL 14.9 m, sigma_v,acc
    1.47 m."""
    res, oracle = add_example(1e-4, "blanch-2012")
    assert res["status"] == Status.OK and res["n_modes"] == 57 and res["order"] == 2
    assert oracle.k_fa[2] == pytest.approx(5.3953, abs=INTERMEDIATE_TOL)
    assert_printed_pl(res["vpl_m"], 19.7)
    assert_printed_pl(res["hpl_m"], 14.9, axes=2)
    assert res["sigma_acc_u_m"] == pytest.approx(1.47, abs=SIGMA_ACC_TOL_M)
    for key in ("vpl_m", "hpl_m", "emt_m"):
        assert res[key] == pytest.approx(getattr(oracle, key), abs=2e-3)


@pytest.mark.xfail(strict=True, reason="Blanch 2012 Appendix J prints EMT 11.8 m; we measure "
                   "8.26 m (the GPS constellation mode, 5.3953 x 1.5307 m): no monitored mode "
                   "with prior >= P_EMT = 1e-5 has a threshold near 11.8 m, and the largest "
                   "threshold of any of the 57 modes is 14.15 m (a satellite pair), so the "
                   "printed value follows a definition the paper does not state")
def test_blanch_2012_appendix_j_emt():
    res, _ = add_example(1e-4, "blanch-2012")
    assert res["emt_m"] == pytest.approx(11.8, abs=PRINT_PL_M)


def test_required_order_follows_the_convention():
    """P_sat = 1e-5: order 1 suffices for every convention; P_sat = 1e-4: the ADD rules need
    pairs (P(two or more events) = 6.6e-7 > P_THRES); blanch-2012 too (N_sat,max = 2)."""
    L = ADD_ROWS.shape[0]
    for p_sat in (1e-5, 1e-4):
        args = (jnp.ones((1, L), bool), jnp.asarray(ADD_CONST[None]),
                jnp.full((1, L), p_sat), jnp.asarray(ADD_P_CONST[None]))
        for rule in CONVENTIONS:
            expect = 1 if p_sat == 1e-5 else 2
            assert required_order(*args, araim.BUDGET_LPV200, fault_modes=rule) == expect, rule
    with pytest.raises(ValueError, match="fault_modes must be one of"):
        add_example(1e-5, "add-v5")
    with pytest.raises(ValueError, match="max_order=3 is above"):
        add_example(1e-5, "add-v4.2", max_order=3)


def test_rule_objects_and_names():
    assert fault_mode_rule(None) == FaultModeRule("add-v4.2")
    assert fault_mode_rule("grouped") == FaultModeRule("grouped")
    assert FaultModeRule("add-v4.2", fc_thres=0.0) != FaultModeRule("add-v4.2")
    with pytest.raises(ValueError, match="fc_thres"):
        FaultModeRule("add-v4.2", fc_thres=1.5)
    # fc_thres = 0 folds nothing: add-v3-consolidated becomes add-v3 (MAAST with fc_thres 0)
    a = add_fault_modes(1e-5, FaultModeRule("add-v3-consolidated", fc_thres=0.0))
    b = add_fault_modes(1e-5, "add-v3")
    assert a["p_beyond_order"] == pytest.approx(b["p_beyond_order"], rel=1e-12)
    np.testing.assert_array_equal(a["live"], b["live"])


# ------------------------------------------------------------ kernel against the oracle

N_RANDOM = 48
L_GPS, L_OTHER = 6, 4  # one compiled shape: 6 GPS + 4 Galileo or SOP slots
C = 3  # GPS 0, Galileo 1, SOP 2


def random_event_cases(seed, n):
    """GPS + Galileo (even index) and GPS + SOPs (odd) geometries with priors that need pairs
    in about half of them: P_sat in {1e-5, 1e-4}, P_s^S in {1e-4, 1e-3} (a pair of towers at
    1e-3 exceeds PHMI: ``add-v4.2`` must monitor it), a random slot or two not valid."""
    rng = np.random.default_rng(seed)
    L = L_GPS + L_OTHER
    az = rng.uniform(0, 2 * np.pi, (n, L))
    el = np.deg2rad(rng.uniform(5, 90, (n, L)))
    sop = (np.arange(n) % 2 == 1)[:, None] & (np.arange(L) >= L_GPS)[None]
    el = np.where(sop, np.deg2rad(rng.uniform(-5, 20, (n, L))), el)
    g = np.stack([-np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), -np.sin(el)], -1)
    vi, va = gnss_variances(np.clip(el, np.deg2rad(5), None), 1.0)
    vs, vsa = sop_variances(np.full((n, L), 2.0))
    var_int = np.where(sop, np.asarray(vs), np.asarray(vi))
    var_acc = np.where(sop, np.asarray(vsa), np.asarray(va))
    const = np.where(np.arange(L)[None] >= L_GPS, np.where(sop, 2, 1), 0)
    p_gnss = rng.choice([1e-5, 1e-4], (n, 1))
    p_sat = np.where(sop, rng.choice([1e-4, 1e-3], (n, 1)), p_gnss)
    b_nom = np.where(sop, 0.0, 0.75)
    p_const = np.tile([1e-8, 1e-4, 1e-4], (n, 1))
    valid = np.ones((n, L), bool)
    drop = rng.integers(0, L, (n, 2))
    keep_all = rng.random(n) < 0.5
    for i in range(n):
        if not keep_all[i]:
            valid[i, drop[i]] = False
    return g, const, var_int, var_acc, b_nom, p_sat, p_const, valid


@pytest.fixture(scope="module")
def event_cases():
    return random_event_cases(2028, N_RANDOM)


@pytest.mark.parametrize("rule, order", [("add-v4.2", 1), ("add-v4.2", 2), ("add-v3", 2),
                                         ("blanch-2012", 2)])
def test_event_conventions_match_the_oracle(event_cases, rule, order):
    """The batched kernel against the oracle's enumeration to 1e-5 m where
    both are OK (the PLs: the kernel's root within 1e-4 m above, the oracle's bisection within
    1e-6 m: 2e-3 m as test_mhss.py), same status, modes, order and P_NM."""
    g, const, vi, va, b, ps, pc, valid = event_cases
    res = araim.protection_levels(araim.Sources(g, const, vi, va, b, ps, valid), pc,
                                  araim.BUDGET_LPV200, araim.MHSSOptions(order, fault_modes=rule))
    res = {k: np.asarray(v) for k, v in res._asdict().items()}
    compared = pairs = 0
    for i in range(g.shape[0]):
        o = ref.protection_levels_reference(araim.Sources(g[i], const[i], vi[i], va[i], b[i], ps[i],
                                                          valid[i]), pc[i], araim.BUDGET_LPV200,
                                            ref.ReferenceOptions(max_order=order, fault_modes=rule))
        if o.borderline:
            continue
        assert res["status"][i] == o.status, i
        assert res["n_modes"][i] == o.n_modes, i
        assert res["p_not_monitored"][i] == pytest.approx(o.p_not_monitored, rel=1e-7,
                                                          abs=1e-22), i
        if o.status == Status.OK:
            compared += 1
            pairs += o.order == 2
            assert res["order"][i] == o.order, i
            for key in ("hpl_m", "vpl_m", "emt_m", "sigma_acc_u_m"):
                assert res[key][i] == pytest.approx(getattr(o, key), abs=2e-3), (i, key)
    assert compared >= N_RANDOM // 4
    if order == 2:
        assert pairs >= 4  # the batch exercises monitored pairs


def test_v42_monitors_every_set_above_phmi():
    """ADD v4.2: a set whose prior exceeds PHMI is monitored even when P_NM would allow leaving
    it out; here two towers at P_s^S = 1e-3 (pair prior ~1e-6 > 1e-7) with six GPS."""
    g, const, vi, va, b, ps, pc, valid = random_event_cases(7, 2)
    i = 1  # GPS + SOPs
    ps = ps.copy()
    ps[i, L_GPS:] = 1e-3
    valid = np.ones_like(valid)
    fm = ref.event_fault_mode_set(valid[i], const[i], ps[i], pc[i], araim.BUDGET_LPV200,
                                  "add-v4.2", 2)
    towers = set(range(L_GPS, L_GPS + L_OTHER))
    pair_modes = {m.excluded for m in fm.modes if len(m.excluded) == 2 and m.excluded <= towers}
    assert pair_modes == {frozenset(p) for p in itertools.combinations(towers, 2)}


def test_add_v42_matches_maast_for_araim_2():
    """MAAST for ARAIM 2 (stanford-gps-lab/maast_for_araim_2 at its 2024 head,
    ``mhss_raim_baseline_v5``, run under GNU Octave 7 by tools/maast_v5_reference.m with
    N_es = 1 (and 25: its LPV-200 preset's number of effective samples), no exposure, no
    position optimisation, PL tolerance 1e-4 m) on the Appendix D
    geometry: P_NM, the number of modes, the EMT and sigma_acc agree to the printed digits. Its
    PLs come from a bisection that stops after 10 halvings (``maxCount`` of its
    ``compute_protection_level``) and returns the upper end of the bracket, so they lie at or
    above the root (ours, within 1e-4 m of it, checked by the oracle above): 0.4 mm to 0.41 m
    above here."""
    refs = json.loads((Path(__file__).parent / "data" / "maast_v5_reference.json").read_text())
    assert len(refs) == 5
    for r in refs:
        rule = FaultModeRule("add-v4.2", fc_thres=r["fc_thres"])
        budget = araim.IntegrityBudget(9.8e-8, 2e-9, 3.9e-6, 9e-8, 8e-8,
                                       n_es_int=r["n_es"], n_es_cont=r["n_es"])
        res, _ = add_example(r["p_sat"], rule, budget=budget)
        assert res["n_modes"] == r["n_modes"]
        assert res["p_not_monitored"] == pytest.approx(r["p_not_monitored"], rel=1e-6)
        assert res["emt_m"] == pytest.approx(r["emt_m"], abs=1e-5)
        assert res["sigma_acc_u_m"] == pytest.approx(r["sigma_acc_m"], abs=1e-5)
        for key in ("vpl_m", "hpl_m"):
            assert res[key] - 1e-4 <= r[key] <= res[key] + 0.45, (r, key, res[key])


# ------------------------------------------------- the Blanch et al. (2015) position estimator

OPT_ALWAYS = araim.PositionOptimization(keep="always")


def test_position_optimization_matches_the_oracle(event_cases):
    """The kernel's adjusted estimator (``keep="always"``) against the
    oracle's (which finds t by brentq instead of the quadratic formula) on the random GPS +
    Galileo / GPS + SOP cases: the same PLs, EMT and sigma_acc to 2e-3 m; the row moves in
    most cases. MAAST's trigger and keep rule are checked against MAAST itself below."""
    opt = OPT_ALWAYS
    g, const, vi, va, b, ps, pc, valid = event_cases
    kw = dict(max_order=2, fault_modes="add-v4.2")
    res = araim.protection_levels(araim.Sources(g, const, vi, va, b, ps, valid), pc,
                                  araim.BUDGET_LPV200,
                                  araim.MHSSOptions(position_optimization=opt, **kw))
    res = {k: np.asarray(v) for k, v in res._asdict().items()}
    adjusted = compared = 0
    for i in range(g.shape[0]):
        o = ref.protection_levels_reference(
            (g[i], const[i], vi[i], va[i], b[i], ps[i], valid[i]), pc[i], araim.BUDGET_LPV200,
            ref.ReferenceOptions(position_optimization=opt, **kw))
        if o.borderline or o.status != Status.OK:
            continue
        compared += 1
        assert res["position_adjusted"][i] == o.position_adjusted, i
        adjusted += o.position_adjusted
        for key in ("hpl_m", "vpl_m", "emt_m", "sigma_acc_u_m"):
            assert res[key][i] == pytest.approx(getattr(o, key), abs=2e-3), (i, key)
    assert compared >= N_RANDOM // 4
    assert adjusted >= compared // 2, (adjusted, compared)


def test_position_optimization_compact_subbatch_keeps_the_bits(event_cases, monkeypatch):
    """The adjusted estimator's second solve on a compact sub-batch of the triggered
    geometries (``entry.OPTIMIZED_SUBBATCH``) gives the bits of the second solve over the
    whole chunk (the sub-batch limit set to 0): every step is elementwise along the batch.
    A chunk of 64 with 10 geometries that have sources (the rest: TOO_FEW_SOURCES)."""
    from oaraim.araim.mhss import entry
    from oaraim.araim.mhss.inputs import host_inputs

    x = [np.concatenate([a, a[:16]]) for a in event_cases]  # 64 geometries: one chunk
    x[-1][10:] = False  # all but 10 without sources: at most 10 trigger
    flat, _ = host_inputs(*x)
    static = dict(budget=araim.BUDGET_LPV200, options=araim.MHSSOptions(
        2, fault_modes=FaultModeRule("add-v4.2"), position_optimization=OPT_ALWAYS).checked())

    def run():  # a new function: traced afresh with the module's current sub-batch limit
        return jax.jit(lambda *a: entry._protection_levels(*a, **static))(*flat)

    compact = run()
    monkeypatch.setattr(entry, "OPTIMIZED_SUBBATCH", 0)
    whole = run()
    assert 3 <= int(np.sum(np.asarray(compact.position_adjusted))) <= 10
    for name in compact._fields:
        np.testing.assert_array_equal(np.asarray(getattr(compact, name)),
                                      np.asarray(getattr(whole, name)), err_msg=name)


def test_position_optimization_by_hand():
    """Closed form: with C_acc = C_int the WLS row s0 is the BLUE, so s0 C (s_k - s0) = 0
    (b = 0) and the accuracy sigma along the move is sqrt(sigma_acc^2 + t^2 sigma_ss,k^2): the
    estimator stops where that reaches sigma_acc_max - 1e-5 m, t = sqrt(limit^2 -
    sigma_acc^2) / sigma_ss of the weakest mode (largest sigma_U). Also: a limit below the
    WLS sigma_acc leaves the vertical unchanged (t = 0)."""
    L = 10
    var = ADD_C_INT
    args = (ADD_ROWS, ADD_CONST, var, var, np.full(L, ADD_B_NOM_M), np.full(L, 1e-5),
            ADD_P_CONST)
    base = ref.protection_levels_reference(araim.Sources(*args[:6]), args[6],
                                           araim.BUDGET_LPV200,
                                           ref.ReferenceOptions(1, fault_modes="add-v4.2"))
    weak = max((m for m in base.monitored if m.mode.prior >= 1e-11), key=lambda m: m.sigma[2])
    limit = base.sigma_acc_u_m + 0.2
    t = np.sqrt((limit - 1e-5) ** 2 - base.sigma_acc_u_m ** 2) / weak.sigma_ss[2]
    assert 0 < t < 1
    opt = araim.PositionOptimization(sigma_acc_max_m=(3.0, 3.0, limit), keep="always")
    a = [x[None] for x in args]
    res = araim.protection_levels(araim.Sources(*a[:6]), a[6], araim.BUDGET_LPV200,
                                  araim.MHSSOptions(fault_modes="add-v4.2",
                                                    position_optimization=opt))
    assert float(res.sigma_acc_u_m[0]) == pytest.approx(limit - 1e-5, abs=1e-9)
    # the vertical separation of the weak mode shrinks by the factor (1 - t)
    adj = ref.protection_levels_reference(araim.Sources(*args[:6]), args[6], araim.BUDGET_LPV200,
                                          ref.ReferenceOptions(max_order=1, fault_modes="add-v4.2",
                                                               position_optimization=opt))
    moved = next(m for m in adj.monitored if m.mode == weak.mode)
    assert moved.sigma_ss[2] == pytest.approx((1 - t) * weak.sigma_ss[2], rel=1e-9)
    # a limit below the WLS sigma_acc leaves the vertical row unchanged (t = 0): the oracle
    # here, the kernel in the MAAST case with row 2 out below (sigma_acc,U 2.076 > 1.86 m)
    tight = araim.PositionOptimization(sigma_acc_max_m=(3.0, 3.0, 1.0), keep="always")
    same = ref.protection_levels_reference(araim.Sources(*args[:6]), args[6], araim.BUDGET_LPV200,
                                           ref.ReferenceOptions(max_order=1, fault_modes="add-v4.2",
                                                                position_optimization=tight))
    assert same.sigma_acc_u_m == pytest.approx(base.sigma_acc_u_m, abs=1e-12)


def test_position_optimization_matches_maast_for_araim_2():
    """MAAST for ARAIM 2's ``prm.opt = 1`` (compute_adjusted_position_1D in
    mhss_raim_baseline_v5, and usr_vhpl_araim's trigger and keep rule with its LPV-200 targets
    35 / 40 / 15 m, sigma_acc limits 3 / 3 / 1.86 m), run under GNU Octave 7 by
    tools/maast_v5_opt_reference.m on 8 subsets of the Appendix D geometry: the adjusted
    estimator's sigma_acc and EMT to the printed digits, its PLs at or just above ours
    (MAAST's bisection returns the upper end of its bracket, see the test above), and the
    same result after MAAST's keep rule (4 of the 8 cases keep the adjusted estimator)."""
    refs = json.loads((Path(__file__).parent / "data" /
                       "maast_v5_opt_reference.json").read_text())
    assert len(refs) == 8
    rule = FaultModeRule("add-v4.2", fc_thres=0.01)
    kept = 0
    for r in refs:
        valid = np.ones(10, bool)
        valid[r["drop"]] = False  # dropped rows masked: one compiled shape for all cases
        args = (ADD_ROWS, ADD_CONST, ADD_C_INT, ADD_C_ACC, np.full(10, ADD_B_NOM_M),
                np.full(10, r["p_sat"]), ADD_P_CONST, valid)
        for name, opt in (("adjusted", OPT_ALWAYS), ("maast", araim.PositionOptimization())):
            a = [x[None] for x in args]
            res = araim.protection_levels(araim.Sources(*a[:6], a[7]), a[6],
                                          araim.BUDGET_LPV200,
                                          araim.MHSSOptions(2, fault_modes=rule,
                                                            position_optimization=opt))
            want = r[name]
            got = {k: float(np.asarray(getattr(res, k))[0])
                   for k in ("vpl_m", "hpl_m", "sigma_acc_u_m", "emt_m")}
            assert got["sigma_acc_u_m"] == pytest.approx(want["sigma_acc_m"], abs=1e-5), r
            assert got["emt_m"] == pytest.approx(want["emt_m"], abs=1e-5), (r, name)
            if name == "maast":
                kept += bool(res.position_adjusted[0])
            for key in ("vpl_m", "hpl_m"):
                assert got[key] - 1e-4 <= want[key], (r, name, key)  # MAAST is conservative
                if key == "vpl_m" and r["drop"] == [5] and r["p_sat"] == 1e-4:
                    # MAAST's compute_protection_level_v5 bounds the modes with sigma within
                    # 1.3 x the smallest by one term (largest sigma and threshold, summed
                    # priors) and stops after 10 halvings: 41.8 m where the root is 31.5 m
                    # (baseline) and 31.0 m (adjusted); the oracle's root agrees with ours
                    continue
                assert want[key] <= got[key] + 0.45, (r, name, key)
    assert kept == 4


def test_availability_map_geometries_match_maast_for_araim_2():
    """Per user-epoch: 72 user-epochs of the default world map's rows at
    -70 and 70 deg (24 where our map keeps the position estimator, 48 at lon 70 every hour)
    with the map's own inputs (sky, mask, C_int, C_acc, b_nom, P_sat), run through MAAST for
    ARAIM 2's usr_vhpl_araim under Octave (tools/maast_map_rows.py and .m: LPV-200, the
    estimator with MAAST's trigger, no FDE, no exposure, N_es 1). Under MAAST's defaults the
    EMT and sigma_acc agree to 1e-6 (relative) and the LPV-200 decision at every user-epoch;
    its VPL and HPL lie at or above ours, by 3.9 / 2.6 % (median over the two full rows):
    its PL bisection stops as soon as the upper end is below the target (35 / 40 m) and
    returns that end. With the bisection run to its tolerance (targets 0, estimator off) they
    agree within 0.5 % at every user-epoch (0.04 / 0.11 % median over the 576 of lon 70)."""
    fx = json.loads((Path(__file__).parent / "data" / "maast_map_rows.json").read_text())
    cases = fx["cases"]
    n = max(len(c["g"]) for c in cases)
    B = len(cases)

    def pad(key, fill):
        out = np.full((B, n) + np.shape(cases[0][key][0]), fill, float)
        for i, c in enumerate(cases):
            out[i, :len(c[key])] = c[key]
        return out

    g = pad("g", 0.0)
    g[..., 2] = np.where(np.all(g == 0, -1), 1.0, g[..., 2])  # padding rows: unit, unused
    valid = np.zeros((B, n), bool)
    for i, c in enumerate(cases):
        valid[i, :len(c["g"])] = True
    args = (g, pad("galileo", 0).astype(int), pad("var_int_m2", 1.0), pad("var_acc_m2", 1.0),
            pad("b_nom_m", 0.0), pad("p_sat", 1e-5), np.tile(fx["p_const"], (B, 1)))
    budget = araim.BUDGET_LPV200_MAAST
    req = av.SERVICE_LEVELS["lpv200"].requirements
    res = {}
    for name, opt in (("maast", araim.PositionOptimization()), ("maast_no_opt_no_target", None)):
        r = araim.protection_levels(araim.Sources(*args[:6], valid), args[6], budget,
                                    araim.MHSSOptions(1, fault_modes="add-v4.2",
                                                      position_optimization=opt))
        res[name] = {k: np.asarray(getattr(r, k)) for k in ("vpl_m", "hpl_m", "emt_m",
                                                            "sigma_acc_u_m", "status",
                                                            "position_adjusted")}
    want = {name: {k: np.array([c[name][k] for c in cases]) for k in cases[0][name]}
            for name in res}
    ours, theirs = res["maast"], want["maast"]
    assert int(ours["position_adjusted"].sum()) == 24
    np.testing.assert_allclose(ours["emt_m"], theirs["emt_m"], rtol=1e-6)
    np.testing.assert_allclose(ours["sigma_acc_u_m"], theirs["sigma_acc_m"], rtol=1e-6)
    assert np.all(theirs["vpl_m"] >= ours["vpl_m"] - 1e-3)
    assert np.all(theirs["hpl_m"] >= ours["hpl_m"] - 1e-3)
    ok_ours = av.available(ours["hpl_m"], ours["vpl_m"], ours["emt_m"],
                                           ours["sigma_acc_u_m"], ours["status"], req)
    ok_maast = av.available(theirs["hpl_m"], theirs["vpl_m"],
                                            theirs["emt_m"], theirs["sigma_acc_m"],
                                            np.zeros(B, int), req)
    np.testing.assert_array_equal(np.asarray(ok_ours), np.asarray(ok_maast))
    ours, theirs = res["maast_no_opt_no_target"], want["maast_no_opt_no_target"]
    assert not ours["position_adjusted"].any()
    for k in ("vpl_m", "hpl_m"):
        rel = theirs[k] / ours[k] - 1
        assert np.all(rel >= -1e-5) and np.all(rel <= 5e-3), (k, rel.min(), rel.max())
