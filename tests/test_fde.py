"""Tests of araim.solution_separation and araim.detect_and_exclude (seed 004 eq. 13, FDE).

Residuals are measurement errors y (L,): (S^(i) - S^(0)) H = 0, so the separations of the
residual at the true linearisation point are those of the errors. Oracle: tests/reference_mhss.py.

Fixed seeds. Tolerances: separations and thresholds to 1e-7 relative (S y from two different
factorisations; the worst subsets here have condition numbers ~1e8), PLs to 2e-3 m
(the MHSS oracle tolerance of tests/test_mhss.py).
Compiled shapes: L = 18 (12 GPS + 6 SOP slots), C = 2, order 1 for the FDE cases; the L = 28
random set of test_mhss.py for the separation-vs-oracle test.
"""


import jax
import numpy as np
import pytest

from oaraim import araim, geometry
from oaraim import reference_mhss as ref
from oaraim.araim import Status
from oaraim.errors import gnss_variances, sop_variances
from tests.test_mhss import grouped, random_cases

# these tests check the grouped convention (seed 004's SOP studies) against the grouped
# oracle; the ADD conventions are tested in test_conformance.py
protection_levels = grouped(araim.protection_levels)
detect_and_exclude = grouped(araim.detect_and_exclude)
solution_separation = grouped(araim.solution_separation)

L_GPS, L_SOP = 12, 6
L = L_GPS + L_SOP
N_FDE = 200

_sky = jax.jit(geometry.random_sky, static_argnums=(1, 3))
_bpp = jax.jit(geometry.bpp_towers, static_argnums=(1, 6))


def fde_cases(seed, n, n_sop_range=(2, 3)):
    """GPS (7..12 satellites above 10 deg, Table I) + 2..3 SOPs in one constellation,
    sigma_URA^S = 3 m (seed 004 VII), P_s^S = P_const^S = 1e-5 so that order 1 meets P_thresh
    (P(GPS and SOP faulty) ~ 1.2e-4 x 4e-5): the order-1 FDE of seed 004 IV-B. With at most 3
    SOPs the whole-GPS subset is singular (prior ~1.7e-8, within P_thresh). Towers 200..3000 m
    away, -200..+50 m high. Padding rows are finite junk."""
    k1, k2 = jax.random.split(jax.random.key(seed))
    rng = np.random.default_rng(seed)
    az_g, el_g = (np.asarray(x) for x in _sky(k1, L_GPS, np.deg2rad(10.0), (n,)))
    tw = _bpp(k2, L_SOP, 200.0, 3000.0, -200.0, 50.0, (n,))
    az = np.concatenate([az_g, np.asarray(tw.az_rad)], axis=1)
    el = np.concatenate([el_g, np.asarray(tw.el_rad)], axis=1)
    n_gps = rng.integers(7, L_GPS + 1, n)
    n_sop = rng.integers(n_sop_range[0], n_sop_range[1] + 1, n)
    idx = np.arange(L)
    valid = (idx < n_gps[:, None]) | ((idx >= L_GPS) & (idx < L_GPS + n_sop[:, None]))
    const = np.broadcast_to((idx >= L_GPS).astype(int), (n, L)).copy()
    vi, va = (np.asarray(x).copy() for x in gnss_variances(el, 1.0))
    s_i, s_a = (float(x) for x in sop_variances(3.0))
    vi[:, L_GPS:], va[:, L_GPS:] = s_i, s_a
    b_nom = np.where(idx < L_GPS, 0.75, 0.0) * np.ones((n, 1))
    p_sat = np.full((n, L), 1e-5)
    g = np.array(geometry.geometry_rows(az, el))
    g[~valid] = rng.normal(0.0, 2.0, ((~valid).sum(), 3))
    return dict(g=g, constellation=const, var_int=vi, var_acc=va, b_nom=b_nom, p_sat=p_sat,
                p_const=np.broadcast_to([1e-8, 1e-5], (n, 2)).copy(), valid=valid), rng


def _args(c, y, valid=None):
    """(sources, p_const, budget, residuals) of the host functions; ``valid`` overrides the
    case's."""
    return (araim.Sources(c["g"], c["constellation"], c["var_int"], c["var_acc"], c["b_nom"],
                          c["p_sat"], c["valid"] if valid is None else valid),
            c["p_const"], araim.BUDGET_SEED004_TABLE_I, y)


