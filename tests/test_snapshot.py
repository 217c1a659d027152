"""Snapshot replay (araim.snapshot) and the atmospheric models (errors.atmosphere), on
synthetic data: no shared files needed."""

import math

import numpy as np
import pytest

from oaraim import araim, geometry
from oaraim.araim import snapshot
from oaraim.constants import C_M_S
from oaraim.errors import atmosphere

# --------------------------------------------------------------------------- Klobuchar

ALPHA_0759 = np.array([1.1180e-08, 1.4900e-08, -5.9600e-08, -5.9600e-08])  # 07590920.05n
BETA_0759 = np.array([8.8060e04, 1.6380e04, -1.9660e05, -1.3110e05])


def klobuchar_by_hand(t_s, lat_deg, lon_deg, az_deg, el_deg, alpha, beta):
    """IS-GPS-200 20.3.3.5.2.5, written out step by step on Python floats (the test oracle)."""
    e = el_deg / 180.0  # semicircles
    a = math.radians(az_deg)
    psi = 0.0137 / (e + 0.11) - 0.022
    phi_i = lat_deg / 180.0 + psi * math.cos(a)
    phi_i = min(max(phi_i, -0.416), 0.416)
    lam_i = lon_deg / 180.0 + psi * math.sin(a) / math.cos(phi_i * math.pi)
    phi_m = phi_i + 0.064 * math.cos((lam_i - 1.617) * math.pi)
    t = (4.32e4 * lam_i + t_s) % 86400.0
    f = 1.0 + 16.0 * (0.53 - e) ** 3
    amp = max(sum(alpha[n] * phi_m**n for n in range(4)), 0.0)
    per = max(sum(beta[n] * phi_m**n for n in range(4)), 72000.0)
    x = 2.0 * math.pi * (t - 50400.0) / per
    if abs(x) < 1.57:
        return C_M_S * f * (5e-9 + amp * (1 - x**2 / 2 + x**4 / 24))
    return C_M_S * f * 5e-9


def test_klobuchar_hand_worked_zenith_at_14h():
    """A case small enough to do with a pencil: user at (0, 0), satellite at the zenith
    (E = 0.5 semicircle), alpha = (2e-8, 0, 0, 0) s, beta = (86400, 0, 0, 0) s, GPS time of day
    50,400 s (14:00). Then psi = 0.0137 / 0.61 - 0.022 = 4.590e-4 semicircle, the pierce point
    is at the user's longitude (A = 0), so its local time is 14:00, x = 0, F = 1 + 16 * 0.03^3
    = 1.000432, and T_iono = F (5 ns + 20 ns) = 25.0108 ns -> 7.4980 m."""
    alpha = np.array([2e-8, 0.0, 0.0, 0.0])
    beta = np.array([86400.0, 0.0, 0.0, 0.0])
    t = 1000 * 86400.0 + 50400.0
    d = float(atmosphere.klobuchar_delay_m(t, 0.0, 0.0, 0.0, np.pi / 2, alpha, beta))
    assert d == pytest.approx(C_M_S * 1.000432 * 25e-9, rel=1e-12)
    assert d == pytest.approx(7.4980, abs=1e-4)
    # a quarter of the way to the cosine's edge, x = pi / 4: the fourth-order cosine
    x = np.pi / 4
    d2 = float(atmosphere.klobuchar_delay_m(t + 86400.0 / 8, 0.0, 0.0, 0.0, np.pi / 2, alpha,
                                            beta))
    assert d2 == pytest.approx(C_M_S * 1.000432 * (5e-9 + 2e-8 * (1 - x**2 / 2 + x**4 / 24)),
                               rel=1e-12)


