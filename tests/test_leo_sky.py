"""LEO skies (geometry.leo): Walker shells against an independent propagation (SGP4 on the
TLEs of the same mean elements), the Walker pattern against the nominal Galileo Walker
24/3/1, the TLE reader, and the composition with the GNSS sky."""

import numpy as np
import pytest

import oaraim  # noqa: F401  (float64)
from oaraim import geometry
from oaraim.geometry import leo
from oaraim.readers import gpstime

T0 = float(gpstime.gps_seconds(2025, 3, 1))


def write_equivalent_tles(shell, t0, path, every):
    """The TLE file of ``geometry.leo.walker_tle_text`` at ``path``; its satellite indices."""
    text, idx = leo.walker_tle_text(shell, t0, every)
    path.write_text(text)
    return idx


@pytest.mark.parametrize("name", sorted(leo.LEO_PRESETS))
def test_walker_shell_agrees_with_sgp4_over_a_day(name, tmp_path):
    shell = leo.LEO_PRESETS[name]
    f = tmp_path / f"{name}.tle"
    idx = write_equivalent_tles(shell, T0, f, max(1, shell.total // 30))
    tle = leo.TleConstellation(f)
    assert tle.names.size == idx.size
    assert abs(tle.epoch_t_gps_s - T0) < 1e-3  # TLE epochs keep 1e-8 day
    t = T0 + np.arange(0.0, 86400.0 + 1.0, 300.0)
    e_tle, ok, _ = tle.sat_position_ecef(t)
    e_w, ok_w, names = leo.WalkerConstellation(shell, T0).sat_position_ecef(t)
    assert bool(np.all(ok)) and bool(np.all(ok_w)) and names.size == shell.total
    d = np.linalg.norm(np.asarray(e_tle) - np.asarray(e_w)[:, idx], axis=-1)
    assert d.max() < leo.SGP4_AGREEMENT_M, d.max()
    # and not trivially: the radius is the filing's altitude
    r = np.linalg.norm(np.asarray(e_w), axis=-1)
    np.testing.assert_allclose(r, shell.a_m, rtol=1e-12)


def test_two_body_shell_leaves_sgp4_within_the_day(tmp_path):
    """Without J2 the Walker shell drifts from SGP4 (nodal regression): the J2 rates are what
    keeps the day within the bound."""
    shell = leo.LEO_PRESETS["starlink"]
    f = tmp_path / "s.tle"
    idx = write_equivalent_tles(shell, T0, f, 100)
    t = T0 + np.array([0.0, 1800.0, 86400.0])
    e_tle = np.asarray(leo.TleConstellation(f).sat_position_ecef(t)[0])
    e_2b = np.asarray(leo.WalkerConstellation(shell, T0, j2=False).sat_position_ecef(t)[0])
    d = np.linalg.norm(e_tle - e_2b[:, idx], axis=-1).max(-1)
    assert d[1] < leo.SGP4_AGREEMENT_M < d[2]


def test_walker_pattern_equals_the_nominal_galileo_walker():
    """Galileo's 24/3/1 as a WalkerShell (no J2) is the nominal Galileo almanac: the same slots
    (planes 120 deg apart, 45 deg in plane, 15 deg between planes) to the millimetre."""
    from oaraim.geometry import nominal

    shell = leo.WalkerShell("gal", nominal.GAL_A_M - leo.WGS84_A_M, nominal.GAL_I_DEG, 3, 8, 1)
    t = nominal.GAL_EPOCH_T_GPS_S + np.array([0.0, 3600.0, 40000.0])
    ours = np.asarray(leo.WalkerConstellation(shell, nominal.GAL_EPOCH_T_GPS_S, j2=False)
                      .sat_position_ecef(t)[0])
    ref = np.asarray(geometry.galileo_walker().sat_position_ecef(t)[0])
    np.testing.assert_allclose(ours, ref, atol=1e-3)


def test_secular_rates_closed_form():
    """Starlink shell 1: period 95.65 min, nodal regression -4.49 deg/day (by hand:
    n = 1.0948e-3 rad/s, (R/a)^2 = 0.8475, cos i = 0.6018 in -3/2 n J2 (R/a)^2 cos i)."""
    shell = leo.LEO_PRESETS["starlink"]
    node_dot, u_dot = leo.secular_rates(shell.a_m, np.deg2rad(53.0))
    n = np.sqrt(leo.WGS84_GM_M3_S2 / shell.a_m**3)
    assert 2 * np.pi / n / 60 == pytest.approx(95.65, abs=0.01)
    assert np.rad2deg(node_dot) * 86400 == pytest.approx(-4.49, abs=0.01)
    assert u_dot > n  # at 53 deg the perigee and mean-anomaly terms add


def test_tle_reader_errors(tmp_path):
    f = tmp_path / "bad.tle"
    f.write_text("SAT\n1 00001U          25059.99979167  .00000000  00000-0  00000+0 0    02\n")
    with pytest.raises(leo.TleFileError, match="without its partner"):
        leo.read_tle(f)
    f.write_text("nothing here\n")
    with pytest.raises(leo.TleFileError, match="no two-line element set"):
        leo.read_tle(f)
    with pytest.raises(leo.TleFileError, match="does not exist"):
        leo.read_tle(tmp_path / "missing.tle")
    with pytest.raises(ValueError, match="unknown: use one of starlink"):
        leo.leo_constellation("starlunk")


def test_leap_seconds():
    assert leo.gps_minus_utc_s(float(gpstime.gps_seconds(2016, 12, 31))) == 17
    assert leo.gps_minus_utc_s(float(gpstime.gps_seconds(2017, 1, 1, 0, 0, 18.0))) == 18
    assert leo.gps_minus_utc_s(0.0) == 0


def test_leo_sky_composes_with_gnss_sky():
    rx = np.asarray(geometry.geodetic_to_ecef(np.deg2rad(45.0), np.deg2rad(7.0), 0.0))
    t = T0 + np.arange(0.0, 3600.0, 600.0)
    g = geometry.sky(rx, t, "nominal", mask_deg=5.0)
    s = leo.leo_sky(rx, t, leo.WalkerConstellation(leo.LEO_PRESETS["starlink"], T0),
                    mask_deg=25.0, code=2)
    both = leo.combine_skies(g, s)
    assert both.valid.shape == (t.size, g.sv.size + 1584)
    assert set(np.unique(both.constellation)) == {0, 1, 2}
    n_leo = np.asarray(s.valid).sum(-1)
    # 1,584 satellites at 550 km over 45 deg N, mask 25 deg (Starlink's user terminal
    # minimum in the filing): ~10-20 in view
    assert n_leo.min() >= 5 and n_leo.max() <= 40, n_leo
    el = np.asarray(s.el_rad)[np.asarray(s.valid)]
    assert el.min() >= np.deg2rad(25.0)
