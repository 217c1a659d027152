"""Earth frames and GPS time: hand-derived points and round trips."""

import numpy as np
import pytest

from oaraim import geometry
from oaraim.constants import WGS84_A_M, WGS84_B_M, WGS84_E2
from oaraim.readers import gpstime

DEG = np.pi / 180.0


def test_geodetic_to_ecef_hand_points():
    # on the equator at the prime meridian: (a, 0, 0); at 90 E: (0, a, 0); at the pole: (0, 0, b)
    np.testing.assert_allclose(geometry.geodetic_to_ecef(0.0, 0.0, 0.0), [WGS84_A_M, 0, 0],
                               atol=1e-9)
    np.testing.assert_allclose(geometry.geodetic_to_ecef(0.0, 90 * DEG, 100.0),
                               [0, WGS84_A_M + 100.0, 0], atol=1e-8)
    np.testing.assert_allclose(geometry.geodetic_to_ecef(90 * DEG, 0.0, 0.0), [0, 0, WGS84_B_M],
                               atol=1e-8)
    # 45 N: N = a / sqrt(1 - e^2 / 2), x = N cos45, z = N (1 - e^2) sin45 (by hand)
    n = WGS84_A_M / np.sqrt(1 - WGS84_E2 / 2)
    np.testing.assert_allclose(geometry.geodetic_to_ecef(45 * DEG, 0.0, 0.0),
                               [n / np.sqrt(2), 0, n * (1 - WGS84_E2) / np.sqrt(2)], atol=1e-8)


def test_ecef_geodetic_round_trip_surface_to_gnss_altitude():
    """Round trip to 1e-6 m and 1e-12 rad (Bowring converges to rounding in 3 steps), from
    the poles to the equator and from -400 m to GNSS altitudes."""
    rng = np.random.default_rng(0)
    lat = rng.uniform(-90, 90, 2000) * DEG
    lat[:4] = [90 * DEG, -90 * DEG, 0.0, 89.9999 * DEG]
    lon = rng.uniform(-180, 180, 2000) * DEG
    h = rng.choice([-400.0, 0.0, 839.7, 1e4, 2.02e7, 2.32e7], 2000)
    xyz = geometry.geodetic_to_ecef(lat, lon, h)
    lat2, lon2, h2 = (np.asarray(v) for v in geometry.ecef_to_geodetic(xyz))
    np.testing.assert_allclose(lat2, lat, atol=1e-12)
    np.testing.assert_allclose(h2, h, atol=1e-6)
    away = np.abs(lat) < 89.99 * DEG  # longitude is undefined at the poles
    np.testing.assert_allclose(np.cos(lon2[away] - lon[away]), 1.0, atol=1e-15)


def test_mdscc_corrected_coordinate_is_near_madrid():
    """DESIGN.md: seed 001's MDSCC with y = -360329.7 m lies at 40.43 N, 4.25 W."""
    lat, lon, h = geometry.ecef_to_geodetic(np.array([4849210.0, -360329.7, 4114920.0]))
    assert float(lat) / DEG == pytest.approx(40.43, abs=0.005)
    assert float(lon) / DEG == pytest.approx(-4.25, abs=0.005)
    assert 0 < float(h) < 2000  # MDSCC is at ~830 m above the ellipsoid-ish


def test_enu_rotation_is_orthonormal_and_points_the_right_way():
    r = np.asarray(geometry.enu_rotation(40 * DEG, -4 * DEG))
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(r) == pytest.approx(1.0)  # right-handed E, N, U
    # at (0, 0): east = +y, north = +z, up = +x
    np.testing.assert_allclose(geometry.enu_rotation(0.0, 0.0), [[0, 1, 0], [0, 0, 1], [1, 0, 0]],
                               atol=1e-15)


def test_enu_round_trip():
    origin = geometry.geodetic_to_ecef(40 * DEG, -4 * DEG, 800.0)
    enu = np.array([[100.0, -50.0, 20.0], [3000.0, 0.0, 0.0]])
    back = geometry.ecef_to_enu(geometry.enu_to_ecef(enu, origin), origin)
    np.testing.assert_allclose(back, enu, atol=1e-8)


