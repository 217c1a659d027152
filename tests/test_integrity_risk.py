"""Tests of araim.integrity_risk: fault injection and importance sampling of the MHSS HMI risk.

Three ways: (1) the receiver as linear maps equals ``detect_and_exclude`` sample by sample (the
oracle of tests/test_fde.py's cases); (2) closed form: fault-free, the vertical error of the
all-in-view solution is N(b, sigma_0^2) with b = sum |S0_u,l| b_nom,l (worst-sign bias) and
independent of the separations (C_int weighting), so P(VPE > VPL, no detection) =
[Q((VPL - b) / sigma_0) + Q((VPL + b) / sigma_0)] (1 - P(detection)), 1 - P(detection) in
[1 - P_FA,V - P_FA,H, 1]; (3) importance sampling against crude Monte Carlo where crude can
resolve (a deliberately weak budget, risks ~1e-3 to 1e-1), and the PL's promise (Table I):
measured risk <= the allocation of seed 004 eqs. 14-16.

Statistics: fixed keys; agreement within 4 combined standard errors (a two-sided 6e-5 tail per
comparison, so the handful of comparisons here fail by chance with probability < 1e-3).
Compiled shapes: L = 18, C = 2 (the FDE cases), order 1.
"""


import jax
import numpy as np
import pytest
from scipy import stats

from oaraim import araim
from oaraim.araim import Status
from oaraim.araim import integrity_risk as ir
from tests.test_fde import L_GPS, L, _args, fde_cases
from tests.test_mhss import grouped

# these tests check the grouped convention (seed 004's SOP studies) against the grouped
# oracle; the ADD conventions are tested in test_conformance.py
detect_and_exclude = grouped(araim.detect_and_exclude)
monitor_maps = grouped(ir.monitor_maps)

#: a deliberately weak budget: fault-free vertical risk ~1e-3, resolvable by crude Monte Carlo
WEAK = araim.IntegrityBudget(phmi_v=2e-3, phmi_h=2e-3, p_fa_v=1e-3, p_fa_h=1e-3, p_thresh=6e-8)
N_GEOM = 6


def _maps(c, budget):
    """One geometry per call, stacked: the (L, 3) shapes the study's kernel compiles (L = 18 is
    12 GPS slots + 6 SOPs there, see tests/test_studies.py SMALL), so the suite compiles once."""
    one = [monitor_maps(araim.Sources(c["g"][i], c["constellation"][i], c["var_int"][i],
                                      c["var_acc"][i], c["b_nom"][i], c["p_sat"][i], c["valid"][i]),
                        c["p_const"][i], budget, araim.MHSSOptions(1)) for i in range(len(c["g"]))]
    return jax.tree.map(lambda *a: np.stack(a), *one)


def _pick(maps, i):
    return jax.tree.map(lambda a: a[i], maps)


@pytest.fixture(scope="module")
def cases():
    c, rng = fde_cases(401, N_GEOM)
    return c, rng, _maps(c, araim.BUDGET_SEED004_TABLE_I), _maps(c, WEAK)


def test_maps_reproduce_detect_and_exclude(cases):
    """Detection, the excluded mode and both HMI events from the maps equal those derived from
    detect_and_exclude (its position and PLs) on noise at 1-5 sigma plus a bias of 0-30 m on
    one GPS satellite, 200 residuals over the 6 geometries: every branch (nothing detected,
    excluded, failed) occurs. Table I and (200, 18) are the shapes tests/test_fde.py compiles;
    the HMI flags are exercised at the weak budget by the closed-form and crude checks."""
    c, rng, maps, _ = cases
    n = 200
    gi = np.arange(n) % N_GEOM
    y = rng.normal(0.0, np.sqrt(c["var_int"][gi])) * rng.uniform(1.0, 5.0, (n, 1))
    src = rng.integers(0, L_GPS, n)
    y[np.arange(n), src] += rng.uniform(0, 30.0, n)
    y = np.where(c["valid"][gi], y, 0.0)
    out = jax.vmap(lambda m, r: ir.evaluate(m, r[None]))(_pick(maps, gi), y)
    out = jax.tree.map(lambda a: np.asarray(a)[:, 0], out)
    bc = {k: v[gi] for k, v in c.items()}
    fde = detect_and_exclude(*_args(bc, y), araim.MHSSOptions(1))
    det = np.asarray(fde.detected)
    mode = np.asarray(fde.exclusion_mode)
    pos = np.asarray(fde.position_m)
    hpl, vpl = np.asarray(fde.pl.hpl_m), np.asarray(fde.pl.vpl_m)
    with np.errstate(invalid="ignore"):
        hmi_h = np.hypot(pos[..., 0], pos[..., 1]) > hpl
        hmi_v = np.abs(pos[..., 2]) > vpl
    np.testing.assert_array_equal(out.detected, det)
    np.testing.assert_array_equal(out.excluded_mode, mode)
    np.testing.assert_array_equal(out.md_h, ~det & hmi_h)
    np.testing.assert_array_equal(out.md_v, ~det & hmi_v)
    np.testing.assert_array_equal(out.we_h, det & (mode >= 0) & hmi_h)
    np.testing.assert_array_equal(out.we_v, det & (mode >= 0) & hmi_v)
    assert (~det).sum() > 10 and (det & (mode >= 0)).sum() > 10
    assert (det & (mode < 0)).sum() > 0


