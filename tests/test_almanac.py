"""Almanacs (YUMA, SEM) and the built-in nominal constellations."""

import numpy as np
import pytest

from oaraim import geometry, readers
from oaraim.constants import GPS_PI, MU_GPS_M3_S2, OMEGA_E_GNSS_RAD_S
from oaraim.geometry.nominal import GPS_SPS_EPOCH_T_GPS_S

DEG = np.pi / 180.0


@pytest.fixture(scope="module")
def almmops(shared_data):
    return geometry.read_yuma(shared_data / "almanac" / "almmops.txt")


def _node_lon_and_arg_lat(alm, t):
    """ECEF longitude of the ascending node and argument of latitude (rad) at t."""
    r = alm.records
    n = np.sqrt(MU_GPS_M3_S2 / r.sqrt_a**6)
    lam = (r.omega0_rad + (r.omegadot_rad_s - OMEGA_E_GNSS_RAD_S) * (t - r.toa_s)
           - OMEGA_E_GNSS_RAD_S * r.toa_tow_s)
    return lam, r.omega_rad + r.m0_rad + n * (t - r.toa_s)


def _wrap(x):
    return np.mod(x + np.pi, 2 * np.pi) - np.pi


def test_yuma_reader_values(almmops):
    assert almmops.prns.size == 24 and list(almmops.prns[:2]) == ["G01", "G02"]
    r = almmops.records
    assert np.all(r.health == 0) and np.all(r.e == 0.0)
    assert r.i_rad[0] == pytest.approx(0.9599310886)
    assert r.sqrt_a[0] == pytest.approx(5153.620087)
    assert r.omega0_rad[0] == pytest.approx(4.762078504)
    assert r.m0_rad[0] == pytest.approx(4.679681510)
    # week 703, t_oa 344063 s: 1993-06-30 23:34:23 GPS time
    assert r.toa_s[0] == 703 * 604800 + 344063.0


def test_almmops_is_the_sps_24_slot_constellation_up_to_a_common_rotation(almmops):
    """The DO-229 almanac (MAAST almmops.txt) against the built-in SPS PS 24-slot
    constellation. Orbital elements: same a and i; each almanac satellite sits in one slot with the
    same
    argument of latitude at its own epoch (the almanac's t_oa, the SPS epoch); the node
    longitudes differ by one common angle (MAAST stores the SPS RAAN as Omega_0 without the
    Greenwich hour angle). So the two are the same relative geometry rotated about the z axis.
    Tolerances: the almanac prints 10 digits (1e-9 rad) and the SPS table 3 decimals of a degree
    (5e-4 deg), hence 1e-3 deg."""
    nom = geometry.gps_24_slot()
    assert np.allclose(almmops.records.i_rad, nom.records.i_rad, atol=1e-9)
    # a = 26,559.7 km vs sqrt(A) = 5153.620087 (26,559.80 km): 0.1 km apart, i.e. the period
    # differs by 0.9 s (4 ppm) -- a rounding in MAAST's file, irrelevant for a day
    assert np.allclose(almmops.records.sqrt_a**2, nom.records.sqrt_a**2, rtol=5e-6)
    lam_a, u_a = _node_lon_and_arg_lat(almmops, almmops.records.toa_s[0])
    lam_n, u_n = _node_lon_and_arg_lat(nom, GPS_SPS_EPOCH_T_GPS_S)
    d_lam = _wrap(lam_a[0] - lam_n[0])
    # match every almanac satellite to the slot with the same rotated node and the same u
    dist = np.hypot(_wrap(lam_a[:, None] - lam_n[None, :] - d_lam),
                    _wrap(u_a[:, None] - u_n[None, :]))
    match = np.argmin(dist, axis=1)
    assert sorted(match) == list(range(24))  # a one-to-one slot assignment
    assert dist[np.arange(24), match].max() < 1e-3 * DEG
    # PRN n is slot n, except that MAAST swaps PRNs 19 and 20 (slots E1 and E3)
    assert [int(m) for m in match] == [*range(18), 19, 18, *range(20, 24)]


