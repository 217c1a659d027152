"""RINEX observation reading, the real-data pseudorange model and the ``rinex-replay`` study.

Tests that need the shared files take the ``shared_data`` fixture (skip without the data, fail
under OARAIM_REQUIRE_DATA=1)."""

import numpy as np
import pytest

from oaraim import araim, geometry, readers
from oaraim.constants import C_M_S
from oaraim.geometry import pseudorange_model as prm
from oaraim.readers import navigation_extras, rinex_obs, tgd_at
from oaraim.registry import STUDIES
from oaraim.studies import rinex_replay

STATIONS = ("07590920", "30400920")


# --------------------------------------------------------------------------- errors, no data


def test_missing_obs_file_names_it(tmp_path):
    with pytest.raises(rinex_obs.ObservationFileError, match="nothere.05o.*not found"):
        rinex_obs.read_observations(tmp_path / "nothere.05o")


def _header(types_line, approx=True):
    lines = ["     2.11           OBSERVATION DATA    G (GPS)             RINEX VERSION / TYPE"]
    if approx:
        lines.append(" -3976219.5082  3382372.5671  3652512.9849                  "
                     "APPROX POSITION XYZ")
    lines.append(types_line)
    lines.append(" " * 60 + "END OF HEADER")
    return "\n".join(lines) + "\n"


def test_obs_file_errors_name_what_is_missing(tmp_path):
    nav_like = tmp_path / "a.05n"
    nav_like.write_text("     2.10           N: GPS NAV DATA                         "
                        "RINEX VERSION / TYPE\n" + " " * 60 + "END OF HEADER\n")
    with pytest.raises(ValueError, match="not a RINEX observation file"):
        rinex_obs.read_observations(nav_like)
    no_code = tmp_path / "b.05o"
    no_code.write_text(_header("     2    L1    L2" + " " * 42 + "# / TYPES OF OBSERV")
                       + " 05  4  2  0  0  0.0000000  0  1G 3\n  1.0  2.0\n")
    with pytest.raises(ValueError, match="b.05o: no GPS L1 code observable.*C1, P1"):
        rinex_obs.read_observations(no_code)
    empty = tmp_path / "c.05o"
    empty.write_text(_header("     2    C1    L1" + " " * 42 + "# / TYPES OF OBSERV"))
    with pytest.raises(ValueError, match="c.05o: .*no observation epochs"):
        rinex_obs.read_observations(empty)
    garbage = tmp_path / "d.05o"
    garbage.write_text("hello\n")
    with pytest.raises(ValueError, match="d.05o: line 1: not a RINEX header"):
        rinex_obs.read_observations(garbage)


def test_rinex3_observation_file(tmp_path):
    """RINEX 3 (mixed header, 'SYS / # / OBS TYPES'): C1C is read; epochs in GPS time."""
    lines = [
        "     3.03           OBSERVATION DATA    M                   RINEX VERSION / TYPE",
        " -3976219.5082  3382372.5671  3652512.9849                  APPROX POSITION XYZ",
        "G    3 C1C L1C C2W                                          SYS / # / OBS TYPES",
        "  2005     4     2     0     0    0.0000000     GPS         TIME OF FIRST OBS",
        "                                                            END OF HEADER",
        "> 2005 04 02 00 00  0.0000000  0  2",
        "G03  24767686.375 8  43647388.242 8  24767684.822 8",
        "G07  24361933.475 8   -537007.140 8  24361930.599 8",
        "> 2005 04 02 00 00 30.0000000  0  2",
        "G03  24795930.671 8  43763044.969 8  24795930.134 8",
        "G07  24359892.126 8   -545368.597 8  24359888.431 8"]
    path = tmp_path / "r3.05o"
    path.write_text("\n".join(lines) + "\n")
    obs = rinex_obs.read_observations(path)
    assert obs.code == "C1C" and obs.version == 3.03 and list(obs.sv) == ["G03", "G07"]
    np.testing.assert_array_equal(obs.pseudorange_m, [[24767686.375, 24361933.475],
                                                      [24795930.671, 24359892.126]])
    assert obs.t_gps_s[0] == readers.gpstime.gps_seconds(2005, 4, 2)
    assert obs.t_gps_s[1] - obs.t_gps_s[0] == 30.0


