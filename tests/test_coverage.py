"""Silent short inputs: a navigation file that does not cover the span a study asks for is
refused in one line (exit 2 from the command line), not mapped as 0 satellites in view.

A RINEX 2 file cut at a record boundary has a valid layout and loads without a word; the
availability map then reported 18.75 % availability with epochs of no satellite. The check
(``geometry.ephemeris_gaps``, tests/test_epoch.py by hand) is wired into the map's skies."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from oaraim.cli import app
from oaraim.studies import availability_map as am


def _cut(shared_data, tmp_path, n_records=40):
    """brdc0010.22n cut after ``n_records`` records (8 lines each in RINEX 2)."""
    lines = (shared_data / "nav/brdc0010.22n").read_text().splitlines(keepends=True)
    head = next(i for i, x in enumerate(lines) if "END OF HEADER" in x) + 1
    cut = tmp_path / "brdc0010.22n"
    cut.write_text("".join(lines[:head + 8 * n_records]))
    return cut


def test_map_refuses_a_navigation_file_cut_short(tmp_path, shared_data):
    """The cut file as the map's GPS sky over a day: refused, naming the file and the hours;
    the whole file over the same day is not; with ``allow_gaps`` the epochs are kept and
    some have no satellite at all."""
    cut = str(_cut(shared_data, tmp_path))
    with pytest.raises(ValueError, match=r"gps=brdc0010\.22n: no usable orbits for most "
                       r"satellites at \d+ of 24 map epochs .*allow_gaps=yes") as e:
        am.constellation_orbits(cut, "none", 86400.0, 3600.0)
    assert "\n" not in str(e.value)
    whole = str(shared_data / "nav/brdc0010.22n")
    ecef, ok, *_ = am.constellation_orbits(whole, "none", 86400.0, 3600.0)
    assert ok.sum(-1).min() >= 25
    ecef, ok, *_ = am.constellation_orbits(cut, "none", 86400.0, 3600.0, allow_gaps=True)
    assert ok.sum(-1).min() == 0 and ok.sum(-1).max() >= 25


def test_cli_map_with_a_file_cut_short_is_one_line_exit_2(tmp_path, shared_data):
    cut = _cut(shared_data, tmp_path)
    r = CliRunner().invoke(app, ["run", "availability-map", "--out", str(tmp_path / "out"),
                                 "--no-progress", "--set", "lat_deg=40", "--set", "lon_deg=0",
                                 "--set", f"gps={cut}", "--set", "galileo=none",
                                 "--set", "step_s=3600"])
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "no usable orbits" in lines[0], r.output
    assert not (tmp_path / "out" / "availability-map" / "data.zarr").exists()


def test_almanacs_and_nominal_orbits_have_no_gaps():
    ecef, ok, *_ = am.constellation_orbits("nominal", "nominal", 86400.0, 3600.0)
    assert np.all(ok)


def test_cli_map_allow_gaps_maps_what_the_file_has(tmp_path, shared_data):
    """``--set allow_gaps=yes``: the run completes, the epochs past the file's end have no
    satellite and are unavailable (status TOO_FEW_SOURCES), counted in the summary and named
    in a warning."""
    import xarray as xr

    cut = _cut(shared_data, tmp_path)
    r = CliRunner().invoke(app, ["run", "availability-map", "--out", str(tmp_path / "out"),
                                 "--no-progress", "--set", "lat_deg=40", "--set", "lon_deg=0",
                                 "--set", f"gps={cut}", "--set", "galileo=none",
                                 "--set", "step_s=3600", "--set", "allow_gaps=yes"])
    assert r.exit_code == 0, r.output
    # the epochs without a solution are counted and named in one warning line, not a raw
    # Python warning with a line of source code
    warn = [x for x in r.output.splitlines() if "too few sources" in x]
    assert len(warn) == 1 and warn[0].startswith("warning: "), r.output
    assert "UserWarning" not in r.output and "warnings.warn" not in r.output
    summary = json.loads((tmp_path / "out" / "availability-map" / "summary.json").read_text())
    assert summary["metrics"]["epochs_too_few_sources"] > 0
    ds = xr.open_zarr(tmp_path / "out" / "availability-map" / "data.zarr", consolidated=False)
    n = ds["n_gnss"].values.ravel()
    assert n.min() == 0 and n.max() >= 6
    assert not ds["available"].values.ravel()[n == 0].any()


def test_rinex_replay_refuses_a_navigation_file_of_another_day(tmp_path, shared_data):
    """The 2005 station hour with the 2022 broadcast file: no orbit covers the epochs; one
    line, exit 2, naming the file and what to do (it used to end with no epoch solved)."""
    obs = shared_data / "obs/07590920.05o"
    r = CliRunner().invoke(app, ["run", "rinex-replay", "--out", str(tmp_path / "out"),
                                 "--no-progress", "--set", f"obs={obs}",
                                 "--set", f"nav={shared_data / 'nav/brdc0010.22n'}"])
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "brdc0010.22n: no usable GPS orbits" in lines[0], r.output
    assert "--set nav=FILE" in lines[0]
