"""The one-call epoch API (``araim.epoch_protection_levels``) and the ephemeris-coverage check
it shares (``geometry.ephemeris_gaps``).

The API is checked against the route a user takes by hand (``geometry.sky`` rows into
``araim.protection_levels``), on the case that tripped that route (a 50-satellite mixed file
and three towers: 53 padded slots against ``add-v4.2``'s 52), and its getting-started example
runs and prints what the page says."""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from oaraim import araim, geometry
from oaraim.araim import Status
from oaraim.errors import gnss_variances, sigma_user_ed259a_m
from oaraim.readers import gpstime

ROOT = Path(__file__).resolve().parents[1]
VILL = "nav/VILL00ESP_R_20181700000_01D_MN.rnx.gz"  # 32 GPS + 18 Galileo, 2018-06-19
MADRID = (40.43, -4.25, 840.0)
T_10H = gpstime.gps_seconds(2018, 6, 19, 10)
TOWERS = [(40.44, -4.24, 30.0, "A"), (40.42, -4.26, 25.0, "A"), (40.435, -4.27, 40.0, "B")]


@pytest.fixture(scope="module")
def vill(shared_data):
    return geometry.load_navigation(shared_data / VILL)


def test_gnss_epoch_equals_the_route_by_hand(vill):
    """Two epochs, GNSS only: the same PLs as ``geometry.sky`` + ``protection_levels`` on the
    padded sky (ED-259A airborne model, ISM defaults), to the root finder's 1e-4 m (the
    compacted and the padded arrays differ in length, so in rounding only); ids are the
    file's names of the satellites in view."""
    t = T_10H + np.array([0.0, 600.0])
    r = araim.epoch_protection_levels(*MADRID, t, vill,
                                      options=araim.EpochOptions(mhss=araim.MHSSOptions(1)))
    rx = geometry.geodetic_to_ecef(np.deg2rad(MADRID[0]), np.deg2rad(MADRID[1]), MADRID[2])
    s = geometry.sky(rx, t, vill, mask_deg=5.0)
    el = np.where(s.valid, s.el_rad, np.pi / 2)
    vi, va = gnss_variances(el, 1.0, user_model=sigma_user_ed259a_m)
    by_hand = araim.protection_levels(araim.Sources(geometry.geometry_rows(s.az_rad, s.el_rad),
                                                    s.constellation, vi, va, 0.75, 1e-5, s.valid),
                                      np.array([1e-8, 1e-4]), araim.BUDGET_LPV200,
                                      araim.MHSSOptions(1, fault_modes="add-v4.2"))
    for k in ("hpl_m", "vpl_m", "emt_m", "sigma_acc_u_m"):
        np.testing.assert_allclose(getattr(r.pl, k), getattr(by_hand, k), atol=1e-4)
    np.testing.assert_array_equal(r.pl.status, by_hand.status)
    np.testing.assert_array_equal(r.pl.n_modes, by_hand.n_modes)
    for i in range(2):
        assert sorted(r.sources[i]) == sorted(s.sv[np.asarray(s.valid)[i]].tolist())
        assert all(re.fullmatch(r"[GE]\d\d", x) for x in r.sources[i])
    assert r.n_sources.tolist() == np.asarray(s.valid).sum(-1).tolist()
    assert r.constellations == ("GPS", "Galileo")


def test_fifty_satellites_and_three_towers(vill):
    """The case that stopped inside JAX: 50 satellites in the file, 3 towers, ``add-v4.2``.
    Padded by hand that is 53 slots (refused: the convention takes 52); compacted to the
    sources in view it runs: finite PLs, the towers T1-T3 in two SOP constellations, and the
    lone tower of carrier B monitored (one mode more than with carrier A's two)."""
    rx = geometry.geodetic_to_ecef(np.deg2rad(MADRID[0]), np.deg2rad(MADRID[1]), MADRID[2])
    s = geometry.sky(rx, T_10H, vill)
    assert s.sv.size == 50
    with pytest.raises(ValueError, match="at most 52 sources"):
        araim.protection_levels(araim.Sources(np.zeros((53, 3)), np.zeros(53, int), np.ones(53),
                                              np.ones(53), 0.0, 1e-5), np.full(4, 1e-4),
                                araim.BUDGET_LPV200, araim.MHSSOptions(1, fault_modes="add-v4.2"))
    r = araim.epoch_protection_levels(*MADRID, T_10H, vill, TOWERS,
                                      options=araim.EpochOptions(mhss=araim.MHSSOptions(2)))
    assert int(r.pl.status) == Status.OK and np.isfinite(r.pl.vpl_m)
    assert r.sources[-3:] == ("T1", "T2", "T3") and r.n_sources == len(r.sources) == 17
    assert r.constellations == ("GPS", "Galileo", "SOP A", "SOP B")
    two = araim.epoch_protection_levels(*MADRID, T_10H, vill, TOWERS[:2],
                                        options=araim.EpochOptions(mhss=araim.MHSSOptions(2)))
    assert int(two.pl.status) == Status.OK
    assert int(r.pl.n_modes) > int(two.pl.n_modes)
    assert float(r.pl.vpl_m) >= float(two.pl.vpl_m) - 2e-3  # a lone carrier adds no position


