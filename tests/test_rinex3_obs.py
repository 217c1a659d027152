"""RINEX 3 observation files in the forms stations publish them (plain, gzip, CRINEX, CRINEX in
gzip or compress; one file or several), every system and observation type read, and the
strict reading kept: a truncated or garbled epoch is named by file and line (for CRINEX, the
line of the decompressed text, or the CRINEX line the decoder stopped at)."""

import gzip

import numpy as np
import pytest

from oaraim import readers
from oaraim.readers import gpstime, rinex_obs

TLSE = "obs3/TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz"
NIST = "obs3/NIST00USA_R_20230010000_01D_30S_MO.crx.gz"
#: the decoded TLSE text: header lines 1-179, first epoch at line 180
TLSE_FIRST_EPOCH = 180


@pytest.fixture(scope="module")
def tlse(shared_data):
    """(table of the published file, its CRINEX bytes, its decoded RINEX lines)."""
    import hatanaka

    crx = gzip.decompress((shared_data / TLSE).read_bytes())
    text = hatanaka.crx2rnx(crx).decode().split("\n")
    return rinex_obs.read_observation_table(shared_data / TLSE), crx, text


def _equal_tables(a, b):
    assert list(a.sv) == list(b.sv) and a.types == b.types
    np.testing.assert_array_equal(a.t_gps_s, b.t_gps_s)
    assert a.values.keys() == b.values.keys() and a.lli.keys() == b.lli.keys()
    for c in a.values:
        np.testing.assert_array_equal(a.values[c], b.values[c], err_msg=c)
    for c in a.lli:
        np.testing.assert_array_equal(a.lli[c], b.lli[c], err_msg=c)


def test_tlse_every_system_and_type(tlse):
    """TLSE (Trimble Alloy, CRINEX 3 + gzip): 120 epochs; GPS, Galileo, BeiDou, GLONASS, SBAS
    and NavIC satellites with every observation type of the header (code, phase, Doppler,
    C/N0); values as written in the decoded text."""
    t, _, text = tlse
    assert t.t_gps_s.size == 120 and np.all(np.diff(t.t_gps_s) == 30.0)
    assert t.t_gps_s[0] == gpstime.gps_seconds(2024, 1, 1, 18)
    assert {s: int(np.sum(t.system_mask(s))) for s in "GECRSI"} == {
        "G": 13, "E": 10, "C": 14, "R": 11, "S": 6, "I": 3}
    assert t.types["G"] == ("C1C", "C1X", "C2W", "C2X", "C5X", "D1C", "D1X", "D2W", "D2X",
                            "D5X", "L1C", "L1X", "L2W", "L2X", "L5X", "S1C", "S1X", "S2W",
                            "S2X", "S5X")
    assert t.types["E"][:5] == ("C1X", "C5X", "C6X", "C7X", "C8X") and len(t.types["C"]) == 24
    assert len(t.values) == 68 and t.epoch_line[0] == TLSE_FIRST_EPOCH
    g04 = list(t.sv).index("G04")  # first epoch: 'G04  24941373.930 5  24941372.051 6 ...'
    row = next(s for s in text if s.startswith("G04"))
    assert row.startswith("G04  24941373.930 5  24941372.051 6  24941381.875 3")
    assert t.values["C1C"][0, g04] == 24941373.930 and t.values["C2W"][0, g04] == 24941381.875
    assert t.values["D5X"][0, g04] == -661.391 and t.values["L5X"][0, g04] == 97875342.680
    assert t.values["S2W"][0, g04] == 19.3 and t.lli["L1C"][0, g04] == 0
    # a type not declared for a system is NaN for its satellites (C1C: GPS, GLONASS, SBAS)
    assert np.all(np.isnan(t.values["C1C"][:, t.system_mask("ECI")]))
    # per satellite and epoch, the first code of a preference list: E1 and E5a of Galileo
    e1, which = t.select("E").pick(("C1C", "C1X"))
    assert np.all(which[np.isfinite(e1)] == 1) and np.isfinite(e1).mean() > 0.85
    e5a, _ = t.select("E").pick(("C5Q", "C5X"))
    assert np.isfinite(e5a).sum() == np.isfinite(t.select("E").values["C5X"]).sum()
    obs = rinex_obs.read_observations(t.paths[0])
    gps = t.select("G")
    assert obs.code == "C1C" and list(obs.sv) == list(gps.sv)
    np.testing.assert_array_equal(obs.pseudorange_m, np.nan_to_num(gps.values["C1C"]))