def _np(res):
    out = {}
    for k in res._fields:
        v = getattr(res, k)
        if hasattr(v, "_fields"):
            out.update({f"pl.{kk}": np.asarray(getattr(v, kk)) for kk in v._fields})
        else:
            out[k] = np.asarray(v)
    return out


def _ref_args(c, i, y, max_order=1):
    return (araim.Sources(c["g"][i], c["constellation"][i], c["var_int"][i], c["var_acc"][i],
                          c["b_nom"][i], c["p_sat"][i], c["valid"][i]),
            c["p_const"][i], araim.BUDGET_SEED004_TABLE_I, y, ref.ReferenceOptions(max_order))


def _modes(excluded, monitored):
    return {frozenset(np.flatnonzero(excluded[k]).tolist()): k for k in np.flatnonzero(monitored)}


def _unit_bias_tau(c, i, l):
    """Largest tau of mode {l} for a unit error on source l (oracle), or 0 if not monitored."""
    y = np.zeros(L)
    y[l] = 1.0
    sep = ref.solution_separation_reference(*_ref_args(c, i, y))
    for ex, tau in zip(sep.excluded, sep.tau, strict=True):
        if ex == frozenset({l}):
            return float(tau.max())
    return 0.0


def biased_residuals(c, rng, sources, noise_scale=0.1, strength=10.0):
    """Small noise (noise_scale x sigma_acc) plus, on source sources[i], a bias giving tau =
    `strength` on its own single-fault mode in the most sensitive direction (oracle)."""
    n = c["g"].shape[0]
    y = rng.normal(0.0, noise_scale * np.sqrt(c["var_acc"]))
    bias = np.zeros(n)
    for i, l in enumerate(sources):
        t = _unit_bias_tau(c, i, l)
        bias[i] = strength / t if t > 0 else 0.0
        y[i, l] += bias[i]
    return np.where(c["valid"], y, 0.0), bias


# --------------------------------------------------------------------------- no fault


def test_no_bias_nothing_detected():
    """Nominal noise drawn from C_acc (P_FA = 1e-7 per test): nothing is detected, nothing is
    excluded, the PLs are the all-in-view ones."""
    c, rng = fde_cases(301, N_FDE)
    y = np.where(c["valid"], rng.normal(0.0, np.sqrt(c["var_acc"])), 0.0)
    fde = _np(detect_and_exclude(*_args(c, y), araim.MHSSOptions(1)))
    pl = protection_levels(*_args(c, y)[:-1], araim.MHSSOptions(1))
    assert not fde["detected"].any()
    assert not fde["excluded"].any()
    assert np.all(fde["exclusion_mode"] == -1)
    np.testing.assert_array_equal(fde["status"], np.asarray(pl.status))
    np.testing.assert_allclose(fde["pl.hpl_m"], np.asarray(pl.hpl_m), rtol=1e-12)
    np.testing.assert_allclose(fde["pl.vpl_m"], np.asarray(pl.vpl_m), rtol=1e-12)
    assert np.mean(fde["status"] == Status.OK) > 0.9
    # and the largest tau is well below 1 (not a near miss)
    assert fde["tau"].max() < 0.9


# --------------------------------------------------------------------------- injected bias


@pytest.fixture(scope="module")
def gps_bias():
    """A bias on one GPS satellite (tau = 10 on its own mode), noise 0.1 sigma_acc."""
    c, rng = fde_cases(302, N_FDE)
    n_gps = np.sum(c["valid"][:, :L_GPS], axis=1)
    src = rng.integers(0, n_gps)
    y, bias = biased_residuals(c, rng, src)
    fde = _np(detect_and_exclude(*_args(c, y), araim.MHSSOptions(1)))
    return c, y, src, bias, fde