def test_klobuchar_night_floor_and_clamps():
    """At night (|x| >= 1.57) only the 5 ns floor times F remains; a negative amplitude
    polynomial is clamped to 0 and a period below 72,000 s to 72,000 s (IS-GPS-200)."""
    el = np.deg2rad([90.0, 30.0, 10.0, 5.0])
    f = 1.0 + 16.0 * (0.53 - el / np.pi) ** 3
    night = atmosphere.klobuchar_delay_m(1000 * 86400.0 + 2 * 3600.0, 0.0, 0.0, 0.0, el,
                                         ALPHA_0759, BETA_0759)
    np.testing.assert_allclose(night, C_M_S * f * 5e-9, rtol=1e-12)
    neg = atmosphere.klobuchar_delay_m(1000 * 86400.0 + 50400.0, 0.0, 0.0, 0.0, np.pi / 2,
                                       -np.abs(ALPHA_0759), BETA_0759)
    assert float(neg) == pytest.approx(C_M_S * 1.000432 * 5e-9, rel=1e-12)


@pytest.mark.parametrize("case", [
    # (t of day s, lat, lon, az, el) with the 07590920.05n coefficients (Japan, 2005-04-02)
    (36000.0, 35.2, 139.8, 45.0, 30.0),
    (21000.0, 35.2, 139.8, 200.0, 12.0),
    (3600.0, -33.9, 151.2, 300.0, 60.0),
    (50400.0, 60.0, -20.0, 10.0, 5.0),  # pierce-point latitude clamp
    (80000.0, 5.0, -75.0, 120.0, 80.0),
])
def test_klobuchar_matches_scalar_oracle(case):
    t, lat, lon, az, el = case
    want = klobuchar_by_hand(t, lat, lon, az, el, ALPHA_0759, BETA_0759)
    got = float(atmosphere.klobuchar_delay_m(
        5000 * 86400.0 + t, np.deg2rad(lat), np.deg2rad(lon), np.deg2rad(az), np.deg2rad(el),
        ALPHA_0759, BETA_0759))
    assert got == pytest.approx(want, rel=1e-9)  # t mod 86400 of ~4e8 s: 1e-12 s rounding
    assert 1.4 < got < 60.0  # L1 slant delays: metres to tens of metres


def test_klobuchar_batched_shapes():
    el = np.deg2rad(np.linspace(5, 90, 12)).reshape(3, 4)
    d = atmosphere.klobuchar_delay_m(np.full((3, 1), 8e8), 0.6, 2.4, 1.0, el, ALPHA_0759,
                                     BETA_0759)
    assert d.shape == (3, 4) and np.all(np.isfinite(d))
    # lower elevation -> larger obliquity -> larger delay, at the same pierce geometry class
    assert np.all(np.diff(np.asarray(d).ravel()) < 0)


def test_sigma_iono_do229():
    """DO-229 J.2.3: max(delay / 5, F_pp tau_vert); tau_vert 4.5 m at mid geomagnetic latitude,
    F_pp = 1 at the zenith and ~3 at the horizon."""
    assert float(atmosphere.iono_obliquity(np.pi / 2)) == pytest.approx(1.0)
    assert 2.5 < float(atmosphere.iono_obliquity(0.0)) < 3.5
    assert float(atmosphere.sigma_iono_klobuchar_m(5.0, np.pi / 2, np.deg2rad(35.0))) == 4.5
    assert float(atmosphere.sigma_iono_klobuchar_m(5.0, np.pi / 2, np.deg2rad(10.0))) == 9.0
    assert float(atmosphere.sigma_iono_klobuchar_m(60.0, np.pi / 2, np.deg2rad(35.0))) == 12.0


# --------------------------------------------------------------------------- troposphere


def test_tropo_zenith_sea_level_standard_value():
    """The zenith delay at sea level is ~2.3 m hydrostatic + 0.05-0.3 m wet: 2.3-2.6 m at any
    latitude and season of the MOPS table; the hydrostatic part equals Saastamoinen's for the
    same pressure (both are k1 Rd / g_m P = 2.2768 mm/hPa) to a few mm."""
    for lat in (0.0, 20.0, 35.0, 45.0, 70.0, -40.0):
        for doy in (1.0, 100.0, 200.0, 300.0):
            z = float(atmosphere.tropo_delay_m(np.deg2rad(lat), 0.0, doy, np.pi / 2))
            assert 2.3 <= z <= 2.65, (lat, doy, z)
    d_hyd, d_wet = atmosphere.mops_zenith_delays_m(np.deg2rad(45.0), 0.0, 28.0)
    # 45 deg N, day 28: P = 1015.75 + 2.25 = 1018.0 hPa (DO-229 Table A-2, winter extreme)
    assert float(d_hyd) == pytest.approx(
        float(atmosphere.saastamoinen_zhd_m(1018.0, np.deg2rad(45.0), 0.0)), abs=0.012)
    assert float(d_hyd) == pytest.approx(2.3178, abs=1e-3)
    assert 0.03 < float(d_wet) < 0.3


