"""The receiver's inputs and options as objects: ``araim.Sources`` (joining GNSS and SOP
sources, padding to a fixed L, selecting constellations) and ``araim.MHSSOptions`` (checked
once, one line per bad field), the objects every MHSS entry point takes."""

import numpy as np
import pytest

from oaraim import araim, geometry
from oaraim.araim import Status

BUDGET = araim.BUDGET_SEED004_TABLE_I
ONE = araim.MHSSOptions(1, fault_modes="grouped")


def _gps(n=8, seed=0):
    """A batch of 3 GPS skies of n satellites (Table I variances, b_nom 0.75 m, P_s 1e-5)."""
    rng = np.random.default_rng(seed)
    az = rng.uniform(0, 2 * np.pi, (3, n))
    el = np.deg2rad(rng.uniform(15, 85, (3, n)))
    vi, va = (np.asarray(x) for x in araim.error_models.gnss_variances(el, 1.0))
    return araim.Sources(np.asarray(geometry.geometry_rows(az, el)), np.zeros((3, n), int), vi,
                         va, 0.75, 1e-5)


def _sops(n=3, seed=1):
    """n SOP towers of one constellation (label 1) for the same 3 skies, sigma_URA^S 3 m."""
    rng = np.random.default_rng(seed)
    az = rng.uniform(0, 2 * np.pi, (3, n))
    el = np.deg2rad(rng.uniform(0, 5, (3, n)))
    return araim.Sources(np.asarray(geometry.geometry_rows(az, el)), 1, 9.0, 9.0, 0.0, 1e-4)


def test_concat_joins_along_the_source_axis_with_scalars_broadcast():
    """GPS then SOPs: every field (..., 8 + 3), scalars broadcast, labels kept; the PLs are the
    bits of the same arrays joined by hand."""
    gps, sops = _gps(), _sops()
    both = gps.concat(sops)
    assert both.g.shape == (3, 11, 3)
    for f in araim.Sources._fields[1:]:
        assert np.shape(getattr(both, f)) == (3, 11), f
    np.testing.assert_array_equal(np.asarray(both.constellation)[0], [0] * 8 + [1] * 3)
    np.testing.assert_array_equal(np.asarray(both.b_nom_m)[1], [0.75] * 8 + [0.0] * 3)
    assert np.asarray(both.valid).all()
    by_hand = araim.Sources(
        np.concatenate([gps.g, sops.g], -2), np.r_[[0] * 8, [1] * 3],
        np.concatenate([gps.var_int_m2, np.full((3, 3), 9.0)], -1),
        np.concatenate([gps.var_acc_m2, np.full((3, 3), 9.0)], -1),
        np.r_[[0.75] * 8, [0.0] * 3], np.r_[[1e-5] * 8, [1e-4] * 3])
    p_const = np.array([1e-8, 1e-4])
    a = araim.protection_levels(both, p_const, BUDGET, ONE)
    b = araim.protection_levels(by_hand, p_const, BUDGET, ONE)
    for name, x, y in zip(a._fields, a, b, strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=name)
    assert np.all(np.asarray(a.status) == Status.OK)


def test_concat_broadcasts_batch_shapes():
    """One SOP set for every sky of a batch: the batch shapes broadcast."""
    both = _gps().concat(araim.Sources(_sops().g[0], 1, 9.0, 9.0, 0.0, 1e-4))
    assert both.g.shape == (3, 11, 3) and np.shape(both.valid) == (3, 11)
    np.testing.assert_array_equal(np.asarray(both.g)[2, 8:], np.asarray(_sops().g)[0])


def test_pad_adds_invalid_sources_that_change_no_result():
    """Padded from 11 to 16 sources: the new ones are invalid unit rows, and the PLs, status,
    modes and P_NM are those of the unpadded sources (to 1e-9 m: a longer source axis may
    round the sums differently, DESIGN.md)."""
    both = _gps().concat(_sops())
    padded = both.pad(16)
    assert padded.g.shape == (3, 16, 3)
    assert not np.asarray(padded.valid)[:, 11:].any() and np.asarray(padded.valid)[:, :11].all()
    np.testing.assert_allclose(np.linalg.norm(np.asarray(padded.g), axis=-1), 1.0)
    p_const = np.array([1e-8, 1e-4])
    a = araim.protection_levels(both, p_const, BUDGET, ONE)
    b = araim.protection_levels(padded, p_const, BUDGET, ONE)
    for name in ("hpl_m", "vpl_m", "emt_m", "p_not_monitored"):
        np.testing.assert_allclose(np.asarray(getattr(b, name)), np.asarray(getattr(a, name)),
                                   rtol=0, atol=1e-9, err_msg=name)
    for name in ("status", "n_modes", "order"):
        np.testing.assert_array_equal(np.asarray(getattr(b, name)),
                                      np.asarray(getattr(a, name)), err_msg=name)
    assert both.pad(11).g.shape == both.g.shape
    with pytest.raises(ValueError, match="cannot pad 11 sources to n_sources=10"):
        both.pad(10)