def test_study_without_data_says_how_to_give_files(tmp_path, monkeypatch):
    monkeypatch.setenv("OARAIM_DATA", str(tmp_path))  # an existing folder without the files
    study = STUDIES["rinex-replay"]
    with pytest.raises(ValueError, match=r"obs/07590920.05o is not in the folder OARAIM_DATA="
                       r".*--set obs=PATH --set nav=PATH"):
        study.run(study.validate({}), 10, 0, None)
    with pytest.raises(ValueError, match="obs must be 'auto' or an existing RINEX file"):
        study.validate({"obs": str(tmp_path / "x.05o")})
    with pytest.raises(ValueError, match="truth must be 'header' or X_M,Y_M,Z_M"):
        study.validate({"truth": "1,2"})
    with pytest.raises(ValueError, match="near the Earth's surface"):
        study.validate({"truth": "1,2,3"})
    assert study.validate({"truth": "-3976219.5,3382372.6,3652513"})["truth"][0] == -3976219.5


# --------------------------------------------------------------------------- strict reading


def _obs_lines(shared_data):
    """07590920.05o as lines: header lines 1-17, then epochs of 9 lines (8 satellites with one
    line each) from line 18."""
    return (shared_data / "obs" / "07590920.05o").read_text().split("\n")


def _write_obs(tmp_path, name, lines_or_bytes):
    p = tmp_path / name
    if isinstance(lines_or_bytes, bytes):
        p.write_bytes(lines_or_bytes)
    else:
        p.write_text("\n".join(lines_or_bytes))
    return p


def test_obs_file_cut_short_names_the_line(shared_data, tmp_path):
    """A file cut in half loaded 59 of 60 epochs without a word. Cut mid-line (a
    download cut short) or at a line break inside an epoch, it is now an error naming the line;
    lenient reading keeps the complete epochs and names the skipped one."""
    raw = (shared_data / "obs" / "07590920.05o").read_bytes()
    half = _write_obs(tmp_path, "half.05o", raw[:len(raw) // 2])
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=r"half\.05o: line 543: the last line does not end with a line "
                       "break: the file is truncated"):
        rinex_obs.read_observations(half)
    with pytest.warns(rinex_obs.ObservationFileWarning,
                      match=r"half\.05o: line 543: .*skipped the epoch at line 543"):
        obs = rinex_obs.read_observations(half, lenient=True)
    complete = sum(s.startswith(" 05  4  2") for s in raw.decode().split("\n")[:542])
    assert obs.t_gps_s.size == complete == 59 and len(obs.skipped) == 1
    lines = _obs_lines(shared_data)
    cut = _write_obs(tmp_path, "cut.05o", lines[:17 + 9 * 3 + 4] + [""])
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=r"cut\.05o: line 48: the file ends inside the epoch at line 45"):
        rinex_obs.read_observations(cut)


@pytest.mark.parametrize("minute", ["6x", "61"])
def test_garbled_epoch_time_names_the_line(shared_data, tmp_path, minute):
    """An epoch with a garbled time was dropped silently (119 of 120 epochs). Strict:
    an error naming line 63; lenient: the other 119 epochs and a warning naming line 63."""
    lines = _obs_lines(shared_data)
    assert lines[62].startswith(" 05  4  2  0  2 30.0000000")
    lines[62] = lines[62][:13] + minute + lines[62][15:]
    p = _write_obs(tmp_path, f"garbled{minute}.05o", lines)
    with pytest.raises(rinex_obs.ObservationFileError, match=r"garbled..\.05o: line 63: "):
        rinex_obs.read_observations(p)
    with pytest.warns(rinex_obs.ObservationFileWarning,
                      match=r"line 63: .*skipped the epoch at line 63 \(lines 63-71\)"):
        obs = rinex_obs.read_observations(p, lenient=True)
    assert obs.t_gps_s.size == 119 and 30.0 * 5 not in np.round(obs.t_gps_s - obs.t_gps_s[0])