def test_options_reach_the_levels(vill):
    """budget, mask, ISM and airborne model change what they should: a looser sigma_URA raises
    the VPL, a 20 deg mask drops satellites, the ADD curve differs from ED-259A."""
    base = araim.epoch_protection_levels(*MADRID, T_10H, vill,
                                         options=araim.EpochOptions(mhss=araim.MHSSOptions(1)))
    loose = {"gps": araim.Ism(sigma_ura_m=2.0)}
    worse = araim.epoch_protection_levels(*MADRID, T_10H, vill,
                                          options=araim.EpochOptions(ism=loose,
                                                                     mhss=araim.MHSSOptions(1)))
    assert float(worse.pl.vpl_m) > float(base.pl.vpl_m)
    high = araim.epoch_protection_levels(*MADRID, T_10H, vill,
                                         options=araim.EpochOptions(mask_deg=20.0,
                                                                    mhss=araim.MHSSOptions(1)))
    assert high.n_sources < base.n_sources and min(high.el_deg) >= 20.0
    add = araim.epoch_protection_levels(*MADRID, T_10H, vill,
                                        options=araim.EpochOptions(airborne_model="add",
                                                                   mhss=araim.MHSSOptions(1)))
    assert abs(float(add.pl.vpl_m) - float(base.pl.vpl_m)) > 0.01


@pytest.mark.parametrize("kwargs, message", [
    (dict(lat_deg=100.0), r"lat_deg must be a number in \[-90.0, 90.0\], got 100.0"),
    (dict(mask_deg="low"), r"mask_deg must be a number in \[0.0, 90.0\], got 'low'"),
    (dict(towers=[(40.44, -4.24, 30.0, "A"), (40.44 + 1e-9, -4.24, 30.0, "A")]),
     r"towers rows 1 and 2: carrier 'A' twice within 1 m"),
    (dict(towers=[(40.4, -4.2, 30.0)]), r"towers row 1: \(lat_deg, lon_deg, height_m, carrier\)"),
    (dict(towers="towers.csv"), "read a tower CSV first"),
    (dict(ism={"gps": 1.0}), r"ism\['gps'\] must be an araim.Ism"),
    (dict(airborne_model="do229"), "airborne_model must be one of add, ed259a"),
    (dict(fault_modes="add-v5"), "fault_modes must be"),
])
def test_bad_input_is_one_line(kwargs, message):
    kwargs = dict(kwargs)
    opts = {k: kwargs.pop(k) for k in list(kwargs) if k in araim.EpochOptions._fields}
    if "fault_modes" in kwargs:
        opts["mhss"] = araim.MHSSOptions(fault_modes=kwargs.pop("fault_modes"))
    args = dict(lat_deg=MADRID[0], lon_deg=MADRID[1], h_m=MADRID[2], t_gps_s=0.0,
                sky="nominal") | kwargs
    if opts:
        args["options"] = araim.EpochOptions(**opts)
    with pytest.raises(ValueError, match=message) as e:
        araim.epoch_protection_levels(**args)
    assert "\n" not in str(e.value)


def test_ephemeris_gaps_by_hand():
    """Per constellation: an epoch with none, or fewer than half of the most at any epoch."""
    usable = np.array([[1, 1, 1, 1, 1, 1],
                       [1, 1, 0, 1, 1, 0],   # GPS 2 of 3 (>= 1.5): fine
                       [1, 0, 0, 1, 1, 1],   # GPS 1 of 3: a gap
                       [0, 0, 0, 1, 1, 1]], bool)  # GPS none: a gap
    cons = np.array([0, 0, 0, 1, 1, 1])
    assert geometry.ephemeris_gaps(usable, cons).tolist() == [False, False, True, True]
    assert not geometry.ephemeris_gaps(usable[:1], cons).any()
    assert geometry.ephemeris_gaps(np.zeros((1, 6), bool), cons).all()


def test_a_file_cut_short_is_refused(tmp_path, shared_data):
    """A RINEX 2 file cut at a record boundary after 40 records (it loads: its layout is
    valid) covers the first hours of its day only: a day of epochs is refused in one line
    naming the count; ``allow_gaps`` keeps them, with too few sources there; the real file's
    whole day has no gap."""
    lines = (shared_data / "nav/brdc0010.22n").read_text().splitlines(keepends=True)
    head = next(i for i, x in enumerate(lines) if "END OF HEADER" in x) + 1
    cut = tmp_path / "brdc0010.22n"
    cut.write_text("".join(lines[:head + 8 * 40]))
    t = gpstime.gps_seconds(2022, 1, 1) + 1800.0 * np.arange(48)
    with pytest.raises(ValueError, match=r"no usable orbits for most satellites at \d+ of 48 "
                       r"epochs .*allow_gaps=True") as e:
        araim.epoch_protection_levels(*MADRID, t, str(cut),
                                      options=araim.EpochOptions(mhss=araim.MHSSOptions(1)))
    assert "\n" not in str(e.value)
    r = araim.epoch_protection_levels(*MADRID, t, str(cut),
                                      options=araim.EpochOptions(allow_gaps=True,
                                                                 mhss=araim.MHSSOptions(1)))
    assert np.any(r.pl.status == Status.TOO_FEW_SOURCES) and np.any(r.pl.status == Status.OK)
    assert np.all(np.isinf(r.pl.vpl_m[r.pl.status == Status.TOO_FEW_SOURCES]))
    whole = araim.epoch_protection_levels(*MADRID, t, shared_data / "nav/brdc0010.22n",
                                          options=araim.EpochOptions(mhss=araim.MHSSOptions(1)))
    assert whole.n_sources.min() >= 5


def test_getting_started_example_prints_what_the_page_says(shared_data):
    text = (ROOT / "docs/getting-started.md").read_text()
    section = text.split("### Protection levels of a receiver in one call", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    claimed = section.split("which prints\n\n```\n", 1)[1].split("```", 1)[0]
    env = os.environ | {"OARAIM_DATA": str(shared_data)}
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       timeout=600, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == claimed.strip()