def test_almmops_sky_equals_nominal_sky_at_rotated_longitude(almmops):
    """The same statement through the sky API: the almanac's sky at (40.43 N, lon) from its
    t_oa on equals the nominal sky at (40.43 N, lon - delta) from the SPS epoch on, for every
    satellite over 24 h to 0.01 deg: the two semi-major axes differ by 0.1 km (3.8 ppm), so the
    mean motions differ by 5.6 ppm and the arguments of latitude drift apart by
    2 revolutions * 360 deg * 5.6e-6 = 0.004 deg in a day; seen from the ground (range ~20,000
    km vs orbit radius 26,560 km) that is up to ~0.006 deg (measured max 0.0053 deg)."""
    nom = geometry.gps_24_slot()
    lam_a, _ = _node_lon_and_arg_lat(almmops, almmops.records.toa_s[0])
    lam_n, _ = _node_lon_and_arg_lat(nom, GPS_SPS_EPOCH_T_GPS_S)
    delta = float(_wrap(lam_a - lam_n)[0])
    tau = np.arange(0.0, 86400.0, 300.0)
    rx_a = geometry.geodetic_to_ecef(40.43 * DEG, -4.25 * DEG, 840.0)
    rx_n = geometry.geodetic_to_ecef(40.43 * DEG, -4.25 * DEG - delta, 840.0)
    sa = geometry.sky(rx_a, almmops.records.toa_s[0] + tau, source=almmops, mask_deg=0.0)
    sn = geometry.sky(rx_n, GPS_SPS_EPOCH_T_GPS_S + tau, source=nom, mask_deg=0.0)
    swap = [*range(18), 19, 18, *range(20, 24)]  # almanac PRN order -> slots (test above)
    sn = sn._replace(el_rad=sn.el_rad[:, swap], az_rad=sn.az_rad[:, swap],
                     valid=sn.valid[:, swap])
    # angle between the two line-of-sight directions, every satellite and epoch
    ga = np.asarray(geometry.geometry_rows(sa.az_rad, sa.el_rad))
    gn = np.asarray(geometry.geometry_rows(sn.az_rad, sn.el_rad))
    angle = np.arccos(np.clip(np.sum(ga * gn, -1), -1, 1))
    assert angle.max() < 0.01 * DEG
    assert np.array_equal(np.asarray(sa.valid), np.asarray(sn.valid)) or (
        np.mean(np.asarray(sa.valid) != np.asarray(sn.valid)) < 1e-3)  # at the horizon only


def test_nominal_gps_orbit_facts():
    """SPS PS 24-slot: radius 26,559.7 km, i = 55 deg, period 11 h 58 min (43,077 s, two-body
    with IS-GPS-200 mu), planes 60 deg apart."""
    nom = geometry.gps_24_slot()
    t = GPS_SPS_EPOCH_T_GPS_S + np.array([0.0, 43077.0 / 4, 43077.0])
    ecef, valid, prns = nom.sat_position_ecef(t)
    r = np.linalg.norm(np.asarray(ecef), axis=-1)
    np.testing.assert_allclose(r, 26_559_700.0, rtol=1e-12)
    assert np.all(np.asarray(valid)) and prns.size == 24
    z_max = np.abs(np.asarray(ecef)[..., 2]).max()
    assert z_max <= 26_559_700.0 * np.sin(55 * DEG) * (1 + 1e-12)
    # slot A1 at the epoch: RAAN 272.847, GHA 279.06 -> node longitude -6.213 deg, u = 268.126
    lam = (272.847 - 279.06) * DEG
    u = 268.126 * DEG
    x_orb = np.array([np.cos(u), np.sin(u) * np.cos(55 * DEG), np.sin(u) * np.sin(55 * DEG)])
    rot = np.array([[np.cos(lam), -np.sin(lam), 0], [np.sin(lam), np.cos(lam), 0], [0, 0, 1]])
    np.testing.assert_allclose(np.asarray(ecef)[0, 0], 26_559_700.0 * rot @ x_orb, atol=1e-3)


def test_nominal_galileo_walker():
    gal = geometry.galileo_walker()
    assert gal.prns.size == 24 and gal.prns[0] == "E01"
    ecef, _, _ = gal.sat_position_ecef(np.array([1.2e9]))
    r = np.linalg.norm(np.asarray(ecef), axis=-1)
    np.testing.assert_allclose(r, 29_599_800.0, rtol=1e-12)
    i = np.rad2deg(gal.records.i_rad)
    assert np.all(i == pytest.approx(56.0))
    # Walker 24/3/1: three node longitudes 120 deg apart, 8 slots 45 deg apart, 15 deg phasing
    lam = np.rad2deg(np.unique(np.round(gal.records.omega0_rad, 9)))
    assert lam.size == 3 and np.allclose(np.diff(np.sort(np.mod(lam, 360))), 120.0)
    u = np.rad2deg(gal.records.m0_rad).reshape(3, 8)
    assert np.allclose(np.diff(u, axis=1), 45.0) and np.allclose(u[:, 0], [0, 15, 30])