def test_tropo_height_and_mapping():
    h1 = float(atmosphere.mops_zenith_delays_m(np.deg2rad(45.0), 1000.0, 100.0)[0])
    h0 = float(atmosphere.mops_zenith_delays_m(np.deg2rad(45.0), 0.0, 100.0)[0])
    # hydrostatic delay scales with pressure: 1 km up, the standard atmosphere keeps 88.7 %
    ratio = float(atmosphere.standard_pressure_hpa(1000.0) / atmosphere.standard_pressure_hpa(0.0))
    assert h1 / h0 == pytest.approx(ratio, abs=0.005)
    assert float(atmosphere.mops_mapping(np.pi / 2)) == pytest.approx(1.0, abs=1e-6)
    assert float(atmosphere.mops_mapping(np.deg2rad(5.0))) == pytest.approx(10.218, abs=1e-3)


# --------------------------------------------------------------------------- snapshot replay

B, L = 60, 12  # the rinex-replay block shape: one compilation for both test modules


def _sky(seed, n_sats=9, n_slots=L, n_epochs=B, sigma=1.0):
    rng = np.random.default_rng(seed)
    lat, lon = np.deg2rad(36.0), np.deg2rad(140.0)
    x = np.asarray(geometry.geodetic_to_ecef(lat, lon, 50.0))
    az = rng.uniform(0, 2 * np.pi, (n_epochs, n_slots))
    el = rng.uniform(np.deg2rad(10), np.deg2rad(85), (n_epochs, n_slots))
    u = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)
    r = np.asarray(geometry.enu_rotation(lat, lon))
    tx = x + 2.2e7 * np.einsum("ji,blj->bli", r, u)
    valid = np.zeros((n_epochs, n_slots), bool)
    valid[:, :n_sats] = True
    noise = rng.normal(0.0, sigma, (n_epochs, n_slots))
    pr = np.linalg.norm(tx - x, axis=-1) + 1234.5 + noise
    return x, tx, pr, valid


def test_replay_fault_free_and_padding_invariance():
    x, tx, pr, valid = _sky(1)
    var = np.ones(valid.shape)
    r = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x)
    assert np.all(r.wnls.status == araim.Status.OK)
    assert np.all(np.isfinite(r.hpe_m)) and np.median(r.hpe_m) < 3.0
    assert np.all(np.isfinite(r.slope.hpl_m)) and np.all(np.isfinite(r.mhss.hpl_m))
    # 1 m noise, P_FA 1e-5: no detection expected in 60 epochs
    assert not np.any(r.slope.detected) and not np.any(r.mhss.detected)
    assert np.all(r.slope.hpl_m == r.slope.hpl_all_in_view_m)
    np.testing.assert_allclose(r.mhss.hpl_m, r.mhss.hpl_all_in_view_m, rtol=1e-9)
    # padding: NaN junk in the unused slots changes nothing
    pr2, tx2 = pr.copy(), tx.copy()
    pr2[~valid] = np.nan
    tx2[~valid] = np.inf
    r2 = snapshot.replay(pr2, tx2, snapshot.ReplaySources(var, var, valid), x)
    np.testing.assert_array_equal(r.hpe_m, r2.hpe_m)
    np.testing.assert_array_equal(r.slope.hpl_m, r2.slope.hpl_m)
    np.testing.assert_array_equal(r.mhss.hpl_m, r2.mhss.hpl_m)


def test_group_slopes_one_clock_equals_araim_slope_hpl():
    x, tx, pr, valid = _sky(2)
    var = np.ones(valid.shape)
    r = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                        config=snapshot.ReplayConfig(p_fa=1e-5, p_md=1e-3))
    ref = araim.slope_hpl(r.g_enu, 1.0, p_fa=1e-5, p_md=1e-3, valid=r.used)
    np.testing.assert_allclose(r.slope.hpl_all_in_view_m, ref.hpl_m, rtol=1e-10)