def _closed_form_ff_v(m, budget):
    s0u = np.asarray(m.s0[2])
    sig = np.asarray(m.sigma_m)
    b = np.sum(np.abs(s0u) * np.asarray(m.b_nom_m))
    s = np.sqrt(np.sum((s0u * sig) ** 2))
    vpl = float(m.vpl_m)
    p_fa = budget.p_fa_v + budget.p_fa_h
    return stats.norm.sf((vpl - b) / s) + stats.norm.sf((vpl + b) / s), p_fa


@pytest.mark.parametrize("weak", [True, False], ids=["weak-budget", "table-i"])
def test_fault_free_vertical_risk_closed_form(cases, weak):
    """Fault-free P(VPE > VPL, no detection) against the closed form of the module docstring:
    ~1e-3 under the weak budget, below 1e-9 (Table I; crude Monte Carlo would need > 1e11
    samples) where importance sampling still finds it to a few per cent."""
    c, _, maps_t, maps_w = cases
    budget = WEAK if weak else araim.BUDGET_SEED004_TABLE_I
    for i in range(3):
        m = _pick(maps_w if weak else maps_t, i)
        assert int(m.status) == Status.OK
        expect, p_fa = _closed_form_ff_v(m, budget)
        _, _, e = ir.scenario_estimate(m, ir.Scenario(ir.FAULT_FREE, ir.VERTICAL, 0.0),
                                       jax.random.key(10 + i), ir.Sampling(n_samples=4000))
        p, se = float(e.p_md), float(e.se_md)
        assert se < 0.2 * p  # mean shift to the boundary: relative variance ~1.25 t per sample
        assert expect * (1 - p_fa) - 4 * se <= p <= expect + 4 * se, (i, p, se, expect)
        if not weak:
            assert expect < 1e-9


def test_importance_sampling_agrees_with_crude_monte_carlo(cases):
    """Weak budget, geometry 0: fault-free and the single-source fault with the largest
    vertical slope at A_det and 1.2 A_det, both directions: IS (4,000 samples) and crude Monte
    Carlo (100,000; P ~5e-4 to 0.3) agree within 4 combined standard errors; IS needs far fewer
    samples for the same relative error (variance per sample)."""
    _, _, _, maps_w = cases
    m = _pick(maps_w, 0)
    worst = int(np.argmax(np.abs(np.asarray(m.s0[2])) * np.asarray(m.valid)))
    gains = []
    for kind, src, x in ((ir.FAULT_FREE, -1, 0.0), (ir.SINGLE, worst, 1.0),
                         (ir.SINGLE, worst, 1.2)):
        for d in (ir.HORIZONTAL, ir.VERTICAL):
            k = jax.random.key(int(100 * kind + 10 * x + d))
            _, _, a = ir.scenario_estimate(m, ir.Scenario(kind, d, x, source=src), k,
                                           ir.Sampling(n_samples=4000))
            _, _, b = ir.scenario_estimate(m, ir.Scenario(kind, d, x, source=src),
                                           jax.random.fold_in(k, 7),
                                           ir.Sampling(n_samples=100_000, crude=True))
            pa, sa, pb, sb = (float(v) for v in (a.p_md, a.se_md, b.p_md, b.se_md))
            # (fault-free horizontal: ~1e-5 here, the HPL adds the east and north PLs; crude
            # sees a few hits and the comparison is loose but still made)
            assert int(b.hits_md) >= (1 if kind == ir.FAULT_FREE and d == ir.HORIZONTAL
                                      else 30), (kind, d, x, pb)
            assert abs(pa - pb) <= 4 * np.hypot(sa, sb), (kind, d, x, pa, sa, pb, sb)
            gains.append(pb * (1 - pb) / (4000 * sa**2))  # crude / IS variance per sample
            # wrong-exclusion HMI, estimated from the same samples, agrees too
            pa, sa, pb, sb = (float(v) for v in (a.p_we, a.se_we, b.p_we, b.se_we))
            assert abs(pa - pb) <= 4 * np.hypot(sa, sb) + 1e-12, (kind, d, x, "we", pa, pb)
    assert gains[0] > 10 and gains[1] > 10  # fault-free: rare events, IS far ahead


