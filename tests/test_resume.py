"""Resumable studies that are not sweeps (``mc.checkpoint``, ``studies.base.ResumableStudy``):
exact round trips of unit values, a fresh run clearing the units, a resume with another identity
refused in one line, and the two gradient studies at their ``--quick`` size interrupted after k
units and resumed, bit-identical to an uninterrupted run (as tests/test_sweep_cli.py does for
sweeps)."""

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from oaraim.cli import app
from oaraim.execute import RunOptions, run_study
from oaraim.mc import checkpoint as ck
from oaraim.registry import STUDIES
from oaraim.studies.base import Param, ResumableStudy, StudyResult, count


class _Interrupted(Exception):
    """Raised by the patched ``Checkpoint.unit`` to stand for a kill after k units."""


def _data(sdir):
    return xr.open_zarr(Path(sdir) / "data.zarr", consolidated=False).load()


def _json(sdir, name):
    return json.loads((Path(sdir) / name).read_text())


def test_unit_values_round_trip_exactly(tmp_path):
    value = {"a": np.array([1.0, np.nan, np.inf, -0.0, 1 / 3]), "i": np.arange(3, dtype=np.int32),
             "b": np.array([True, False]), "t": (1, 0.1 + 0.2, None, "x", True),
             "l": [float("nan"), float("-inf"), np.float64(2.5), np.int64(7)],
             "none": None, "nested": {"k": [np.zeros((2, 0))]}}
    path = tmp_path / "u.npz"
    path.write_bytes(ck.unit_bytes(value))
    ok, got = ck.read_unit(path)
    assert ok
    np.testing.assert_array_equal(got["a"], value["a"])
    assert got["a"].tobytes() == value["a"].tobytes() and got["i"].dtype == np.int32
    assert got["t"] == (1, 0.1 + 0.2, None, "x", True) and isinstance(got["t"], tuple)
    assert np.isnan(got["l"][0]) and got["l"][1:] == [float("-inf"), 2.5, 7]
    assert got["none"] is None and got["nested"]["k"][0].shape == (2, 0)
    assert ck.read_unit(tmp_path / "missing.npz") == (False, None)
    (tmp_path / "half.npz").write_bytes(path.read_bytes()[:40])
    assert ck.read_unit(tmp_path / "half.npz") == (False, None)
    with pytest.raises(TypeError, match="cannot store a set"):
        ck.unit_bytes({1, 2})


def test_fresh_run_clears_units_and_resume_reuses_them(tmp_path):
    ident = ck.identity("s", {"x": (1, 2)}, 0, 10)
    calls = []

    def compute(v):
        calls.append(v)
        return v

    a = ck.Checkpoint(tmp_path, ident)
    assert a.unit("one", lambda: compute(1)) == 1 and a.unit("two", lambda: compute(2)) == 2
    b = ck.Checkpoint(tmp_path, ident, resume=True)
    assert b.unit("one", lambda: compute(-1)) == 1 and b.unit("three", lambda: compute(3)) == 3
    assert (b.computed, b.reused) == (1, 1) and calls == [1, 2, 3]
    fresh = ck.Checkpoint(tmp_path, ident)  # no --resume: nothing of the earlier run is reused
    assert fresh.unit("one", lambda: compute(4)) == 4 and not (tmp_path / "checkpoints" /
                                                               "two.npz").exists()
    with pytest.raises(ValueError, match="must match"):
        fresh.unit("a/b", lambda: 0)


def test_resume_with_another_identity_is_refused_naming_the_difference(tmp_path):
    ck.Checkpoint(tmp_path, ck.identity("s", {"x": 1}, 0, 10)).unit("u", lambda: 1)
    with pytest.raises(ValueError) as e:
        ck.Checkpoint(tmp_path, ck.identity("s", {"x": 2}, 1, 10), resume=True)
    msg = str(e.value)
    assert "\n" not in msg and "params.x (was 1, now 2)" in msg and "seed (was 0, now 1)" in msg
    assert "drop --resume" in msg and "--out" in msg
    # without --resume another run simply starts afresh
    assert ck.Checkpoint(tmp_path, ck.identity("s", {"x": 2}, 1, 10)).unit("u", lambda: 2) == 2