@pytest.mark.parametrize("edit, message", [
    (lambda x: x[:26] + x[17:26] + x[26:],
     r"line 27: the epoch time is not later than that of the epoch at line 18 \(the same time\)"),
    (lambda x: x[:30] + x[31:],
     r"line 35: an epoch line where the epoch at line 27 has more observations \(8 satellites"),
    (lambda x: x[:20] + [x[20][:10] + "x" + x[20][11:]] + x[21:],
     r"line 21: columns 1-14: cannot read '17984490x035' as an observation"),
    (lambda x: x[:17] + [x[17][:32] + "G 3G 3" + x[17][38:]] + x[18:],
     r"line 18: satellite G03 is listed twice"),
    (lambda x: x[:11] + ["     x    L1    C1    L2    P2" + x[11][30:]] + x[12:],
     r"line 12: # / TYPES OF OBSERV: cannot read the number of observables 'x'"),
    (lambda x: x[:11] + [x[11][:30] + "    C1" + x[11][36:]] + x[12:],
     r"line 12: # / TYPES OF OBSERV: 4 observables announced, 5 listed"),
])
def test_malformed_obs_lines_name_the_line(shared_data, tmp_path, edit, message):
    """A duplicated epoch, a missing satellite line, a garbled value or satellite list, a bad
    observable count: each an ObservationFileError naming the file and line (before: silently
    re-sorted, misread or a bare ValueError without file)."""
    p = _write_obs(tmp_path, "edit.05o", edit(_obs_lines(shared_data)))
    with pytest.raises(rinex_obs.ObservationFileError, match=r"edit\.05o: " + message):
        rinex_obs.read_observations(p)


def test_obs_reader_matches_georinex_and_accepts_a_bom(shared_data, tmp_path):
    """Our reader against georinex (the reader used before) on both real files: the same
    satellites and C1 values; times equal to georinex's to its millisecond resolution
    (georinex truncates the time tags to ms; ours are exact). A UTF-8 byte-order mark is
    accepted."""
    import warnings

    import georinex

    for st in STATIONS:
        p = shared_data / "obs" / f"{st}.05o"
        obs = rinex_obs.read_observations(p)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ds = georinex.load(p, use="G", meas=["C1"])
        t_ref = readers.gpstime.from_datetime64(ds["time"].values)
        assert obs.t_gps_s.size == t_ref.size == 120
        assert np.all(np.abs(obs.t_gps_s - t_ref) < 1.001e-3)
        names = [str(s) for s in ds["sv"].values]
        for j, s in enumerate(obs.sv):
            ref = ds["C1"].values[:, names.index(s)]
            np.testing.assert_array_equal(obs.pseudorange_m[obs.valid[:, j], j],
                                          ref[obs.valid[:, j]])
    bom = _write_obs(tmp_path, "bom.05o", b"\xef\xbb\xbf" + p.read_bytes())
    same = rinex_obs.read_observations(bom)
    np.testing.assert_array_equal(same.pseudorange_m, obs.pseudorange_m)


