"""oaraim.data and `oaraim data` against a loopback mirror of ../shared/data.

Every server here is an http.server on 127.0.0.1, port 0, in a thread, shut down at teardown;
nothing leaves the machine. The mirror counts the requests it answers, so a cache hit is seen
as no request at all.
"""

import functools
import gzip
import http.server
import re
import shutil
import socket
import threading
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from oaraim import cli, data
from oaraim.cli import app
from oaraim.registry import STUDIES
from oaraim.studies.base import Study, StudyResult

SMALL = "almanac/almmops.txt"
runner = CliRunner()


class _Handler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):  # quiet
        pass

    def do_GET(self):  # noqa: N802 - http.server's name
        self.server.paths.append(self.path)
        super().do_GET()


@pytest.fixture
def serve():
    """serve(folder) -> base URL of a loopback HTTP server of ``folder`` (request log in
    ``.paths`` of the returned server)."""
    servers = []

    def start(folder):
        handler = functools.partial(_Handler, directory=str(folder))
        srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        srv.paths = []
        srv.timeout = 5
        threading.Thread(target=srv.serve_forever, daemon=True).start()
        servers.append(srv)
        return f"http://127.0.0.1:{srv.server_address[1]}/", srv

    yield start
    for srv in servers:
        srv.shutdown()
        srv.server_close()


@pytest.fixture
def cache(tmp_path, monkeypatch):
    c = tmp_path / "cache"
    monkeypatch.setenv("OARAIM_CACHE", str(c))
    return c


