"""The documentation: the site builds strictly, the README stays short and in step with the
committed benchmark JSON, and every module, function and code example the docs name exists."""

import importlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from oaraim.bench import TABLE_BEGIN, TABLE_END, combined_table

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
README = ROOT / "README.md"


def test_mkdocs_build_strict(tmp_path):
    """`mkdocs build --strict` (what CI runs): no broken link, anchor or docstring warning."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}  # mkdocs-material's banner, not a warning
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q",
                        "-d", str(tmp_path / "site")], cwd=ROOT, capture_output=True,
                       text=True, timeout=300, env=env)
    assert r.returncode == 0, f"mkdocs build --strict failed:\n{r.stderr}\n{r.stdout}"
    assert (tmp_path / "site" / "api" / "araim" / "index.html").is_file()
    api = (tmp_path / "site" / "api" / "araim" / "index.html").read_text()
    assert "protection_levels" in api and "multiple-hypothesis solution separation" in api


def _table_block(text):
    return text.split(TABLE_BEGIN, 1)[1].split(TABLE_END, 1)[0].strip()


@pytest.mark.parametrize("page, runs", [
    (README, ["bench.json"]), (DOCS / "benchmarks.md", ["bench.json", "bench_gpu.json"])],
    ids=["README.md", "benchmarks.md"])
def test_bench_table_matches_committed_json(page, runs):
    """The README's table is generated from docs/bench.json (the CPU run), docs/benchmarks.md's
    from it and docs/bench_gpu.json (a run on a GPU); regenerate them with `python -m
    oaraim.bench --table docs/bench.json [docs/bench_gpu.json] --update PAGE`."""
    expected = combined_table([json.loads((DOCS / r).read_text()) for r in runs])
    assert _table_block(page.read_text()) == expected


def test_readme_is_short_and_has_no_session_notes():
    text = README.read_text()
    assert len(text.splitlines()) <= 200
    assert not re.search(r"\b[Ss]top \d+", text), "session notes ('stop N') belong in git"


def _directive_modules():
    mods = set()
    for md in DOCS.rglob("*.md"):
        mods.update(re.findall(r"^:::\s+([\w.]+)", md.read_text(), flags=re.M))
    return sorted(mods)


def test_every_documented_module_imports():
    mods = _directive_modules()
    assert {"oaraim.araim", "oaraim.geometry", "oaraim.mc"} <= set(mods)
    for name in mods:
        importlib.import_module(name)


def _resolve(dotted):
    """oaraim.<dotted>: the longest importable module prefix, then attributes."""
    parts = f"oaraim.{dotted}".split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def test_equation_map_names_exist():
    """Every `araim.x`, `geometry.x`, `mc.x`, `studies.x` in the equation tables exists."""
    text = (DOCS / "equations.md").read_text()
    names = set(re.findall(r"`((?:araim|geometry|mc|studies)(?:\.\w+)+)`", text))
    assert len(names) > 30
    missing = []
    for name in sorted(names):
        try:
            _resolve(name)
        except (ImportError, AttributeError):
            missing.append(name)
    assert not missing, f"named in docs/equations.md but not in the code: {missing}"


def test_readme_api_example_runs_and_prints_what_it_says():
    text = README.read_text()
    section = text.split("## The Python API in ten lines", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    claimed = re.search(r"prints `([^`]+)`", section).group(1)
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == claimed
