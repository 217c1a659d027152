"""Seed 004 sweep studies: Fig. 3 (one SOP), Fig. 4 (HPL-reduction maps), Theorems 1-2.

The generic study tests (tests/test_studies.py) cover storage, chunk-size bit-identity and the
CLI path; here: the studies compute what they claim (against the public MHSS API), the hand-
checkable helpers, and the paper's statements at reduced size.
"""


import jax
import numpy as np
import pytest

from oaraim import araim, errors, geometry, mc
from oaraim.registry import STUDIES
from oaraim.studies.common import seed004 as c
from oaraim.studies.common.seed004 import Fig4Cell
from oaraim.studies.seed004_fig4 import largest_reducing_sigma, monotone_share
from tests.test_mhss import grouped

# these tests check the grouped convention (seed 004's SOP studies) against the grouped
# oracle; the ADD conventions are tested in test_conformance.py
protection_levels = grouped(araim.protection_levels)


def test_receiver_is_orange_county():
    lat, lon, h = geometry.ecef_to_geodetic(np.array(c.ORANGE_COUNTY_ECEF_M))
    assert abs(np.rad2deg(float(lat)) - 33.643) < 1e-3
    assert abs(np.rad2deg(float(lon)) + 117.841) < 1e-3
    assert abs(float(h)) < 100.0


def test_order_rule_by_hand():
    """P(GPS faulty) = 1 - (1 - 1e-8)(1 - 1e-5)^12 = 1.2e-4. With 2 SOPs at P_s 1e-7:
    P(SOP faulty) = 1 - (1 - 1e-4)(1 - 1e-7)^2 = 1.0e-4, product 1.2e-8 <= P_thresh = 6e-8:
    order 1. With 8 SOPs at 1e-4: P(SOP faulty) = 9.0e-4, product 1.08e-7 > 6e-8: order 2."""
    assert c.order_for(12, 2, 1e-7, 1e-4) == 1
    assert c.order_for(12, 8, 1e-4, 1e-4) == 2
    # boundary: product = 6e-8 at P(SOP faulty) = 6e-8 / 1.2e-4 = 5e-4
    assert c.order_for(12, 1, 3.9e-4, 1e-4) == 1  # 4.9e-4
    assert c.order_for(12, 1, 4.1e-4, 1e-4) == 2  # 5.1e-4


def test_summary_helpers_by_hand():
    red = np.array([[1.0, 0.5, -0.1], [0.2, -0.3, -0.5]])
    np.testing.assert_array_equal(largest_reducing_sigma(red, np.array([1.0, 2.0, 3.0])),
                                  [2.0, 1.0])
    assert np.isnan(largest_reducing_sigma(np.array([[-1.0, -2.0]]), np.array([1.0, 2.0]))[0])
    # pairs: along sigma (4): all decrease; along p (3): all decrease -> 100 %
    assert monotone_share(red) == 1.0
    # one increase along sigma out of 7 pairs
    assert monotone_share(np.array([[1.0, 1.5, -0.1], [0.2, -0.3, -0.5]])) == pytest.approx(
        6 / 7)


