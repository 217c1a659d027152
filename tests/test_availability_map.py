"""availability-map: the service-level criteria by hand, the grid's sky against
geometry.sky, every PL of a small map against the NumPy oracle, SOP towers (BPP and CSV), the
sweep engine's index kernels and Values reducer, and the command line."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from oaraim import geometry
from oaraim.araim import availability as av
from oaraim.cli import app
from oaraim.errors import (
    AIRBORNE_MODELS,
    gnss_variances,
    sigma_user_airborne_m,
    sigma_user_ed259a_m,
    sop_variances,
)
from oaraim.execute import RunOptions, run_study
from oaraim.geometry.sky import line_of_sight, look_angles
from oaraim.readers import GALILEO
from oaraim.reference_mhss import ReferenceOptions, protection_levels_reference
from oaraim.registry import STUDIES
from oaraim.studies import availability_map as am
from oaraim.studies.availability_map import slots

STUDY = STUDIES["availability-map"]
#: two latitude rows x three longitudes x 4 epochs (3 h at 2700 s)
SMALL = {"lat_deg": "-35,50", "lon_deg": "-120,0,140", "duration_s": "10800",
         "step_s": "2700"}


# ------------------------------------------------------------------ criteria, by hand


def test_available_needs_every_criterion_and_a_computed_pl():
    req = av.Requirements(val_m=35.0, hal_m=40.0, emt_m=15.0, sigma_acc_v_m=1.87)
    hpl = np.array([10.0, 41.0, 10.0, 10.0, 10.0, np.inf, 40.0])
    vpl = np.array([20.0, 20.0, 35.5, 20.0, 20.0, np.inf, 35.0])
    emt = np.array([5.0, 5.0, 5.0, 15.5, 5.0, np.inf, 15.0])
    acc = np.array([1.0, 1.0, 1.0, 1.0, 1.9, np.inf, 1.87])
    status = np.array([0, 0, 0, 0, 0, 3, 0])
    got = np.asarray(av.available(hpl, vpl, emt, acc, status, req))
    assert got.tolist() == [True, False, False, False, False, False, True]  # limits inclusive
    h_only = av.Requirements(np.inf, 40.0, np.inf, np.inf)
    assert np.asarray(av.available(hpl, vpl, emt, acc, status, h_only)).tolist() == \
        [True, False, True, True, True, False, True]


def test_pl_percentile_is_nearest_rank_and_inf_past_the_unavailable_share():
    x = np.arange(1.0, 201.0)  # 200 epochs: 99.5 % -> rank ceil(199) = 199 -> value 199
    assert av.pl_percentile(x, 99.5) == 199.0
    x[-1] = np.inf  # one epoch of 200 unavailable (0.5 %): still finite
    assert av.pl_percentile(x, 99.5) == 199.0
    x[-2] = np.inf  # two (1 %): the 99.5 % PL is infinite
    assert av.pl_percentile(x, 99.5) == np.inf
    assert av.pl_percentile(np.array([[3.0, 1.0, 2.0]]), 50.0)[0] == 2.0


def test_coverage_weights_points_by_cos_latitude():
    # cos 0 = 1, cos 60 = 0.5, cos 90 = 0: covered points (0, a) and (60, b)
    a = np.array([[1.0, 0.99], [0.996, 0.5], [0.0, 0.0]])
    got = av.coverage(a, [0.0, 60.0, 90.0], target=0.995)
    assert got == pytest.approx((1.0 + 0.5) / (2 * 1.0 + 2 * 0.5), abs=1e-15)
    with pytest.raises(ValueError, match="away from the poles"):
        av.coverage([[1.0]], [90.0])


def test_presets_are_maast_and_add_values():
    """MAAST for ARAIM (main_maast_araim.m): vhal = [35, 40, 15, 1.87], percent = 0.995,
    PHMI_VERT 9.8e-8, PHMI_HOR 2e-9, PFA_VERT 3.9e-6, PFA_HOR 0.9e-6, P_THRES 6e-8, P_EMT 1e-5;
    the ADD table: PFA_HOR 9e-8, P_THRES 8e-8; H-ARAIM: HAL 185 m (RNP 0.1) at 99.9 %."""
    def six(b):
        return (b.phmi_v, b.phmi_h, b.p_fa_v, b.p_fa_h, b.p_thresh, b.p_emt)

    lpv = av.SERVICE_LEVELS["lpv200"]
    assert lpv.requirements == (35.0, 40.0, 15.0, 1.87) and lpv.target == 0.995
    assert six(lpv.budget) == (9.8e-8, 2e-9, 3.9e-6, 9e-7, 6e-8, 1e-5)
    assert six(av.SERVICE_LEVELS["lpv200-add"].budget) == (9.8e-8, 2e-9, 3.9e-6, 9e-8, 8e-8,
                                                           1e-5)
    h = av.SERVICE_LEVELS["h-araim"]
    assert h.requirements.hal_m == 185.0 and np.isinf(h.requirements.val_m) and h.target == 0.999


def test_defaults_are_maast_conventions():
    """main_maast_araim.m (2018): 5 deg mask, URA 1 m, URE 2/3 URA, b_nom 0.75 m, P_sat 1e-5,
    P_const 1e-8 GPS / 1e-4 Galileo, 24 h at 300 s; usrworld.dat: 10 deg, lat -90..80."""
    p = STUDY.validate({})
    assert (p["mask_deg"], p["sigma_ura_gps_m"], p["sigma_ura_gal_m"], p["b_nom_gps_m"],
            p["b_nom_gal_m"], p["p_sat_gps"], p["p_sat_gal"], p["p_const_gps"],
            p["p_const_gal"]) == (5.0, 1.0, 1.0, 0.75, 0.75, 1e-5, 1e-5, 1e-8, 1e-4)
    assert len(p["lat_deg"]) * len(p["lon_deg"]) == 648 and max(p["lat_deg"]) == 80.0
    assert STUDY.fixed_realizations(p) == 36 * 288


def test_grid_parser():
    parse = am.parse_grid(-90.0, 90.0)
    assert parse("lat", "-90:90:10") == tuple(float(x) for x in range(-90, 91, 10))
    assert parse("lat", "10,-5") == (-5.0, 10.0)
    assert len(am.parse_grid(-180, 360)("lon", "-180:179:1")) == 360
    for bad, msg in (("0:10", "START:STOP:STEP"), ("10:0:1", "START:STOP:STEP"),
                     ("-91:0:1", r"\[-90.0, 90.0\]"), ("1,1", "twice")):
        with pytest.raises(ValueError, match=msg):
            parse("lat_deg", bad)


# ------------------------------------------------------------------ the map against oracles


@pytest.fixture(scope="module")
def small(shared_data):
    p = STUDY.validate(SMALL)
    return p, STUDY.run(p, STUDY.fixed_realizations(p), 0)


def test_grid_sky_matches_geometry_sky(small, shared_data):
    """Satellites in view at every (lat, lon, epoch) of the cube equal geometry.sky's count
    for the same receiver, every almanac at the same time of its GPS week (MAAST: epoch 0 at
    the week's start, ``sky_time="week"``)."""
    p, res = small
    ds = res.dataset
    t_off = ds["time_s"].values
    counts = 0
    for name, file, system in (("gps", am.GPS_ALMANAC, "G"), ("galileo", am.GALILEO_ALMANAC,
                                                               "E")):
        alm = geometry.read_yuma(shared_data / file, system=system)
        week_start = alm.records.toa_s - alm.records.toa_tow_s
        assert np.all(week_start == week_start[0]) and 0 <= alm.records.toa_tow_s[0] < 604800
        t0 = float(week_start[0])
        lat, lon = np.meshgrid(np.deg2rad(ds["lat_deg"].values),
                               np.deg2rad(ds["lon_deg"].values), indexing="ij")
        rx = np.asarray(geometry.geodetic_to_ecef(lat, lon, 0.0))
        s = geometry.sky(rx, t0 + t_off, source=alm, mask_deg=p["mask_deg"],
                         constellations=(name,))
        counts = counts + np.asarray(s.valid).sum(-1)
    np.testing.assert_array_equal(ds["n_gnss"].values, counts)
    assert ds["n_gnss"].values.min() >= 8  # GPS 24 + Galileo 24 at a 5 deg mask


def test_max_visible_counts_what_look_angles_counts(shared_data, monkeypatch):
    """The kernel's GNSS slots: ``max_visible`` (upper bounds of every row first, then bounds
    without an arctangent, exact count where they disagree) equals the largest count of
    ``look_angles``' valid flags over a grid, also when a wide margin (0.05 rad) sends most
    rows to the exact count; the bounds bracket that count and the one-pass upper bound is
    the bounds' upper one."""
    p = STUDY.validate({"lat_deg": "-90:90:15", "lon_deg": "-180:170:20"})
    ecef, ok, *_ = am.constellation_orbits(p["gps"], p["galileo"], p["duration_s"],
                                           p["step_s"], p["sky_time"])
    mask = np.deg2rad(p["mask_deg"])
    want, differ = 0, 0
    for la in p["lat_deg"]:
        rx = geometry.geodetic_to_ecef(np.deg2rad(la), np.deg2rad(np.asarray(p["lon_deg"])), 0.0)
        count = int(np.asarray(look_angles(rx, ecef, ok, mask)[3]).sum(-1).max())
        want = max(want, count)
        sure, maybe = slots._in_view_bounds(np.deg2rad(la), np.deg2rad(np.asarray(p["lon_deg"])),
                                         0.0, ecef, ok, np.tan(mask - 0.05), np.tan(mask + 0.05))
        assert int(sure) <= count <= int(maybe)
        assert int(slots._most_maybe_in_view(np.deg2rad(la), np.deg2rad(np.asarray(
            p["lon_deg"])), 0.0, ecef, ok, np.tan(mask - 0.05))) == int(maybe)
        differ += int(sure) != int(maybe)
    assert differ > 0  # the wide margin sends rows to the exact count
    args = (am.OrbitWindow(p["gps"], p["galileo"], p["duration_s"], p["step_s"], p["sky_time"]),
            p["mask_deg"], p["lat_deg"], p["lon_deg"], p["height_m"])
    am.max_visible.cache_clear()
    assert am.max_visible(*args) == want
    monkeypatch.setattr(slots, "_MASK_MARGIN_RAD", 0.05)
    am.max_visible.cache_clear()
    assert am.max_visible(*args) == want
    am.max_visible.cache_clear()


def test_in_view_flags_are_look_angles_flags(shared_data, monkeypatch):
    """The kernel's in-view flags without an arctangent (``in_view``) equal ``look_angles``'
    on a 15 deg grid over a day, both through the squared comparisons and, with a margin of
    0.05 rad that every batch has satellites within, through the exact branch."""
    p = STUDY.validate({"lat_deg": "-90:90:15", "lon_deg": "-180:170:20"})
    ecef, ok, *_ = am.constellation_orbits(p["gps"], p["galileo"], p["duration_s"],
                                           p["step_s"], p["sky_time"])
    mask = np.deg2rad(p["mask_deg"])
    lats, lons = np.meshgrid(np.deg2rad(p["lat_deg"]), np.deg2rad(p["lon_deg"]))
    rx = geometry.geodetic_to_ecef(lats.ravel(), lons.ravel(), 0.0)
    want = np.asarray(look_angles(rx, ecef, ok, mask)[3])
    e, n, u = line_of_sight(rx, ecef)
    usable = np.broadcast_to(np.asarray(ok), want.shape)
    assert 0 < want.mean() < 1
    for margin in (slots._MASK_MARGIN_RAD, 0.05):
        monkeypatch.setattr(slots, "_MASK_MARGIN_RAD", margin)
        np.testing.assert_array_equal(np.asarray(am.in_view(e, n, u, usable, mask)), want)


def test_map_kernel_bits_do_not_depend_on_the_call_size(shared_data):
    """The map kernel runs in chunks of 128 realizations (front end included), so one call of
    2,048 realizations gives the bits of two calls of 1,024 (a sweep's batch size may grow
    without moving a result)."""
    import jax

    p = STUDY.validate({"lat_deg": "40", "lon_deg": "-180:170:10"})
    row = am.MapRow(p, 40.0)
    key = jax.random.key(0)
    whole = row(np.arange(2048), key)
    halves = [row(np.arange(s, s + 1024), key) for s in (0, 1024)]
    for name, v in whole.items():
        np.testing.assert_array_equal(
            np.asarray(v), np.concatenate([np.asarray(h[name]) for h in halves]), err_msg=name)


@pytest.mark.parametrize(("n_sat", "n_slots"), [(48, 23), (7, 3), (5, 5), (1, 1)])
def test_slots_are_the_stable_argsort_of_visibility(n_sat, n_slots):
    """The kernel's slot order without a sort (``in_view_first``) is NumPy's stable argsort of
    ~visible: in-view satellites first, each kind in index order; none, some and all in
    view."""
    rng = np.random.default_rng(1)
    for share in (0.0, 0.3, 0.7, 1.0):
        vis = rng.random((500, n_sat)) < share
        want = np.argsort(~vis, axis=-1, kind="stable")[:, :n_slots]
        np.testing.assert_array_equal(np.asarray(am.in_view_first(vis, n_slots)), want)


def test_every_pl_matches_the_numpy_oracle(small):
    """Each cube entry's HPL, VPL, EMT and sigma_acc against oaraim.reference_mhss on the same
    satellites (look angles from geometry.sky.look_angles, inputs built here from the MAAST
    defaults), to 1e-5 m."""
    p, res = small
    ds = res.dataset
    lay = am.layout(p)
    ecef, ok, cons, _, t_off, _ = am.constellation_orbits(p["gps"], p["galileo"],
                                                          p["duration_s"], p["step_s"],
                                                          p["sky_time"])
    worst = 0.0
    adjusted = 0
    for i, la in enumerate(ds["lat_deg"].values):
        for j, lo in enumerate(ds["lon_deg"].values):
            rx = np.asarray(geometry.geodetic_to_ecef(np.deg2rad(la), np.deg2rad(lo), 0.0))
            az, el, _, valid = (np.asarray(x) for x in look_angles(
                rx, ecef, ok, np.deg2rad(p["mask_deg"])))
            for k in range(t_off.size):
                v = valid[k]
                gal = cons[v] == GALILEO
                e = el[k][v]
                user = AIRBORNE_MODELS[p["airborne_model"]]
                vi_g, va_g = (np.asarray(x) for x in gnss_variances(e, p["sigma_ura_gps_m"],
                                                                    user_model=user))
                vi_e, va_e = (np.asarray(x) for x in gnss_variances(e, p["sigma_ura_gal_m"],
                                                                    user_model=user))
                sources = (np.asarray(geometry.geometry_rows(az[k][v], e)), cons[v],
                           np.where(gal, vi_e, vi_g), np.where(gal, va_e, va_g),
                           np.where(gal, p["b_nom_gal_m"], p["b_nom_gps_m"]),
                           np.where(gal, p["p_sat_gal"], p["p_sat_gps"]), None)
                ref = protection_levels_reference(
                    sources, lay["p_const"], lay["level"].budget, ReferenceOptions(
                        max_order=lay["max_order"], fault_modes=p["fault_modes"],
                        position_optimization=lay["position_optimization"]))
                got = [ds[n].values[i, j, k] for n in ("hpl_m", "vpl_m", "emt_m",
                                                       "sigma_acc_m")]
                want = [ref.hpl_m, ref.vpl_m, ref.emt_m, ref.sigma_acc_u_m]
                assert ds["status"].values[i, j, k] == ref.status
                assert bool(ds["position_adjusted"].values[i, j, k]) == ref.position_adjusted
                adjusted += ref.position_adjusted
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)
                worst = max(worst, float(np.max(np.abs(np.subtract(got, want)))))
                a = av.available(*got, ref.status, lay["requirements"])
                assert bool(ds["available"].values[i, j, k]) == bool(a)
    assert worst < 1e-5