def test_nist_day(shared_data):
    """NIST (Septentrio, CRINEX 3 + gzip), a whole day: 2,880 epochs, GPS and Galileo with the
    codes of a later dual-frequency replay; the header's APPROX POSITION."""
    t = rinex_obs.read_observation_table(shared_data / NIST)
    assert t.t_gps_s.size == 2880 and t.marker == "nist" and t.interval_s == 30.0
    assert t.types["G"][:6] == ("C1C", "C1L", "C1W", "C2L", "C2W", "C5Q")
    assert t.types["E"][:5] == ("C1C", "C5Q", "C6C", "C7Q", "C8Q")
    assert set(t.types) == set("CEGRS")
    gps, gal = t.select("G"), t.select("E")
    assert gps.sv.size == 31 and gal.sv.size >= 24
    l1, _ = gps.pick(("C1C",))
    l2, _ = gps.pick(("C2W",))
    # C1C + C2W for nearly every GPS observation; E1 + E5a for every Galileo one
    assert np.isfinite(l2)[np.isfinite(l1)].mean() > 0.95
    e1, e5 = gal.values["C1C"], gal.values["C5Q"]
    assert np.isfinite(e5)[np.isfinite(e1)].mean() > 0.98
    np.testing.assert_allclose(t.approx_position_m, [-1288398.6784, -4721696.7639,
                                                     4078625.2178])


def test_every_published_form_reads_the_same(tlse, tmp_path):
    """Plain, gzip, CRINEX, CRINEX + gzip, CRINEX + compress (.Z), and a name that says
    nothing of the form: one table."""
    import hatanaka

    t, crx, text = tlse
    plain = "\n".join(text).encode()
    forms = {"a.rnx": plain, "a.rnx.gz": gzip.compress(plain), "a.crx": crx,
             "a.crx.gz": gzip.compress(crx), "a.crx.Z": hatanaka.compress(crx, compression="Z"),
             "a.24o": gzip.compress(crx)}
    for name, raw in forms.items():
        (tmp_path / name).write_bytes(raw)
        _equal_tables(t, rinex_obs.read_observation_table(tmp_path / name))


def _split(text, k):
    """Two files of the decoded text: the header with epochs before index k, and after."""
    end = next(i for i, s in enumerate(text) if "END OF HEADER" in s)
    head = [s for s in text[:end + 1] if "TIME OF LAST OBS" not in s[60:80]]
    return head + text[end + 1:k], head + text[k:]


def test_several_files_of_one_receiver(tlse, tmp_path):
    """Hourly or split files: read together in any order, the same table as the whole file;
    overlapping files and files of another station are refused with file and line."""
    t, _, text = tlse
    k = next(i for i, s in enumerate(text) if s.startswith("> 2024 01 01 18 30"))
    first, second = _split(text, k)
    a, b = tmp_path / "a.rnx", tmp_path / "b.rnx"
    a.write_text("\n".join(first) + "\n")
    b.write_text("\n".join(second).rstrip("\n") + "\n")
    both = rinex_obs.read_observation_table([b, a])
    _equal_tables(t, both)
    assert both.paths == (str(a.resolve()), str(b.resolve()))
    assert both.epoch_file[59] == 0 and both.epoch_file[60] == 1
    assert both.epoch_line[60] == next(i for i, s in enumerate(second) if s[:1] == ">") + 1
    obs = rinex_obs.read_observations([a, b])
    assert obs.t_gps_s.size == 120 and obs.code == "C1C"
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=r"a\.rnx: line \d+: its first epoch is not after the last epoch "
                             r"of .*a\.rnx .* given twice"):
        rinex_obs.read_observation_table([a, tmp_path / "." / "a.rnx"])
    other = tmp_path / "c.rnx"
    other.write_text(b.read_text().replace("TLSE" + " " * 56 + "MARKER NAME",
                                           "ABCD" + " " * 56 + "MARKER NAME"))
    with pytest.raises(rinex_obs.ObservationFileError, match="c.rnx: MARKER NAME 'ABCD' "
                       "differs from 'TLSE'"):
        rinex_obs.read_observation_table([a, other])


