"""RINEX 3 navigation files as stations and the IGS publish them: mixed (``MN``), the IGS merged
daily ``BRDC00IGS`` file whose records come from several contributors (optional and spare
fields written by some, left blank by others), and single-system ``GN`` / ``EN`` files. Records
are read by field position (``readers.rinex_nav3``) and checked by what they mean."""

import gzip
import io
import warnings

import numpy as np
import pytest

from oaraim import geometry, readers
from oaraim.readers import check_navigation_file, gpstime, rinex_nav3
from oaraim.readers import navigation as ephemeris

BRDC = {2023: "obs3/BRDC00IGS_R_20230010000_01D_MN.rnx.gz",
        2024: "obs3/BRDC00IGS_R_20240010000_01D_MN.rnx.gz"}


def _lines(path):
    with gzip.open(path, "rt") as f:
        return f.read().split("\n")


def _write(tmp_path, name, lines):
    p = tmp_path / name
    p.write_text("\n".join(lines).rstrip("\n") + "\n")
    return p


# counts read from the files (grep '^G', '^E' record starts; health words of the records)
@pytest.mark.parametrize("year, n_gps, rec_gps, n_gal, rec_gal, unhealthy, n_records", [
    (2023, 31, 436, 26, 5663, ["E14", "E18"], 19979),
    (2024, 32, 452, 25, 5390, ["E14", "E18", "G01", "G27"], 19601),
])
def test_igs_merged_brdc_loads_whole(shared_data, year, n_gps, rec_gps, n_gal, rec_gal,
                                     unhealthy, n_records):
    """The IGS merged files stopped at a BeiDou record whose spare field another contributor
    had written ("4 fields where the same line of the first record of C05 has 3"); every record
    of every system is now checked and the GPS and Galileo ones loaded."""
    path = shared_data / BRDC[year]
    info = check_navigation_file(path)
    assert info["records"] == n_records and info["systems"] == list("CEGIJRS")
    eph = geometry.load_navigation(path)
    gps, gal = eph.constellation == readers.GPS, eph.constellation == readers.GALILEO
    assert (gps.sum(), eph.n_records[gps].sum()) == (n_gps, rec_gps)
    assert (gal.sum(), eph.n_records[gal].sum()) == (n_gal, rec_gal)
    assert sorted(eph.prns[~eph.sat_healthy]) == unhealthy
    # healthy records all day: orbit radii of the constellations at 15 min steps
    t = gpstime.gps_seconds(year, 1, 1) + np.arange(0, 86400, 900.0)
    s = eph.sat_state(t)
    r = np.linalg.norm(np.asarray(s.ecef_m), axis=-1)
    v = np.asarray(s.valid)
    assert v[:, gps].mean() > 0.9 and v[:, gal].mean() > 0.85
    assert np.all(np.abs(r[:, gps][v[:, gps]] - 26.56e6) < 0.7e6)
    assert np.all(np.abs(r[:, gal][v[:, gal]] - 29.6e6) < 0.1e6)
    assert np.all(np.abs(np.asarray(s.age_s)[v]) <= 4 * 3600.0)
    ex = readers.navigation_extras(path)
    assert ex.alpha is not None and ex.tgd_sv.size == rec_gps


@pytest.mark.parametrize("name", ["nav/VILL00ESP_R_20181700000_01D_MN.rnx.gz",
                                  "nav/ELKO00USA_R_20182100000_01D_MN.rnx.gz"])