def test_position_opt_replaces_the_baseline_only_where_it_helps(small):
    """``position_opt=maast`` against ``none`` with a VAL of 18 m (MAAST's trigger follows the
    limits, so most epochs try the estimator): where adjusted, the VPL or the HPL is lower
    and sigma_acc has moved up to its 1.86 m limit; elsewhere the cube is the baseline's, and
    the default map's cube agrees with ``none`` wherever it was not adjusted."""
    p, res = small
    over = dict(SMALL, val_m="18")
    runs = [STUDY.validate(over), STUDY.validate(dict(over, position_opt="none"))]
    opt, base = (STUDY.run(q, STUDY.fixed_realizations(q), 0).dataset for q in runs)
    adj = opt["position_adjusted"].values
    assert 0 < adj.sum() < adj.size, adj.sum()
    assert not base["position_adjusted"].values.any()
    lower = ((opt["vpl_m"].values < base["vpl_m"].values)
             | (opt["hpl_m"].values < base["hpl_m"].values))
    np.testing.assert_array_equal(lower[adj], True)
    assert np.all(opt["sigma_acc_m"].values[adj] <= 1.86)
    assert np.all(opt["sigma_acc_m"].values[adj] > base["sigma_acc_m"].values[adj])
    for k in ("vpl_m", "hpl_m", "emt_m", "sigma_acc_m"):
        np.testing.assert_array_equal(opt[k].values[~adj], base[k].values[~adj])
    d = res.dataset
    keep = ~d["position_adjusted"].values
    np.testing.assert_array_equal(d["vpl_m"].values[keep], base["vpl_m"].values[keep])
    assert res.metrics["position_opt"] == "maast"