@pytest.fixture(scope="module")
def cell():
    study = STUDIES["seed004-fig4-hpl-maps"]
    params = study.validate({"nav": "nominal"})
    coords = {"n_sops": 4, "sigma_ura_sop_m": 3.0, "p_s_sop": 1e-3}
    keys = mc.realization_keys(5, 0, 0, 1024)
    return Fig4Cell(params, coords), params, coords, keys


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_fig4_cell_matches_public_protection_levels(cell):
    """The study's per-realization HPLs equal araim.protection_levels on the same geometries
    (rebuilt here from the same keys with the public API), GPS-only and GPS + SOPs."""
    kernel, params, coords, keys = cell
    out = kernel(keys)
    t = c.gps_sky_table("nominal", params["mask_deg"], params["sky_step_s"])
    n = 64
    idx = [int(c.draw_gps(k, t["az_rad"], t["el_rad"], t["valid"])[0]) for k in keys[:n]]
    az, el, valid = t["az_rad"][idx], t["el_rad"][idx], t["valid"][idx]
    tw = [c.draw_sops(k, 4, params["d_min_m"], params["d_max_m"], params["h_min_m"],
                      params["h_max_m"]) for k in keys[:n]]
    az_s = np.stack([np.asarray(x.az_rad) for x in tw])
    el_s = np.stack([np.asarray(x.el_rad) for x in tw])
    vi, va = (np.asarray(x) for x in errors.gnss_variances(el, 1.0))
    gps_sources = araim.Sources(geometry.geometry_rows(az, el), np.zeros(az.shape, int), vi, va,
                                0.75, 1e-5, valid)
    gps = protection_levels(gps_sources, [1e-8], araim.BUDGET_SEED004_TABLE_I)
    si, sa = errors.sop_variances(np.full(az_s.shape, 3.0))
    sops = araim.Sources(geometry.geometry_rows(az_s, el_s), 1, si, sa, 0.0, 1e-3)
    both = protection_levels(gps_sources.concat(sops), [1e-8, 1e-4],
                             araim.BUDGET_SEED004_TABLE_I)
    hg, hs = np.asarray(gps.hpl_m), np.asarray(both.hpl_m)
    fin = np.isfinite(hg) & np.isfinite(hs)
    np.testing.assert_array_equal(out["both_finite"][:n], fin)
    # the public call may pick a lower order for this batch than the cell's worst case: the
    # PLs agree to the solver tolerance, not bit for bit
    np.testing.assert_allclose(out["hpl_reduction_m"][:n][fin], (hg - hs)[fin], atol=2e-3)
    assert np.all(out["hpl_reduction_m"][~out["both_finite"]] == 0.0)
    assert not np.any(np.isnan(out["hpl_reduction_m"]))


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_fig4_common_random_numbers(cell):
    """Cells of a panel share their geometries: the GPS-only HPLs are identical whatever
    sigma_URA^S and P_s^S, and a different sigma changes the GPS + SOP result."""
    kernel, params, coords, keys = cell
    other = Fig4Cell(params, {**coords, "sigma_ura_sop_m": 10.0})
    a, b = kernel(keys), other(keys)
    np.testing.assert_array_equal(a["hpl_gps_m"], b["hpl_gps_m"])
    assert not np.array_equal(a["hpl_reduction_m"], b["hpl_reduction_m"])


