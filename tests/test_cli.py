"""The oaraim command line as a user meets it: errors exit 2 with one line, no traceback."""

import pytest
from typer.testing import CliRunner

from oaraim.cli import app

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, list(args), catch_exceptions=False)


def _one_error_line(result):
    text = result.output.strip()
    assert "Traceback" not in text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return lines[0]


def test_bad_probability_names_field_and_range():
    r = _run("run", "seed001-fig4-hpl-cdf", "--set", "p_md=2", "--no-progress")
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert "p_md" in line and "(0, 1)" in line and "2" in line


def test_unknown_study_lists_known_ones():
    r = _run("run", "seed001-fig9", "--no-progress")
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert "seed001-fig9" in line
    assert "seed001-fig3-elevation" in line and "seed001-fig4-hpl-cdf" in line


def test_unknown_set_key_lists_valid_keys():
    r = _run("run", "seed001-fig3-elevation", "--set", "n_sats=5", "--no-progress")
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert "n_sats" in line and "n_gps" in line and "mask_deg" in line


@pytest.mark.parametrize("setting, field", [("d_min_m=4000", "d_min_m"), ("sigma_sop_m=-1",
                                            "sigma_sop_m"), ("n_gps=abc", "n_gps"),
                                            ("mask_deg=95", "mask_deg"), ("p_fa", "--set")])
def test_other_bad_inputs(setting, field):
    r = _run("run", "seed001-fig4-hpl-cdf", "--set", setting, "--no-progress")
    assert r.exit_code == 2
    assert field in _one_error_line(r)


@pytest.mark.parametrize("args, words", [(("--only", "mhss,gpu"), ("gpu", "latency", "risk")),
                                         (("--mhss-batch", "0"), ("--mhss-batch", "0"))])
def test_bad_bench_options_are_one_line(args, words):
    r = _run("bench", *args)
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert all(w in line for w in words)


def test_bench_tables_of_two_runs_share_one_header():
    from oaraim.bench import combined_table

    cpu = {"fig3": {"realizations": 10, "wall_s": 1.0, "host": {"cpus": 2, "jax": "0.1"}}}
    gpu = {"fig3": {"realizations": 10, "wall_s": 0.5, "host": {
        "cpus": 16, "jax": "0.1", "backend": "gpu", "device": "NVIDIA H200"}}}
    lines = combined_table([cpu, gpu]).splitlines()
    assert len(lines) == 4 and lines[0].startswith("| kernel")
    assert "| 2 cores, JAX 0.1 |" in lines[2] and "NVIDIA H200 (16 cores host)" in lines[3]


def test_list_shows_studies_and_parameters():
    r = _run("list")
    assert r.exit_code == 0
    assert "seed001-fig3-elevation" in r.output and "--set p_md=0.001" in r.output


def test_list_prints_every_help_text_literally():
    """Help texts are not Rich markup ("towers within [d_min_m, d_max_m] of a user"
    lost its brackets): every study's title and every parameter's text appear verbatim
    (whitespace folded, as the console wraps)."""
    from oaraim.registry import STUDIES

    fold = lambda x: " ".join(x.split())  # noqa: E731
    text = fold(_run("list").output)
    assert "[d_min_m, d_max_m]" in text
    for name, s in STUDIES.items():
        assert fold(s.title) in text, name
        for key, p in s.params.items():
            assert fold(p.doc) in text, (name, key)


def test_run_then_report(tmp_path):
    r = _run("run", "seed001-fig4-hpl-cdf", "--realizations", "1500", "--out", str(tmp_path),
             "--no-progress")
    assert r.exit_code == 0, r.output
    assert "availability at HAL = 30 m" in r.output
    r = _run("report", "--out", str(tmp_path), "--write", str(tmp_path / "REPORT.md"))
    assert r.exit_code == 0
    assert "81.4" in r.output and "94.7" in r.output and "46" in r.output
    assert (tmp_path / "REPORT.md").read_text().startswith("# Reproduction report")


def test_report_without_results_is_a_clear_error(tmp_path):
    r = _run("report", "--out", str(tmp_path))
    assert r.exit_code == 2
    assert "no study results" in _one_error_line(r)


# ------------------------------------------------------------------------ the output folder