def _refused_url():
    """A loopback URL nobody listens on (a port just bound and released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"http://127.0.0.1:{port}/"


def _one_line(text):
    assert "Traceback" not in text, text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return lines[0]


def test_registry_covers_every_shared_file_with_its_checksum(shared_data):
    on_disk = sorted(str(p.relative_to(shared_data)) for p in shared_data.rglob("*")
                     if p.is_file() and p.name != "README.md")
    reg = data.registry()
    assert sorted(reg) == on_disk
    for name, e in reg.items():
        assert e.size == (shared_data / name).stat().st_size, name
        assert e.sha256 == data.sha256(shared_data / name), name
        assert e.url.startswith("https://raw.githubusercontent.com/"), name
        assert e.url.endswith("/" + Path(name).name) and e.licence and e.description


def test_fetch_from_mirror_then_from_cache(shared_data, serve, cache, monkeypatch):
    url, srv = serve(shared_data)
    monkeypatch.setenv("OARAIM_DATA", url)
    assert data.status(SMALL) == ("missing", None)
    p = data.path(SMALL, progress=False)
    assert p == cache / SMALL
    assert p.read_bytes() == (shared_data / SMALL).read_bytes()
    assert srv.paths == ["/" + SMALL]
    assert data.path(SMALL) == p and srv.paths == ["/" + SMALL]  # cached: no request
    assert data.status(SMALL) == ("cached", p)


def test_file_url_mirror(shared_data, cache, monkeypatch):
    monkeypatch.setenv("OARAIM_DATA", shared_data.as_uri())
    p = data.path("obs/07590920.05n")
    assert p == cache / "obs/07590920.05n"
    assert p.read_bytes() == (shared_data / "obs/07590920.05n").read_bytes()


@pytest.mark.parametrize("scheme", ["http", "file"])
def test_checksum_mismatch_names_both_hashes_and_keeps_nothing(shared_data, serve, cache,
                                                               tmp_path, monkeypatch, scheme):
    bad = tmp_path / "mirror"
    (bad / "almanac").mkdir(parents=True)
    body = bytearray((shared_data / SMALL).read_bytes())
    body[100] ^= 1  # one flipped bit
    (bad / SMALL).write_bytes(bytes(body))
    monkeypatch.setenv("OARAIM_DATA", serve(bad)[0] if scheme == "http" else bad.as_uri())
    with pytest.raises(data.DataUnavailable) as exc:
        data.path(SMALL)
    msg = str(exc.value)
    assert "\n" not in msg and SMALL in msg
    import hashlib

    assert f"expected sha256 {data.entry(SMALL).sha256}, got " \
           f"{hashlib.sha256(bytes(body)).hexdigest()}" in msg
    assert [p for p in cache.rglob("*") if p.is_file()] == []


def test_offline_mirror_is_one_line_with_the_command(cache, monkeypatch):
    monkeypatch.setenv("OARAIM_DATA", _refused_url())
    with pytest.raises(data.DataUnavailable) as exc:
        data.path(SMALL)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"data file {SMALL}: download from http://127.0.0.1:")
    assert "Connection refused" in msg and f"`oaraim data fetch {SMALL}`" in msg


def test_missing_on_mirror_is_http_404(serve, cache, tmp_path, monkeypatch):
    monkeypatch.setenv("OARAIM_DATA", serve(tmp_path)[0])
    with pytest.raises(data.DataUnavailable, match=f"data file {SMALL}: .* failed: HTTP 404"):
        data.path(SMALL)


def test_folder_without_the_file_names_folder_and_fix(tmp_path, monkeypatch):
    monkeypatch.setenv("OARAIM_DATA", str(tmp_path))
    with pytest.raises(data.DataUnavailable,
                       match=f"data file {SMALL} is not in the folder OARAIM_DATA={tmp_path}; "
                       "copy it into"):
        data.path(SMALL)
    with pytest.raises(data.DataUnavailable, match="unknown data file 'nav/x.10n'; known files: "
                       "almanac/alm_gal_ed259.txt"):
        data.path("nav/x.10n")


# ------------------------------------------------------------------------------------ CLI


def test_cli_data_list_and_fetch(shared_data, serve, cache, monkeypatch):
    url, srv = serve(shared_data)
    monkeypatch.setenv("OARAIM_DATA", url)
    # rows unwrapped: the CLI's console reads the width once, when oaraim.cli is imported, from
    # COLUMNS or the terminal, which a pytest worker may not have
    monkeypatch.setattr(cli.out, "width", 250)
    r = runner.invoke(app, ["data", "list"], catch_exceptions=False)
    assert r.exit_code == 0
    row = next(ln for ln in r.output.splitlines() if SMALL in ln)
    assert "missing" in row and "stanford-gps-lab/maast" in row and "13 kB" in row
    assert f"files come from the mirror OARAIM_DATA={url}" in r.output
    r = runner.invoke(app, ["data", "fetch", SMALL, "--no-progress"], catch_exceptions=False)
    assert r.exit_code == 0 and r.output.strip() == f"{SMALL}: {cache / SMALL}"
    r = runner.invoke(app, ["data", "list"], catch_exceptions=False)
    assert "cached" in next(ln for ln in r.output.splitlines() if SMALL in ln)


def test_cli_data_fetch_unknown_name_and_offline(cache, monkeypatch):
    monkeypatch.setenv("OARAIM_DATA", _refused_url())
    r = runner.invoke(app, ["data", "fetch", "nav/nope.22n"], catch_exceptions=False)
    assert r.exit_code == 2
    line = _one_line(r.output)
    assert "unknown data file 'nav/nope.22n'" in line and "nav/brdc0010.22n" in line
    r = runner.invoke(app, ["data", "fetch", SMALL, "--no-progress"], catch_exceptions=False)
    assert r.exit_code == 2
    line = _one_line(r.output)
    assert SMALL in line and "Connection refused" in line and "oaraim data fetch" in line
    r = runner.invoke(app, ["data", "fetch"], catch_exceptions=False)
    assert r.exit_code == 2 and "--all" in _one_line(r.output)


@pytest.mark.parametrize("codec", [".Z", ".gz"])
def test_cli_data_nav_from_an_archive(shared_data, serve, cache, tmp_path, codec):
    """2010-07-01 = day 182: the archive holds brdc1820.10n compressed as IGS archives do;
    the RINEX 3 names are tried first (404), then the RINEX 2 ones."""
    import ncompress

    day = tmp_path / "archive" / "2010" / "182"
    day.mkdir(parents=True)
    raw = (shared_data / "nav/brdc1820.10n").read_bytes()
    packed = ncompress.compress(raw) if codec == ".Z" else gzip.compress(raw)
    (day / f"brdc1820.10n{codec}").write_bytes(packed)
    url, srv = serve(tmp_path / "archive")
    r = runner.invoke(app, ["data", "nav", "2010-07-01", "--archive", url, "--no-progress"],
                      catch_exceptions=False)
    assert r.exit_code == 0, r.output
    p = Path(r.output.strip())
    assert p.parent == cache / "brdc"
    assert p.name == ("brdc1820.10n" if codec == ".Z" else "brdc1820.10n.gz")
    assert srv.paths == ["/2010/182/BRDC00IGS_R_20101820000_01D_MN.rnx.gz",
                         "/2010/182/BRDC00WRD_R_20101820000_01D_MN.rnx.gz",
                         "/2010/182/brdc1820.10n.gz"] + \
        (["/2010/182/brdc1820.10n.Z"] if codec == ".Z" else [])
    assert data.sha256(p) in p.with_name(p.name + ".sha256").read_text()
    from oaraim import geometry

    eph = geometry.load_navigation(p, systems=("G",))
    assert "421 records" in repr(eph)
    r = runner.invoke(app, ["data", "nav", "2010-07-01", "--archive", url], catch_exceptions=False)
    assert r.exit_code == 0 and Path(r.output.strip()) == p  # cached: no new request
    assert len(srv.paths) == (4 if codec == ".Z" else 3)


def test_cli_data_nav_errors(serve, cache, tmp_path):
    url, _ = serve(tmp_path)
    r = runner.invoke(app, ["data", "nav", "2010-07-01", "--archive", url],
                      catch_exceptions=False)
    assert r.exit_code == 2
    line = _one_line(r.output)
    assert "no daily broadcast file of 2010-07-01 (day 182)" in line and "--archive" in line
    r = runner.invoke(app, ["data", "nav", "2010-13-01"], catch_exceptions=False)
    assert r.exit_code == 2 and "YYYY-MM-DD" in _one_line(r.output)
    r = runner.invoke(app, ["data", "nav", "2010-07-01", "--archive", _refused_url()],
                      catch_exceptions=False)
    assert r.exit_code == 2 and "Connection refused" in _one_line(r.output)


@pytest.mark.parametrize("served", ["html", "observation file", "truncated"])
def test_cli_data_nav_refuses_a_download_that_is_not_navigation(shared_data, serve, cache,
                                                                tmp_path, served):
    """An archive answering with an HTML page, another RINEX type or a cut file: one line
    naming the URL and what is wrong, and nothing cached."""
    day = tmp_path / "archive" / "2010" / "182"
    day.mkdir(parents=True)
    nav = (shared_data / "nav/brdc1820.10n").read_bytes()
    body = {"html": b"<!DOCTYPE html><html><body>Please log in</body></html>\n",
            "observation file": gzip.compress((shared_data / "obs/07590920.05o").read_bytes()),
            "truncated": gzip.compress(nav)[:50_000]}[served]
    name = "BRDC00IGS_R_20101820000_01D_MN.rnx.gz"
    (day / name).write_bytes(body)
    url, _ = serve(tmp_path / "archive")
    r = runner.invoke(app, ["data", "nav", "2010-07-01", "--archive", url, "--no-progress"],
                      catch_exceptions=False)
    assert r.exit_code == 2
    line = _one_line(r.output)
    assert line.startswith(f"error: daily broadcast file of 2010-07-01: {url}2010/182/{name} "
                           "is not a RINEX navigation file (")
    assert {"html": "not gzip-compressed, it starts with b'<!DOCTYPE html>",
            "observation file": "type 'O' in column 21",
            "truncated": "Compressed file ended before the end-of-stream marker"}[served] in line
    assert "nothing was cached" in line and "--archive URL" in line
    assert [p for p in cache.rglob("*") if p.is_file()] == []


# ----------------------------------------------------------------------- studies, reproduce


def test_study_with_auto_sky_and_offline_mirror_exits_2_with_one_line(cache, monkeypatch,
                                                                       tmp_path):
    from oaraim.studies.common import seed004

    # a seed 004 study run earlier in this process left the day's sky table in memory
    seed004.gps_sky_table.cache_clear()
    seed004.gps_sky_arrays.cache_clear()
    monkeypatch.setenv("OARAIM_DATA", _refused_url())
    r = runner.invoke(app, ["run", "seed004-fig3-one-sop", "--realizations", "1024", "--out",
                            str(tmp_path), "--no-progress"], catch_exceptions=False)
    assert r.exit_code == 2
    line = _one_line(r.output)
    assert "data file nav/brdc0010.22n: download from" in line
    assert "`oaraim data fetch nav/brdc0010.22n`" in line and "--set nav=nominal" in line


class _FakeStudy(Study):
    title = "a study for the reproduce tests"
    realization = "nothing"
    params = {}

    def __init__(self, name, fail=None):
        self.name, self.fail = name, fail

    def run(self, params, realizations, seed, progress):
        if self.fail is not None:
            raise self.fail
        ds = xr.Dataset({"x": ("i", np.arange(3.0))})
        return StudyResult(ds, [{"quantity": "answer", "unit": "-", "published": 42.0,
                                 "reproduced": 42.0, "note": ""}], {})

    def plot(self, out_dir):
        return []


@pytest.fixture
def fakes(monkeypatch):
    for s in (_FakeStudy("fake-ok"), _FakeStudy("fake-bug", RuntimeError("boom\nsecond line")),
              _FakeStudy("fake-input", ValueError("x must be > 0, got -1"))):
        monkeypatch.setitem(STUDIES, s.name, s)


def test_reproduce_reports_failures_and_runs_the_rest(fakes, cache, monkeypatch, tmp_path):
    monkeypatch.setenv("OARAIM_DATA", _refused_url())
    out = tmp_path / "out"
    r = runner.invoke(app, ["reproduce", "--quick", "--out", str(out), "--no-progress",
                            "--only", "seed001-fig5-madrid-24h", "--only", "fake-bug",
                            "--only", "fake-ok", "--only", "fake-input"],
                      catch_exceptions=False)
    assert r.exit_code == 2
    text = r.output
    assert "Traceback" not in text
    assert sum(ln.startswith("missing data: data file nav/VILL00ESP") for ln in
               text.splitlines()) == 1
    assert "seed001-fig5-madrid-24h: FAILED: data file nav/VILL00ESP_R_20181700000_01D_MN" \
           ".rnx.gz unavailable (see above)" in text
    assert "fake-bug: FAILED: RuntimeError: boom second line (rerun `oaraim run fake-bug` for " \
           "the traceback)" in text
    assert "fake-input: FAILED: x must be > 0, got -1" in text
    assert "## fake-ok" in text and "## fake-bug" not in text
    assert "3 of 4 studies failed:" in text
    assert not (out / "REPORT.md").exists()  # quick: the report is printed only


def test_reproduce_full_size_writes_report_under_out_or_results(fakes, tmp_path):
    out, res = tmp_path / "out", tmp_path / "results"
    r = runner.invoke(app, ["reproduce", "--out", str(out), "--no-progress", "--only",
                            "fake-ok"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert "## fake-ok" in (out / "REPORT.md").read_text() and not res.exists()
    r = runner.invoke(app, ["reproduce", "--out", str(out), "--no-progress", "--only",
                            "fake-ok", "--only", "fake-bug", "--results", str(res)],
                      catch_exceptions=False)
    assert r.exit_code == 2
    assert sorted(p.name for p in (res / "fake-ok").iterdir()) == ["provenance.json",
                                                                   "summary.json"]
    assert not (res / "fake-bug").exists()
    report = (res / "REPORT.md").read_text()
    assert "## fake-ok" in report and "fake-bug" not in report
    r = runner.invoke(app, ["reproduce", "--quick", "--results", str(res)],
                      catch_exceptions=False)
    assert r.exit_code == 2 and "--results takes the full-size run" in _one_line(r.output)


@pytest.mark.parametrize("where", ["--out a file", "--out under /proc", "--results a file"])
def test_reproduce_checks_its_output_folders_once_before_any_study(fakes, tmp_path, where):
    """Before: every study ran, then each failed on the folder (one FAILED line per study).
    Now: one line naming the option and the folder, exit 2, no study run."""
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    out = {"--out a file": a_file, "--out under /proc": Path("/proc/oaraim-out")}.get(
        where, tmp_path / "out")
    extra = ["--results", str(a_file)] if where == "--results a file" else []
    r = runner.invoke(app, ["reproduce", "--out", str(out), "--no-progress", "--only",
                            "fake-ok", "--only", "fake-input", *extra], catch_exceptions=False)
    assert r.exit_code == 2
    line = _one_line(r.output)
    option = "--results" if extra else "--out"
    assert line.startswith(f"error: {option}: ") and str(a_file if where != "--out under /proc"
                                                         else out) in line
    assert f"choose a writable {option}" in line or f"choose another {option}" in line


def test_cli_source_never_points_at_its_own_folder():
    """The installed CLI computes no path from its own location (no results/ beside it)."""
    import inspect

    from oaraim import cli

    src = inspect.getsource(cli)
    assert "__file__" not in src and "RESULTS_DIR" not in src
    shutil.which("oaraim")  # the entry point exists in the venv


# ------------------------------------------------------------------ local data verified


def _edited_folder(shared_data, tmp_path):
    folder = tmp_path / "data"
    (folder / "almanac").mkdir(parents=True)
    # a one-byte edit that keeps the almanac readable: one more trailing newline
    (folder / SMALL).write_bytes((shared_data / SMALL).read_bytes() + b"\n")
    return folder


def test_edited_folder_file_is_refused_naming_both_hashes(shared_data, cache, tmp_path,
                                                          monkeypatch):
    folder = _edited_folder(shared_data, tmp_path)
    monkeypatch.setenv("OARAIM_DATA", str(folder))
    with pytest.raises(data.DataUnavailable) as e:
        data.path(SMALL)
    msg = str(e.value)
    assert data.entry(SMALL).sha256 in msg and data.sha256(folder / SMALL) in msg
    assert "--trust-data" in msg and "\n" not in msg
    monkeypatch.setenv("OARAIM_TRUST_DATA", "1")
    assert data.path(SMALL) == folder / SMALL


def test_folder_files_are_hashed_once(shared_data, cache, tmp_path, monkeypatch):
    """The check costs one hash per file: remembered by (path, size, mtime) in the cache's
    verified.json, so a new process does not hash again; an edit (new mtime) is hashed."""
    folder = tmp_path / "data"
    (folder / "almanac").mkdir(parents=True)
    shutil.copy2(shared_data / SMALL, folder / SMALL)
    monkeypatch.setenv("OARAIM_DATA", str(folder))
    calls = []
    real = data.sha256
    monkeypatch.setattr(data, "sha256", lambda p: calls.append(p) or real(p))
    monkeypatch.setattr(data, "_HASHED", {})
    for _ in range(3):
        assert data.path(SMALL) == folder / SMALL
    assert len(calls) == 1
    monkeypatch.setattr(data, "_HASHED", {})  # a new process: verified.json remembers
    assert data.path(SMALL) == folder / SMALL and len(calls) == 1
    raw = bytearray((folder / SMALL).read_bytes())
    raw[100] ^= 0x01
    (folder / SMALL).write_bytes(bytes(raw))
    with pytest.raises(data.DataUnavailable, match="not the published file"):
        data.path(SMALL)
    assert len(calls) == 2


def test_cli_run_refuses_an_edited_almanac_unless_trusted(shared_data, cache, tmp_path,
                                                          monkeypatch):
    folder = _edited_folder(shared_data, tmp_path)
    monkeypatch.setenv("OARAIM_DATA", str(folder))
    monkeypatch.setenv("OARAIM_TRUST_DATA", "0")  # restored at teardown (--trust-data sets it)
    args = ["run", "availability-map", "--set", "lat_deg=40", "--set", "lon_deg=0",
            "--set", "galileo=none", "--set", "duration_s=600", "--no-progress",
            "--out", str(tmp_path / "out")]
    r = runner.invoke(app, args, catch_exceptions=False)
    assert r.exit_code == 2
    assert "not the published file" in _one_line(r.output)
    r = runner.invoke(app, args + ["--trust-data"], catch_exceptions=False)
    assert r.exit_code == 0, r.output


def test_changed_cached_broadcast_file_is_refused(shared_data, serve, cache, tmp_path):
    day = tmp_path / "archive" / "2010" / "182"
    day.mkdir(parents=True)
    (day / "brdc1820.10n.gz").write_bytes(gzip.compress(
        (shared_data / "nav/brdc1820.10n").read_bytes()))
    url, _ = serve(tmp_path / "archive")
    p = data.fetch_daily_nav("2010-07-01", url, progress=False)
    assert data.fetch_daily_nav("2010-07-01", url, progress=False) == p
    p.write_bytes(p.read_bytes() + b"\n")
    with pytest.raises(data.DataUnavailable, match="changed since it was downloaded"):
        data.fetch_daily_nav("2010-07-01", url, progress=False)


# ------------------------------------------------- the tests get their data as users do


def test_link_folder_fetches_verifies_and_links(shared_data, serve, cache, tmp_path,
                                                monkeypatch):
    url, srv = serve(shared_data)
    monkeypatch.setenv("OARAIM_DATA", url)
    names = [SMALL, "obs/07590920.05n"]
    assert data.link_folder(tmp_path / "linked", names) == {}
    for name in names:
        assert (tmp_path / "linked" / name).resolve() == (cache / name).resolve()
        assert (tmp_path / "linked" / name).read_bytes() == (shared_data / name).read_bytes()
    assert sorted(srv.paths) == sorted("/" + n for n in names)


def test_link_folder_names_each_missing_file_and_why(shared_data, serve, cache, tmp_path,
                                                     monkeypatch):
    bad = tmp_path / "mirror"
    (bad / "almanac").mkdir(parents=True)
    (bad / SMALL).write_bytes((shared_data / SMALL).read_bytes() + b"\n")
    monkeypatch.setenv("OARAIM_DATA", serve(bad)[0])
    failed = data.link_folder(tmp_path / "linked", [SMALL, "obs/07590920.05n"])
    assert f"data file {SMALL} from http://127.0.0.1:" in failed[SMALL]
    assert "failed its checksum" in failed[SMALL]
    assert "HTTP 404" in failed["obs/07590920.05n"]
    assert not (tmp_path / "linked" / SMALL).exists()
    monkeypatch.setenv("OARAIM_DATA", _refused_url())  # the first refusal stops the others
    failed = data.link_folder(tmp_path / "linked", [SMALL, "obs/07590920.05n"])
    assert "Connection refused" in failed[SMALL]
    assert failed["obs/07590920.05n"].startswith(f"not tried, as {SMALL} could not be "
                                                 "fetched from 127.0.0.1:")


def _pytest_data_test(env_extra, cache_dir):
    """Run the data fixture's test in a fresh pytest process with only ``env_extra`` as the
    data settings (no folder beside the checkout is used once OARAIM_DATA is a URL)."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith("OARAIM_")}
    env.update(OARAIM_CACHE=str(cache_dir), **env_extra)
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs",
                        "tests/test_data.py::test_shared_data_holds_every_registry_file_"
                        "verified"], cwd=data.REPO_ROOT, env=env, capture_output=True,
                       text=True, timeout=300)
    return r.returncode, r.stdout + r.stderr


