"""Unusable kernel inputs are refused by the host wrappers (one ValueError
naming the argument, the batch index and the source) and reported as Status.INVALID_INPUT by
the kernels under jit (inf PLs, no detection, no exclusion, no NaN anywhere).

Geometry: the ADD v3.0 Appendix D example (tests/test_conformance.py), two copies in a batch;
the offending entry is always batch index 1, source 3.
"""

import jax
import numpy as np
import pytest

from oaraim import araim
from oaraim.araim import Status
from tests.test_conformance import ADD_C_ACC, ADD_C_INT, ADD_CONST, ADD_P_CONST, ADD_ROWS

L = 10
B = 2
BUDGET = araim.BUDGET_LPV200
OPTIONS = araim.MHSSOptions(1, fault_modes="add-v4.2")


def inputs():
    return dict(g=np.tile(ADD_ROWS, (B, 1, 1)), constellation=np.tile(ADD_CONST, (B, 1)),
                var_int_m2=np.tile(ADD_C_INT, (B, 1)), var_acc_m2=np.tile(ADD_C_ACC, (B, 1)),
                b_nom_m=np.full((B, L), 0.5), p_sat=np.full((B, L), 1e-5),
                p_const=np.tile(ADD_P_CONST, (B, 1)))


def call(fn, x, *extra, valid=None):
    sources = araim.Sources(x["g"], x["constellation"], x["var_int_m2"], x["var_acc_m2"],
                            x["b_nom_m"], x["p_sat"], valid)
    return fn(sources, x["p_const"], BUDGET, *extra, OPTIONS)


def residuals():
    return np.zeros((B, L))


# one compiled program each (the tests share them)
pl_jit = jax.jit(lambda x: call(araim.protection_levels, x))
fde_jit = jax.jit(lambda y: call(araim.detect_and_exclude, inputs(), y))
sep_jit = jax.jit(lambda y: call(araim.solution_separation, inputs(), y))


BAD_ROWS = {"nan": [np.nan, 0.0, 1.0], "zero": [0.0, 0.0, 0.0], "norm 1.01": [0.0, 0.0, 1.01],
            "ecef vector": [1.2e7, -2.0e7, 8.0e6]}


@pytest.mark.parametrize("row", BAD_ROWS.values(), ids=BAD_ROWS.keys())
def test_host_refuses_a_bad_row_naming_where(row):
    x = inputs()
    x["g"][1, 3] = row
    with pytest.raises(ValueError, match=r"g \(line-of-sight rows\).*batch index \(1,\), "
                                         r"source 3"):
        call(araim.protection_levels, x)
    with pytest.raises(ValueError, match=r"g \(line-of-sight rows\).*batch index \(1,\)"):
        call(araim.detect_and_exclude, x, residuals())


def test_rows_of_invalid_sources_are_not_checked_and_printed_rows_pass():
    """A padding slot may hold anything; the ADD's rows, printed to 4 decimals (norms up to
    1 + 3.1e-5), are accepted (UNIT_ROW_TOLERANCE 1e-3)."""
    x = inputs()
    x["g"][1, 3] = [np.nan, np.nan, np.nan]
    valid = np.ones((B, L), bool)
    valid[1, 3] = False
    r = call(araim.protection_levels, x, valid=valid)
    assert np.all(np.asarray(r.status) == Status.OK)
    assert np.all(np.isfinite(np.asarray(r.vpl_m)))


def test_host_names_the_batch_index_of_a_bad_variance():
    x = inputs()
    x["var_int_m2"][1, 3] = -1.0
    with pytest.raises(ValueError, match=r"var_int_m2 .*batch index \(1,\), source 3"):
        call(araim.protection_levels, x)


def _no_nan(tree):
    for leaf in jax.tree.leaves(tree):
        a = np.asarray(leaf)
        if a.dtype.kind == "f":
            assert not np.any(np.isnan(a))