def test_injected_gps_bias_is_detected_and_excluded(gps_bias):
    """Detected, and exactly the biased satellite excluded (the whole-GPS subset is singular, the
    whole-SOP and other single subsets keep the bias and fail their own test); status OK; PLs
    after exclusion are those of the subset without it."""
    c, y, src, bias, fde = gps_bias
    assert np.all(bias > 0) and np.all(bias < 1e3)
    assert fde["detected"].all()
    expect = np.zeros_like(c["valid"])
    expect[np.arange(len(src)), src] = True
    wrong = np.flatnonzero(np.any(fde["excluded"] != expect, axis=1))
    assert wrong.size == 0, [(i, src[i], np.flatnonzero(fde["excluded"][i])) for i in wrong[:5]]
    assert np.all(fde["status"] == Status.OK)
    sub = protection_levels(*_args(c, y, c["valid"] & ~expect)[:-1], araim.MHSSOptions(1))
    np.testing.assert_allclose(fde["pl.hpl_m"], np.asarray(sub.hpl_m), rtol=1e-9)
    np.testing.assert_allclose(fde["pl.vpl_m"], np.asarray(sub.vpl_m), rtol=1e-9)


def test_injected_sop_bias_is_detected_and_excluded():
    """A bias on one SOP of a 3-SOP constellation: detected, and the biased SOP is among the
    excluded sources (the min-SSE rule may prefer dropping the whole SOP constellation; the
    exact choice is compared with the oracle)."""
    c, rng = fde_cases(303, N_FDE, n_sop_range=(3, 3))
    n_sop = np.sum(c["valid"][:, L_GPS:], axis=1)
    src = L_GPS + rng.integers(0, n_sop)
    y, bias = biased_residuals(c, rng, src)
    fde = _np(detect_and_exclude(*_args(c, y), araim.MHSSOptions(1)))
    has = bias > 0
    assert has.mean() > 0.9
    assert fde["detected"][has].all()
    assert fde["excluded"][np.arange(N_FDE), src][has].all()
    for i in np.flatnonzero(has)[:40]:
        o = ref.detect_and_exclude_reference(*_ref_args(c, i, y[i]))
        np.testing.assert_array_equal(fde["excluded"][i], o.excluded, err_msg=str(i))


def test_fde_matches_oracle(gps_bias):
    """detect_and_exclude against the oracle on the biased GPS cases and on moderate biases
    (tau 0.5..3: some undetected, some excluded, some exclusions failing): same detection, same
    excluded sources, same status (the oracle's failed exclusion is EXCLUSION_FAILED here, with
    inf PLs), PLs after exclusion within 2e-3 m."""
    c, y, src, _, fde = gps_bias
    rng = np.random.default_rng(304)
    y2, _ = biased_residuals(c, rng, src, noise_scale=1.0, strength=1.0)
    y2 = y2 * np.where(c["valid"], rng.uniform(0.5, 3.0, (N_FDE, 1)), 0.0)
    fde2 = _np(detect_and_exclude(*_args(c, y2), araim.MHSSOptions(1)))
    counts = {"undetected": 0, "excluded": 0, "failed": 0}
    for res, yy in ((fde, y), (fde2, y2)):
        for i in range(0, N_FDE, 4):
            o = ref.detect_and_exclude_reference(*_ref_args(c, i, yy[i]))
            if o.pl.borderline:
                continue
            assert bool(res["detected"][i]) == o.detected, i
            np.testing.assert_array_equal(res["excluded"][i], o.excluded, err_msg=str(i))
            if o.status is None:
                assert res["status"][i] == Status.EXCLUSION_FAILED, i
                assert res["pl.hpl_m"][i] == np.inf and res["pl.vpl_m"][i] == np.inf
                counts["failed"] += 1
            else:
                assert res["status"][i] == o.status, i
                if o.status == ref.OK:
                    assert abs(res["pl.hpl_m"][i] - o.pl.hpl_m) <= 2e-3, i
                    assert abs(res["pl.vpl_m"][i] - o.pl.vpl_m) <= 2e-3, i
                counts["excluded" if o.detected else "undetected"] += 1
    assert counts["undetected"] > 5 and counts["excluded"] > 20 and counts["failed"] > 0, counts


# --------------------------------------------------------------------------- statistics vs oracle