def test_test_suite_fetches_its_data_from_a_mirror_url(shared_data, serve, cache):
    """The README's test command with OARAIM_DATA set to a mirror URL and an empty cache runs
    the data-backed tests: every file is fetched once, checksum-verified, into the cache."""
    url, srv = serve(shared_data)
    rc, out = _pytest_data_test({"OARAIM_DATA": url, "OARAIM_REQUIRE_DATA": "1"}, cache)
    assert rc == 0 and "1 passed" in out, out
    assert sorted(srv.paths) == sorted("/" + n for n in data.registry())
    assert sorted(str(p.relative_to(cache)) for p in cache.rglob("*")
                  if p.is_file() and p.parent != cache) == sorted(data.registry())


def test_test_suite_without_a_source_skips_naming_files_or_fails_when_required(cache):
    url = _refused_url()
    rc, out = _pytest_data_test({"OARAIM_DATA": url}, cache)
    assert rc == 0 and "1 skipped" in out, out
    assert "real GNSS files unavailable (21 of 21 failed; looked in the mirror" in out
    rc, out = _pytest_data_test({"OARAIM_DATA": url, "OARAIM_REQUIRE_DATA": "1"}, cache)
    assert rc == 1 and "1 error" in out, out  # the fixture fails: the test is an error
    assert "Connection refused" in out and "(OARAIM_REQUIRE_DATA=1)" in out
    assert "obs/07590920.05n, obs/07590920.05o, obs/30400920.05n" in out
    assert "not tried, as almanac/alm_gal_ed259.txt could not be fetched" in out