@pytest.mark.parametrize("field, value", [("g", [np.nan, 0.0, 1.0]), ("g", [0.0, 0.0, 0.0]),
                                          ("var_int_m2", np.nan), ("p_sat", 1.5)])
def test_kernel_under_jit_reports_invalid_input(field, value):
    x = inputs()
    x[field][1, 3] = value
    r = pl_jit(x)
    status = np.asarray(r.status)
    assert status[0] == Status.OK and status[1] == Status.INVALID_INPUT
    assert np.isfinite(np.asarray(r.vpl_m)[0])
    for k in ("hpl_m", "vpl_m", "emt_m", "sigma_acc_u_m"):
        assert np.asarray(getattr(r, k))[1] == np.inf, k
    _no_nan(r)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_nonfinite_residual_is_refused_on_the_host(value):
    y = residuals()
    y[1, 3] = value
    with pytest.raises(ValueError, match=r"residual_m .*batch index \(1,\), source 3"):
        call(araim.detect_and_exclude, inputs(), y)
    with pytest.raises(ValueError, match="residual_m"):
        call(araim.solution_separation, inputs(), y)


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_nonfinite_residual_under_jit_claims_nothing(value):
    """Before: a NaN residual passed detection (status OK, finite HPL); an inf residual
    excluded a source and reported OK. Now: INVALID_INPUT, nothing detected or excluded,
    position inf; the other geometry of the batch, with a 40 m fault on source 4, is detected
    and source 4 excluded as usual (the check can fail the other way too)."""
    y = residuals()
    y[1, 3] = value
    y[0, 4] = 40.0
    r = fde_jit(y)
    status = np.asarray(r.status)
    assert status[1] == Status.INVALID_INPUT
    assert not bool(np.asarray(r.detected)[1])
    assert not np.asarray(r.excluded)[1].any() and int(np.asarray(r.exclusion_mode)[1]) == -1
    assert np.all(np.asarray(r.position_m)[1] == np.inf)
    assert np.asarray(r.pl.vpl_m)[1] == np.inf
    assert bool(np.asarray(r.detected)[0]) and status[0] == Status.OK
    assert np.flatnonzero(np.asarray(r.excluded)[0]).tolist() == [4]
    _no_nan(r.pl)
    s = sep_jit(y)
    assert not bool(np.asarray(s.detected)[1])
    assert np.asarray(s.pl.status)[1] == Status.INVALID_INPUT


# ---------------------------------------------- slope RAIM and WNLS (the same treatment)

SIGMA = np.full((B, L), 1.5)
slope_jit = jax.jit(lambda g, s: araim.slope_hpl(g, s, 1e-5, 1e-3))


@pytest.mark.parametrize("fn", ["slope_hpl", "slopes"])
@pytest.mark.parametrize("row", BAD_ROWS.values(), ids=BAD_ROWS.keys())
def test_slope_host_refuses_a_bad_row_naming_where(row, fn):
    """Before: a NaN row gave SINGULAR_GEOMETRY, a (0, 0, 0) row or an ECEF vector a finite
    HPL with status OK."""
    g = np.tile(ADD_ROWS, (B, 1, 1))
    g[1, 3] = row
    args = (1e-5, 1e-3) if fn == "slope_hpl" else ()
    with pytest.raises(ValueError, match=r"g \(line-of-sight rows\) of a valid source is not a "
                                         r"unit vector at batch index \(1,\), source 3"):
        getattr(araim, fn)(g, SIGMA, *args)


def test_slope_host_names_where_a_sigma_is_bad_and_skips_padding():
    s = SIGMA.copy()
    s[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"sigma_m must be finite .*batch index \(1,\), "
                                         r"source 3"):
        araim.slope_hpl(np.tile(ADD_ROWS, (B, 1, 1)), s, 1e-5, 1e-3)
    g = np.tile(ADD_ROWS, (B, 1, 1))
    g[1, 3] = np.nan
    valid = np.ones((B, L), bool)
    valid[1, 3] = False
    r = araim.slope_hpl(g, s, 1e-5, 1e-3, valid=valid)  # both bad entries are padding
    assert np.all(np.asarray(r.status) == Status.OK) and np.all(np.isfinite(r.hpl_m))