def test_maps_and_summary_follow_from_the_cube(small):
    p, res = small
    ds = res.dataset
    avail = ds["available"].values.mean(-1)
    np.testing.assert_array_equal(ds["availability"].values, avail)
    np.testing.assert_array_equal(ds["vpl_995_m"].values, av.pl_percentile(ds["vpl_m"].values))
    want = 100 * av.coverage(avail, ds["lat_deg"].values, 0.995)
    assert res.metrics["coverage_pct"] == want
    assert res.rows[0]["reproduced"] == want


# ------------------------------------------------------------------ SOPs


def test_bpp_towers_are_fixed_per_user_and_counted(shared_data):
    # the tower mechanics do not depend on the fault-mode convention; grouped keeps the
    # compiled template small (the ADD rules monitor every pair of the 6 towers' events here)
    p = STUDY.validate({**SMALL, "lat_deg": "50", "sops_per_km2": "0.5",
                        "d_max_m": "2000", "max_sops": "8", "fault_modes": "grouped"})
    n = am.bpp_count(p)
    assert n == min(round(0.5 * np.pi * (2000.0**2 - 5.0**2) / 1e6), 8) == 6
    lay = am.layout(p)
    assert lay["n_sops"] == 6 and lay["p_const"].tolist() == [1e-8, 1e-4, 1e-4]
    res = STUDY.run(p, STUDY.fixed_realizations(p), 0)
    assert np.all(res.dataset["n_sops"].values == 6)
    base = STUDY.run(STUDY.validate({**SMALL, "lat_deg": "50"}), 12, 0).dataset
    # six extra ranging sources never leave a user worse off in view and, as SOP, add one
    # clock column: the VPL of a geometry that was available stays finite
    ok = np.isfinite(base["vpl_m"].values)
    assert np.all(np.isfinite(res.dataset["vpl_m"].values[ok]))