def _sem_text(alm):
    """A SEM file with the same orbits as ``alm`` (angles in semicircles, delta_i from 0.30)."""
    r = alm.records
    week = int(r.toa_s[0] // 604800)
    out = [f"{r.prn.size} TEST.AL3", f"{week} {int(r.toa_tow_s[0])}", ""]
    for k in range(r.prn.size):
        out += [f"{r.prn[k]}", f"{r.prn[k] + 30}", "0",
                f" {r.e[k]:.12E} {r.i_rad[k] / GPS_PI - 0.30:.12E} "
                f"{r.omegadot_rad_s[k] / GPS_PI:.12E}",
                f" {r.sqrt_a[k]:.12E} {r.omega0_rad[k] / GPS_PI:.12E} "
                f"{r.omega_rad[k] / GPS_PI:.12E}",
                f" {r.m0_rad[k] / GPS_PI:.12E} {r.af0_s[k]:.12E} {r.af1_s_s[k]:.12E}",
                f"{r.health[k]}", "9", ""]
    return "\n".join(out)


def test_sem_reader_matches_yuma(shared_data, tmp_path):
    """A real 31-satellite YUMA almanac (January 2020, week 38 = 2086 mod 1024) written as SEM:
    both readers give the same orbits (to the 13 printed digits: < 1 mm)."""
    ref = readers.gpstime.gps_seconds(2020, 1, 1)
    yuma = geometry.read_yuma(shared_data / "almanac" / "almyuma_01jan2020.txt",
                              week_reference_t_gps_s=ref)
    assert int(yuma.records.toa_s[0] // 604800) == 2086
    p = tmp_path / "current.al3"
    p.write_text(_sem_text(yuma))
    sem = geometry.read_sem(p)
    t = ref + np.arange(0.0, 86400.0, 3600.0)
    a, va, _ = yuma.sat_position_ecef(t)
    b, vb, _ = sem.sat_position_ecef(t)
    assert np.array_equal(np.asarray(va), np.asarray(vb))
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-3)


def test_galileo_yuma_almanac_ed259(shared_data):
    gal = geometry.read_yuma(shared_data / "almanac" / "alm_gal_ed259.txt", system="E")
    assert gal.prns.size == 24 and gal.prns[0] == "E01"  # numbered from the 'SVID- 1' headers
    ecef, _, _ = gal.sat_position_ecef(gal.records.toa_s[:1])
    np.testing.assert_allclose(np.linalg.norm(np.asarray(ecef), axis=-1), 29.6e6, rtol=1e-4)


def test_almanac_file_errors(tmp_path):
    p = tmp_path / "bad.txt"
    p.write_text("******** Week 703 almanac for PRN-01 ********\nID: 01\nHealth: 000\n"
                 "Eccentricity: 0.x\n")
    with pytest.raises(readers.AlmanacFileError, match=r"bad\.txt: line 4: cannot read "
                       "'Eccentricity' value"):
        geometry.read_yuma(p)
    p.write_text("******** Week 703 almanac for PRN-01 ********\nID: 01\nHealth: 000\n")
    with pytest.raises(readers.AlmanacFileError, match="line 3: the almanac block starting at "
                       "line 1 lacks"):
        geometry.read_yuma(p)
    p.write_text("24 X.AL3\n703 344063\n\n1\n31\n")
    with pytest.raises(readers.AlmanacFileError, match="truncated"):
        geometry.read_sem(p)


def _mutated(shared_data, tmp_path, old, new, count=1):
    text = (shared_data / "almanac" / "almmops.txt").read_text()
    assert old in text
    p = tmp_path / "alm.txt"
    p.write_text(text.replace(old, new, count))
    return p, text


def _line_of(text, needle):
    return text[:text.index(needle)].count("\n") + 1


@pytest.mark.parametrize("field, bad, why", [
    ("Eccentricity", "nan", "finite"), ("Eccentricity", "1.5", r"in \[0, 1\)"),
    ("SQRT(A)  (m 1/2)", "-5153.6", "> 0"), ("Health", "1.5", "integer")])
def test_yuma_unphysical_values_are_parse_errors_with_the_line(shared_data, tmp_path, field,
                                                               bad, why):
    """'Eccentricity: nan' or 1.5 loaded a healthy satellite with a NaN position, a
    negative sqrt(A) was accepted. Now: the file and the line of the first record's field."""
    text = (shared_data / "almanac" / "almmops.txt").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith(field))
    value = line.partition(":")[2].strip()
    p, _ = _mutated(shared_data, tmp_path, line, line.replace(value, bad))
    with pytest.raises(readers.AlmanacFileError,
                       match=rf"alm\.txt: line {_line_of(text, line)}: .*{why}"):
        geometry.read_yuma(p)


