"""``availability-map --set leo=...``: a LEO constellation as one SOP constellation beside GPS
and Galileo. Its LEO slots against the LEO sky of ``geometry.leo_sky`` (the n of highest
elevation), the map without LEO stored beside equal to a run without LEO (bit for bit), LEO
of GPS-like quality lowering the PLs, one clock per LEO satellite never lowering them (seed
004 Theorem 1), and the one-line refusals."""

import numpy as np
import pytest

from oaraim import geometry
from oaraim.registry import STUDIES
from oaraim.studies.availability_map import leo as leo_option

STUDY = STUDIES["availability-map"]
#: one latitude row of three longitudes x 4 epochs; 4 LEO slots at small priors (order 1:
#: one compiled program of ~26 sources)
SMALL = {"lat_deg": "45", "lon_deg": "-120,0,140", "duration_s": "3600", "step_s": "900",
         "leo": "starlink", "leo_max": "4", "p_s_leo": "1e-6", "p_const_leo": "1e-6"}


@pytest.fixture(scope="module")
def with_leo(shared_data):
    p = STUDY.validate(SMALL)
    return p, STUDY.run(p, STUDY.fixed_realizations(p), 0)


def test_leo_slots_are_the_highest_in_view(with_leo):
    p, _ = with_leo
    slots = leo_option.leo_slots(p, 45.0, 4)
    ecef, ok, _ = leo_option.leo_orbits("starlink", 3600.0, 900.0)
    for j, lon in enumerate(p["lon_deg"]):
        rx = np.asarray(geometry.geodetic_to_ecef(np.deg2rad(45.0), np.deg2rad(lon), 0.0))
        _, el, _, v = (np.asarray(x) for x in geometry.look_angles(
            rx, ecef, ok, np.deg2rad(p["leo_mask_deg"])))
        for t in range(el.shape[0]):
            want = np.sort(el[t][v[t]])[::-1][:4]
            got = np.asarray(slots["el"][j, t])[np.asarray(slots["valid"][j, t])]
            np.testing.assert_allclose(got, want, atol=1e-12)


def test_map_with_leo_lowers_the_pls_and_keeps_the_gnss_map(with_leo, shared_data):
    p, res = with_leo
    ds = res.dataset
    assert res.metrics["leo_slots"] == 4
    assert float(ds.n_sops.mean()) > 3.0  # Starlink shell 1 at 45 N: >= 4 above 25 deg
    # the map without LEO beside it is the map of a run without LEO, bit for bit
    q = STUDY.validate({k: v for k, v in SMALL.items() if not k.startswith(("leo", "p_"))})
    base = STUDY.run(q, STUDY.fixed_realizations(q), 0).dataset
    np.testing.assert_array_equal(ds.vpl_m_gnss.values, base.vpl_m.values)
    np.testing.assert_array_equal(ds.hpl_m_gnss.values, base.hpl_m.values)
    fin = np.isfinite(ds.vpl_m.values) & np.isfinite(ds.vpl_m_gnss.values)
    assert fin.all()
    assert np.all(ds.vpl_m.values < ds.vpl_m_gnss.values)  # 4 GPS-like ranges always help
    assert np.all(ds.hpl_m.values < ds.hpl_m_gnss.values)


def test_one_clock_per_leo_satellite_never_lowers_the_map_pls(shared_data):
    p = STUDY.validate({**SMALL, "leo_clocks": "satellite"})
    ds = STUDY.run(p, STUDY.fixed_realizations(p), 0).dataset
    assert np.all(ds.vpl_m.values >= ds.vpl_m_gnss.values - 2e-3)
    assert np.all(ds.hpl_m.values >= ds.hpl_m_gnss.values - 2e-3)


def test_leo_refusals():
    with pytest.raises(ValueError, match="leo must be one of none, starlink"):
        STUDY.validate({"leo": "starlunk"})
    with pytest.raises(ValueError, match="give either leo=... or towers"):
        STUDY.validate({"leo": "oneweb", "sops_per_km2": "1"})