def test_tower_csv_gives_one_constellation_per_carrier(tmp_path, shared_data):
    """Three towers within 3 km of (50 N, 0 E) from two carriers, one far away: that user has
    three SOPs in two SOP constellations (labels 2, 3), the others none."""
    f = tmp_path / "towers.csv"
    f.write_text("lat_deg,lon_deg,height_m,carrier\n50.01,0.0,40,A\n50.0,0.02,30,B\n"
                 "49.99,-0.01,25,A\n10,10,30,A\n")
    p = STUDY.validate({**SMALL, "lat_deg": "50", "towers": str(f), "max_sops": "4",
                        "fault_modes": "grouped"})  # (as above)
    az, el, valid, label, n_car = am.tower_slots(str(f), 50.0, p["lon_deg"], p["d_min_m"],
                                                 p["d_max_m"], 4, 0.0)
    assert n_car == 2 and valid.sum(-1).tolist() == [0, 3, 0]
    assert sorted(label[1, :3].tolist()) == [2, 2, 3]
    assert am.layout(p)["p_const"].size == 4
    res = STUDY.run(p, STUDY.fixed_realizations(p), 0)
    assert res.dataset["n_sops"].values[0].max(-1).tolist() == [0, 3, 0]
    bad = tmp_path / "bad.csv"
    bad.write_text("lat,lon\n1,2\n")
    with pytest.raises(ValueError, match="lat_deg, lon_deg, height_m, carrier"):
        STUDY.validate({"towers": str(bad)})