def test_replay_detects_and_excludes_a_faulty_satellite():
    """A 150 m step on one satellite in 10 epochs (1 m noise): both monitors detect it, exclude
    exactly that satellite, and the errors after exclusion are bounded by their PLs."""
    x, tx, pr, valid = _sky(3)
    pr = pr.copy()
    pr[:10, 4] += 150.0
    var = np.ones(valid.shape)
    r = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x)
    for m in (r.slope, r.mhss):
        assert np.all(m.detected[:10]) and not np.any(m.detected[10:])
        assert np.all(np.argmax(m.excluded[:10], -1) == 4)
        assert np.all(m.excluded[:10].sum(-1) == 1) and not np.any(m.excluded[10:])
        assert np.all(m.status == araim.Status.OK)
        assert np.all(m.hpe_m < m.hpl_m)
        assert np.all(m.hpe_m[:10] < 5.0)
    assert np.median(r.hpe_m[:10]) > 20.0  # the all-in-view solution was pulled off
    m = snapshot.replay_metrics(r)
    assert m["detections_slope"] == 10 and m["exclusions_mhss"] == 10
    assert m["misleading_information_epochs"] == 0


def test_replay_failures_are_inf_not_nan():
    x, tx, pr, valid = _sky(4)
    valid = valid.copy()
    valid[:5] = False
    valid[:5, :3] = True  # 3 sources: no solution
    valid[5:10] = False
    valid[5:10, :4] = True  # 4 sources: a solution without redundancy
    var = np.ones(valid.shape)
    r = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x)
    for a in (r.hpe_m, r.slope.hpl_m, r.mhss.hpl_m, r.slope.vpl_m, r.mhss.vpl_m):
        assert not np.any(np.isnan(a))
    assert np.all(np.isinf(r.hpe_m[:5])) and np.all(np.isinf(r.mhss.hpl_m[:10]))
    assert np.all(np.isinf(r.slope.hpl_m[:10]))
    assert np.all(r.wnls.status[:5] == araim.Status.TOO_FEW_SOURCES)
    assert np.all(np.isfinite(r.hpe_m[5:10]))  # solved, but no integrity
    assert np.all(np.isfinite(r.mhss.hpl_m[10:]))


def _gnss_plus_sop(seed):
    """7 GPS satellites (group 0) and 4 towers 300 m - 3 km away, 10-60 m up (group 1, their
    own clock of 777 m); noise-free ranges."""
    x, tx, pr, valid = _sky(seed, n_sats=7, sigma=0.0)
    rng = np.random.default_rng(seed + 100)
    r_enu = np.asarray(geometry.enu_rotation(np.deg2rad(36.0), np.deg2rad(140.0)))
    ang = rng.uniform(0, 2 * np.pi, (B, 4))
    d = rng.uniform(300.0, 3000.0, (B, 4))
    enu = np.stack([d * np.sin(ang), d * np.cos(ang), rng.uniform(10, 60, (B, 4))], -1)
    tx, pr, valid = tx.copy(), pr.copy(), valid.copy()
    tx[:, 7:11] = x + np.einsum("ji,blj->bli", r_enu, enu)
    pr[:, 7:11] = np.linalg.norm(tx[:, 7:11] - x, axis=-1) + 777.0
    valid[:, 7:11] = True
    cons = np.zeros((B, L), np.int32)
    cons[:, 7:11] = 1
    return x, tx, pr, valid, cons, rng