_COMPILE_EVENTS = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, _s, **_kw: _COMPILE_EVENTS.append(event) if "jaxpr_trace" in event else None)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_fig4_cell_warm_compiles_what_its_call_runs(cell, monkeypatch):
    """``warm`` (what mc.sweep runs ahead of a cell) traces and compiles this cell's programs
    without running them: the call that follows traces nothing. The cell is the P_s^S group
    of one of the next test, compiled nowhere before in this module."""
    _, params, coords, keys = cell
    monkeypatch.setattr(c, "_WARMED", set())  # what an earlier module's sweeps warmed
    alone = Fig4Cell({**params, "p_s_sop": (coords["p_s_sop"],)}, coords)
    _COMPILE_EVENTS.clear()
    alone.warm(keys.shape[0])
    assert _COMPILE_EVENTS  # it compiled something
    other = mc.realization_keys(6, 0, 0, keys.shape[0])  # not the next test's (memoized) keys
    _COMPILE_EVENTS.clear()
    alone(other)
    assert _COMPILE_EVENTS == []


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_fig4_cells_of_a_p_s_group_share_one_kernel_call(cell, monkeypatch):
    """The cells whose P_s^S needs the same order form a group computed by one kernel call:
    the group's other cells are read from the cache (no kernel call), and a grid narrowed to
    one P_s^S value (a group of one) gives the same bits as the full grid's group."""
    kernel, params, coords, keys = cell
    a = kernel(keys)
    assert len(kernel.group) > 1 and coords["p_s_sop"] in kernel.group
    slots = kernel.table["az_rad"].shape[1]
    assert all(c.order_for(slots, 4, p, 1e-4) == kernel.max_order for p in kernel.group)
    sibling = next(p for p in kernel.group if p != coords["p_s_sop"])
    calls = []
    real = c.sop_kernel
    monkeypatch.setattr(c, "sop_kernel", lambda *x: calls.append(x) or real(*x))
    Fig4Cell(params, {**coords, "p_s_sop": sibling})(keys)
    assert calls == []
    alone = Fig4Cell({**params, "p_s_sop": (coords["p_s_sop"],)}, coords)
    assert alone.group == (coords["p_s_sop"],)
    b = alone(keys)
    assert len(calls) == 1
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_fig3_one_sop_raises_pls_and_ignores_its_sigma():
    """Theorem 2 / Fig. 3 at reduced size: every realization's HPL and VPL rise; the SOP's own
    sigma_URA^S changes nothing (its clock absorbs it)."""
    study = STUDIES["seed004-fig3-one-sop"]
    params = study.validate({"nav": "nominal", "p_s_sop": "1e-6,1e-4,1e-2",
                             "sigma_ura_sop_m": "1,25"})
    res = study.run(params, 1024, 3, None)
    m = res.metrics
    assert m["min_hpl_increase_m"] >= -2e-3 and m["min_vpl_increase_m"] >= -2e-3
    assert m["max_change_across_sigma_ura_sop_m"] < 1e-9
    rows = {r["quantity"]: r for r in res.rows}
    assert rows["realizations where adding one SOP raises the HPL"]["reproduced"] == 100.0
    inc = m["mean_hpl_increase_m"]
    assert inc[1e-4] > inc[1e-6] > 0.0


def test_theorems_hold_at_reduced_size():
    study = STUDIES["seed004-theorems"]
    res = study.run(study.validate({"n_gps": "6,12"}), 1024, 1, None)
    m = res.metrics
    assert m["hypotheses_met"] >= 0.99 * m["realizations_total"]
    assert m["share_theorem_1_pct"] == 100.0 and m["share_theorem_2_pct"] == 100.0
    assert m["sop_faults_1e4_m"] > 500 and m["sop_faults_detected_by_own_mode"] == 0
    assert m["old_system_detections"] > 0


def test_bad_axis_values_are_rejected():
    study = STUDIES["seed004-fig4-hpl-maps"]
    with pytest.raises(ValueError, match="p_s_sop"):
        study.validate({"p_s_sop": "1e-4,2"})
    with pytest.raises(ValueError, match="n_sops"):
        study.validate({"n_sops": "2,0"})
    with pytest.raises(ValueError, match="d_min_m"):
        study.validate({"d_min_m": "5000"})


def test_keys_do_not_depend_on_axis_values_for_common_random_numbers():
    """key_axes = (): every cell of Fig. 4 uses the same keys (mc.sweep derives the cell key
    from the key axes only)."""
    from oaraim.mc.sweep import cell_key_id

    study = STUDIES["seed004-fig4-hpl-maps"]
    a = cell_key_id({"n_sops": 2, "p_s_sop": 1e-4, "sigma_ura_sop_m": 1.0}, study.key_axes)
    b = cell_key_id({"n_sops": 8, "p_s_sop": 1e-1, "sigma_ura_sop_m": 25.0}, study.key_axes)
    assert a == b
    jax.block_until_ready(mc.realization_keys(0, a, 0, 4))


# ------------------------------------------------------------------------------ seed004-uav
def test_uav_tower_table_is_the_papers_carriers_by_operator():
    """Seed 004 VII-A: 11 towers on 739, 1955 (AT&T), 2125 (T-Mobile), 2145 MHz (Verizon);
    numbered operator by operator so that SOPs 1 and 2 share a clock (Fig. 8)."""
    from oaraim.studies import seed004_uav as u
    assert [t.sop for t in u.TOWERS] == list(range(1, 12))
    assert {t.carrier_mhz for t in u.TOWERS} == set(u.CARRIERS_MHZ)
    op = {739: "AT&T", 1955: "AT&T", 2125: "T-Mobile", 2145: "Verizon"}
    assert all(op[t.carrier_mhz] == t.operator for t in u.TOWERS)
    ops = u.tower_operators()
    assert ops == sorted(ops, key=u.OPERATORS.index)  # operator blocks in SOP order
    assert ops[0] == ops[1] != ops[5]
    d = np.linalg.norm(u.towers_enu_m()[:, :2], axis=1)
    assert np.all((d > 500.0) & (d < 3000.0))  # the docstring's 0.6-2.9 km


