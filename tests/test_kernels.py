"""The public jit-safe kernels (``araim.protection_levels_kernel``, ``separation_kernel``,
``detect_and_exclude_kernel``, ``slopes_kernel``, ``slope_hpl_kernel``, ``wnls_kernel``): they
run under ``jax.jit`` and ``jax.vmap``, give the numbers of the host functions that wrap them,
and report a bad input as ``Status.INVALID_INPUT`` inside the trace instead of raising.

Compiled shapes: the bench case (9 GPS + 4 SOPs, order 1, grouped) at 64 geometries and the
FDE cases of test_fde.py (L = 18, C = 2, order 1) at 16. Under ``jax.vmap`` each geometry is
computed at batch shape 1 instead of in one chunk of 64, which XLA may round differently: there
the comparison is to 1e-12 relative.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import araim
from oaraim.araim import Sources, Status
from oaraim.bench import mhss_bench_inputs
from tests.test_fde import fde_cases

GROUPED = araim.FaultModeRule("grouped")
BUDGET = araim.BUDGET_SEED004_TABLE_I
N = 64


def _equal(got, want, rtol=0.0):
    for name in want._fields:
        a, b = getattr(got, name), getattr(want, name)
        if hasattr(b, "_fields"):
            _equal(a, b, rtol)
            continue
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape, name
        if rtol and a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=rtol, atol=0, err_msg=name)
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)


@pytest.fixture(scope="module")
def bench():
    x = mhss_bench_inputs(N, seed=7)
    return Sources(*(np.asarray(x[k]) for k in Sources._fields)), np.asarray(x["p_const"])


def _host(sources, p_const):
    return araim.protection_levels(sources, p_const, BUDGET,
                                   araim.MHSSOptions(1, fault_modes=GROUPED))


def _kernel(sources, p_const):
    return araim.protection_levels_kernel(sources, p_const, BUDGET,
                                          araim.MHSSOptions(1, fault_modes=GROUPED))


def test_protection_levels_kernel_under_jit_and_vmap_matches_host(bench):
    """Under the caller's ``jax.jit`` (the kernel inline, XLA's default options) the bits of
    ``protection_levels``; under ``jax.vmap`` (one geometry per call) the same numbers; called
    with concrete arrays (jitted on its own) the same bits again."""
    sources, p_const = bench
    host = _host(sources, p_const)
    assert np.all(np.asarray(host.status) == Status.OK)
    _equal(jax.jit(_kernel)(sources, p_const), host)
    _equal(_kernel(sources, p_const), host)
    _equal(jax.jit(jax.vmap(_kernel))(sources, p_const), host, rtol=1e-12)


def test_protection_levels_kernel_reports_bad_inputs_as_status(bench):
    """A negative variance, a non-unit row and a label outside 0..C-1 at valid sources give
    INVALID_INPUT with infinite PLs inside jit; the other geometries keep their bits; the host
    function names the first bad argument instead."""
    sources, p_const = bench
    var_int = sources.var_int_m2.copy()
    var_int[3, 2] = -1.0
    g = sources.g.copy()
    g[5, 0] *= 2.0
    const = sources.constellation.copy()
    const[9, 11] = 5
    bad = sources._replace(var_int_m2=var_int, g=g, constellation=const)
    res = jax.jit(_kernel)(bad, p_const)
    status = np.asarray(res.status)
    flagged = np.zeros(N, bool)
    flagged[[3, 5, 9]] = True
    assert np.all(status[flagged] == Status.INVALID_INPUT)
    assert np.all(np.isinf(np.asarray(res.hpl_m)[flagged]))
    assert np.all(np.isinf(np.asarray(res.vpl_m)[flagged]))
    host = _host(sources, p_const)
    for name in ("hpl_m", "vpl_m", "status"):
        np.testing.assert_array_equal(np.asarray(getattr(res, name))[~flagged],
                                      np.asarray(getattr(host, name))[~flagged])
    with pytest.raises(ValueError, match="var_int_m2 of a valid source"):
        _host(bad, p_const)
    # invalid padding changes nothing: the bad row marked invalid is not flagged
    padded = bad._replace(valid=sources.valid.copy())
    padded.valid[5, 0] = padded.valid[3, 2] = padded.valid[9, 11] = False
    assert not np.any(np.asarray(jax.jit(_kernel)(padded, p_const).status)
                      == Status.INVALID_INPUT)


def test_protection_levels_kernel_static_arguments_are_checked(bench):
    """A malformed static argument is a ValueError naming it, before any tracing."""
    sources, p_const = bench
    with pytest.raises(ValueError, match="max_order"):
        araim.protection_levels_kernel(sources, p_const, BUDGET, araim.MHSSOptions(None))
    with pytest.raises(ValueError, match="budget"):
        araim.protection_levels_kernel(sources, p_const, 1e-7, araim.MHSSOptions(1))
    with pytest.raises(ValueError, match="all_in_view_weighting"):
        araim.protection_levels_kernel(sources, p_const, BUDGET,
                                       araim.MHSSOptions(1, all_in_view_weighting="x"))


def test_priors_kernel_equals_one_kernel_call_per_prior_set(bench):
    """``protection_levels_priors_kernel`` over three P_s^S values (one with a P_s of 1.2 at a
    valid source of geometry 4) gives, set by set, what ``protection_levels_kernel`` gives
    with that set's priors (measured bit-identical; compared to 1e-12): the same statuses,
    orders and mode counts, INVALID_INPUT in that set only. A set's bits do not depend on the
    other sets (one loop body per set): the second set alone gives the same bits."""
    sources, p_const = bench
    sop = sources.constellation == 1
    sets = np.stack([np.where(sop, p, sources.p_sat) for p in (1e-5, 1e-3, 5e-2)])
    sets[1, 4, np.flatnonzero(sources.valid[4])[0]] = 1.2
    pc = np.broadcast_to(p_const, (3,) + p_const.shape)
    res = araim.protection_levels_priors_kernel(sources._replace(p_sat=sets), pc, BUDGET,
                                                araim.MHSSOptions(2, fault_modes=GROUPED))
    orders = set()
    for i in range(3):
        one = araim.protection_levels_kernel(sources._replace(p_sat=sets[i]), pc[i], BUDGET,
                                             araim.MHSSOptions(2, fault_modes=GROUPED))
        _equal(type(one)(*(x[i] for x in res)), one, rtol=1e-12)
        orders |= set(np.asarray(one.order).tolist())
        bad = np.asarray(one.status) == Status.INVALID_INPUT
        assert bad.tolist() == [i == 1 and b == 4 for b in range(N)]
    assert orders == {1, 2}  # both templates' paths are exercised
    alone = araim.protection_levels_priors_kernel(sources._replace(p_sat=sets[1:2]), pc[1:2],
                                                  BUDGET, araim.MHSSOptions(2, fault_modes=GROUPED))
    _equal(type(alone)(*(x[0] for x in alone)), type(res)(*(x[1] for x in res)))
    with pytest.raises(ValueError, match="leading axis"):
        araim.protection_levels_priors_kernel(sources, p_const, BUDGET, araim.MHSSOptions(1))


@pytest.fixture(scope="module")
def fde():
    c, rng = fde_cases(21, 16)
    y = rng.normal(0.0, 1.0, c["valid"].shape) * np.sqrt(c["var_int"])
    y[2, 0] += 80.0  # a fault on a GPS satellite of geometry 2
    sources = Sources(c["g"], c["constellation"], c["var_int"], c["var_acc"], c["b_nom"],
                      c["p_sat"], c["valid"])
    return sources, c["p_const"], y


def test_separation_and_exclusion_kernels_under_jit_match_host(fde):
    """``separation_kernel`` and ``detect_and_exclude_kernel`` inside the caller's jit: the
    bits of ``solution_separation`` and ``detect_and_exclude``; a non-finite residual of a
    valid source comes back as INVALID_INPUT (no detection), where the host raises."""
    sources, p_const, y = fde
    kw = araim.MHSSOptions(1, fault_modes=GROUPED)
    sep = jax.jit(lambda s, p, r: araim.separation_kernel(s, p, BUDGET, r, kw))(
        sources, p_const, y)
    _equal(sep, araim.solution_separation(sources, p_const, BUDGET, y, kw))
    fde_res = jax.jit(lambda s, p, r: araim.detect_and_exclude_kernel(s, p, BUDGET, r, kw))(
        sources, p_const, y)
    host = araim.detect_and_exclude(sources, p_const, BUDGET, y, kw)
    _equal(fde_res, host)
    assert bool(np.asarray(host.detected)[2])
    y_bad = y.copy()
    y_bad[4, 1] = np.nan
    sep_bad = jax.jit(lambda s, p, r: araim.separation_kernel(s, p, BUDGET, r, kw))(
        sources, p_const, y_bad)
    assert int(np.asarray(sep_bad.pl.status)[4]) == Status.INVALID_INPUT
    assert not bool(np.asarray(sep_bad.detected)[4])
    with pytest.raises(ValueError, match="residual_m"):
        araim.solution_separation(sources, p_const, BUDGET, y_bad, kw)


def test_slope_kernels_under_jit_and_vmap_match_host(bench):
    """``slopes_kernel`` and ``slope_hpl_kernel`` under jit and vmap give the numbers of
    ``slopes`` and ``slope_hpl``; a non-unit row is INVALID_INPUT there, a ValueError here."""
    sources, _ = bench
    g, valid = sources.g, sources.valid
    sigma = np.sqrt(sources.var_int_m2)
    table = jnp.asarray(araim.lambda_det_table(1e-5, 1e-3, g.shape[-2] - 4))
    _equal(jax.jit(araim.slopes_kernel)(g, sigma, valid), araim.slopes(g, sigma, valid))
    host = araim.slope_hpl(g, sigma, 1e-5, 1e-3, valid)
    _equal(jax.jit(araim.slope_hpl_kernel)(g, sigma, valid, table), host)
    _equal(jax.vmap(araim.slope_hpl_kernel, (0, 0, 0, None))(g, sigma, valid, table), host,
           rtol=1e-12)
    g_bad = g.copy()
    g_bad[1, 4] = 0.0
    res = jax.jit(araim.slope_hpl_kernel)(g_bad, sigma, valid, table)
    assert int(np.asarray(res.status)[1]) == Status.INVALID_INPUT
    assert np.isinf(np.asarray(res.hpl_m)[1])
    with pytest.raises(ValueError, match="not a unit vector"):
        araim.slope_hpl(g_bad, sigma, 1e-5, 1e-3, valid)


def test_wnls_kernel_under_jit_matches_host():
    """``wnls_kernel`` inside jit: the bits of ``wnls``; a non-finite pseudorange of a valid
    source is INVALID_INPUT there and a ValueError naming it here."""
    rng = np.random.default_rng(3)
    tx = rng.normal(0.0, 2e7, (8, 7, 3))
    rx = rng.normal(0.0, 10.0, (8, 3))
    pr = np.linalg.norm(tx - rx[:, None], axis=-1) + 30.0 + rng.normal(0.0, 1.0, (8, 7))
    sigma = np.ones((8, 7))
    valid = np.ones((8, 7), bool)
    clock = np.zeros((8, 7), np.int32)
    x0 = np.zeros((8, 4))
    host = araim.wnls(pr, tx, sigma, x0, valid, clock)
    one = araim.WNLSOptions(n_clocks=1)
    got = jax.jit(lambda *a: araim.wnls_kernel(*a, one))(pr, tx, sigma, x0, valid, clock)
    _equal(got, host)
    assert np.all(np.asarray(host.status) == Status.OK)
    pr_bad = pr.copy()
    pr_bad[6, 2] = np.inf
    bad = jax.jit(lambda *a: araim.wnls_kernel(*a, one))(pr_bad, tx, sigma, x0, valid, clock)
    assert int(np.asarray(bad.status)[6]) == Status.INVALID_INPUT
    with pytest.raises(ValueError, match="pseudorange_m"):
        araim.wnls(pr_bad, tx, sigma, x0, valid, clock)
