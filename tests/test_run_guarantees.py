"""What a run promises when something is wrong (docs/errors.md): one line, exit status 2, no
traceback, nothing half-written. The cases a bad-input review found broken: seeds past the
keys' range, a full disk, leftovers of a killed run, a sweep that fails before its first
chunk, a realization count past a sweep's keys, advice that did not fit the study, the notice
of a stale lock's takeover and orbit files refused before anything is written."""

import errno
import os
import subprocess
import sys
import warnings

import jax
import pytest
from typer.testing import CliRunner

from oaraim.cli import app
from oaraim.mc import sweep_store
from oaraim.mc.keys import SEED_RANGE, cell_key, check_seed
from oaraim.mc.store import LOCK_NAME
from tests.test_sweep_cli import TOY, ToySweep

FAST = ("run", "seed001-fig4-hpl-cdf", "--realizations", "1500", "--no-progress")


def _run(*args):
    return CliRunner().invoke(app, list(args), catch_exceptions=False)


def _one_line(result):
    text = result.output.strip()
    assert "Traceback" not in text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return " ".join(lines[0].split())


def _dead_pid():
    return int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                              capture_output=True, text=True, check=True).stdout)


@pytest.fixture
def toy(monkeypatch):
    from oaraim import registry

    monkeypatch.setitem(registry.STUDIES, TOY.name, TOY)
    return TOY


# ------------------------------------------------------------------------------ seeds


@pytest.mark.parametrize("seed", [str(2**63), str(-(2**63) - 1), "1" + "0" * 30])
def test_a_seed_outside_the_keys_range_is_one_line(tmp_path, seed):
    """``--seed 9223372036854775808`` (2^63) ended in a 64-line traceback (OverflowError:
    Python int too large to convert to C long, exit 1). The seed is checked against the range
    ``jax.random.key`` takes before anything is written, by run, reproduce and calibrate."""
    r = _run("run", "seed001-fig3-elevation", "--seed", seed, "--out", str(tmp_path),
             "--no-progress")
    assert r.exit_code == 2
    line = _one_line(r)
    assert "--seed must be an integer in [-2^63, 2^63 - 1]" in line and seed in line
    assert list(tmp_path.iterdir()) == []
    r = _run("reproduce", "--quick", "--seed", seed, "--out", str(tmp_path / "r"),
             "--no-progress")
    assert r.exit_code == 2 and "--seed must be" in _one_line(r)
    r = _run("calibrate", "seed001-fig4-hpl-cdf", "--seed", seed)
    assert r.exit_code == 2 and "--seed must be" in _one_line(r)


def test_the_seed_range_is_the_one_the_keys_take():
    """Both ends of ``SEED_RANGE`` make keys (distinct ones), one past either end does not:
    the check refuses exactly what the key derivation cannot take."""
    lo, hi = SEED_RANGE
    assert (lo, hi) == (-(2**63), 2**63 - 1)
    keys = [jax.random.key_data(cell_key(check_seed(s), 0)).tolist() for s in (lo, -1, 0, hi)]
    assert len({tuple(k) for k in keys}) == 4
    for s in (lo - 1, hi + 1):
        with pytest.raises(OverflowError):
            jax.random.key(s)
        with pytest.raises(ValueError, match=r"--seed must be an integer in \[-2\^63"):
            check_seed(s)
    with pytest.raises(ValueError, match="got 1.5"):
        check_seed(1.5)


# -------------------------------------------------------------------------- full disk


def test_a_full_disk_names_the_path_and_leaves_nothing(tmp_path, monkeypatch):
    """A full disk gave ``error: [Errno 28] No space left on device``: no path, no hint, and
    the half-written ``data.zarr.tmp-PID`` stayed. Now one line naming the path and what to
    do; the partial store is removed and a folder the run made and left empty goes too."""
    import xarray as xr

    def full_disk(self, store, *a, **k):
        os.makedirs(store)
        (store / "zarr.json").write_text("{")  # half written
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(xr.Dataset, "to_zarr", full_disk)
    r = _run(*FAST, "--out", str(tmp_path))
    assert r.exit_code == 2
    folder = tmp_path / "seed001-fig4-hpl-cdf"
    assert _one_line(r) == (f"error: {folder / 'data.zarr'}: No space left on device; free "
                            "space on that disk (or choose another --out) and rerun")
    assert list(tmp_path.iterdir()) == []  # no partial store, no empty study folder


class _DiskFullAfter:
    """``os`` for ``mc.sweep_store`` whose fsync fails from its ``n``-th call on (ENOSPC)."""

    def __init__(self, n):
        self.calls, self.n = 0, n

    def __getattr__(self, name):
        return getattr(os, name)

    def fsync(self, fd):
        self.calls += 1
        if self.calls >= self.n:
            raise OSError(errno.ENOSPC, "No space left on device")
        os.fsync(fd)