@pytest.fixture(scope="module")
def uav_runs(shared_data):
    """The first 160 epochs: the realistic world, the same with an unmodelled 120 m bias on
    SOP 2, and the clean world (white noise from the PL's own model)."""
    study = STUDIES["seed004-uav"]
    base = {"n_epochs": "2880", "exclusion": "false", "fault_onset_s": "4",
            "fault_ramp_mps": "2"}
    return [study.run(study.validate({**base, **kw}), 160, 0, None)
            for kw in ({}, {"inject_sop_bias_m": "120", "inject_sop": "2"},
                       {"world": "clean"})]


def test_uav_constellations_by_operator_and_prn8(uav_runs):
    """The clock groups are the operators; PRN 8 (Fig. 7) is in view at the default take-off."""
    m = uav_runs[0].metrics
    assert m["carriers"] == ["AT&T", "T-Mobile", "Verizon"]
    assert m["fault_prn"] == 8
    assert m["gps_visible_min"] >= 5


def test_uav_mi_check_can_fail(uav_runs):
    """The MI check on the UAV, in the realistic world (the default): no epoch of GPS + 11
    SOPs has HPE > HPL (MHSS all-in-view bounds a single SOP fault at P_s^S = 1e-4, and the
    world's LTE errors, ~4 m RMS over the flight, stay under the HPL); a 120 m bias (40
    sigma_URA^S) on SOP 2 is beyond what the PL covers without detection, and MI becomes
    common, with Clopper-Pearson intervals that do not overlap (160 epochs each; correlated in
    this world, so the intervals are narrower than they should be, as the study's note says).
    GPS only does not use the tower: its HPL and HPE are the same numbers."""
    ok, bad = (r.metrics["misleading_information_rate"]["11"] for r in uav_runs[:2])
    assert uav_runs[0].metrics["world"] == "realistic"
    assert ok["count"] == 0 and ok["trials"] == 160
    assert bad["count"] > 40
    assert bad["ci_low"] > ok["ci_high"]
    # on top of this world's errors the bias makes every epoch MI: the Clopper-Pearson
    # interval then ends at 1, the rate itself
    assert bad["ci_low"] < bad["rate"] <= bad["ci_high"]
    a, b = (r.dataset for r in uav_runs[:2])
    np.testing.assert_array_equal(a["hpl_m"].values[0], b["hpl_m"].values[0])
    np.testing.assert_array_equal(a["hpe_m"].values[0], b["hpe_m"].values[0])
    assert b["mi_count"].values[-1] == bad["count"]
    assert "correlated" in uav_runs[0].metrics["misleading_information_epochs_note"]


#: the first 160 epochs of the flight (fault ramp 2 m/s from 4 s) before the error world
#: (commit 4c96b37): sum over the epochs of the HPE per configuration (GPS + 0..11 SOPs), the
#: HPE of GPS + 11 SOPs at the first five epochs, and the two detection times (Fig. 7)
WHITE_NOISE_HPE_SUM_M = (136.6616249162341, 136.6616249162341, 127.95842386931642,
                         123.7486238484647, 119.9606107623942, 120.11400710387836,
                         120.11400710358197, 118.97033728533813, 117.21517493164616,
                         117.2151749323946, 115.20945357493598, 107.93212247075573)
WHITE_NOISE_HPE_11_FIRST_M = (0.9193110398498929, 0.47774973637326656, 0.1348576384416682,
                              1.1214975241244893, 0.47634775081475605)
