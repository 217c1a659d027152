"""JAX's persistent compilation cache (oaraim/_compile_cache.py): on by default, moved or turned
off by OARAIM_JAX_CACHE, a compiled program read back by the next process."""

import os
import subprocess
import sys
import time

import pytest

from oaraim import _compile_cache

# A program that takes a measurable time to compile (an unrolled chain of 300 sines), the cache
# events of this process, and the entries in the folder.
PROBE = """
import jax, jax.numpy as jnp, json, os
import oaraim
from oaraim import _compile_cache
events = []
jax.monitoring.register_event_listener(lambda name, **kw: events.append(name))
def f(x):
    for i in range(300):
        x = jnp.sin(x) * 1.0001 + i
    return x
jax.jit(f)(jnp.ones(3)).block_until_ready()
folder = _compile_cache.compile_cache_dir()
print(json.dumps({"folder": None if folder is None else str(folder),
                  "hits": events.count("/jax/compilation_cache/cache_hits"),
                  "misses": events.count("/jax/compilation_cache/cache_misses"),
                  "entries": sorted(os.listdir(folder)) if folder else []}))
"""


def _probe(env):
    import json

    full = {k: v for k, v in os.environ.items()
            if k not in ("OARAIM_JAX_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    full.update(env, JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    out = subprocess.run([sys.executable, "-c", PROBE], env=full, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


def test_second_process_reads_the_first_ones_program(tmp_path):
    first, _ = _probe({"OARAIM_JAX_CACHE": str(tmp_path / "c")})
    assert first["folder"] == str(tmp_path / "c")
    assert first["hits"] == 0 and first["misses"] >= 1
    assert any(e.startswith("jit_f-") for e in first["entries"])
    second, _ = _probe({"OARAIM_JAX_CACHE": str(tmp_path / "c")})
    assert second["hits"] >= 1 and second["misses"] == 0
    assert second["entries"] == first["entries"]


def test_default_folder_is_per_cpu_inside_oaraim_cache(tmp_path):
    got, _ = _probe({"OARAIM_CACHE": str(tmp_path)})
    assert got["folder"] == str(tmp_path / "jax" / _compile_cache.cpu_key())
    assert got["entries"]


@pytest.mark.parametrize("word", ["off", "False"])
def test_off_writes_nothing(tmp_path, word):
    got, _ = _probe({"OARAIM_JAX_CACHE": word, "OARAIM_CACHE": str(tmp_path)})
    assert got["folder"] is None and got["hits"] == 0
    assert not (tmp_path / "jax").exists()


def test_unwritable_folder_warns_once_and_runs(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    got, err = _probe({"OARAIM_JAX_CACHE": str(blocker / "cache")})
    assert got["folder"] is None
    assert err.count("cannot be written") == 1 and "OARAIM_JAX_CACHE" in err


def test_cpu_key_names_the_machine_and_a_hash():
    machine, digest = _compile_cache.cpu_key().rsplit("-", 1)
    assert machine and len(digest) == 12 and int(digest, 16) >= 0
    assert _compile_cache.cpu_key() == _compile_cache.cpu_key()


def test_prune_removes_the_oldest_entries_down_to_three_quarters(tmp_path):
    now = time.time()
    for i in range(8):  # 8 entries of 100 bytes, entry 0 the oldest
        p = tmp_path / f"e{i}"
        p.write_bytes(b"x" * 100)
        os.utime(p, (now - 100 + i, now - 100 + i))
    _compile_cache._prune(tmp_path, 1000)  # 800 bytes: under the cap, nothing removed
    assert len(os.listdir(tmp_path)) == 8
    _compile_cache._prune(tmp_path, 700)  # over: down to <= 525 bytes, the oldest first
    assert sorted(os.listdir(tmp_path)) == ["e3", "e4", "e5", "e6", "e7"]


FLAGS_PROBE = """
import json, os, sys
if sys.argv[1] == "jax-first":
    import jax.numpy as jnp
    jnp.ones(3).sum().block_until_ready()
import oaraim
from oaraim import _compile_cache
print(json.dumps({"xla_flags": os.environ.get("XLA_FLAGS"),
                  "in_effect": _compile_cache.use_faster_compiler_flags()}))
"""


@pytest.mark.parametrize("case", ["fresh", "user-flags", "user-sets-it", "jax-first"])
def test_faster_compiler_flags_are_added_before_jax_runs_and_never_over_the_users(case):
    """import oaraim adds XLA_CPU_FLAGS to XLA_FLAGS (kept with the user's other flags); a flag
    the user set stays as set; a process that ran JAX first keeps XLA's defaults and says so."""
    import json

    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["XLA_FLAGS"] = {"fresh": "", "user-flags": "--xla_cpu_enable_fast_math=false",
                        "user-sets-it": "--xla_cpu_use_fusion_emitters=true",
                        "jax-first": ""}[case]
    out = subprocess.run([sys.executable, "-c", FLAGS_PROBE, case], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    ours = " ".join(f"--{k}={v}" for k, v in _compile_cache.XLA_CPU_FLAGS.items())
    want = {"fresh": (ours, True),
            "user-flags": ("--xla_cpu_enable_fast_math=false " + ours, True),
            "user-sets-it": ("--xla_cpu_use_fusion_emitters=true", False),
            "jax-first": ("", False)}[case]
    assert (got["xla_flags"], got["in_effect"]) == want