def test_truncated_crinex_names_the_crinex_line(tlse, tmp_path):
    """A CRINEX file cut mid-epoch (a partial download): the Hatanaka decoder stops, and the
    error names the file and the CRINEX line; gzip of it too. The CLI says it in one line,
    exit 2."""
    from typer.testing import CliRunner

    from oaraim.cli import app

    _, crx, _ = tlse
    lines = crx.split(b"\n")
    cut = b"\n".join(lines[:3000]) + b"\n" + lines[3000][:5]
    p = tmp_path / "cut.crx.gz"
    p.write_bytes(gzip.compress(cut))
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=r"cut\.crx\.gz: line 3001 of the CRINEX text: the CRINEX "
                             r"\(Hatanaka\) decoder stopped: .*truncated"):
        rinex_obs.read_observations(p)
    half = tmp_path / "half.crx.gz"
    half.write_bytes(gzip.compress(crx)[:50000])
    with pytest.raises(rinex_obs.ObservationFileError, match=r"half\.crx\.gz: cannot read"):
        rinex_obs.read_observation_table(half)
    nav = tmp_path / "nav.rnx"
    nav.write_text("     3.04           N: GNSS NAV DATA    G: GPS              RINEX VERSION / "
                   "TYPE\n")
    res = CliRunner().invoke(app, ["run", "rinex-replay", "--set", f"obs={p}", "--set",
                                   f"nav={nav}", "--out", str(tmp_path / "out")])
    out = res.output.strip()
    errors = [ln for ln in out.splitlines() if ln.startswith("error:")]
    assert res.exit_code == 2 and "Traceback" not in out and len(errors) == 1, out
    assert "cut.crx.gz: line 3001 of the CRINEX text" in errors[0]


def test_garbled_crinex_epoch_names_the_decoded_line(tlse, tmp_path):
    """A garbled epoch line inside a CRINEX file decodes to a RINEX line our check refuses: the
    error names the line of the decompressed text; lenient reading skips the epoch and says
    the same. (A garbled digit of a compressed difference decodes to well-formed wrong numbers
    that no reader can tell from real ones: CRINEX has no checksum.)"""
    t, crx, text = tlse
    lines = crx.decode().split("\n")
    k = next(i for i, s in enumerate(lines) if s.startswith("> 2024"))
    # the minute's last digit of the first epoch: later epoch lines are written as differences
    # to it, so the 'x' stays until a minute change rewrites the digit (two epochs); a
    # character of a field never rewritten would garble every later epoch
    lines[k] = lines[k][:17] + "x" + lines[k][18:]
    p = tmp_path / "garbled.crx"
    p.write_text("\n".join(lines))
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=rf"garbled\.crx: line {TLSE_FIRST_EPOCH} of the decompressed text: "
                             "expected an epoch line"):
        rinex_obs.read_observation_table(p)
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=rf"line {TLSE_FIRST_EPOCH} of the decompressed text"):
        rinex_obs.read_observations(p)
    with pytest.warns(rinex_obs.ObservationFileWarning,
                      match=rf"garbled\.crx: line {TLSE_FIRST_EPOCH} of the decompressed text"):
        skipped = rinex_obs.read_observation_table(p, lenient=True)
    # both garbled epochs in one skip: the reader resumes at the next well-formed epoch line
    assert skipped.t_gps_s.size == 118 and len(skipped.skipped) == 1
    assert skipped.skipped[0].endswith(f"(lines {TLSE_FIRST_EPOCH}-275)")
    np.testing.assert_array_equal(skipped.values["C1C"], t.values["C1C"][2:])