def test_rinex_replay_bad_epoch_is_one_line_exit_2(shared_data, tmp_path):
    """The CLI passes a strict-reading error on as one line, exit status 2, no traceback, before
    any computation; with bad_epochs=skip the study runs on the other 119 epochs, warns with
    the line and counts the skipped epoch in its metrics."""
    from typer.testing import CliRunner

    from oaraim.cli import app

    lines = _obs_lines(shared_data)
    lines[62] = lines[62][:13] + "6x" + lines[62][15:]
    obs = _write_obs(tmp_path, "garbled.05o", lines)
    nav = shared_data / "obs" / "07590920.05n"
    res = CliRunner().invoke(app, ["run", "rinex-replay", "--set", f"obs={obs}", "--set",
                                   f"nav={nav}", "--out", str(tmp_path / "out")])
    assert res.exit_code == 2, res.output
    out = res.output.strip()
    assert "Traceback" not in out and "garbled.05o: line 63: expected an epoch line" in out
    study = STUDIES["rinex-replay"]
    with pytest.raises(ValueError, match="bad_epochs"):
        study.validate({"bad_epochs": "ignore"})
    params = study.validate({"obs": str(obs), "nav": str(nav), "bad_epochs": "skip"})
    with pytest.warns(rinex_obs.ObservationFileWarning, match="garbled.05o: line 63"):
        res = study.run(params, 2880, 0, None)
    assert res.metrics["skipped_epochs"] == 1 and res.metrics["epochs"] == 119


# --------------------------------------------------------------------------- shared data


@pytest.fixture(scope="module")
def station(shared_data):
    obs = rinex_obs.read_observations(shared_data / "obs" / "07590920.05o")
    nav = shared_data / "obs" / "07590920.05n"
    return obs, geometry.load_navigation(nav, systems=("G",)), navigation_extras(nav)


def test_read_observations_0759(station):
    obs, eph, extras = station
    assert obs.t_gps_s.size == 120 and obs.interval_s == 30.0 and obs.code == "C1"
    # receiver time tags: 30 s steps, drifting by up to 5 ms late in the hour (the receiver
    # clock; the transmit time from the pseudorange absorbs it)
    np.testing.assert_allclose(np.diff(obs.t_gps_s), 30.0, atol=2.1e-3)
    cut = rinex_obs.read_observations(obs.path, max_epochs=20)
    assert cut.t_gps_s.size == 20 and np.array_equal(cut.pseudorange_m, obs.pseudorange_m[:20])
    np.testing.assert_array_equal(obs.approx_position_m,
                                  [-3976219.5082, 3382372.5671, 3652512.9849])
    assert obs.sv.size == 11 and obs.marker == "0759"
    assert np.all(obs.pseudorange_m[obs.valid] > 1.9e7)
    assert not np.any(np.isnan(obs.pseudorange_m))
    # header ION ALPHA / ION BETA of 07590920.05n
    np.testing.assert_allclose(extras.alpha, [1.118e-8, 1.49e-8, -5.96e-8, -5.96e-8])
    np.testing.assert_allclose(extras.beta, [8.806e4, 1.638e4, -1.966e5, -1.311e5])
    tgd = tgd_at(extras, obs.sv, obs.t_gps_s)
    # T_GD of these satellites: -1.4 to -21.4 ns (0.4-6.4 m): it matters for L1 users
    assert np.all((tgd < 0) & (tgd > -3e-8))


def synthetic_pseudoranges(obs, eph, extras, x, clock_s):
    """Exact L1 C/A pseudoranges from the broadcast orbits for a receiver at x whose clock is
    ``clock_s`` (T,) ahead: light-time equation with the Earth's rotation during transit,
    satellite clock with the relativistic term and T_GD, Klobuchar and MOPS delays."""
    t = obs.t_gps_s
    sv = obs.sv  # the file's satellites (the same array shapes as the real replay)
    t_true = t - clock_s
    tgd = tgd_at(extras, sv, t)
    pr = np.zeros((t.size, sv.size))
    ok = np.zeros(pr.shape, bool)
    sat_tx = np.zeros(pr.shape + (3,))
    for j, s in enumerate(sv):
        tau = np.full(t.size, 0.075)
        for _ in range(6):
            st = eph.sat_state(t_true - tau, prns=[str(s)])
            p = np.asarray(st.ecef_m)[:, 0]
            rot = np.asarray(geometry.earth_rotation_correction(p, tau))
            tau = np.linalg.norm(rot - x, axis=-1) / C_M_S
        ok[:, j] = np.asarray(st.valid)[:, 0]
        sat_tx[:, j] = p
        pr[:, j] = C_M_S * (tau + clock_s - (np.asarray(st.clock_s)[:, 0] - tgd[:, j]))
    rt = prm.receiver_terms(np.broadcast_to(x, (t.size, 3)), sat_tx, t, extras.alpha,
                                  extras.beta)
    ok &= np.asarray(rt.el_rad) > 0
    pr = pr + np.asarray(rt.iono_m) + np.asarray(rt.tropo_m)
    return obs._replace(pseudorange_m=np.where(ok, pr, 0.0), valid=ok)