def test_yuma_duplicated_block_is_an_error_naming_both_lines(shared_data, tmp_path):
    """A duplicated PRN block gave the satellite twice (a duplicated measurement in every
    geometry, the map's median VPL 16.2 -> 12.4 m with exit 0)."""
    text = (shared_data / "almanac" / "almmops.txt").read_text()
    blocks = text.split("********")
    first = "********" + blocks[1] + "********" + blocks[2]
    p = tmp_path / "alm.txt"
    p.write_text(text + first)
    with pytest.raises(readers.AlmanacFileError, match=r"satellite 1 appears again \(first "
                                                        r"at line 1\)"):
        geometry.read_yuma(p)


def test_sem_wrong_file_and_bad_values_name_the_line(tmp_path):
    p = tmp_path / "x.al3"
    p.write_text("not an almanac at all\nsecond line\n")
    with pytest.raises(readers.AlmanacFileError, match=r"x\.al3: line 1: .*not a SEM"):
        geometry.read_sem(p)
    p.write_text("1 X.AL3\n703\n\n1\n31\n0\n 1.5 0 0\n 5153 0 0\n 0 0 0\n0\n9\n")
    with pytest.raises(readers.AlmanacFileError, match=r"line 2: expected the week and t_oa"):
        geometry.read_sem(p)
    p.write_text("1 X.AL3\n703 344064\n\n1\n31\n0\n 1.5 0 0\n 5153 0 0\n 0 0 0\n0\n9\n")
    with pytest.raises(readers.AlmanacFileError, match=r"line 7: e = 1\.5 must be in \[0, 1\)"):
        geometry.read_sem(p)


@pytest.mark.parametrize("field, value, message", [
    ("*", "******** Week 38 almanac for PRN-9999999999999 ********",
     r"line 1: prn = 9999999999999 must be an integer in 1\.\.99"),
    ("Health:", "4096", r"line 3: health = 4096\.0 must be an integer in 0\.\.255"),
    ("week:", "1e12", r"line 14: week = 1000000000000\.0 must be an integer in 0\.\.100000"),
])
def test_yuma_integers_out_of_range_name_the_line(shared_data, tmp_path, field, value, message):
    """A garbled 13-digit PRN passed as "a positive integer" and overflowed the int32 cast (a
    wrong PRN, a RuntimeWarning found by tests/test_fuzz_parsers.py); PRN, health and week are
    now checked against their ranges. (The ID line may differ from the header's number: the
    Galileo almanac alm_gal_ed259.txt has 'SVID- 1' with 'ID: 75'.)"""
    text = (shared_data / "almanac" / "almyuma_01jan2020.txt").read_text()
    first = text.split("\n\n")[0].splitlines()
    k = next(i for i, s in enumerate(first) if s.startswith(field))
    first[k] = value if field == "*" else f"{field:<28s}{value}"
    p = tmp_path / "edit.alm"
    p.write_text("\n".join(first) + "\n")
    with pytest.raises(readers.AlmanacFileError, match=r"edit\.alm: " + message):
        geometry.read_yuma(p)


