"""The tower-placement study: its geometry and objective by hand, its gradient against central
differences, and its selection against exhaustive search (within 1 %)."""

import jax.numpy as jnp
import numpy as np
import pytest

from oaraim.registry import STUDIES
from oaraim.studies import tower_placement as tp
from oaraim.studies.common import seed004 as c

STUDY = STUDIES["tower-placement"]
#: the sizes of tests/test_studies.py's SMALL entry (one compiled program for both files)
SETS = {"nav": "nominal", "grid_n": "2", "sky_step_s": "21600"}


@pytest.fixture(scope="module")
def problem():
    params = STUDY.validate(SETS)
    sky = c.gps_sky_table(params["nav"], params["mask_deg"], params["sky_step_s"])
    return tp.Problem(params, sky)


def test_tower_rows_by_hand():
    """A tower 100 m east and 100 m up of the receiver: azimuth 90 deg, elevation 45 deg; one
    due north at the receiver's height: azimuth 0, elevation 0."""
    az, el = tp.tower_rows(jnp.array([[100.0, 0.0, 100.0], [0.0, 50.0, 0.0]]),
                           jnp.zeros((1, 3)))
    assert np.degrees(np.asarray(az))[0] == pytest.approx([90.0, 0.0], abs=1e-9)
    assert np.degrees(np.asarray(el))[0] == pytest.approx([45.0, 0.0], abs=1e-6)


def test_objective_and_surrogate_by_hand():
    """1..200 m: the 99.5 % order statistic is the ceil(0.995 x 200) = 199th, 199 m; an
    inf counts as HPL_CAP_M. The log-sum-exp lies between the mean and the max and tends to
    the max minus tau log n as tau -> 0."""
    h = np.arange(1.0, 201.0)
    assert tp.quantile_hpl(h) == 199.0
    assert tp.quantile_hpl(np.append(h[:-1], np.inf)) == 199.0
    assert tp.quantile_hpl(np.array([1.0, np.inf])) == tp.HPL_CAP_M
    s = float(tp.soft_max_hpl(jnp.asarray(h), 5.0))
    assert h.mean() < s < h.max()
    assert float(tp.soft_max_hpl(jnp.asarray(h), 0.01)) == pytest.approx(
        200.0 - 0.01 * np.log(200.0), abs=1e-9)


def test_no_tower_is_the_gps_only_hpl(problem):
    """Masked towers leave the GPS-only PL: the region's HPLs equal the seed 004 GPS kernel's
    (same sky, Table I) to 1e-9 m."""
    h = problem.hpls(np.zeros((1, 3, 3)), np.zeros((1, 3), bool))[0]
    sky = problem.sky
    hg, _, _, _, _ = c.mhss(c.gps_sources(sky["az_rad"], sky["el_rad"], sky["valid"]),
                            jnp.array([c.P_CONST_GPS]), 1)
    want = np.tile(np.asarray(hg), problem.receivers.shape[0])
    assert np.isfinite(want).all()
    np.testing.assert_allclose(h, want, rtol=0, atol=1e-9)


def test_surrogate_gradient_matches_central_differences(problem):
    """d surrogate / d tower east and north against central differences of 0.5 m (the
    surrogate's curvature over 0.5 m is ~1e-7 of its slope at kilometre distances): relative
    agreement 1e-5; the up coordinate has a derivative too (heights are only held fixed by
    the descent)."""
    towers = np.array([[1200.0, -300.0, 30.0], [-900.0, 800.0, 45.0], [100.0, -1500.0, 30.0]])
    v, g = problem.value_and_grad(towers)
    assert np.isfinite(g).all() and np.abs(g).max() > 0
    for t, k in ((0, 0), (1, 1), (2, 0), (2, 2)):
        up, down = towers.copy(), towers.copy()
        up[t, k] += 0.5
        down[t, k] -= 0.5
        fd = (problem.value_and_grad(up)[0] - problem.value_and_grad(down)[0]) / 1.0
        assert g[t, k] == pytest.approx(fd, rel=1e-5, abs=1e-9), (t, k)