def test_select_keeps_the_constellations_named():
    """Selecting GPS (label 0) of GPS + SOPs marks the towers invalid: the PLs of GPS alone
    (the SOP constellation loses its clock and its P_const event; to 1e-9 m)."""
    gps, both = _gps(), _gps().concat(_sops())
    only = both.select([0])
    np.testing.assert_array_equal(np.asarray(only.valid)[:, 8:], False)
    np.testing.assert_array_equal(np.asarray(only.valid)[:, :8], True)
    a = araim.protection_levels(only, np.array([1e-8, 1e-4]), BUDGET, ONE)
    b = araim.protection_levels(gps, np.array([1e-8]), BUDGET, ONE)
    np.testing.assert_allclose(np.asarray(a.hpl_m), np.asarray(b.hpl_m), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(a.vpl_m), np.asarray(b.vpl_m), rtol=0, atol=1e-9)
    assert not np.asarray(both.select([]).valid).any()
    np.testing.assert_array_equal(np.asarray(both.select([0, 1]).valid), True)


def test_valid_none_is_every_source():
    s = _gps()
    assert s.valid is None
    assert np.asarray(s.filled().valid).shape == (3, 8) and np.asarray(s.filled().valid).all()
    a = araim.protection_levels(s, np.array([1e-8]), BUDGET, ONE)
    b = araim.protection_levels(s.filled(), np.array([1e-8]), BUDGET, ONE)
    np.testing.assert_array_equal(np.asarray(a.hpl_m), np.asarray(b.hpl_m))
    k = araim.protection_levels_kernel(s, np.array([1e-8]), BUDGET, ONE)
    np.testing.assert_array_equal(np.asarray(k.hpl_m), np.asarray(a.hpl_m))


@pytest.mark.parametrize("options, match", [
    (araim.MHSSOptions(all_in_view_weighting="x"), "all_in_view_weighting must be 'int' or"),
    (araim.MHSSOptions(fault_modes="add-v5"), "fault_modes must be"),
    (araim.MHSSOptions(3, fault_modes="add-v4.2"), "max_order=3 is above"),
    (araim.MHSSOptions(0), "max_order"),
    (araim.MHSSOptions(1, iterations=0), "iterations"),
    (araim.MHSSOptions(1, position_optimization="maast"), "position_optimization must be"),
    ({"max_order": 1}, "options must be an araim.MHSSOptions"),
])
def test_bad_options_are_one_line(options, match):
    with pytest.raises(ValueError, match=match) as e:
        araim.protection_levels(_gps(), np.array([1e-8]), BUDGET, options)
    assert "\n" not in str(e.value)


def test_kernels_need_an_order_and_host_functions_pick_one():
    s, pc = _gps(), np.array([1e-8])
    with pytest.raises(ValueError, match="a kernel needs a static order"):
        araim.protection_levels_kernel(s, pc, BUDGET, araim.MHSSOptions())
    auto = araim.protection_levels(s, pc, BUDGET, araim.MHSSOptions(fault_modes="grouped"))
    assert np.all(np.asarray(auto.order) == 1)
    checked = araim.MHSSOptions(2, fault_modes="grouped").checked()
    assert isinstance(checked.fault_modes, araim.FaultModeRule) and checked.max_order == 2
    assert checked.checked() == checked  # canonical: the same compiled programs


def test_a_p_const_of_another_batch_is_named():
    with pytest.raises(ValueError, match=r"p_const of shape \(4, 1\) does not broadcast to the "
                                         r"sources' batch shape \(3,\)"):
        araim.protection_levels(_gps(), np.full((4, 1), 1e-8), BUDGET, ONE)


def test_solution_separation_takes_no_position_estimator():
    with pytest.raises(ValueError, match="position_optimization=None"):
        araim.solution_separation(_gps(), np.array([1e-8]), BUDGET, np.zeros((3, 8)),
                                  araim.MHSSOptions(1, position_optimization=(
                                      araim.PositionOptimization())))
