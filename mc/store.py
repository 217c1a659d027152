"""Result storage: ``OUT/STUDY/`` holds data.zarr, summary.json, provenance.json and figures."""

import datetime as _dt
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

PACKAGES = ("oaraim", "jax", "jaxlib", "numpy", "scipy", "xarray", "zarr", "matplotlib")


def jsonable(x):
    """``x`` as plain JSON values: dict keys as strings, tuples and arrays as lists, NumPy
    scalars as Python ones, NaN as null and +-inf as the strings "inf" / "-inf"."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, float) and not np.isfinite(x):
        return None if np.isnan(x) else ("inf" if x > 0 else "-inf")
    return x


def write_json(path, obj):
    """Write ``jsonable(obj)`` to ``path`` (indented, parent folders made) atomically: a
    reader never sees half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(jsonable(obj), indent=2, allow_nan=False) + "\n")
    os.replace(tmp, path)  # atomic: a reader never sees half a file


def read_summary(path):
    """The JSON object stored at ``path`` (a ``summary.json``); "inf" stays a string."""
    return json.loads(Path(path).read_text())


def git_commit(cwd=None):
    """The repository commit the code runs from, with '+dirty' for local changes."""
    here = Path(cwd or Path(__file__).resolve().parent)
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def package_versions():
    """{name: installed version or None} for Python and ``PACKAGES``, for provenance.json."""
    out = {"python": sys.version.split()[0]}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


def provenance(study, params, seed, realizations, wall_s, **extra):
    """Everything needed to rerun a result: parameters, seed, versions, commit, machine, time."""
    return {
        "study": study,
        "parameters": params,
        "seed": int(seed),
        "realizations": int(realizations),
        "wall_time_s": float(wall_s),
        "finished_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
        "versions": package_versions(),
        "machine": {"platform": platform.platform(), "cpu_count": os.cpu_count()},
        **extra,
    }


def write_results(out_dir, dataset, summary, provenance_dict, before_summary=None):
    """Write one study's results so that a folder holding ``summary.json`` is always complete:
    the old summary is removed first, the data written to a temporary name and renamed over
    the old, provenance next, then ``before_summary()`` (the figures, which read the data), the
    summary last (atomic renames throughout). Returns ``before_summary()``'s value."""
    import shutil

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").unlink(missing_ok=True)
    tmp = out_dir / f"data.zarr.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    with warnings.catch_warnings():
        # zarr 3 warns that fixed-length string arrays (e.g. tower or satellite names) have no
        # Zarr V3 specification yet; zarr and xarray read them back exactly (tested), and the
        # warning says nothing a user can act on
        warnings.filterwarnings("ignore", message=".*does not have a Zarr V3 specification")
        dataset.to_zarr(tmp, mode="w", consolidated=False)
    final = out_dir / "data.zarr"
    if final.exists():
        old = out_dir / f"data.zarr.old-{os.getpid()}"
        os.replace(final, old)
        os.replace(tmp, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, final)
    write_json(out_dir / "provenance.json", provenance_dict)
    out = before_summary() if before_summary is not None else None
    write_json(out_dir / "summary.json", summary)
    return out


LOCK_NAME = ".oaraim.lock"


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    except OSError:
        return False
    return True


def check_output_folder(d, option="--out"):
    """Make sure ``d`` is a folder this process can write: created if needed, a folder, and a
    file can be made in it. ``OutputError`` with one line naming ``option`` and ``d``
    otherwise, so a command checks its output folder before it computes anything."""
    d = Path(d)
    if d.exists() and not d.is_dir():
        raise OutputError(f"{option}: {d} exists and is not a folder; choose another {option}")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{option}: cannot create {d} ({e.strerror or e}); choose a "
                          f"writable {option}") from None
    try:
        fd, probe = tempfile.mkstemp(dir=d, prefix=".oaraim-write-test-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise OutputError(f"{option}: {d} is not writable ({e.strerror or e}); choose a "
                          f"writable {option}") from None


class OutputLock:
    """Exclusive use of a study's output folder for one run (a context manager).

    On entry the folder is created if needed and checked to be a writable directory (one-line
    ``OutputError`` otherwise, before any computation); a lock file holding the pid is created
    exclusively. A second run into a folder whose lock names a live process is refused; a lock
    left by a dead process is taken over (``taken_over`` names its pid). Released on exit."""

    def __init__(self, out_dir):
        self.out_dir = Path(out_dir)
        self.path = self.out_dir / LOCK_NAME
        self.taken_over = None

    def __enter__(self):
        d = self.out_dir
        check_output_folder(d)
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                try:
                    pid = int(self.path.read_text().split()[0])
                except (OSError, ValueError, IndexError):
                    pid = None
                if pid is not None and pid != os.getpid() and _pid_alive(pid):
                    raise OutputError(f"--out: {d} is in use by another run (pid {pid}); wait "
                                      "for it to finish or choose another --out") from None
                self.taken_over = pid
                self.path.unlink(missing_ok=True)
                continue
            except OSError as e:
                raise OutputError(f"--out: {d} is not writable ({e.strerror or e}); choose a "
                                  "writable --out") from None
            with os.fdopen(fd, "w") as f:
                f.write(f"{os.getpid()}\n")
            return self
        raise OutputError(f"--out: could not lock {d}; remove {self.path} if no run uses it")

    def __exit__(self, *exc):
        try:
            if self.path.read_text().split()[0] == str(os.getpid()):
                self.path.unlink()
        except (OSError, IndexError):
            pass
        return False


class OutputError(ValueError):
    """An unusable output folder (one line for the CLI)."""