def test_ramp_risk(cases):
    """A ramp at rate 0 is the fault-free case at every epoch (closed form, weak budget; the
    union bound is the sum); a 1 m/s ramp on the satellite with the largest vertical slope is
    detected with certainty once it is large, its risk first grows then vanishes."""
    _, _, _, maps_w = cases
    m = _pick(maps_w, 1)
    l = int(np.argmax(np.abs(np.asarray(m.s0[2])) * np.asarray(m.valid)))
    r = ir.ramp_risk(m, ir.Ramp(l, ir.VERTICAL, 0.0, 4.0, 1.0), jax.random.key(5),
                     ir.Sampling(n_samples=4000))
    expect, p_fa = _closed_form_ff_v(m, WEAK)
    np.testing.assert_array_equal(r.time_s, [1.0, 2.0, 3.0, 4.0])
    assert np.all(np.abs(r.p_md - expect) <= 4 * r.se_md + expect * p_fa)
    assert r.union_p_md == pytest.approx(r.p_md.sum()) and r.mean_p_md == pytest.approx(
        r.p_md.mean())
    a_det = float(ir.injection(m, ir.SINGLE, l, -1, ir.VERTICAL).a_det_m)
    # 30 epochs: the study test's shapes
    r = ir.ramp_risk(m, ir.Ramp(l, ir.VERTICAL, 1.0, 3.0 * a_det, a_det / 10), jax.random.key(6),
                     ir.Sampling(n_samples=1000, ce_samples=500))
    assert r.p_detect[-1] > 0.999 and r.p_md[-1] < 1e-6
    assert r.p_md.max() > 10 * r.p_md[0]
    with pytest.raises(ValueError, match="epoch_s"):
        ir.ramp_risk(m, ir.Ramp(l, ir.VERTICAL, 1.0, 3.0, 0.0), jax.random.key(0))


def test_injection_hand_values(cases):
    """Single source: the fault is +-e_l with the sign of its slope, at A_det the mean
    separation of its own mode equals the threshold and at A_PL the mean error the VPL;
    constellation: the fault direction has no component along a common bias (the clock
    absorbs it), and the PL bias is b_nom with the slope's sign."""
    _, _, maps, _ = cases
    m = _pick(maps, 1)
    s0 = np.asarray(m.s0)
    l = int(np.argmax(np.abs(s0[2])))
    inj = ir.injection(m, ir.SINGLE, l, -1, ir.VERTICAL)
    expect = np.zeros(L)
    expect[l] = np.sign(s0[2, l])
    np.testing.assert_array_equal(np.asarray(inj.fault_dir), expect)
    k = int(inj.mode)
    assert set(np.flatnonzero(np.asarray(m.excluded[k]))) == {l} and bool(inj.monitored)
    sep_mean = float(np.asarray(m.sep[k, 2]) @ (float(inj.a_det_m) * expect))
    assert abs(abs(sep_mean) - float(m.threshold_m[k, 2])) < 1e-9
    # A_PL: the fault alone puts the mean vertical error on the VPL
    assert abs(float(inj.a_pl_m) * abs(s0[2, l]) - float(m.vpl_m)) < 1e-9
    np.testing.assert_allclose(np.asarray(inj.bias_m), np.asarray(m.b_nom_m) * np.where(
        s0[2] >= 0, 1.0, -1.0))
    inj = ir.injection(m, ir.CONSTELLATION, -1, 0, ir.VERTICAL)
    f = np.asarray(inj.fault_dir)
    member = np.asarray(m.valid) & (np.asarray(m.constellation) == 0)
    assert np.all(f[~member] == 0) and abs(np.linalg.norm(f) - 1) < 1e-12
    assert abs(f[member].sum()) < 1e-9
    assert abs(s0[2] @ member) < 1e-9  # a common GPS bias does not move the position


