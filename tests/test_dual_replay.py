"""The dual-frequency GPS + Galileo ARAIM user of ``rinex-replay`` on the real RINEX 3 files
(TLSE 2024 hour, NIST 2023 first hour): ionosphere-free pairs, one clock per constellation,
the ISM per constellation, the summary numbers pinned."""

import numpy as np
import pytest

from oaraim import araim, errors
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
        float(errors.iono_free_factor()), rel=1e-12)
    assert dual_replay.parse_ism("g", dual_replay.ISM_GALILEO_TEXT) == araim.ISM_GALILEO
    with pytest.raises(ValueError, match="g must be SIGMA_URA_M,B_NOM_M,P_SAT,P_CONST"):
        dual_replay.parse_ism("g", "1,2")
    with pytest.raises(ValueError, match="gps_pair must be one of l1l5, l1l5-raw, l1l2"):
        dfq.iono_free(None, gps_pair="l2l5")


def _table(c1c, c2w, c5q):
    """A GPS-only observation table of three satellites from (T, 3) code arrays."""
    from oaraim.readers import ObservationTable

    t = np.arange(c1c.shape[0]) * 30.0
    return ObservationTable(t, np.array(["G01", "G02", "G03"]), {"G": ("C1C", "C2W", "C5Q")},
                            {"C1C": c1c, "C2W": c2w, "C5Q": c5q}, {}, np.arange(t.size),
                            np.zeros(t.size, int), None, 30.0, 3.04, "TEST", ("x",))


def test_l5_offsets_refer_l1l5_to_l1l2_by_hand():
    """Codes built from one range r and per-signal biases: P_IF(L1/L5) - P_IF(L1/L2) =
    g15 b1 - h15 b5 - (g12 b1 - h12 b2) with g = f1^2/(f1^2 - f2^2), h = f2^2/(f1^2 - f2^2)
    (ionosphere removed by both). G01: b = (0, 0, 2) m -> -h15 2 = -2.522 m; G02 never has
    C2W (offset NaN, L1/L5 uncorrected); G03 has no L5 (L1/L2). After the offset, G01's L1/L5
    equals its L1/L2 to the noise: the L1/L2 reference of the LNAV clock."""
    rng = np.random.default_rng(1)
    r = 2.2e7 + np.zeros((50, 3))
    iono_l1 = 5.0 + rng.normal(0, 0.1, (50, 1))  # metres on L1, scaled by (f1/f)^2
    f1, f2, f5 = dfq.F_L1_HZ, dfq.F_L2_HZ, dfq.F_L5_HZ
    b1, b2, b5 = 0.0, 0.0, np.array([2.0, 0.0, 0.0])
    c1c = r + iono_l1 + b1
    c2w = r + iono_l1 * (f1 / f2) ** 2 + b2
    c5q = r + iono_l1 * (f1 / f5) ** 2 + b5
    c2w[:, 1] = np.nan
    c5q[:, 2] = np.nan
    tab = _table(c1c, c2w, c5q)
    h15 = f5**2 / (f1**2 - f5**2)
    off = dfq.l5_offsets_m(tab)
    assert off[0] == pytest.approx(-h15 * 2.0, abs=1e-6) == pytest.approx(-2.522, abs=1e-3)
    assert np.isnan(off[1]) and np.isnan(off[2])
    iof = dfq.iono_free(tab)
    np.testing.assert_array_equal(iof.combination[0], [dfq.GPS_L1L5, dfq.GPS_L1L5,
                                                       dfq.GPS_L1L2])
    np.testing.assert_allclose(iof.pseudorange_m[:, 0], r[:, 0], atol=1e-6)  # bias removed
    np.testing.assert_allclose(iof.pseudorange_m[:, 2], r[:, 2], atol=1e-6)
    raw = dfq.iono_free(tab, "l1l5-raw")
    np.testing.assert_allclose(raw.pseudorange_m[:, 0], r[:, 0] - h15 * 2.0, atol=1e-6)
    assert np.isnan(raw.l5_offset_m).all() and np.isnan(iof.l5_offset_m[1])