def test_azimuth_elevation_hand_cases():
    rx = np.asarray(geometry.geodetic_to_ecef(0.0, 0.0, 0.0))
    # straight up: el = 90 deg
    _, el, rng = geometry.azimuth_elevation(rx, rx * 4)
    assert float(el) == pytest.approx(np.pi / 2)
    assert float(rng) == pytest.approx(3 * WGS84_A_M)
    # due north along the local meridian tangent (+z at (0, 0)): az = 0, el = 0
    az, el, _ = geometry.azimuth_elevation(rx, rx + [0, 0, 1e6])
    assert float(az) == pytest.approx(0.0, abs=1e-12) and float(el) == pytest.approx(0, abs=1e-12)
    # due east (+y at (0, 0)), 45 deg up: az = 90 deg, el = 45 deg
    az, el, _ = geometry.azimuth_elevation(rx, rx + [1e6, 1e6, 0])
    assert float(az) == pytest.approx(np.pi / 2) and float(el) == pytest.approx(np.pi / 4)
    # due west: az = 270 deg (in [0, 2 pi))
    az, _, _ = geometry.azimuth_elevation(rx, rx + [0, -1e6, 0])
    assert float(az) == pytest.approx(1.5 * np.pi)


def test_azimuth_elevation_matches_geometry_rows_convention():
    """geometry_rows(az, el) equals (rx - tx)/|rx - tx| in ENU (seed 001 2.4)."""
    rx = geometry.geodetic_to_ecef(40.4 * DEG, -4.25 * DEG, 840.0)
    tx = np.array([[1.5e7, -1.0e7, 1.8e7], [2.0e7, 1.0e7, 1.0e7]])
    az, el, _ = geometry.azimuth_elevation(rx, tx)
    g = np.asarray(geometry.geometry_rows(az, el))
    enu = np.asarray(geometry.ecef_to_enu(tx, rx))
    np.testing.assert_allclose(g, -enu / np.linalg.norm(enu, axis=-1, keepdims=True), atol=1e-14)


def test_earth_rotation_correction_rotates_about_z():
    p = np.array([2.0e7, 0.0, 1.0e7])
    q = np.asarray(geometry.earth_rotation_correction(p, 0.075))
    assert q[2] == p[2] and np.linalg.norm(q) == pytest.approx(np.linalg.norm(p))
    # a satellite on +x moves to -y (the frame turned east under it): ~ 7.29e-5 * 0.075 * 2e7
    assert q[1] == pytest.approx(-7.2921151467e-5 * 0.075 * 2.0e7, rel=1e-9)


def test_gps_time_hand_points():
    assert gpstime.gps_seconds(1980, 1, 6) == 0.0
    # GPS week 1590 starts 2010-06-27 (1590 * 7 days after 1980-01-06); the SP3 file igs15904
    # is day 4 of that week: 2010-07-01 = 4 * 86400 s into the week
    w, tow = gpstime.week_tow(gpstime.gps_seconds(2010, 7, 1))
    assert (int(w), float(tow)) == (1590, 345600.0)
    # the first week rollover: 1999-08-22 is week 1024, the second 2019-04-07 week 2048
    assert gpstime.week_tow(gpstime.gps_seconds(1999, 8, 22))[0] == 1024
    assert gpstime.week_tow(gpstime.gps_seconds(2019, 4, 7))[0] == 2048
    assert gpstime.gps_seconds(2000, 3, 1) - gpstime.gps_seconds(2000, 2, 28) == 2 * 86400  # leap


def test_gps_time_round_trips_and_rollover():
    rng = np.random.default_rng(1)
    t = rng.uniform(0, 2.0e9, 500).round(3)
    y, mo, d, h, mi, s = gpstime.calendar(t)
    np.testing.assert_allclose(gpstime.gps_seconds(y, mo, d, h, mi, s), t, atol=1e-6)
    w, tow = gpstime.week_tow(t)
    np.testing.assert_allclose(gpstime.from_week_tow(w, tow), t, atol=1e-6)
    assert np.all((tow >= 0) & (tow < gpstime.SECONDS_PER_WEEK))
    np.testing.assert_allclose(gpstime.from_datetime64(gpstime.to_datetime64(t)), t, atol=1e-6)
    # a 10-bit week resolved near a reference time
    ref = gpstime.gps_seconds(2018, 6, 19)  # week 2006
    assert gpstime.resolve_week(2006 % 1024, ref) == 2006
    assert gpstime.resolve_week(1023, ref) == 2047  # just before the 2019 rollover
    assert gpstime.resolve_week(5, gpstime.gps_seconds(2019, 4, 20)) == 2053
    assert gpstime.resolve_week(703, ref) == 1727  # nearest to 2018, not 1993
    assert gpstime.resolve_week(2006, 0.0) == 2006  # a full week is kept