GOOD_TOWERS = "lat_deg,lon_deg,height_m,carrier\n50.01,0.0,40,A\n50.0,0.02,30,B\n"


@pytest.mark.parametrize("content, message", [
    (GOOD_TOWERS + "49.99,-0.01\n", r"line 4: 2 fields where the header has 4"),
    (GOOD_TOWERS + "50.01,0.0,40,A\n", r"line 4: the tower of line 2 again"),
    (b"\x89PNG\r\n\x1a\n\x00\xff\xfe", r"towers\.csv, line 1: not UTF-8 text"),
    (GOOD_TOWERS + "nan,0,10,A\n", r"line 4: lat_deg in \[-90, 90\]"),
    ("", r"an empty file"),
    (GOOD_TOWERS[:-3], r"line 3: the last line does not end with a line break"),
    (GOOD_TOWERS + '50.0,0.03,30,"B\n', r"line 4: not CSV"),
    (GOOD_TOWERS + "50.0,0.03,30,B\x00\n", r"line 4: control character")])
def test_tower_csv_errors_name_file_and_line(tmp_path, content, message):
    """A short row gave a traceback, a binary file an error without its name, six
    identical rows six independent SOPs, a file cut short lost its last tower, a NUL byte gave
    a csv.Error. Each is now one TowerFileError (a ValueError) naming the file and the line."""
    f = tmp_path / "towers.csv"
    (f.write_bytes if isinstance(content, bytes) else f.write_text)(content)
    with pytest.raises(am.TowerFileError, match=message) as e:
        am.read_towers(f)
    assert "towers.csv" in str(e.value)