def test_field_reader_equals_georinex_where_georinex_reads_right(shared_data, name):
    """On files of one writer (every record laid out alike) georinex, the RINEX 3 parser used
    before, reads every record: our records are the same, bit for bit."""
    import georinex

    path = shared_data / name
    text = ephemeris._navigation_text(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = georinex.load(io.StringIO(text), use=["G", "E"])
    theirs = ephemeris._record_table(ds, ("G", "E"), str(path))
    info, ours_ds = ephemeris.georinex_navigation(str(path), 0, 0, ("G", "E"))
    ours = ephemeris._record_table(ours_ds, ("G", "E"), str(path))
    a = np.lexsort((theirs["Toe"], theirs["toc_s"], theirs["sv"]))
    b = np.lexsort((ours["Toe"], ours["toc_s"], ours["sv"]))
    assert theirs.keys() == ours.keys() and a.size == b.size == sum(
        sv[0] in "GE" for sv, _, _ in info["index"])
    for k in theirs:
        np.testing.assert_array_equal(theirs[k][a], ours[k][b], err_msg=k)
    np.testing.assert_array_equal(ds.attrs["ionospheric_corr_GPS"],
                                  ours_ds.attrs["ionospheric_corr_GPS"])


def _header_end(lines):
    return next(k for k, s in enumerate(lines) if "END OF HEADER" in s[60:80])


def _records(lines, sysch, version=3.05):
    end = _header_end(lines)
    out, k = [], end + 1
    while k < len(lines):
        if not lines[k].strip():
            k += 1
            continue
        n = rinex_nav3.record_lines(lines[k][0], version)
        if lines[k][0] in sysch:
            out.append(lines[k:k + n])
        k += n
    return out


def test_layout_is_not_meaning(shared_data, tmp_path):
    """Spare fields written as zeros or left blank, lines cut after their last field or padded
    to 80 columns, a blank optional field in the middle (Galileo's spare): the same records."""
    lines = _lines(shared_data / BRDC[2024])
    end = _header_end(lines)
    recs = _records(lines, "GE")[:60]
    base = _write(tmp_path, "base.rnx", lines[:end + 1] + [s for r in recs for s in r])

    def relayout(rec, n):
        out = [s.rstrip() if n % 2 else f"{s:80s}" for s in rec]
        if rec[0][0] == "E":  # BROADCAST ORBIT 5 field 4 and ORBIT 7 fields 2-4: spares
            out[5] = out[5][:61] + (" " * 19 if n % 3 else f"{0.0:19.12e}")
        return out

    other = _write(tmp_path, "other.rnx", lines[:end + 1]
                   + [s for n, r in enumerate(recs) for s in relayout(r, n)])
    a, b = geometry.load_navigation(base), geometry.load_navigation(other)
    assert a.n_records.sum() == 60
    assert list(a.prns) == list(b.prns)
    for k, v in a._params.items():
        np.testing.assert_array_equal(v, b._params[k], err_msg=k)
    # a record repeated with another layout is a duplicate, named with both lines
    dup = _write(tmp_path, "dup.rnx", lines[:end + 1] + [s for r in recs for s in r]
                 + relayout(recs[0], 1))
    with pytest.raises(readers.NavigationFileError,
                       match=rf"dup\.rnx: line {end + 2 + 60 * 8}: the record of "
                             rf"{recs[0][0][:3]} repeats the record at line {end + 2} exactly"):
        geometry.load_navigation(dup)


def test_single_system_gn_en_files(shared_data, tmp_path):
    """Separate GPS (``GN``) and Galileo (``EN``) files load, each with its own system only;
    together they hold what the mixed file holds."""
    lines = _lines(shared_data / BRDC[2024])
    end = _header_end(lines)
    mixed = geometry.load_navigation(shared_data / BRDC[2024])
    for sysch, label, code in (("G", "G: GPS", readers.GPS), ("E", "E: GALILEO",
                                                               readers.GALILEO)):
        head = [lines[0][:20] + f"{'N: GNSS NAV DATA':20s}{label:20s}" + lines[0][60:]]
        head += [s for s in lines[1:end + 1] if s[60:80].strip() != "IONOSPHERIC CORR"
                 or s[:3] == ("GPS" if sysch == "G" else "GAL")]
        p = _write(tmp_path, f"X_{sysch}N.rnx",
                   head + [s for r in _records(lines, sysch) for s in r])
        eph = geometry.load_navigation(p)
        assert set(eph.constellation) == {code}
        m = mixed.constellation == code
        assert list(eph.prns) == list(mixed.prns[m])
        assert eph.n_records.tolist() == mixed.n_records[m].tolist()
        if sysch == "E":  # no GPS records: the replay's GPS extras say so
            with pytest.raises(readers.NavigationFileError, match="no GPS records"):
                geometry.load_navigation(p, systems=("G",))


def test_glonass_305_records_have_five_lines(shared_data, tmp_path):
    """RINEX 3.05 added a fifth line to GLONASS records (status flags, L1/L2 delay, URAI,
    health flags); read as four, the next record start was out of step. A record cut to four
    lines in a 3.05 file is named."""
    lines = _lines(shared_data / BRDC[2024])
    end = _header_end(lines)
    k = next(i for i in range(end + 1, len(lines)) if lines[i].startswith("R01 "))
    vals = rinex_nav3.record_values(lines, k, "R", 3.05)
    f = dict(zip(rinex_nav3.FIELDS["R"], vals, strict=True))
    assert f["X_km"] == pytest.approx(-15908.60058594) and f["FreqNum"] == 1.0
    assert np.isnan(f["StatusFlags"]) and f["DelayL1L2"] == pytest.approx(0.999999999999e9)
    cut = lines[:end + 1] + lines[k:k + 4] + lines[k + 5:k + 15]
    p = _write(tmp_path, "cut.rnx", cut)
    with pytest.raises(readers.NavigationFileError, match=rf"cut\.rnx: line {end + 6}, column 1: "
                       "unexpected character 'R'"):
        check_navigation_file(p)


@pytest.mark.parametrize("edit, message", [
    # BROADCAST ORBIT 2 of the first record: a blank sqrt(A) (required) and a garbled field
    (lambda r: r[:3] + [r[3][:61]] + r[4:], r"line 4, columns 62-80: an orbital element is blank"),
    (lambda r: r[:3] + [r[3][:23] + "    0.77x2765435725" + r[3][42:]] + r[4:],
     r"line 4, columns 24-42: cannot read"),
    (lambda r: r[:8] + [r[8][:4] + "2024 01 01 25 00 00" + r[8][23:]] + r[9:],
     r"line 9: cannot read the record epoch '2024 01 01 25 00 00'"),
])
def test_meaning_checks_name_the_line(shared_data, tmp_path, edit, message):
    lines = _lines(shared_data / BRDC[2024])
    end = _header_end(lines)
    recs = [s for r in _records(lines, "G")[:3] for s in r]
    p = _write(tmp_path, "bad.rnx", lines[:end + 1] + edit(recs))
    msg = message.replace("line ", "line ", 1)
    n = int(msg.split("line ")[1].split(",")[0].split(":")[0])
    msg = msg.replace(f"line {n}", f"line {end + 1 + n}", 1)
    with pytest.raises(readers.NavigationFileError, match=r"bad\.rnx: " + msg):
        geometry.load_navigation(p)


def test_cli_names_a_bad_navigation_file_in_one_line(shared_data, tmp_path):
    """The replay with a merged navigation file cut inside a record: exit 2, one error line
    naming the file and the line."""
    from typer.testing import CliRunner

    from oaraim.cli import app

    lines = _lines(shared_data / BRDC[2024])
    end = _header_end(lines)
    p = _write(tmp_path, "cut.rnx", lines[:end + 1 + 8 * 40 + 3])
    obs = shared_data / "obs3" / "TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz"
    res = CliRunner().invoke(app, ["run", "rinex-replay", "--set", f"obs={obs}", "--set",
                                   f"nav={p}", "--out", str(tmp_path / "out")])
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert res.exit_code == 2 and "Traceback" not in res.output and len(errors) == 1, res.output
    assert f"cut.rnx: line {end + 1 + 8 * 40 + 3}: the file ends inside the record" in errors[0]