def test_pl_bounds_measured_risk_table_i(cases):
    """Seed 004 Table I (PHMI_H 9.9e-8, PHMI_V 1e-9): on each geometry the measured risk (its
    95 % upper bound) stays below the allocation of eqs. 14-16, horizontal and vertical."""
    _, _, maps, _ = cases
    for i in range(2):
        m = _pick(maps, i)
        # the sizes of the study's generic tests (tests/test_studies.py SMALL): one compilation
        t = ir.risk_table(m, jax.random.key(i), (0.0, 0.9, 1.1, 1.5),
                          sampling=ir.Sampling(n_samples=1000, ce_samples=500))
        risk, upper, _, _ = ir.measured_risk(t)
        alloc = ir.allocated_budget(araim.BUDGET_SEED004_TABLE_I, float(m.p_not_monitored))
        assert np.all(np.isfinite(upper)) and np.all(risk > 0)
        assert upper[0] <= alloc[0] and upper[1] <= alloc[1], (i, upper, alloc)
        assert not np.any(np.isnan(np.asarray(t.estimate.p_md)))


def test_total_risk_counts_unmonitored_priors():
    """By hand, Table I (PHMI_H 9.9e-8, PHMI_V 1e-9): a measured risk (4e-8, 5e-10) with P_NM
    2e-8 adds 2e-8 x 0.99 and 2e-8 x 0.01 (the directions' shares of PHMI): (5.98e-8,
    7e-10) of (9.9e-8, 1e-9); the ratio is <= 1 exactly where measured <= allocated, and it
    fails (> 1) once the unmonitored prior alone exceeds the room left (P_NM 5e-8 with the
    vertical risk 5e-10 gives 1.0 vertical, P_NM 6e-8 1.1)."""
    b = araim.BUDGET_SEED004_TABLE_I
    total, phmi = ir.total_risk(np.array([4e-8, 5e-10]), 2e-8, b)
    np.testing.assert_allclose(total, [4e-8 + 2e-8 * 0.99, 5e-10 + 2e-8 * 0.01], rtol=1e-12)
    np.testing.assert_allclose(phmi, [9.9e-8, 1e-9])
    for p_nm in (2e-8, 4.9e-8, 5.1e-8, 6e-8):
        total, phmi = ir.total_risk(np.array([4e-8, 5e-10]), p_nm, b)
        alloc = np.array(ir.allocated_budget(b, p_nm))
        np.testing.assert_array_equal(total <= phmi * (1 + 1e-12),
                                      np.array([4e-8, 5e-10]) <= alloc * (1 + 1e-12))
    total, phmi = ir.total_risk(np.array([4e-8, 5e-10]), 6e-8, b)
    assert total[1] / phmi[1] == pytest.approx(1.1, rel=1e-9)


def test_unavailable_geometry_has_no_risk_and_no_nan(cases):
    """Too few sources (status TOO_FEW_SOURCES, inf PLs): every scenario inactive, estimates
    0, no NaN (failures are data)."""
    c, _, _, _ = cases
    c1 = {k: v.copy() for k, v in c.items()}  # the fixture's shapes: no new compilation
    c1["valid"][0, 4:] = False
    m = _pick(_maps(c1, WEAK), 0)
    assert int(m.status) != Status.OK
    t = ir.risk_table(m, jax.random.key(0), (0.0, 1.0),
                      sampling=ir.Sampling(n_samples=100, ce_samples=100))
    assert not np.asarray(t.active).any()
    for v in t.estimate:
        assert np.all(np.asarray(v) == 0) or v is t.estimate.weight_sup


def test_bad_options_are_named(cases):
    _, _, maps, _ = cases
    m = _pick(maps, 0)
    with pytest.raises(ValueError, match="nominal_bias"):
        ir.risk_table(m, jax.random.key(0), sampling=ir.Sampling(nominal_bias="max"))
    with pytest.raises(ValueError, match="one geometry"):
        ir.risk_table(maps, jax.random.key(0))
    with pytest.raises(ValueError, match="x_grid"):
        ir.risk_table(m, jax.random.key(0), (-1.0,))
    with pytest.raises(ValueError, match="direction"):
        ir.scenario_estimate(m, ir.Scenario(ir.FAULT_FREE, 2, 0.0), jax.random.key(0))
    with pytest.raises(ValueError, match="budget"):
        monitor_maps(araim.Sources(np.zeros((5, 3)), 0, 1.0, 1.0, 0.0, 1e-5), [1e-8], None)