def test_uncorrected_l1l5_biases_break_the_real_day(shared_data):
    """Without the L1/L5 offsets (l1l5-raw) the TLSE hour has metres of inter-signal bias
    between GPS blocks (IIF +4.9 to +7.4 m, III -1.1 to -0.3 m against L1/L2): the MHSS
    detects at every epoch; referred to L1/L2 (the default) it detects nothing."""
    raw = _run(shared_data, TLSE, 120, gps_pair="l1l5-raw").metrics
    ref = _run(shared_data, TLSE, 120).metrics
    assert raw["detections_mhss"] == 120 and ref["detections_mhss"] == 0
    assert raw["gps_l5_uncorrected"] and not ref["gps_l5_uncorrected"]
    off = ref["gps_l5_offset_removed_m"]
    assert off["G10"] == pytest.approx(7.39, abs=0.05) and off["G23"] == pytest.approx(
        -0.31, abs=0.05)


def _run(shared_data, files, n, **sets):
    study = STUDIES["rinex-replay"]
    params = study.validate({"obs": str(shared_data / files[0]),
                             "nav": str(shared_data / files[1])} | sets)
    return study.run(params, n, 0, None)


@pytest.mark.parametrize(("files", "pinned"), [
    # TLSE 2024-01-01 18:00-19:00 (120 epochs): GPS L1/L5 32 %, L1/L2 26 %, E1/E5a 42 %;
    # L1/L5 referred to L1/L2 (dual_frequency.l5_offsets_m), ED-259A airborne model
    (TLSE, {"hpe_median_m": 0.769, "hpe_max_m": 1.627, "vpe_median_m": 1.067,
            "vpe_max_m": 1.973, "hpl_median_m": 11.85, "vpl_median_m": 15.21,
            "lpv200_available_pct": 100.0, "detections_mhss": 0}),
    # NIST 2023-01-01, its first 120 epochs: GPS L1/L5 21 %, L1/L2 29 %, E1/E5a 50 %
    (NIST, {"hpe_median_m": 0.414, "hpe_max_m": 1.512, "vpe_median_m": 0.801,
            "vpe_max_m": 2.990, "hpl_median_m": 9.410, "vpl_median_m": 11.34,
            "lpv200_available_pct": 100.0, "detections_mhss": 0}),
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
    np.testing.assert_allclose(add15, errors.sigma_user_airborne_m(el), rtol=1e-12)
    np.testing.assert_allclose(dual_replay.user_sigma_m(el, np.full(3, f12)), add15 * f12 / f15)
    ed = dual_replay.user_sigma_m(el, np.full(3, f15), "ed259a")
    np.testing.assert_allclose(ed, errors.sigma_user_ed259a_m(el), rtol=1e-12)
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


def _hide_codes(src, dst, subs):
    """``src`` CRINEX decompressed to ``dst`` with GPS observation codes renamed in the header
    (``subs``: (old, new) pairs; a renamed code is one the replay does not use), the data
    untouched."""
    import hatanaka

    text = hatanaka.decompress(src.read_bytes()).decode()
    end = text.index("END OF HEADER")
    out, system = [], ""
    for line in text[:end].split("\n"):
        if "SYS / # / OBS TYPES" in line:
            system = line[0] if line[0] != " " else system
            if system == "G":
                for old, new in subs:
                    line = line.replace(old, new)
        out.append(line)
    dst.write_text("\n".join(out) + text[end:])
    return dst


@pytest.mark.parametrize(("subs", "detections", "uncorrected"), [
    ((("C2W", "C2Z"),), 0, []),
    ((("C2W", "C2Z"), ("C2X", "C2Y")), 107, ["G04", "G18", "G23", "G25", "G26", "G28"]),
], ids=["no-C2W", "no-L2"])
def test_receivers_without_semicodeless_l2(shared_data, tmp_path, subs, detections,
                                           uncorrected):
    """The TLSE hour as a receiver without C2W would record it: L2C (C2X) takes its place in
    L1/L2 and refers L1/L5 to it (no detection). Without any L2 code the L1/L5 offsets cannot
    be removed: the satellites are listed and a warning says so (measured 107 detections, 0
    misleading epochs)."""
    obs = _hide_codes(shared_data / TLSE[0], tmp_path / "TEST00FRA_R_20240011800_01H_30S_MO.rnx",
                      subs)
    study = STUDIES["rinex-replay"]
    params = study.validate({"obs": str(obs), "nav": str(shared_data / TLSE[1])})
    if uncorrected:
        with pytest.warns(UserWarning, match="have L5 but no L2 code"):
            m = study.run(params, 120, 0, None).metrics
    else:
        m = study.run(params, 120, 0, None).metrics
    assert m["detections_mhss"] == detections
    assert m["gps_l5_uncorrected"] == uncorrected
    assert m["misleading_information_epochs"] == 0
    assert ("GPS L1/L2" in m["combination"]) == (not uncorrected)