@pytest.mark.parametrize("field, bad, message", [
    ("SQRT(A)  (m 1/2):", "1000.000000",
     r"line 8: satellite 1: sqrt\(A\) = 1000\.0 m\^1/2 is a semi-major axis of 1,000 km, not a "
     r"GPS orbit \(25,560 \.\. 27,560 km"),
    ("Eccentricity:", "0.99", r"line 4: satellite 1: eccentricity 0\.99 is not a GPS orbit's "
                             r"\(0 \.\. 0\.05\)"),
    ("Orbital Inclination(rad):", "50.0", r"line 6: satellite 1: inclination 50\.0 rad "
                                         r"\(2,864\.8 deg\) is not a GPS orbit's \(40 \.\. 70 "
                                         r"deg\)"),
])
def test_yuma_implausible_orbits_are_refused_with_the_line(shared_data, tmp_path, field, bad,
                                                           message):
    """A well-formed record that is no GPS orbit loaded silently: SQRT(A) = 1000 (an orbit
    1,000 km from the Earth's centre) took the satellite out of the sky without a word (the
    HPL of seed 001's MDSCC day at epoch 1 went from 11.90 to 12.62 m), e = 0.99 and an
    inclination of 50 rad were accepted. Each is now an error naming the file and the line of
    the element (the first block of the real January 2020 almanac edited)."""
    text = (shared_data / "almanac" / "almyuma_01jan2020.txt").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith(field))
    assert _line_of(text, line) == int(message.split()[1].rstrip(":"))
    p = tmp_path / "alm.txt"
    p.write_text(text.replace(line, f"{field:<28s}{bad}", 1))
    with pytest.raises(readers.AlmanacFileError, match=r"alm\.txt: " + message):
        geometry.read_yuma(p)


def test_orbit_limits_are_the_constellations_and_hold_every_real_orbit(shared_data, tmp_path):
    """A Galileo almanac with a GPS-sized orbit (26,560 km) is refused (the limits are per
    constellation), and so is a SEM record inside the Earth; every satellite of the real
    almanacs passes (GPS 2020 and MAAST's DO-229 file, Galileo ED-259)."""
    from oaraim.readers import ORBIT_LIMITS, implausible_orbit

    gal = (shared_data / "almanac" / "alm_gal_ed259.txt").read_text()
    line = next(ln for ln in gal.splitlines() if ln.startswith("SQRT(A)"))
    p = tmp_path / "gal.txt"
    p.write_text(gal.replace(line, "SQRT(A)  (m 1/2):           5153.6", 1))
    with pytest.raises(readers.AlmanacFileError,
                       match=rf"gal\.txt: line {_line_of(gal, line)}: satellite \d+: sqrt\(A\) = "
                       r"5153\.6 m\^1/2 is a semi-major axis of 26,560 km, not a Galileo orbit"):
        geometry.read_yuma(p, system="E")
    p = tmp_path / "x.al3"
    p.write_text("1 X.AL3\n703 344064\n\n1\n31\n0\n 0.0 0.0056 0\n 1000.0 0 0\n 0 0 0\n0\n9\n")
    with pytest.raises(readers.AlmanacFileError, match=r"x\.al3: line 8: satellite 1: sqrt\(A\) "
                       r"= 1000\.0"):
        geometry.read_sem(p)
    p.write_text("1 X.AL3\n703 344064\n\n1\n31\n0\n 0.0 0.0056 0\n 5153.6 0 0\n 0 0 0\n0\n9\n")
    assert geometry.read_sem(p).prns.tolist() == ["G01"]  # the same record, a GPS orbit
    for name, system in (("almyuma_01jan2020.txt", "G"), ("almmops.txt", "G"),
                         ("alm_gal_ed259.txt", "E")):
        r = geometry.read_yuma(shared_data / "almanac" / name, system=system).records
        for k in range(r.prn.size):
            assert implausible_orbit(system, r.sqrt_a[k], r.e[k], r.i_rad[k]) is None
    # the limits by hand: GPS a = 26,560 km +- 1,000 km, so sqrt(A) 5055.7 .. 5249.8
    lo, hi = ORBIT_LIMITS["G"].a_m
    assert implausible_orbit("G", np.sqrt(lo) * (1 + 1e-9), 0.0, 0.96) is None
    assert implausible_orbit("G", np.sqrt(lo) * (1 - 1e-9), 0.0, 0.96)[0] == "sqrt_a"
    assert implausible_orbit("G", np.sqrt(hi) * (1 + 1e-9), 0.0, 0.96)[0] == "sqrt_a"
    assert implausible_orbit("E", 5289.3, 0.16, np.radians(49.8)) is None  # E14 / E18
    assert implausible_orbit("G", 5153.6, 0.16, 0.96)[0] == "e"  # but not for GPS
