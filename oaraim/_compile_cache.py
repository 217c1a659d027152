"""JAX's persistent compilation cache, on by default for the CLI, the API and the tests.

A kernel compiled once (seconds to tens of seconds per batch shape and static configuration) is
written to disk and read back by the next process, and by the same process after
``jax.clear_caches()`` (the test suite clears after every module): the MHSS kernel of the bench
case compiles in 10-25 s and loads from the cache in 1-5 s (the rest is tracing and lowering,
which JAX does not cache). docs/benchmarks.md has the measured runs.

Where: ``OARAIM_JAX_CACHE`` (a folder; ``off`` / ``0`` / ``none`` / ``false`` / ``no``
disables it), else a compilation-cache folder the user already gave JAX
(``JAX_COMPILATION_CACHE_DIR`` or ``jax.config``; used as it is), else ``jax/CPU-KEY`` inside
oaraim's cache folder (``OARAIM_CACHE``, else the user cache folder that ``oaraim.data`` uses:
``~/.cache/oaraim/jax/...`` on Linux).

Safe across versions and machines: JAX's cache key hashes the lowered program, the compile
options, the backend and the jax / jaxlib versions, so a changed kernel or a new JAX makes a
new entry, never a wrong hit. The key does not hold the host CPU's instruction set, and
XLA:CPU compiles for the host (AVX-512 here): a cache folder shared by machines of another CPU
(a network home folder) could hand one machine code it cannot run. ``CPU-KEY`` (the machine
type and a hash of the CPU model and feature flags) keeps each kind of CPU in its own folder.
The folder is kept under ``MAX_SIZE_BYTES``: when it has grown past that, ``configure`` removes
the entries written longest ago until it holds three quarters of it (JAX's own cap needs the
``filelock`` package, which oaraim does not install). Removing the folder is always safe (the
next run compiles again).
"""

import hashlib
import os
import platform
import warnings
from pathlib import Path

import jax

ENV = "OARAIM_JAX_CACHE"
OFF_WORDS = frozenset({"", "0", "off", "none", "false", "no"})
#: programs that compile faster than this are not written (JAX's default is 1 s): every
#: program is, also the ~600 single operations of a ``reproduce --quick`` (0.01-0.3 s each,
#: ~18 s of compiling in all) and the suite's small helpers, which compile again after every
#: ``jax.clear_caches()``
MIN_COMPILE_TIME_S = 0.0
#: the cache folder's cap (``_prune``)
MAX_SIZE_BYTES = 2 * 1024**3


#: XLA:CPU flags oaraim sets for its process (``use_faster_compiler_flags``): the elemental
#: emitters instead of the fusion emitters compile the MHSS kernels in ~2/3 of the time (a
#: first ``reproduce --quick`` on 2 cores 405 -> 304 s) and run them as fast; outputs move by
#: rounding only (1e-16 to 1e-13 relative, the iterated solvers' results up to 1e-9)
XLA_CPU_FLAGS = {"xla_cpu_use_fusion_emitters": "false"}


def use_faster_compiler_flags() -> bool:
    """Add ``XLA_CPU_FLAGS`` to the ``XLA_FLAGS`` environment variable (inherited by the
    processes oaraim starts) unless it already names them, which the user's setting wins.

    XLA reads ``XLA_FLAGS`` once, when JAX first runs a computation; ``import oaraim`` comes
    before that in the CLI, the tests and most scripts. A process that ran JAX computations
    before importing oaraim keeps XLA's defaults (results equal to rounding). Returns whether
    this process runs with oaraim's values of the flags."""
    from jax._src import xla_bridge

    current = os.environ.get("XLA_FLAGS", "").strip()
    missing = [f"--{k}={v}" for k, v in XLA_CPU_FLAGS.items() if f"--{k}=" not in current]
    if missing and not xla_bridge.backends_are_initialized():
        current = " ".join([current] * bool(current) + missing)
        os.environ["XLA_FLAGS"] = current
    return all(f"--{k}={v}" in current.split() for k, v in XLA_CPU_FLAGS.items())


def _user_cache_root() -> Path:
    env = os.environ.get("OARAIM_CACHE")
    if env:
        return Path(env).expanduser()
    import platformdirs  # what pooch.os_cache uses; installed with pooch

    return Path(platformdirs.user_cache_dir("oaraim"))


def cpu_key() -> str:
    """``MACHINE-HASH``: the machine type and 12 hex digits of the CPU model name and feature
    flags (``/proc/cpuinfo``; the processor string elsewhere), the name of the cache subfolder
    of machines that can run each other's compiled code."""
    info = platform.processor()
    try:
        with open("/proc/cpuinfo") as fh:
            lines = [ln for ln in fh if ln.split(":", 1)[0].strip() in
                     ("model name", "flags", "Features", "CPU part")]
        info = "".join(sorted(set(lines))) or info
    except OSError:
        pass
    return f"{platform.machine() or 'cpu'}-{hashlib.sha256(info.encode()).hexdigest()[:12]}"


def default_dir() -> Path:
    """The cache folder when neither ``OARAIM_JAX_CACHE`` nor JAX's own setting names one."""
    return _user_cache_root() / "jax" / cpu_key()


def compile_cache_dir() -> Path | None:
    """The folder of JAX's persistent compilation cache this process uses, None when off."""
    current = jax.config.jax_compilation_cache_dir
    return Path(current) if current else None


def configure() -> Path | None:
    """Point JAX's persistent compilation cache at oaraim's folder (see the module docstring).

    Called once on ``import oaraim``, before anything compiles. Returns the folder, or None
    when ``OARAIM_JAX_CACHE`` turns the cache off or the folder cannot be written (one
    warning saying so; JAX would otherwise warn at every compilation).
    """
    setting = os.environ.get(ENV)
    if setting is not None and setting.strip().lower() in OFF_WORDS:
        jax.config.update("jax_enable_compilation_cache", False)
        return None
    if setting is not None:
        folder = Path(setting.strip()).expanduser()
    elif jax.config.jax_compilation_cache_dir:
        return Path(jax.config.jax_compilation_cache_dir)
    else:
        folder = default_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        usable = folder.is_dir() and os.access(folder, os.W_OK | os.X_OK)
    except OSError:
        usable = False
    if not usable:
        warnings.warn(f"oaraim: the compilation cache folder {folder} cannot be written, so "
                      f"kernels compile in every process; set {ENV} to a writable folder, or "
                      f"to 'off'", stacklevel=3)
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
    _prune(folder, MAX_SIZE_BYTES)
    return folder


def _prune(folder: Path, max_bytes: int) -> None:
    """Remove the oldest entries (by modification time) of a folder larger than
    ``max_bytes`` until it holds at most 3/4 of it. A process reading an entry removed here
    still reads it (POSIX); one that misses it compiles again."""
    try:
        entries = [(e.stat().st_mtime, e.stat().st_size, e.path) for e in os.scandir(folder)
                   if e.is_file(follow_symlinks=False)]
    except OSError:
        return
    total = sum(size for _, size, _ in entries)
    if total <= max_bytes:
        return
    for _, size, path in sorted(entries):
        if total <= 0.75 * max_bytes:
            break
        try:
            os.remove(path)
            total -= size
        except OSError:
            pass