WHITE_NOISE_DETECTION_S = (6.645833333333334, 6.645833333333334)


def test_uav_clean_world_is_the_white_noise_flight(uav_runs):
    """world=clean is the study before the realistic error world: the same draws (epoch k from
    fold_in(key(seed), k)), the same HPE to rounding, the same detection times; the HPL
    depends on the world only through the linearisation point (geometry and the PL's sigmas)."""
    clean, real = uav_runs[2], uav_runs[0]
    assert clean.metrics["world"] == "clean"
    hpe = clean.dataset["hpe_m"].values
    np.testing.assert_allclose(hpe.sum(-1), WHITE_NOISE_HPE_SUM_M, rtol=1e-9)
    np.testing.assert_allclose(hpe[-1, :5], WHITE_NOISE_HPE_11_FIRST_M, rtol=1e-9, atol=1e-12)
    m = clean.metrics
    assert (m["detection_time_gps_s"], m["detection_time_sop1_s"]) == WHITE_NOISE_DETECTION_S
    # (to the linearisation point: the WNLS solution moves with the errors; <= 0.4 % here)
    np.testing.assert_allclose(real.dataset["hpl_m"].values, clean.dataset["hpl_m"].values,
                               rtol=1e-2)
    # the clean world's LTE noise is 2 m white; the realistic world's is 1 m white, 1.5 m
    # multipath and 0.5 m epsilon_n (1.87 m together), plus NLOS and the clock fit's drift
    assert 1.7 < m["error_rms_sop_m"] < 2.3
    assert real.metrics["error_rms_sop_m"] > np.sqrt(1.0 + 1.5**2 + 0.5**2)


def test_uav_realistic_world_wiring(shared_data):
    """The realistic synthesis is sim.gnss_errors on the GPS columns and sim.sop_errors on the
    towers, with the towers' operators (AT&T 1-5, T-Mobile 6-8, Verizon 9-11) sharing their
    operator's common clock term (seed 004 eq. 3), from the flight's key fold_in(key(0), 0)."""
    import jax
    import jax.numpy as jnp

    from oaraim import sim
    from oaraim.studies.seed004_uav import study as u
    st = STUDIES["seed004-uav"]
    p = st.validate({"n_epochs": "40", "exclusion": "false"})
    geom, pr, _, _ = u.synthesize(p, 0)
    err = pr - sim.pseudoranges(geom, 0.0)
    e_world, sig = u.world_errors(geom, p, 0)
    np.testing.assert_allclose(err, e_world, atol=1e-6)
    key = jax.random.fold_in(jax.random.key(0), 0)
    tw = ~geom.is_gps
    operator = jnp.asarray([0] * 5 + [1] * 3 + [2] * 3)
    t = jnp.asarray(geom.t_s)
    world = errors.ErrorModel(fault_onset_s=np.inf, fault_bias_m=0.0, nlos_rate_per_s=0.0,
                           calib_window_s=float(u.GNSS_PERIOD_EPOCHS))
    # the aircraft sees the towers in line of sight and fits their clocks over the whole
    # pre-flight GNSS period
    assert p["nlos_rate_per_s"] == 0.0 and p["calib_window_s"] == u.GNSS_PERIOD_EPOCHS
    sop, sig_ref = sim.sop_errors(key, world, t,
                                  11, -jnp.arange(u.GNSS_PERIOD_EPOCHS, dtype=t.dtype)[::-1],
                                  operator)
    np.testing.assert_allclose(e_world[:, tw], np.asarray(sop), rtol=1e-12)
    assert sig == float(sig_ref)
    gps = np.asarray(sim.gnss_errors(key, t, jnp.asarray(geom.el_rad), 1.0,
                                     errors.GnssErrorModel()))
    v = geom.valid & geom.is_gps
    np.testing.assert_allclose(e_world[v], gps[v], rtol=1e-12)
    clean = u.synthesize(st.validate({"n_epochs": "40", "world": "clean"}), 0)[1]
    assert not np.allclose(clean[:, tw], pr[:, tw], atol=1e-3)