def test_reproduce_runs_studies_in_parallel_processes_with_the_same_report(tmp_path):
    """--jobs 2 runs the studies in spawned processes (the costliest first) and prints the
    report the one-process run prints, in registry order (the results do not depend on the
    process); --jobs 0 is one line."""
    only = ["--only", "seed001-fig4-hpl-cdf", "--only", "seed001-fig3-elevation"]
    reports = {}
    for jobs in (1, 2):
        out = tmp_path / f"jobs{jobs}"
        r = runner.invoke(app, ["reproduce", "--quick", "--out", str(out), "--no-progress",
                                "--jobs", str(jobs), *only], catch_exceptions=False)
        assert r.exit_code == 0, r.output
        reports[jobs] = re.sub(r"wall [0-9.]+ s", "wall", r.stdout)
        assert all((out / n / "summary.json").exists() for n in only[1::2])
    assert reports[1] == reports[2]
    assert reports[2].index("## seed001-fig3-elevation") < reports[2].index(
        "## seed001-fig4-hpl-cdf")
    r = runner.invoke(app, ["reproduce", "--quick", "--jobs", "0", *only])
    assert r.exit_code == 2 and "--jobs must be >= 1, got 0" in _one_line(r.output)


def test_only_registry_studies_go_to_worker_processes(fakes):
    """A study registered at run time (the fakes) does not exist in a new process: reproduce
    runs those in its own."""
    assert STUDIES.is_builtin("seed001-fig4-hpl-cdf")
    assert not STUDIES.is_builtin("fake-ok") and not STUDIES.is_builtin("no-such-study")