def test_replay_gnss_plus_sop_clock_groups_slope():
    """Source-agnostic: SOP towers are transmitters with fixed positions and their own clock
    group. Noise-free ranges give the position and both clocks back; a 60 m fault on one tower
    (0.3 m noise elsewhere) is detected and that tower alone is excluded by slope RAIM. (Slope
    only: the two-group MHSS compiles for another ~30 s; see the slow test below.)"""
    x, tx, pr, valid, cons, rng = _gnss_plus_sop(5)
    var_int = np.where(cons == 1, 9.0, 1.0)
    r = snapshot.replay(pr, tx, snapshot.ReplaySources(var_int, var_int, valid, constellation=cons),
                        x, p_const=(1e-8, 1e-4), x0_m=x + 100.0,
                        config=snapshot.ReplayConfig(monitors=("slope",)))
    assert r.mhss is None and r.max_order == 0
    assert np.all(r.wnls.status == araim.Status.OK)
    assert np.max(r.hpe_m) < 1e-6 and np.max(r.vpe_m) < 1e-6
    np.testing.assert_allclose(r.wnls.clock_m, np.broadcast_to([1234.5, 777.0], (B, 2)),
                               atol=1e-6)
    assert np.all(np.isfinite(r.slope.hpl_m)) and not np.any(r.slope.detected)
    pr[:20, 9] += 60.0
    noisy = pr + np.where(valid, rng.normal(0.0, 0.3, pr.shape), 0.0)
    r = snapshot.replay(noisy, tx,
                        snapshot.ReplaySources(var_int, var_int, valid, constellation=cons), x,
                        p_const=(1e-8, 1e-4), x0_m=x + 100.0,
                        config=snapshot.ReplayConfig(monitors=("slope",)))
    assert np.all(r.slope.detected[:20]) and not np.any(r.slope.detected[20:])
    assert np.all(r.slope.excluded[:20, 9]) and np.all(r.slope.excluded[:20].sum(-1) == 1)
    assert np.all(r.slope.hpe_m < r.slope.hpl_m)
    m = snapshot.replay_metrics(r)
    assert m["hpl_median_m"] == m["hpl_slope_median_m"] and "hpl_mhss_median_m" not in m


@pytest.mark.slow
def test_replay_gnss_plus_sop_clock_groups_mhss():
    """The same with the MHSS (seed 004 P_const^S = 1e-4, P_s^S = 1e-4, b_nom^S = 0): the tower
    fault is detected; the MHSS keeps its best-fitting monitored mode, here the whole SOP
    constellation. Slow: ~30-45 s of compilation for the two-group MHSS with exclusion."""
    x, tx, pr, valid, cons, rng = _gnss_plus_sop(5)
    var_int = np.where(cons == 1, 9.0, 1.0)
    sources = snapshot.ReplaySources(var_int, var_int, valid, constellation=cons,
                                     p_sat=np.where(cons == 1, 1e-4, 1e-5),
                                     b_nom_m=np.where(cons == 1, 0.0, 0.75))
    pr[:20, 9] += 60.0
    noisy = pr + np.where(valid, rng.normal(0.0, 0.3, pr.shape), 0.0)
    r = snapshot.replay(noisy, tx, sources, x, (1e-8, 1e-4), x0_m=x + 100.0)
    assert r.max_order == 1
    for m in (r.slope, r.mhss):
        assert np.all(m.detected[:20]) and not np.any(m.detected[20:])
        assert np.all(m.excluded[:20, 9]) and np.all(m.hpe_m < m.hpl_m)
    assert np.all(r.mhss.excluded[:20, 7:11]) and not np.any(r.mhss.excluded[:20, :7])
    assert np.all(np.isfinite(r.mhss.hpl_m[20:]))


def test_replay_rejects_bad_input():
    x, tx, pr, valid = _sky(7)
    var = np.ones(valid.shape)
    with pytest.raises(ValueError, match="var_int_m2"):
        snapshot.replay(pr, tx, snapshot.ReplaySources(-var, var, valid), x)
    with pytest.raises(ValueError, match="p_fa"):
        snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                        config=snapshot.ReplayConfig(p_fa=2.0))
    with pytest.raises(ValueError, match="constellation"):
        snapshot.replay(pr, tx,
                        snapshot.ReplaySources(var, var, valid,
                                               constellation=np.full(valid.shape, 3)), x)
    with pytest.raises(ValueError, match="frame"):
        snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                        config=snapshot.ReplayConfig(frame="ned"))
    with pytest.raises(ValueError, match="config must be an araim.snapshot.ReplayConfig"):
        snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x, config={"frame": "enu"})