def test_tower_csv_with_a_byte_order_mark_and_shared_masts(tmp_path):
    """Excel's "CSV UTF-8" starts with a BOM (was: 'missing column lat_deg'); two carriers on
    one mast are two rows, both kept."""
    f = tmp_path / "towers.csv"
    f.write_bytes(b"\xef\xbb\xbf" + (GOOD_TOWERS + "50.01,0.0,40,B\n").encode())
    lat, lon, h, car, names = am.read_towers(f)
    assert lat.size == 3 and names == ["A", "B"] and car.tolist() == [0, 1, 1]


@pytest.mark.parametrize("extra, message", [
    ("50.010000001,0.0,40,A\n", r"line 4: the tower of line 2 again \(0\.000111 m from it\): "
                               r"two rows of carrier 'A' closer than 1 m"),
    ("50.01,0.0,40.5,A\n", r"line 4: the tower of line 2 again \(0\.5 m from it\)"),
    ("50.01,360.0,40,A\n", r"line 4: the tower of line 2 again: two rows of carrier 'A'"),
])
def test_near_duplicate_towers_are_refused(tmp_path, extra, message):
    """Two rows of one carrier 1e-9 deg apart (0.1 mm) passed the exact duplicate check and
    counted as two independent ranges. Rows of one carrier closer than 1 m
    (``readers.MIN_SEPARATION_M``) are one transmitter given twice; 1.5 m apart,
    or the same mast for another carrier, are two."""
    f = tmp_path / "towers.csv"
    f.write_text(GOOD_TOWERS + extra)
    with pytest.raises(am.TowerFileError, match=r"towers\.csv, " + message):
        am.read_towers(f)
    f.write_text(GOOD_TOWERS + "50.01,0.0,41.5,A\n" + extra.replace(",A", ",C"))
    assert am.read_towers(f)[0].size == 4


