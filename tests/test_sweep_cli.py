"""Sweep studies from the command line: narrowing with --set, SIGKILL then --resume, a resume
with other parameters, a real 2-worker Dask cluster, and the flags' errors.

The toy study is registered only inside these tests (monkeypatch) and inside the subprocesses
they start, never in the real registry.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from oaraim.cli import app
from oaraim.execute import RunOptions, run_study
from oaraim.mc.sweep import Count, Execution, Histogram, Max, Mean
from oaraim.studies.base import Param, StudyResult, SweepStudy, axis, count, positive
from tests.test_sweep import EDGES, toy_factory

ROOT = Path(__file__).resolve().parents[1]
DELAY_ENV = "OARAIM_TOY_SWEEP_DELAY_S"  # slows every kernel call, so a test can kill mid-run


class _Slow:
    def __init__(self, kernel, delay_s):
        self.kernel, self.delay_s = kernel, delay_s

    def __call__(self, keys):
        time.sleep(self.delay_s)
        return self.kernel(keys)


class ToySweep(SweepStudy):
    name = "toy-sweep"
    title = "toy sweep (tests only)"
    realization = "three standard normals"
    default_realizations = 3000
    quick_realizations = 1024
    axis_names = ("a", "b")
    key_axes = ("a",)
    params = {
        "a": Param((1, 2, 3), axis(count(1, 10)), "key axis"),
        "b": Param((0.5, 1.0), axis(positive), "non-key axis"),
        "chunk": Param(1024, count(1024), "realizations per task"),
    }

    def kernel(self, params, coords):
        k = toy_factory(coords)
        delay_s = float(os.environ.get(DELAY_ENV, "0"))
        return _Slow(k, delay_s) if delay_s > 0 else k

    def reducers(self, params):
        return (Mean("r", where="pos"), Max("r"), Histogram("x0", EDGES), Count("pos"))

    def finish(self, params, dataset, realizations, seed):
        rows = [{"quantity": "mean r", "unit": "", "published": None,
                 "reproduced": float(dataset["r_mean"].mean()), "note": "toy"}]
        return StudyResult(dataset, rows, {"cells": int(dataset["r_mean"].size)})

    def plot(self, out_dir):
        return []


TOY = ToySweep()
BOOT = ("import oaraim.registry as r, tests.test_sweep_cli as t; "
        "r.STUDIES[t.TOY.name] = t.TOY; "
        "import atexit, sys; atexit.register(lambda: print('distributed imported:', "
        "'distributed' in sys.modules)); from oaraim.cli import main; main()")


@pytest.fixture
def toy(monkeypatch):
    from oaraim import registry

    monkeypatch.setitem(registry.STUDIES, TOY.name, TOY)
    return TOY


def _cli(*args):
    return CliRunner().invoke(app, list(args), catch_exceptions=False)


def _one_line(result):
    text = result.output.strip()
    assert "Traceback" not in text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return lines[0]


def _data(sdir):
    return xr.open_zarr(Path(sdir) / "data.zarr", consolidated=False).load()


def _prov(sdir):
    return json.loads((Path(sdir) / "provenance.json").read_text())


def test_narrowing_with_set_gives_the_same_cells(tmp_path, toy):
    _, full, _, _ = run_study(TOY.name, out=tmp_path / "full", show_progress=False)
    _, one, _, _ = run_study(TOY.name, out=tmp_path / "one", sets=["a=2", "b=1.0"],
                             show_progress=False)
    _, two, _, _ = run_study(TOY.name, out=tmp_path / "two", sets=["a=3,1", "b=1e0",
                                                                    "chunk=4096"],
                             show_progress=False)
    d_full, d_one, d_two = _data(full), _data(one), _data(two)
    assert d_one["r_mean"].shape == (1, 1) and d_two["r_mean"].shape == (2, 1)
    for ds, cells in ((d_one, [(2, 1.0)]), (d_two, [(3, 1.0), (1, 1.0)])):
        for a, b in cells:
            for var in d_full.data_vars:
                assert np.array_equal(ds[var].sel(a=a, b=b).values,
                                      d_full[var].sel(a=a, b=b).values), (var, a, b)
    p = _prov(full)["sweep"]
    assert p["cells"] == 6 and p["chunks_computed"] == 18 and p["chunks_reused"] == 0
    assert p["workers"] is None and p["batch_size"] == 1024


def test_sigkill_then_resume_is_bit_identical_and_recomputes_only_the_rest(tmp_path, toy):
    """A subprocess killed with SIGKILL mid-sweep; --resume finishes it; the data equal an
    uninterrupted run's and only the missing chunks were computed."""
    args = ["run", TOY.name, "--realizations", "6000", "--out", str(tmp_path / "killed"),
            "--no-progress"]
    chunks = tmp_path / "killed" / TOY.name / "chunks"
    env = {**os.environ, DELAY_ENV: "0.1"}  # 36 chunks x 0.1 s
    proc = subprocess.Popen([sys.executable, "-c", BOOT, *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 90
        while len(list(chunks.glob("*.npz"))) < 4:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk file appeared in 90 s"
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    before = len(list(chunks.glob("*.npz")))
    assert 4 <= before < 36
    assert not (tmp_path / "killed" / TOY.name / "summary.json").exists()

    resumed = subprocess.run([sys.executable, "-c", BOOT, *args, "--resume"], cwd=ROOT,
                             capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert "distributed imported: False" in resumed.stdout  # in-process: no Dask cluster
    p = _prov(tmp_path / "killed" / TOY.name)["sweep"]
    assert p["chunks_reused"] >= before and p["chunks_computed"] < 36
    assert p["chunks_reused"] + p["chunks_computed"] == 36 and p["resumed"] is True

    _, ref, _, _ = run_study(TOY.name, realizations=6000, out=tmp_path / "ref",
                             show_progress=False)
    xr.testing.assert_identical(_data(tmp_path / "killed" / TOY.name), _data(ref))


def test_resume_with_another_set_value_refuses_and_names_it(tmp_path, toy):
    r = _cli("run", TOY.name, "--realizations", "1024", "--out", str(tmp_path), "--no-progress")
    assert r.exit_code == 0, r.output
    r = _cli("run", TOY.name, "--realizations", "1024", "--out", str(tmp_path), "--no-progress",
             "--set", "b=0.5", "--resume")
    assert r.exit_code == 2
    line = _one_line(r)
    assert "params.b" in line and "--resume" in line and "--out" in line
    assert "a narrowed or changed axis is a new run" in line
    # another chunk size changes no result, so it resumes (nothing left to compute)
    r = _cli("run", TOY.name, "--realizations", "1024", "--out", str(tmp_path), "--no-progress",
             "--set", "chunk=2048", "--resume")
    assert r.exit_code == 0, r.output
    assert _prov(tmp_path / TOY.name)["sweep"]["chunks_computed"] == 0


def test_docs_do_not_promise_narrowing_on_resume():
    """--resume refuses other parameters (above), so no page may say a sweep resumes narrowed:
    the README once said "sweeps resume and narrow" beside a narrowed --resume command."""
    readme = (ROOT / "README.md").read_text()
    sweeps = (ROOT / "docs" / "sweeps.md").read_text()
    assert "resume and narrow" not in readme
    for line in readme.splitlines():
        if "--resume" in line and "--set" in line:
            raise AssertionError(f"README shows --resume with a changed grid: {line}")
    assert "continue a killed run (same parameters)" in readme
    assert "a narrowed or changed grid is a new run" in " ".join(sweeps.split())


@pytest.mark.dask
def test_two_worker_local_dask_cluster_is_bit_identical_to_in_process(tmp_path, toy):
    _, local, _, _ = run_study(TOY.name, realizations=2500, out=tmp_path / "local",
                               sets=["chunk=2048"], show_progress=False)
    t0 = time.perf_counter()
    _, dist, _, _ = run_study(TOY.name, realizations=2500, out=tmp_path / "dask",
                              sets=["chunk=1024"], show_progress=False,
                              options=RunOptions(execution=Execution(workers=2)))
    wall = time.perf_counter() - t0
    xr.testing.assert_identical(_data(dist), _data(local))
    p = _prov(dist)["sweep"]
    assert p["workers"] == 2 and p["chunks_computed"] == 18 and p["distributed"]
    assert wall < 120


@pytest.mark.parametrize("args, words", [
    (["seed001-fig3-elevation", "--resume"], ["resumable studies", "seed001-fig3-elevation"]),
    (["seed001-fig3-elevation", "--workers", "2"], ["sweep studies"]),
    (["toy-sweep", "--workers", "0"], ["--workers", ">= 1"]),
    (["toy-sweep", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], ["not both"]),
    (["toy-sweep", "--scheduler", "tcp://127.0.0.1:1"], ["Dask scheduler", "127.0.0.1:1"]),
    (["toy-sweep", "--scheduler", "nonsense://x"], ["Dask scheduler", "nonsense"]),
    (["toy-sweep", "--set", "a=1,1"], ["a", "twice"]),
    (["toy-sweep", "--set", "a=1,,2"], ["a", "empty"]),
    (["toy-sweep", "--set", "a=0"], ["a", "integer"]),
])
def test_flag_and_axis_errors_are_one_line(tmp_path, toy, args, words):
    r = _cli("run", *args, "--out", str(tmp_path), "--no-progress", "--realizations", "1024")
    assert r.exit_code == 2
    line = _one_line(r)
    for w in words:
        assert w in line, line


def test_sweep_study_run_works_without_an_output_folder(toy):
    """SweepStudy.run (tests, notebooks) runs in-process in a temporary folder."""
    res = TOY.run(TOY.validate({"a": "2"}), 1024, 0)
    assert res.dataset["r_mean"].shape == (1, 2) and res.metrics["cells"] == 2


def test_registered_studies_travel_to_workers_by_name(toy):
    """A registered study of the package reaches Dask workers as its name (looked up there),
    a study defined elsewhere (the toy) as the pickled object."""
    from oaraim.execute import _study_ref
    from oaraim.registry import STUDIES

    assert _study_ref(STUDIES["seed004-fig4-hpl-maps"]) == "seed004-fig4-hpl-maps"
    assert _study_ref(toy) is toy