def test_a_full_disk_in_a_sweep_keeps_the_finished_chunks_for_resume(tmp_path, monkeypatch,
                                                                     toy):
    """The disk fills while a sweep writes its 4th chunk file: one line naming that file and
    saying that --resume keeps the finished chunks; no temporary file stays; --resume then
    reuses the 2 chunks written before."""
    import json

    monkeypatch.setenv("OARAIM_THREADS", "1")
    args = ("run", TOY.name, "--realizations", "2048", "--out", str(tmp_path), "--no-progress",
            "--set", "a=1,2")
    monkeypatch.setattr(sweep_store, "os", _DiskFullAfter(4))  # sweep.json, 2 chunks, fail
    r = _run(*args)
    assert r.exit_code == 2
    line = _one_line(r)
    folder = tmp_path / TOY.name
    assert line.startswith(f"error: {folder / 'chunks'}/") and ".npz: No space left on " in line
    assert line.endswith("free space on that disk (or choose another --out) and rerun with "
                         "--resume (the finished chunks or units are kept)")
    assert sorted(p.name for p in folder.iterdir()) == ["chunks", "sweep.json"]
    assert len(list((folder / "chunks").iterdir())) == 2  # whole files only, no .tmp
    monkeypatch.undo()
    monkeypatch.setitem(__import__("oaraim.registry").registry.STUDIES, TOY.name, TOY)
    r = _run(*args, "--resume")
    assert r.exit_code == 0, r.output
    sweep = json.loads((folder / "provenance.json").read_text())["sweep"]
    assert sweep["chunks_reused"] == 2 and sweep["chunks_computed"] == 6  # of 4 cells x 2


# -------------------------------------------------------------------------- leftovers


def test_leftovers_of_a_killed_run_are_removed_by_the_next(tmp_path, toy):
    """A run killed while assembling data.zarr left ``data.zarr.tmp-PID``, which a later
    successful ``--resume`` never removed. The next run that holds the folder's lock removes
    the temporary files and folders of dead runs (not a live run's lock being made)."""
    r = _run("run", TOY.name, "--realizations", "1024", "--out", str(tmp_path), "--no-progress")
    assert r.exit_code == 0, r.output
    folder = tmp_path / TOY.name
    dead = _dead_pid()
    left = [folder / f"data.zarr.tmp-{dead}", folder / f"data.zarr.old-{dead}"]
    for d in left:
        d.mkdir()
        (d / "zarr.json").write_text("{")
    left += [folder / "summary.json.tmp", folder / f".sweep.json.{dead}.tmp",
             folder / f"{LOCK_NAME}.tmp-{dead}-0123abcd"]
    for f in left[2:]:
        f.write_text("x")
    live = folder / f"{LOCK_NAME}.tmp-1-0123abcd"  # pid 1 runs: a lock being made
    live.write_text("1\n")
    r = _run("run", TOY.name, "--realizations", "1024", "--out", str(tmp_path), "--no-progress",
             "--resume")
    assert r.exit_code == 0, r.output
    assert [p for p in left if p.exists()] == [] and live.exists()
    assert (folder / "summary.json").exists()


class _FailingSweep(ToySweep):
    """A sweep whose kernel cannot be built (as a malformed input file read by the kernel)."""

    name = "toy-failing-sweep"

    def kernel(self, params, coords):
        raise ValueError("almanac file x.txt: line 3: the file is truncated")


def test_a_sweep_that_fails_before_its_first_chunk_leaves_nothing(tmp_path, monkeypatch):
    """A YUMA error raised by the kernel left ``sweep.json`` and an empty ``chunks/``. A sweep
    that fails before finishing a chunk removes both, and the study folder it made."""
    from oaraim import registry

    bad = _FailingSweep()
    monkeypatch.setitem(registry.STUDIES, bad.name, bad)
    r = _run("run", bad.name, "--realizations", "1024", "--out", str(tmp_path), "--no-progress")
    assert r.exit_code == 2
    assert _one_line(r) == "error: almanac file x.txt: line 3: the file is truncated"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("edit, message", [
    (lambda t: t[:t.index("Af0")], r"line \d+: the almanac block starting at line 1 lacks"),
    (lambda t: t.replace("5153.594238", "1000.000000", 1),
     r"line 8: satellite 1: sqrt\(A\) = 1000\.0 m\^1/2 is a semi-major axis of 1,000 km"),
])
def test_a_bad_almanac_for_the_map_is_refused_before_anything_is_written(shared_data, tmp_path,
                                                                        edit, message):
    """The availability map read its orbit files in the sweep's kernel: a malformed YUMA file
    left sweep.json and an empty chunks/, an orbit inside the Earth ran the map without the
    satellite. ``gps=``/``galileo=`` files are read when the parameters are checked."""
    import re

    text = (shared_data / "almanac" / "almyuma_01jan2020.txt").read_text()
    p = tmp_path / "alm.txt"
    p.write_text(edit(text))
    out = tmp_path / "out"
    r = _run("run", "availability-map", "--quick", "--set", f"gps={p}", "--out", str(out),
             "--no-progress")
    assert r.exit_code == 2
    assert re.search(rf"alm\.txt: {message}", _one_line(r))
    assert not (out / "availability-map").exists()