def test_sop_inputs_are_the_seed004_model():
    vi, va = (np.asarray(x) for x in sop_variances(np.array([2.0])))
    assert vi[0] == va[0] == 4.0  # sigma_URE^S = sigma_URA^S, no user term (DESIGN.md)


# ------------------------------------------------------------------ engine and CLI


def test_resume_and_chunking_give_the_same_cube(tmp_path, shared_data):
    sets = [f"{k}={v}" for k, v in SMALL.items()]
    _, a, _, _ = run_study(STUDY.name, out=tmp_path / "a", sets=sets + ["chunk=1024"],
                           show_progress=False)
    _, b, _, _ = run_study(STUDY.name, out=tmp_path / "b", sets=sets + ["chunk=4096"],
                           show_progress=False)
    import xarray as xr

    da, db = (xr.open_zarr(d / "data.zarr", consolidated=False) for d in (a, b))
    xr.testing.assert_identical(da.load(), db.load())
    prov = json.loads((b / "provenance.json").read_text())
    assert prov["realizations"] == 12 and set(prov["data_files"]) == {am.GPS_ALMANAC,
                                                                       am.GALILEO_ALMANAC}
    _, c, _, _ = run_study(STUDY.name, out=tmp_path / "a", sets=sets + ["chunk=1024"],
                           show_progress=False, options=RunOptions(resume=True))
    assert json.loads((c / "provenance.json").read_text())["sweep"]["chunks_computed"] == 0


def test_cli_runs_and_rejects_realizations(tmp_path, shared_data):
    r = CliRunner().invoke(app, ["run", STUDY.name, "--out", str(tmp_path), "--no-progress",
                                 *sum((["--set", f"{k}={v}"] for k, v in SMALL.items()), [])])
    assert r.exit_code == 0, r.output
    assert (tmp_path / STUDY.name / "availability_maps.png").is_file()
    r = CliRunner().invoke(app, ["run", STUDY.name, "--realizations", "5", "--no-progress"])
    assert r.exit_code == 2 and "drop --realizations" in r.output
    r = CliRunner().invoke(app, ["run", STUDY.name, "--set", "lat_deg=0:10", "--no-progress"])
    assert r.exit_code == 2 and "START:STOP:STEP" in r.output


