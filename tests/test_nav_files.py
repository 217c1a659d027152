"""Navigation files as stations publish them: a station's separate GPS (``GN``) and Galileo
(``EN``) RINEX 3 files read as one, and ``nav=auto`` finding the day's file beside a RINEX 3
observation file. The split files are written from the IGS merged file of the same day, so the
merged and split replays must agree to the last bit."""

import gzip
import shutil

import numpy as np
import pytest

from oaraim import geometry
from oaraim.registry import STUDIES
from oaraim.studies import rinex_replay

OBS = "obs3/TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz"
MN = "obs3/BRDC00IGS_R_20240010000_01D_MN.rnx.gz"


def split_mixed(src, folder):
    """Write the GPS and Galileo records of a mixed RINEX 3 navigation file as a GN and an EN
    file (header kept, the system letter of its first line and its IONOSPHERIC CORR lines
    reduced to the system); returns their paths."""
    lines = gzip.open(src, "rt").read().split("\n")
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    recs, cur = [], None
    for ln in lines[end + 1:]:
        if ln[:1] in "GRECJSI" and ln[1:3].strip().isdigit():
            cur = [ln]
            recs.append(cur)
        elif cur is not None and ln:
            cur.append(ln)
    out = []
    for sysch, tag, ion in (("G", "GN", "GPS"), ("E", "EN", "GAL")):
        head = [h for h in lines[:end + 1]
                if not h[60:].startswith("IONOSPHERIC CORR") or h.startswith(ion)]
        head[0] = head[0][:40] + f"{sysch:<20}" + head[0][60:]
        p = folder / f"TEST00XXX_R_20240010000_01D_{tag}.rnx"
        p.write_text("\n".join(head + [ln for r in recs if r[0][0] == sysch for ln in r])
                     + "\n")
        out.append(p)
    return out


@pytest.fixture(scope="module")
def split(shared_data, tmp_path_factory):
    folder = tmp_path_factory.mktemp("nav")
    return split_mixed(shared_data / MN, folder)


def test_gn_plus_en_load_as_the_mixed_file(shared_data, split):
    """Same satellites, the same positions and clocks at the hour's epochs (to 0 m), GPS and
    Galileo alike; a file with none of the systems is passed over, none at all is one line."""
    t = geometry.load_navigation(shared_data / MN, systems=("G",)).prns
    one = geometry.load_navigation(shared_data / MN)
    two = geometry.load_navigation(split)
    np.testing.assert_array_equal(one.prns, two.prns)
    assert t.size and all(p in two.prns for p in t)
    tt = 1388167218.0 + np.arange(0, 3600, 300.0)  # 2024-01-01 18:00 GPS
    a = geometry.satellites(one, tt, ("gps", "galileo"))
    b = geometry.satellites(two, tt, ("gps", "galileo"))
    for x, y in zip(a, b, strict=True):
        if not hasattr(x, "shape"):  # the ephemeris object itself
            continue
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    gps_only = geometry.load_navigation([split[1], split[0]], systems=("G",))
    np.testing.assert_array_equal(gps_only.prns, t)
    with pytest.raises(ValueError, match="no G records in any of the files"):
        geometry.load_navigation([split[1], split[1]], systems=("G",))


def test_replay_with_gn_en_equals_the_mixed_file(shared_data, split):
    """``--set nav=GN,EN`` gives the summary of the merged file, number for number."""
    study = STUDIES["rinex-replay"]
    obs = str(shared_data / OBS)
    m1 = study.run(study.validate({"obs": obs, "nav": str(shared_data / MN)}), 30, 0,
                   None).metrics
    m2 = study.run(study.validate({"obs": obs, "nav": f"{split[0]},{split[1]}"}), 30, 0,
                   None).metrics
    for k in ("hpe_median_m", "vpe_max_m", "hpl_median_m", "vpl_median_m",
              "lpv200_available_pct", "combination"):
        assert m1[k] == m2[k], k
    assert m2["nav_file"] == f"{split[0].name} + {split[1].name}"


def test_nav_auto_beside_a_rinex3_file(shared_data, split, tmp_path):
    """The IGS merged file of the observation file's day beside it; else a GN + EN pair of
    that day; else one line naming what was looked for and `oaraim data nav`."""
    obs = tmp_path / "TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz"
    shutil.copy(shared_data / OBS, obs)
    hint = "pass --set obs"
    with pytest.raises(ValueError, match="none of day 2024-001 beside it.*oaraim data nav"):
        rinex_replay.navigation_beside(str(obs), hint)
    for p in split:
        shutil.copy(p, tmp_path / p.name)
    assert rinex_replay.navigation_beside(str(obs), hint) == (
        f"{tmp_path / split[0].name},{tmp_path / split[1].name}")
    shutil.copy(shared_data / MN, tmp_path / (shared_data / MN).name)
    assert rinex_replay.navigation_beside(str(obs), hint) == str(
        tmp_path / (shared_data / MN).name)
    _, nav = rinex_replay.resolve_files(str(obs), "auto")
    assert nav.endswith("BRDC00IGS_R_20240010000_01D_MN.rnx.gz")
    odd = tmp_path / "myfile.obs"
    odd.write_text("x")
    with pytest.raises(ValueError, match="its name says no day"):
        rinex_replay.navigation_beside(str(odd), hint)