def test_truncated_and_garbled_rinex3_name_the_line(tlse, tmp_path):
    """The plain RINEX 3 text: cut inside an epoch, a garbled observation field, a garbled
    satellite; each named by file and line."""
    _, _, text = tlse
    k = next(i for i, s in enumerate(text) if s.startswith("> 2024 01 01 18 30"))
    cut = tmp_path / "cut.rnx"
    cut.write_text("\n".join(text[:k + 5]) + "\n")
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=rf"cut\.rnx: line {k + 5}: the file ends inside the epoch at line "
                             rf"{k + 1}"):
        rinex_obs.read_observation_table(cut)
    bad = list(text)
    bad[k + 2] = bad[k + 2][:10] + "x" + bad[k + 2][11:]
    p = tmp_path / "bad.rnx"
    p.write_text("\n".join(bad))
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=rf"bad\.rnx: line {k + 3}: columns 4-17: cannot read"):
        rinex_obs.read_observation_table(p)
    bad = list(text)
    bad[k + 2] = "X05" + bad[k + 2][3:]
    p.write_text("\n".join(bad))
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=rf"bad\.rnx: line {k + 3}: columns 1-3: expected a satellite"):
        rinex_obs.read_observation_table(p)


def test_time_system_not_gps_is_refused(tlse, tmp_path):
    _, _, text = tlse
    k = next(i for i, s in enumerate(text) if "TIME OF FIRST OBS" in s[60:80])
    lines = list(text)
    lines[k] = lines[k][:48] + "GLO" + lines[k][51:]
    p = tmp_path / "glo.rnx"
    p.write_text("\n".join(lines))
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=rf"glo\.rnx: line {k + 1}: TIME OF FIRST OBS: the epochs are in GLO"):
        rinex_obs.read_observation_table(p)


def test_rinex2_table_matches_the_l1_reader(shared_data):
    """RINEX 2: the header's one list of types, for every system present."""
    path = shared_data / "obs" / "07590920.05o"
    t = rinex_obs.read_observation_table(path)
    assert t.types == {"G": ("L1", "C1", "L2", "P2")} and t.version == 2.1
    obs = readers.read_observations(path)
    np.testing.assert_array_equal(obs.pseudorange_m,
                                  np.nan_to_num(t.select("G").values["C1"])[:, :obs.sv.size])
    assert list(obs.sv) == list(t.sv)


def test_crinex_decoder_skipping_data_is_an_error(tlse, tmp_path):
    """The Hatanaka decoder goes past what it cannot decode with a warning only ("skip until
    an initialized epoch is found"): here a lost first epoch line made it drop every epoch.
    Strict reading names the CRINEX line; lenient reading lists it among the skipped."""
    _, crx, _ = tlse
    lines = crx.split(b"\n")
    k = next(i for i, s in enumerate(lines) if s.startswith(b"> 2024"))
    p = tmp_path / "lost.crx"
    p.write_bytes(b"\n".join(lines[:k] + lines[k + 1:]))
    with pytest.raises(rinex_obs.ObservationFileError,
                       match=rf"lost\.crx: line {k + 1} of the CRINEX text: the CRINEX "
                             r"\(Hatanaka\) decoder skipped data"):
        rinex_obs.read_observation_table(p)
    with pytest.raises(rinex_obs.ObservationFileError, match="no observation epochs"):
        rinex_obs.read_observation_table(p, lenient=True)


def test_crinex1_of_a_rinex2_file(shared_data, tmp_path):
    """CRINEX 1 (Hatanaka-compressed RINEX 2, '.yyd'), written here with the same package's
    compressor: the same observations as the RINEX 2 file."""
    import hatanaka

    src = shared_data / "obs" / "07590920.05o"
    crx = hatanaka.rnx2crx(src.read_bytes())
    assert crx[:20].strip() == b"1.0"
    p = tmp_path / "07590920.05d"
    p.write_bytes(crx)
    _equal_tables(rinex_obs.read_observation_table(src), rinex_obs.read_observation_table(p))
