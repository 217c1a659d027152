"""The sky API: visibility over a day, batching, araim-ready output, bad input."""

import numpy as np
import pytest

from oaraim import araim, geometry, readers
from oaraim.readers import gpstime

MDSCC_ECEF_M = np.array([4849210.0, -360329.7, 4114920.0])  # DESIGN.md corrected y
DAY_30S = gpstime.gps_seconds(2018, 6, 19) + 30.0 * np.arange(2880)
VILL = "nav/VILL00ESP_R_20181700000_01D_MN.rnx.gz"


def _counts(s, code=None):
    v = np.asarray(s.valid)
    if code is not None:
        v = v[..., s.constellation == code]
    return v.sum(-1)


def test_visibility_nominal_gps_madrid_day():
    """DESIGN.md: 4-8 GPS above 15 deg with the nominal 24-slot constellation at mid-latitudes.
    Measured at MDSCC, 2018-06-19 at 30 s: 4-8, mean 5.97."""
    n = _counts(geometry.sky(MDSCC_ECEF_M, DAY_30S, source="nominal-gps", mask_deg=15.0))
    assert n.min() >= 4 and n.max() <= 8
    assert 5.0 < n.mean() < 7.0


def test_visibility_real_gps_and_galileo_madrid_day(shared_data):
    """DESIGN.md: 5-12 GPS above 15 deg with real files, below 6 for under 5 % of the day.
    Measured (Villafranca file, MDSCC, 2018-06-19): GPS 5-11, below 6 for 1.9 % of the epochs;
    Galileo (14 healthy in June 2018) 2-5."""
    s = geometry.sky(MDSCC_ECEF_M, DAY_30S, source=shared_data / VILL, mask_deg=15.0)
    n = _counts(s, readers.GPS)
    assert n.min() >= 5 and n.max() <= 12
    assert np.mean(n < 6) < 0.05
    ng = _counts(s, readers.GALILEO)
    assert ng.max() <= 8 and ng.mean() > 1.0
    assert not np.asarray(s.valid)[:, list(s.sv).index("G04")].any()  # unhealthy all day


def test_visibility_nominal_galileo_and_brdc_2010(shared_data):
    """Walker 24/3/1 at 15 deg: 4-8 in view. A 2010 broadcast file (31 healthy-ish GPS) at a
    mid-latitude site over its own day: 5-12."""
    n = _counts(geometry.sky(MDSCC_ECEF_M, DAY_30S, source="nominal-galileo", mask_deg=15.0))
    assert n.min() >= 4 and n.max() <= 8
    t = gpstime.gps_seconds(2010, 7, 1) + 30.0 * np.arange(2880)
    n = _counts(geometry.sky(MDSCC_ECEF_M, t, source=shared_data / "nav" / "brdc1820.10n",
                             mask_deg=15.0))
    assert n.min() >= 5 and n.max() <= 12 and np.mean(n < 6) < 0.05


def test_batched_over_receivers_equals_one_by_one():
    lat = np.deg2rad(np.array([[10.0, 40.4], [-33.0, 60.0]]))
    lon = np.deg2rad(np.array([[0.0, -4.25], [151.0, 25.0]]))
    rx = np.asarray(geometry.geodetic_to_ecef(lat, lon, np.zeros_like(lat)))
    t = DAY_30S[:20]
    s = geometry.sky(rx, t, source="nominal", mask_deg=10.0)
    assert s.el_rad.shape == (2, 2, 20, 48) and s.prn.shape == (48,)
    assert list(np.unique(s.constellation)) == [0, 1]
    one = geometry.sky(rx[1, 0], t, source="nominal", mask_deg=10.0)
    np.testing.assert_allclose(np.asarray(s.el_rad[1, 0]), np.asarray(one.el_rad), atol=1e-13)
    # and against the per-point frames function
    ecef, _, _ = geometry.gps_24_slot().sat_position_ecef(t)
    az, el, _ = geometry.azimuth_elevation(rx[1, 0], ecef)
    np.testing.assert_allclose(np.asarray(one.el_rad)[:, :24], np.asarray(el), atol=1e-12)
    np.testing.assert_allclose(np.asarray(one.az_rad)[:, :24], np.asarray(az), atol=1e-12)
    assert np.array_equal(np.asarray(one.valid), np.asarray(one.el_rad) >= np.deg2rad(10.0))


def test_sky_feeds_araim_with_padding_masked():
    """geometry rows from the sky go straight into araim: the padded satellites (valid False)
    do not change the HPL (compare with the valid satellites alone)."""
    s = geometry.sky(MDSCC_ECEF_M, DAY_30S[:20], source="nominal-gps", mask_deg=15.0)
    g = geometry.geometry_rows(s.az_rad, s.el_rad)
    r = araim.slope_hpl(g, 1.0, p_fa=1e-5, p_md=1e-3, valid=s.valid)
    hpl = np.asarray(r.hpl_m)
    for k in (7,):
        keep = np.asarray(s.valid[k])
        rk = araim.slope_hpl(np.asarray(g[k])[keep], 1.0, p_fa=1e-5, p_md=1e-3)
        assert float(rk.hpl_m) == pytest.approx(hpl[k], rel=1e-12) or (
            np.isinf(hpl[k]) and np.isinf(float(rk.hpl_m)))
    assert not np.any(np.isnan(hpl))


def test_invalid_entries_are_finite_zero(shared_data):
    t = gpstime.gps_seconds(2030, 1, 1) + np.array([0.0, 60.0])  # far outside the file
    s = geometry.sky(MDSCC_ECEF_M, t, source=shared_data / "nav" / "brdc1820.10n")
    assert not np.asarray(s.valid).any()
    assert np.all(np.asarray(s.el_rad) == 0.0) and np.all(np.isfinite(np.asarray(s.az_rad)))


def test_sky_bad_input():
    with pytest.raises(ValueError, match="mask_deg must be a number in"):
        geometry.sky(MDSCC_ECEF_M, DAY_30S[:2], mask_deg=95)
    with pytest.raises(ValueError, match="receiver_ecef_m must be ECEF metres"):
        geometry.sky(np.array([40.4, -4.2, 800.0]), DAY_30S[:2])
    with pytest.raises(ValueError, match="last axis 3"):
        geometry.sky(np.zeros((2, 2)), DAY_30S[:2])
    with pytest.raises(ValueError, match="neither 'nominal"):
        geometry.sky(MDSCC_ECEF_M, DAY_30S[:2], source="/no/such/file.rnx")
    with pytest.raises(ValueError, match="constellations must be"):
        geometry.sky(MDSCC_ECEF_M, DAY_30S[:2], constellations=("glonass",))