def test_greedy_swap_within_one_percent_of_exhaustive(problem):
    """Selection of 3 of 8 sites on the exact objective, greedy + swap against every
    one of the 56 subsets."""
    rng = np.random.default_rng(7)
    sites = np.concatenate([rng.uniform(-3000, 3000, (8, 2)), np.full((8, 1), 30.0)], -1)
    chosen, q, history = tp.greedy_swap(problem, sites, 3)
    best, q_best, all_q = tp.exhaustive(problem, sites, 3, 100)
    assert len(all_q) == 56 and q_best == all_q.min()
    assert q <= 1.01 * q_best
    assert q == pytest.approx(problem.objective(sites[chosen][None])[0])
    assert all(np.diff(history) < 0)
    assert tp.exhaustive(problem, sites, 3, 55) is None


def test_descent_lowers_the_objective(problem):
    """From a poor placement (three towers bunched in a corner) ten steps lower the 99.5 %
    HPL and keep the towers in the box."""
    start = np.array([[2900.0, 2900.0, 30.0], [2800.0, 2950.0, 30.0], [2950.0, 2800.0, 30.0]])
    q0 = problem.objective(start[None])[0]
    x, q, surrogate, objective = tp.descend(problem, start, 10, 300.0, -3000.0, 3000.0)
    assert q < q0 and objective[0] == pytest.approx(q0)
    assert np.all(np.abs(x[:, :2]) <= 3000.0) and np.all(x[:, 2] == 30.0)
    assert surrogate.shape == (10,)


def test_candidates_csv(tmp_path):
    f = tmp_path / "sites.csv"
    f.write_text("east_m,north_m,up_m\n100,200,30\n-50,10,25\n")
    p = STUDY.validate({"candidates": str(f)})
    np.testing.assert_array_equal(tp.read_candidates(p["candidates"]),
                                  [[100, 200, 30], [-50, 10, 25]])
    f.write_text("1,2,3\n4,x,6\n")
    with pytest.raises(ValueError, match=r"sites.csv:2: expected east_m,north_m,up_m"):
        tp.read_candidates(str(f))
    with pytest.raises(ValueError, match="candidates must be 'auto' or an existing CSV"):
        STUDY.validate({"candidates": str(tmp_path / "none.csv")})
    with pytest.raises(ValueError, match="receivers must be 'grid' or an existing CSV"):
        STUDY.validate({"receivers": str(tmp_path / "none.csv")})
    with pytest.raises(ValueError, match="objective must be one of hpl, availability"):
        STUDY.validate({"objective": "vpl"})
        STUDY.validate({"candidates": str(tmp_path / "none.csv")})
    with pytest.raises(ValueError, match=r"n_select \(5\) must not exceed n_candidates \(4\)"):
        STUDY.validate({"n_select": "5", "n_candidates": "4"})


def test_geodetic_candidates_become_enu(tmp_path):
    """A cell-tower extract in latitude, longitude, ellipsoidal height: the origin itself maps
    to (0, 0, 0); a point 0.01 deg of latitude north and 30 m higher lies 1,109-1,110 m
    north (one hundredth of a degree of latitude at 34 deg: 1109.3 m on WGS-84) and 30 m up."""
    from oaraim import geometry

    lat_rad, lon_rad, h = geometry.ecef_to_geodetic(np.asarray(c.ORANGE_COUNTY_ECEF_M))
    lat, lon, h = float(np.degrees(lat_rad)), float(np.degrees(lon_rad)), float(h)
    f = tmp_path / "towers.csv"
    f.write_text(f"lat_deg,lon_deg,height_m\n{lat:.10f},{lon:.10f},{h:.4f}\n"
                 f"{lat + 0.01:.10f},{lon:.10f},{h + 30:.4f}\n")
    pts = tp.read_candidates(str(f))
    np.testing.assert_allclose(pts[0], 0.0, atol=1e-3)
    assert pts[1][1] == pytest.approx(1109.3, abs=1.0)
    assert abs(pts[1][0]) < 1e-3 and pts[1][2] == pytest.approx(30.0, abs=0.2)


def test_availability_objective_by_hand():
    """Unavailability counts HPLs above the HAL and the ones that cannot be computed; its
    surrogate is the mean sigmoid, 50 % at HPL = HAL."""
    h = np.array([10.0, 39.0, 41.0, np.inf])
    assert tp.unavailability_pct(h, 40.0) == 50.0
    assert float(tp.soft_unavailability_pct(jnp.array([40.0]), 40.0, 1.0)) == 50.0
    assert float(tp.soft_unavailability_pct(jnp.asarray(h), 40.0, 0.01)) == pytest.approx(50.0)
