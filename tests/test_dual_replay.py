"""The dual-frequency GPS + Galileo ARAIM user of ``rinex-replay`` on the real RINEX 3 files
(TLSE 2024 hour, NIST 2023 first hour): ionosphere-free pairs, one clock per constellation,
the ISM per constellation, the summary numbers pinned."""

import numpy as np
import pytest

from oaraim import araim
from oaraim.geometry import dual_frequency as dfq
from oaraim.registry import STUDIES
from oaraim.studies.common import dual_replay

TLSE = ("obs3/TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz",
        "obs3/BRDC00IGS_R_20240010000_01D_MN.rnx.gz")
NIST = ("obs3/NIST00USA_R_20230010000_01D_30S_MO.crx.gz",
        "obs3/BRDC00IGS_R_20230010000_01D_MN.rnx.gz")


def test_iono_free_factors_and_parse_ism():
    """The factors of the pairs (2.98 L1/L2, 2.59 L1/L5 and E1/E5a), equal to the ADD's."""
    assert dfq.factor(dfq.F_L1_HZ, dfq.F_L2_HZ) == pytest.approx(2.978, abs=1e-3)
    assert dfq.factor(dfq.F_L1_HZ, dfq.F_L5_HZ) == pytest.approx(
        float(araim.error_models.iono_free_factor()), rel=1e-12)
    assert dual_replay.parse_ism("g", dual_replay.ISM_GALILEO_TEXT) == araim.ISM_GALILEO
    with pytest.raises(ValueError, match="g must be SIGMA_URA_M,B_NOM_M,P_SAT,P_CONST"):
        dual_replay.parse_ism("g", "1,2")
    with pytest.raises(ValueError, match="gps_pair"):
        dfq.iono_free(None, gps_pair="l2l5")


def _run(shared_data, files, n, **sets):
    study = STUDIES["rinex-replay"]
    params = study.validate({"obs": str(shared_data / files[0]),
                             "nav": str(shared_data / files[1])} | sets)
    return study.run(params, n, 0, None)


@pytest.mark.parametrize(("files", "pinned"), [
    # TLSE 2024-01-01 18:00-19:00 (120 epochs): GPS L1/L5 32 %, L1/L2 26 %, E1/E5a 42 %
    (TLSE, {"hpe_median_m": 1.295, "hpe_max_m": 2.155, "vpe_median_m": 0.561,
            "vpe_max_m": 2.890, "hpl_median_m": 12.16, "vpl_median_m": 16.93,
            "lpv200_available_pct": 97.5}),
    # NIST 2023-01-01, its first 120 epochs: GPS L1/L5 21 %, L1/L2 29 %, E1/E5a 50 %
    (NIST, {"hpe_median_m": 0.601, "hpe_max_m": 2.085, "vpe_median_m": 2.453,
            "vpe_max_m": 4.600, "hpl_median_m": 10.04, "vpl_median_m": 12.50,
            "lpv200_available_pct": 100.0}),
], ids=["TLSE", "NIST"])
def test_dual_frequency_replay_by_default(shared_data, files, pinned):
    """Only obs and nav given: GPS + Galileo dual-frequency is chosen, 0 misleading epochs,
    the main summary numbers pinned (measured; 1 % room for platform arithmetic)."""
    res = _run(shared_data, files, 120)
    m = res.metrics
    assert m["epochs"] == 120 and m["epochs_solved"] == 120
    assert m["constellations"] == ["GPS", "Galileo"]
    assert m["combination"].startswith("dual-frequency ionosphere-free GPS + Galileo")
    assert m["misleading_information_epochs"] == 0
    assert m["satellites_used_median_per_constellation"]["Galileo"] >= 4
    comb = res.dataset["combination"].values
    assert set(np.unique(comb)) <= {0, dfq.GPS_L1L5, dfq.GPS_L1L2, dfq.GAL_E1E5A}
    for k, v in (pinned or {}).items():
        assert m[k] == pytest.approx(v, rel=1e-2, abs=0.01), k


def test_airborne_models_scale_with_the_pair():
    """ADD: the L1 curves times the pair's factor; ED-259A: its own curve, times 2.98 / 2.59
    for L1/L2 only."""
    el = np.deg2rad(np.array([5.0, 30.0, 90.0]))
    f15 = dfq.factor(dfq.F_L1_HZ, dfq.F_L5_HZ)
    f12 = dfq.factor(dfq.F_L1_HZ, dfq.F_L2_HZ)
    add15 = dual_replay.user_sigma_m(el, np.full(3, f15))
    np.testing.assert_allclose(add15, araim.error_models.sigma_user_airborne_m(el), rtol=1e-12)
    np.testing.assert_allclose(dual_replay.user_sigma_m(el, np.full(3, f12)), add15 * f12 / f15)
    ed = dual_replay.user_sigma_m(el, np.full(3, f15), "ed259a")
    np.testing.assert_allclose(ed, araim.error_models.sigma_user_ed259a_m(el), rtol=1e-12)
    np.testing.assert_allclose(dual_replay.user_sigma_m(el, np.full(3, f12), "ed259a"),
                               ed * f12 / f15)


def test_dual_on_a_single_frequency_file_is_one_line(shared_data):
    """signals=dual on the 2005 RINEX 2 file (C1, P2: no RINEX 3 pair) names the fix; auto
    keeps the GPS L1 user there (its numbers: tests/test_rinex_replay.py)."""
    obs = shared_data / "obs" / "07590920.05o"
    study = STUDIES["rinex-replay"]
    params = study.validate({"obs": str(obs), "nav": str(obs.with_suffix(".05n")),
                             "signals": "dual"})
    with pytest.raises(ValueError, match="07590920.05o: no dual-frequency code pair.*"
                                         "signals=gps-l1"):
        study.run(params, 10, 0, None)


def test_single_frequency_gps_galileo_option(shared_data):
    """signals=single on TLSE: GPS L1 (T_GD) + Galileo E1 (I/NAV clock, BGD(E1,E5b)),
    Klobuchar on both (a stand-in for NeQuick-G, said in iono_model); measured median HPE
    0.392 m (the GPS L1 user: 0.387 m), HPL 59.6 m (sigma_iono of DO-229), 0 MI."""
    m = _run(shared_data, TLSE, 120, signals="single").metrics
    assert m["constellations"] == ["GPS", "Galileo"]
    assert m["combination"].startswith("single-frequency GPS + Galileo")
    assert "NeQuick-G (not implemented)" in m["iono_model"]
    assert m["hpe_median_m"] == pytest.approx(0.392, abs=0.01)
    assert m["hpl_median_m"] == pytest.approx(59.57, rel=1e-2)
    assert m["misleading_information_epochs"] == 0