class _Toy(ResumableStudy):
    name = "toy-resumable"
    title = "toy resumable study (tests only)"
    realization = "one unit"
    default_realizations = 3
    quick_realizations = 2
    params = {"units": Param(3, count(1, 10), "units of work")}

    def run_units(self, params, realizations, seed, progress, checkpoint):
        vals = [checkpoint.unit(f"u{i}", lambda i=i: float(np.sqrt(i + seed)))
                for i in range(params["units"])]
        ds = xr.Dataset({"v": ("i", np.array(vals))})
        return StudyResult(ds, [{"quantity": "sum", "unit": "-", "published": None,
                                 "reproduced": sum(vals), "note": ""}], {})

    def plot(self, out_dir):
        return []


@pytest.fixture
def toy(monkeypatch):
    monkeypatch.setitem(STUDIES, _Toy.name, _Toy())


def _cli(*args):
    return CliRunner().invoke(app, list(args), catch_exceptions=False)


def _one_line(r):
    lines = [ln for ln in r.output.strip().splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and "Traceback" not in r.output, r.output
    return lines[0]


def test_cli_resume_errors_are_one_line(tmp_path, toy):
    assert _cli("run", "toy-resumable", "--out", str(tmp_path), "--no-progress").exit_code == 0
    line = _one_line(_cli("run", "toy-resumable", "--out", str(tmp_path), "--no-progress",
                          "--set", "units=4", "--resume"))
    assert "params.units (was 3, now 4)" in line and "drop --resume" in line
    line = _one_line(_cli("run", "seed001-fig3-elevation", "--resume", "--out", str(tmp_path)))
    assert "resumable studies" in line and "toy-resumable" in line and "tower-placement" in line
    line = _one_line(_cli("run", "toy-resumable", "--workers", "2", "--out", str(tmp_path)))
    assert "sweep studies" in line
    r = _cli("run", "toy-resumable", "--out", str(tmp_path), "--no-progress", "--resume")
    assert r.exit_code == 0
    prov = _json(tmp_path / "toy-resumable", "provenance.json")["checkpoint"]
    assert prov["resumed"] and (prov["units_computed"], prov["units_reused"]) == (0, 3)


@pytest.mark.parametrize("name, stop_after", [("tower-placement", 3), ("sop-requirements", 4)])
def test_interrupted_quick_run_resumed_is_bit_identical(name, stop_after, tmp_path,
                                                        monkeypatch, shared_data):
    """The ``--quick`` size (what ``reproduce --quick`` runs): uninterrupted, then killed after
    ``stop_after`` units and resumed; data, summary and figures' inputs are identical."""
    _, whole, _, _ = run_study(name, quick=True, out=tmp_path / "whole", show_progress=False)
    unit = ck.Checkpoint.unit

    def dies(self, unit_name, compute):
        if not self.resumed and self.computed >= stop_after:
            raise _Interrupted(unit_name)
        return unit(self, unit_name, compute)

    monkeypatch.setattr(ck.Checkpoint, "unit", dies)
    with pytest.raises(_Interrupted):
        run_study(name, quick=True, out=tmp_path / "cut", show_progress=False)
    _, cut, _, _ = run_study(name, quick=True, out=tmp_path / "cut", show_progress=False,
                             options=RunOptions(resume=True))
    xr.testing.assert_identical(_data(cut), _data(whole))
    assert _json(cut, "summary.json") == _json(whole, "summary.json")
    p = _json(cut, "provenance.json")["checkpoint"]
    assert p["resumed"] and p["units_reused"] == stop_after and p["units_computed"] > 0
    assert not _json(whole, "provenance.json")["checkpoint"]["resumed"]