def test_measurement_model_recovers_position_to_a_millimetre(station):
    """Exact synthetic pseudoranges (transmit time, Sagnac, broadcast clock + relativistic +
    T_GD, Klobuchar, MOPS) at the station with a 0.25 ms receiver clock: the replay gives the
    position back to < 1 mm (measured 0.1 mm: float64 GPS seconds resolve 1e-7 s). Leaving out
    the Earth rotation during transit moves it by metres (the model is tested, not bypassed)."""
    obs, eph, extras = station
    x = obs.approx_position_m
    clock = 2.5e-4 + 1e-9 * (obs.t_gps_s - obs.t_gps_s[0])
    syn = synthetic_pseudoranges(obs, eph, extras, x, clock)
    inp = rinex_replay.gnss_replay_inputs(syn, eph, extras, mask_deg=5.0)
    assert inp["valid"].sum(-1).min() >= 7
    params = STUDIES["rinex-replay"].validate({})
    out = rinex_replay.replay_blocks(inp, x, params, max_order=1)
    assert np.max(out["hpe_m"]) < 1e-3 and np.max(out["vpe_m"]) < 1e-3
    assert np.max(np.abs(out["residual_m"])) < 1e-3
    assert np.all(np.isfinite(out["hpl_mhss_m"])) and not np.any(out["mhss_detected"])
    # the same pseudoranges with satellites left in their transmit-time frame
    sat = prm.satellites_at_transmit(eph, syn.t_gps_s, syn.pseudorange_m, syn.valid, syn.sv,
                                     tgd_at(extras, syn.sv, syn.t_gps_s))
    v = inp["valid"]
    no_sagnac = araim.wnls(np.where(v, inp["pseudorange_m"] + inp["correction_m"], 0.0),
                           sat.ecef_tx_m, 1.0, x, v)
    assert np.median(np.linalg.norm(np.asarray(no_sagnac.position_m) - x, axis=-1)) > 2.0


@pytest.mark.parametrize("stem", STATIONS)
def test_real_station_solves_near_surveyed_position(shared_data, stem):
    """GSI stations 0759 and 3040, 2005-04-02 00:00-01:00, C1 code, broadcast orbits and clocks,
    Klobuchar + MOPS, 5 deg mask: measured median HPE 0.34 m / max 0.73 m (0759) and
    0.36 m / 0.84 m (3040), median VPE 1.7 m and 2.2 m (with georinex's time tags, truncated to
    the millisecond: 0.36 / 0.93 m and 0.45 / 1.46 m), against the header's surveyed APPROX
    POSITION; the bounds leave room for noise only (a missing T_GD, Sagnac or clock term
    gives metres to tens of metres)."""
    study = STUDIES["rinex-replay"]
    obs = shared_data / "obs" / f"{stem}.05o"
    sets = {"obs": str(obs), "nav": str(obs.with_suffix(".05n"))}
    if stem == "30400920":  # the --set truth path, with the same surveyed point
        sets["truth"] = "-3978242.4348,3382841.1715,3649902.7667"
    res = study.run(study.validate(sets), 2880, 0, None)
    m = res.metrics
    assert m["epochs"] == 120 and m["epochs_solved"] == 120
    assert m["hpe_median_m"] < 1.5 and m["hpe_max_m"] < 5.0
    assert m["vpe_median_m"] < 4.0
    assert m["misleading_information_epochs"] == 0
    assert m["misleading_information_epochs_slope"] == 0
    assert 0 < m["hpl_mhss_median_m"] < 1000 and 0 < m["hpl_slope_median_m"] < 1000
    assert m["hpl_median_m"] == m["hpl_mhss_median_m"]
    assert m["truth_source"] == ("--set truth" if "truth" in sets
                                 else "header APPROX POSITION XYZ")
    assert m["iono_model"].startswith("klobuchar")
    ds = res.dataset
    assert ds.sizes["epoch"] == 120 and not np.any(np.isnan(ds["hpl_mhss_m"].values))
    # the ionospheric and tropospheric corrections are of the expected size
    used = ds["used"].values
    assert 1.0 < np.median(ds["iono_m"].values[used]) < 20.0
    assert 2.3 < np.min(ds["tropo_m"].values[used]) < 2.6 * 10.3