def test_broadcast_file_sky_runs_from_its_day(shared_data):
    """A RINEX navigation file as the GPS sky (Galileo off): epochs from 00:00 of the file's
    day, 30-32 healthy GPS satellites give 6-12 in view at 5 deg at mid-latitudes."""
    nav = shared_data / "nav" / "brdc1820.10n"
    p = STUDY.validate({"lat_deg": "40", "lon_deg": "-4", "duration_s": "86400",
                        "step_s": "3600", "gps": str(nav), "galileo": "none"})
    *_, t_off, desc = am.constellation_orbits(p["gps"], p["galileo"], p["duration_s"],
                                              p["step_s"])
    assert t_off.size == 24 and "brdc1820.10n" in desc
    res = STUDY.run(p, STUDY.fixed_realizations(p), 0)
    n = res.dataset["n_gnss"].values
    assert 5 <= n.min() and n.max() <= 13
    assert np.all(res.dataset["n_sops"].values == 0) and res.metrics["gnss_slots"] == n.max()


def test_coastlines_from_geojson_are_read_and_drawn(tmp_path, small):
    """A GeoJSON of a LineString and a Polygon gives two lon/lat polylines; the maps draw
    them; a file without line geometry is refused naming the parameter."""
    f = tmp_path / "coast.geojson"
    f.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "LineString",
                                         "coordinates": [[-10, 40], [0, 45], [10, 50]]}},
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [
            [[100, -10], [120, -10], [120, 10], [100, -10]]]}},
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [0, 0]}}]}))
    lines = am.read_lines(f)
    assert [ln.shape for ln in lines] == [(3, 2), (4, 2)]
    assert lines[0][1].tolist() == [0.0, 45.0]
    p = STUDY.validate({**SMALL, "coastlines": str(f)})
    assert p["coastlines"] == str(f.resolve())
    bad = tmp_path / "points.geojson"
    bad.write_text(json.dumps({"type": "Point", "coordinates": [0, 0]}))
    with pytest.raises(ValueError, match="coastlines must be 'none' or a GeoJSON"):
        STUDY.validate({"coastlines": str(bad)})
    _, res = small
    out = tmp_path / "plot"
    out.mkdir()
    res.dataset.assign_attrs(coastlines=str(f)).to_zarr(out / "data.zarr",
                                                         consolidated=False)
    assert STUDY.plot(out) == [f"{out}/availability_maps.png"]


def test_ed259a_airborne_model_hand_values_and_map():
    """ED-259A (MAAST 2024): at the zenith sqrt(0.4^2 + (0.34 + 0.40 exp(-90 / 14))^2 +
    (40 / 8361 + 0.018)^2) =
    0.52589 m (by hand), at 5 deg half the ADD curve's 1.49 m; a map run selects it (its
    sigma_acc differs from the ADD curve's; the oracle comparison above covers the path)."""
    zen = float(sigma_user_ed259a_m(np.pi / 2))
    assert zen == pytest.approx(np.sqrt(0.16 + (0.34 + 0.4 * np.exp(-90 / 14)) ** 2
                                        + (40 / 8361 + 0.018) ** 2), rel=1e-12)
    assert zen == pytest.approx(0.52589, abs=1e-5)
    assert float(sigma_user_ed259a_m(np.deg2rad(5.0))) < 0.51 * float(
        sigma_user_airborne_m(np.deg2rad(5.0)))
    p = STUDY.validate({**SMALL, "lat_deg": "40", "lon_deg": "0"})
    assert p["airborne_model"] == "ed259a"  # the default: MAAST for ARAIM 2's model
    q = STUDY.validate({**SMALL, "lat_deg": "40", "lon_deg": "0", "airborne_model": "add"})
    a = STUDY.run(p, STUDY.fixed_realizations(p), 0).dataset["sigma_acc_m"].values
    b = STUDY.run(q, STUDY.fixed_realizations(q), 0).dataset["sigma_acc_m"].values
    assert np.all(np.isfinite(a)) and not np.allclose(a, b)