FAST = ("run", "seed001-fig4-hpl-cdf", "--realizations", "1500", "--no-progress")


def test_out_that_is_a_file_fails_before_computing(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    r = _run(*FAST, "--out", str(f))
    assert r.exit_code == 2
    assert "not a folder" in _one_error_line(r) or "cannot create" in _one_error_line(r)


def test_out_that_cannot_be_created_is_one_line():
    r = _run(*FAST, "--out", "/proc/oaraim-out")
    assert r.exit_code == 2
    assert "--out" in _one_error_line(r)


def test_busy_folder_is_refused_and_a_stale_lock_taken_over(tmp_path):
    """A lock naming a live process (pid 1) refuses the run; one naming a finished process is
    taken over, the run completes and releases the lock."""
    import subprocess
    import sys

    from oaraim.mc.store import LOCK_NAME

    folder = tmp_path / "seed001-fig4-hpl-cdf"
    folder.mkdir()
    (folder / LOCK_NAME).write_text("1\n")
    r = _run(*FAST, "--out", str(tmp_path))
    assert r.exit_code == 2
    assert "in use by another run (pid 1)" in _one_error_line(r)
    assert not (folder / "summary.json").exists()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (folder / LOCK_NAME).write_text(f"{dead}\n")
    r = _run(*FAST, "--out", str(tmp_path))  # the notice: tests/test_run_guarantees.py
    assert r.exit_code == 0, r.output
    assert f"took over the lock of process {dead}" in r.output
    assert (folder / "summary.json").exists() and not (folder / LOCK_NAME).exists()


def test_a_run_that_fails_while_writing_leaves_no_summary(tmp_path, monkeypatch):
    """summary.json marks a complete folder: a second run that fails while writing its data
    removes the first run's summary before touching the data, and keeps the complete data of
    the first run or none, never a mix."""
    import xarray as xr

    r = _run(*FAST, "--out", str(tmp_path))
    assert r.exit_code == 0
    folder = tmp_path / "seed001-fig4-hpl-cdf"
    assert (folder / "summary.json").exists()

    def broken(self, *a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(xr.Dataset, "to_zarr", broken)
    r = _run(*FAST, "--out", str(tmp_path), "--set", "p_md=0.002")
    assert r.exit_code == 2
    assert "No space left on device" in _one_error_line(r)
    assert not (folder / "summary.json").exists()
    monkeypatch.undo()
    assert xr.open_zarr(folder / "data.zarr", consolidated=False) is not None


def test_huge_realization_count_is_refused_before_computing():
    """A non-sweep study keeps its realizations in memory; 1e12 was accepted
    and grew until killed. Refused with one line naming the limit (20 x the default)."""
    r = _run("run", "seed001-fig4-hpl-cdf", "--realizations", "1000000000000", "--no-progress")
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert "at most 20,000,000" in line and "--seed" in line


def test_the_command_puts_numpy_on_small_pages_unless_the_user_chose(monkeypatch):
    """``oaraim`` turns NumPy's huge-page advice off at start (``config.small_pages_for_numpy``,
    docs/benchmarks.md: assembling a 1 x 1 deg map's 0.7 GB went 10 -> ~1 s); a user's
    ``NUMPY_MADVISE_HUGEPAGE`` is left to NumPy."""
    import os
    import sys

    import numpy as np

    from oaraim import cli, config

    ma = np._core.multiarray
    before = ma._get_madvise_hugepage()
    try:
        monkeypatch.setenv(config.NUMPY_HUGEPAGE_ENV, "unset below, absent again after")
        monkeypatch.delenv(config.NUMPY_HUGEPAGE_ENV)
        ma._set_madvise_hugepage(True)
        monkeypatch.setattr(sys, "argv", ["oaraim", "list"])
        with pytest.raises(SystemExit) as exit_:
            cli.main()
        assert exit_.value.code in (0, None)
        assert not ma._get_madvise_hugepage()
        assert os.environ[config.NUMPY_HUGEPAGE_ENV] == "0"  # reproduce's spawned jobs too
        ma._set_madvise_hugepage(True)
        monkeypatch.setenv(config.NUMPY_HUGEPAGE_ENV, "1")
        assert config.small_pages_for_numpy() is False
        assert ma._get_madvise_hugepage()
    finally:
        ma._set_madvise_hugepage(before)