def test_solution_separation_matches_oracle():
    """Separations, thresholds, tau and detection on 128 of the L = 28 random GPS + SOP
    geometries (orders 1..3) with noise plus a 20 m bias on one source, against the oracle."""
    n = 128
    case, _ = random_cases(20261125, n)
    rng = np.random.default_rng(305)
    y = rng.normal(0.0, np.sqrt(np.abs(case["var_acc"])))
    y[np.arange(n), rng.integers(0, case["g"].shape[1], n)] += 20.0
    y = np.where(case["valid"], y, 0.0)
    bud = araim.BUDGET_SEED004_TABLE_I
    sep = _np(solution_separation(araim.Sources(case["g"], case["constellation"], case["var_int"],
                                                case["var_acc"], case["b_nom"], case["p_sat"],
                                                case["valid"]), case["p_const"], bud, y,
                                  araim.MHSSOptions(3)))
    checked = 0
    for i in range(n):
        o = ref.solution_separation_reference(
            araim.Sources(case["g"][i], case["constellation"][i], case["var_int"][i],
                          case["var_acc"][i], case["b_nom"][i], case["p_sat"][i],
                          case["valid"][i]), case["p_const"][i], bud, y[i],
            ref.ReferenceOptions(3))
        if o.result.borderline or o.result.status != ref.OK:
            continue
        modes = _modes(sep["excluded"][i], sep["monitored"][i])
        assert set(modes) == set(o.excluded), i
        for j, ex in enumerate(o.excluded):
            k = modes[ex]
            np.testing.assert_allclose(sep["separation_m"][i, k], o.separation[j], rtol=1e-7,
                                       atol=1e-8, err_msg=str(i))
            thr = np.array(o.result.monitored[j].threshold)
            np.testing.assert_allclose(sep["threshold_m"][i, k], thr, rtol=1e-7, atol=1e-9)
            np.testing.assert_allclose(sep["tau"][i, k], o.tau[j], rtol=1e-6, atol=1e-9)
            assert sep["prior"][i, k] == pytest.approx(o.result.monitored[j].mode.prior,
                                                       rel=1e-9, abs=1e-300)
        if np.all(np.abs(o.tau - 1.0) > 1e-6):
            assert bool(sep["detected"][i]) == o.detected, i
        checked += 1
    assert checked > 100
    assert 0 < np.mean(sep["detected"]) < 1


# --------------------------------------------------------------------------- failures as data


def test_failures_are_data_in_fde():
    """Too few sources, singular and unmet-P_thresh geometries (rows 1..3) inside a batch of the
    FDE cases (same compiled shape), with a 50 m error on the first satellite and NaN residuals
    on padding rows: statuses 1, 2, 5 per row, never a NaN, inf PLs, no detection or exclusion
    where there is no PL to protect."""
    from tests.test_mhss import _gps_only

    c, rng = fde_cases(306, N_FDE)
    cases = [_gps_only(8), _gps_only(4), _gps_only(6, el_deg=40.0),
             _gps_only(8, p_const_gps=1e-6)]
    keys = ["g", "constellation", "var_int", "var_acc", "b_nom", "p_sat", "p_const", "valid"]
    for i, case in enumerate(cases):
        for k, v in zip(keys, case, strict=True):
            if k == "p_const":
                c[k][i] = v
            else:
                c[k][i] = 0
                c[k][i, :8] = v
    c["var_int"][:4, 8:] = c["var_acc"][:4, 8:] = 1.0
    y = np.where(c["valid"], rng.normal(0.0, np.sqrt(c["var_acc"])), np.nan)
    y[:4, 0] = 50.0
    fde = _np(detect_and_exclude(*_args(c, y), araim.MHSSOptions(1)))
    for k, v in fde.items():
        assert not np.any(np.isnan(v.astype(float))), k
    np.testing.assert_array_equal(fde["pl.status"][1:4], [1, 2, 5])
    np.testing.assert_array_equal(fde["status"][1:4], [1, 2, 5])
    assert np.all(np.isinf(fde["pl.hpl_m"][1:4])) and np.all(np.isinf(fde["pl.vpl_m"][1:4]))
    assert not fde["detected"][1:4].any() and not fde["excluded"][1:4].any()
    # row 0: a 50 m error on one of 8 satellites, as the oracle decides
    o = ref.detect_and_exclude_reference(*_ref_args(c, 0, y[0]))
    assert bool(fde["detected"][0]) == o.detected
    np.testing.assert_array_equal(fde["excluded"][0], o.excluded)