@pytest.mark.parametrize("field, value", [("g", [np.nan, 0.0, 1.0]), ("g", [0.0, 0.0, 0.0]),
                                          ("sigma", np.inf)])
def test_slope_kernel_under_jit_reports_invalid_input(field, value):
    g, s = np.tile(ADD_ROWS, (B, 1, 1)), SIGMA.copy()
    (g if field == "g" else s)[1, 3] = value
    r = slope_jit(g, s)
    status = np.asarray(r.status)
    assert status[0] == Status.OK and status[1] == Status.INVALID_INPUT
    assert np.isfinite(np.asarray(r.hpl_m)[0]) and np.asarray(r.hpl_m)[1] == np.inf
    assert np.asarray(r.slope_max)[1] == np.inf and np.all(np.asarray(r.slopes)[1] == np.inf)
    _no_nan(r)


def _wnls_inputs():
    """Two epochs of 6 satellites at 20,200 km seen from the Earth's surface (x axis)."""
    rx = np.array([6.371e6, 0.0, 0.0])
    az = np.deg2rad([0.0, 60.0, 120.0, 180.0, 240.0, 300.0])
    el = np.deg2rad([80.0, 40.0, 25.0, 55.0, 30.0, 15.0])
    los = np.stack([np.sin(el), np.cos(el) * np.sin(az), np.cos(el) * np.cos(az)], -1)
    tx = np.tile(rx + 2.02e7 * los, (B, 1, 1))
    pr = np.linalg.norm(tx - rx, axis=-1) + 30.0
    return pr, tx, np.full((B, 6), 2.0)


wnls_jit = jax.jit(lambda pr, tx, s, ci: araim.wnls(pr, tx, s, clock_index=ci))


@pytest.mark.parametrize("field, value, message", [
    ("pr", np.nan, r"pseudorange_m of a valid source is not finite at batch index \(1,\), "
                   r"source 3"),
    ("tx", np.inf, r"tx_pos_m of a valid source is not finite at batch index \(1,\), source 3"),
    ("sigma", 0.0, r"sigma_m must be finite and > 0 .*batch index \(1,\), source 3"),
    ("clock", 1, r"clock_index must be an integer in 0..0 .*got 1 at batch index \(1,\), "
                 r"source 3")])
def test_wnls_refuses_on_the_host_and_flags_under_jit(field, value, message):
    """Before: a NaN pseudorange gave a NaN position with status NOT_CONVERGED or OK; a clock
    group out of range left the source in no clock column, silently."""
    pr, tx, s = _wnls_inputs()
    ci = np.zeros((B, 6), np.int32)
    {"pr": pr, "tx": tx[..., 0], "sigma": s, "clock": ci}[field][1, 3] = value
    with pytest.raises(ValueError, match=message):
        araim.wnls(pr, tx, s, clock_index=ci)
    r = wnls_jit(pr, tx, s, ci)
    status = np.asarray(r.status)
    assert status[0] == Status.OK and status[1] == Status.INVALID_INPUT
    np.testing.assert_allclose(np.asarray(r.clock_m)[0], [30.0], atol=1e-6)
    for k in ("position_m", "clock_m", "wsse", "covariance_m2"):
        assert np.all(np.asarray(getattr(r, k))[1] == np.inf), k
    assert np.all(np.asarray(r.residual_m)[1] == np.inf)
    _no_nan(r)


def test_wnls_refuses_a_nonfinite_initial_state():
    pr, tx, s = _wnls_inputs()
    x0 = np.zeros((B, 3))
    x0[1, 2] = np.nan
    with pytest.raises(ValueError, match=r"x0_m \(the initial state\) is not finite at batch "
                                         r"index \(1,\)"):
        araim.wnls(pr, tx, s, x0)