def test_near_duplicate_towers_for_the_map_are_one_line_before_anything_is_written(tmp_path):
    """Two rows of one carrier 1e-9 deg apart counted as two independent ranges; the map's
    tower file is read when the parameters are checked: one line, exit 2, nothing written."""
    f = tmp_path / "towers.csv"
    f.write_text("lat_deg,lon_deg,height_m,carrier\n50.01,0.0,40,A\n50.010000001,0.0,40,A\n")
    out = tmp_path / "out"
    r = _run("run", "availability-map", "--quick", "--set", f"towers={f}", "--out", str(out),
             "--no-progress")
    assert r.exit_code == 2
    assert "towers.csv, line 3: the tower of line 2 again (0.000111 m from it)" in _one_line(r)
    assert not out.exists()


# ---------------------------------------------------------------- sizes and advice


def test_a_sweep_refuses_more_realizations_than_its_keys_index(tmp_path, toy):
    """A sweep's realization index is 32-bit in its key: more than 2^32 per cell is refused
    with one line saying so, before anything is written (docs/errors.md said "any count")."""
    r = _run("run", TOY.name, "--realizations", str(2**32 + 1), "--out", str(tmp_path),
             "--no-progress")
    assert r.exit_code == 2
    line = _one_line(r)
    assert "at most 2^32 = 4,294,967,296" in line and "32-bit" in line and "--seed" in line
    assert list(tmp_path.iterdir()) == []
    assert TOY.realization_limit() == 2**32


def test_rinex_replay_refuses_a_huge_count_with_advice_for_a_file(tmp_path):
    """rinex-replay's realizations are the epochs of a file (its seed draws nothing): its
    refusal said "run several --seed values", which means nothing for a replay."""
    r = _run("run", "rinex-replay", "--realizations", "1000000000", "--out", str(tmp_path),
             "--no-progress")
    assert r.exit_code == 2
    line = _one_line(r)
    assert "at most 57,600" in line and "one epoch of the observation file" in line
    assert "--seed" not in line and "split a longer file" in line


# --------------------------------------------------------------------- the lock's notice


def test_a_stale_lock_takeover_is_one_clean_line(tmp_path):
    """Taking over a dead run's lock printed a raw ``UserWarning`` with a line of source code;
    now one line ``warning: ...`` naming the folder and the pid, and no Python warning."""
    folder = tmp_path / "seed001-fig4-hpl-cdf"
    folder.mkdir()
    dead = _dead_pid()
    (folder / LOCK_NAME).write_text(f"{dead}\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = _run(*FAST, "--out", str(tmp_path))
    assert r.exit_code == 0, r.output
    assert not [w for w in caught if "took over" in str(w.message)]
    notes = [ln for ln in r.output.splitlines() if "took over" in ln]
    assert [" ".join(n.split()) for n in notes] == [
        f"warning: {folder}: took over the lock of process {dead}, which is no longer running"]
    assert "UserWarning" not in r.output and "warnings.warn" not in r.output
    assert not (folder / LOCK_NAME).exists() and (folder / "summary.json").exists()


def test_every_test_that_docs_errors_names_exists():
    """docs/errors.md names the test of each guarantee (``tests/test_x.py::test_name``, or
    ``::test_name`` for another test of the file named last): each of them exists."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    text = (root / "docs" / "errors.md").read_text()
    current, named = None, []
    for span in re.findall(r"`([^`]+)`", text):
        m = re.fullmatch(r"(tests/\w+\.py)(?:::(\w+))?", span)
        if m:
            current = m.group(1)
            if m.group(2):
                named.append((current, m.group(2)))
        elif re.fullmatch(r"::\w+", span):
            assert current is not None, span
            named.append((current, span[2:]))
    assert len(named) >= 15
    for file, name in named:
        assert re.search(rf"^def {name}\(", (root / file).read_text(), re.M), (file, name)


def test_report_write_to_an_unusable_path_is_one_line(tmp_path):
    """``oaraim report --write`` into a path that cannot be made ended in a traceback; now one
    line naming the path (an OSError of the command, as of a run)."""
    r = _run(*FAST, "--out", str(tmp_path / "out"))
    assert r.exit_code == 0, r.output
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    r = _run("report", "--out", str(tmp_path / "out"), "--write", str(blocker / "REPORT.md"))
    assert r.exit_code == 2 and "Traceback" not in r.output  # the report, then one error line
    errors = [" ".join(ln.split()) for ln in r.output.splitlines() if ln.startswith("error:")]
    assert errors == [f"error: {blocker}: File exists; check that path and its disk and rerun"]