@pytest.mark.parametrize("obs, nav, epochs, hpe", [
    ("TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz", "BRDC00IGS_R_20240010000_01D_MN.rnx.gz", 120,
     0.387),
    ("NIST00USA_R_20230010000_01D_30S_MO.crx.gz", "BRDC00IGS_R_20230010000_01D_MN.rnx.gz", 240,
     1.041),
])
def test_replay_of_published_rinex3_files(shared_data, obs, nav, epochs, hpe):
    """The GPS L1 C/A replay (``signals=gps-l1``) on files as the IGS publishes them: CRINEX 3
    + gzip observations of TLSE (1 h) and NIST (the first 2 h of its day) with the IGS merged
    broadcast file of the day, truth the header's APPROX POSITION (the stations' coordinates).
    Measured median HPE 0.387 m (TLSE, 120 epochs) and 1.041 m (NIST, 240 epochs; 1.047 m
    over its whole day)."""
    study = STUDIES["rinex-replay"]
    res = study.run(study.validate({"obs": str(shared_data / "obs3" / obs),
                                    "nav": str(shared_data / "obs3" / nav),
                                    "signals": "gps-l1"}), epochs, 0, None)
    m = res.metrics
    assert m["epochs"] == epochs and m["epochs_solved"] == epochs
    assert m["satellites_used_min"] >= 7 and m["iono_model"].startswith("klobuchar")
    assert m["hpe_median_m"] == pytest.approx(hpe, abs=0.02)
    assert m["vpe_median_m"] < 6.0 and m["hpe_max_m"] < 6.0
    assert m["misleading_information_epochs"] == 0


def test_nav_header_without_klobuchar_coefficients(shared_data, tmp_path):
    """Without ION ALPHA / ION BETA the replay applies no ionospheric correction, warns, says so
    in the summary, and bounds the whole delay with sigma_iono (the HPLs do not shrink)."""
    src = shared_data / "obs" / "07590920.05n"
    text = [ln for ln in src.read_text().splitlines() if "ION ALPHA" not in ln[60:]
            and "ION BETA" not in ln[60:]]
    nav = tmp_path / "07590920.05n"
    nav.write_text("\n".join(text) + "\n")
    assert navigation_extras(nav).alpha is None
    study = STUDIES["rinex-replay"]
    params = study.validate({"obs": str(shared_data / "obs" / "07590920.05o"), "nav": str(nav)})
    with pytest.warns(UserWarning, match="no Klobuchar coefficients"):
        res = study.run(params, 2880, 0, None)
    m = res.metrics
    assert m["iono_model"].startswith("none (header lacks")
    assert np.all(res.dataset["iono_m"].values == 0.0)
    assert m["misleading_information_epochs"] == 0 and m["hpl_mhss_median_m"] > 50.0
