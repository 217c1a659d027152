"""Result storage: ``OUT/STUDY/`` holds data.zarr, summary.json, provenance.json and figures."""

import contextlib
import datetime as _dt
import errno
import importlib.metadata
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import threading
import uuid
import warnings
from pathlib import Path

import numpy as np

#: the lock file of a study's output folder (``OutputLock``)
LOCK_NAME = ".oaraim.lock"
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
    reader never sees half a file, and a failed write (a full disk) leaves no temporary file
    and the old file whole."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    text = json.dumps(jsonable(obj), indent=2, allow_nan=False) + "\n"
    try:
        with writing(path):
            tmp.write_text(text)
            os.replace(tmp, path)  # atomic: a reader never sees half a file
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def writing(path):
    """Name ``path`` in an ``OSError`` raised inside that does not name a file (a full disk
    while writing through an open file says only ``[Errno 28] No space left on device``)."""
    try:
        yield
    except OSError as e:
        if e.filename is None:
            e.filename = str(path)
        raise


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
    final = out_dir / "data.zarr"
    tmp = out_dir / f"data.zarr.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        with warnings.catch_warnings(), writing(final):
            # zarr 3 warns that fixed-length string arrays (e.g. tower or satellite names)
            # have no Zarr V3 specification yet; zarr and xarray read them back exactly
            # (tested), and the warning says nothing a user can act on
            warnings.filterwarnings("ignore", message=".*does not have a Zarr V3 specification")
            dataset.to_zarr(tmp, mode="w", consolidated=False)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)  # no half-written data left behind
        raise
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


#: what a run killed mid-write leaves in its output folder (``write_results``, ``write_json``,
#: ``mc.sweep_store.write_atomic``'s ``.NAME.PID.tmp`` of sweep.json): removed by the next run
#: that holds the folder's lock
LEFTOVER_PATTERNS = ("data.zarr.tmp-*", "data.zarr.old-*", "*.json.tmp", ".*.tmp")


def remove_leftovers(out_dir):
    """Remove the temporary files and folders of earlier runs from ``out_dir`` (a run killed
    while assembling ``data.zarr`` leaves ``data.zarr.tmp-PID``): the data of a run that holds
    the folder's lock, so no other run is writing them. Also lock files of a dead process left
    half-made. Returns the removed paths."""
    import shutil

    out_dir = Path(out_dir)
    gone = []
    for pattern in LEFTOVER_PATTERNS:
        for p in out_dir.glob(pattern):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
            gone.append(p)
    for p in out_dir.glob(f"{LOCK_NAME}.tmp-*"):  # a lock being made: only a dead run's
        pid = p.name[len(LOCK_NAME) + 5:].split("-")[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _pid_alive(int(pid)):
            p.unlink(missing_ok=True)
            gone.append(p)
    return gone



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
    ``OutputError`` otherwise, before any computation), and the lock file ``LOCK_NAME`` is
    made: the pid (with the host and a random token) is written to a temporary file that is
    then hard-linked to the lock's name, so the lock never exists without its pid and a link
    onto an existing lock fails. A lock naming a live process (or another host, whose
    processes cannot be checked) refuses the run; a lock left by a dead process is taken over
    (``taken_over`` names its pid; 0 for a lock file naming none) by replacing it while
    holding ``flock`` on the folder, so two runs that find the same stale lock cannot both
    take it. Released on exit (the lock file only if it is still this run's; a folder this
    run made is removed again if the run failed and left it empty). On entry the leftovers of
    earlier runs are removed (``remove_leftovers``)."""

    def __init__(self, out_dir):
        self.out_dir = Path(out_dir)
        self.path = self.out_dir / LOCK_NAME
        self.taken_over = None
        self._text = None
        self._created = False

    def __enter__(self):
        d = self.out_dir
        self._created = not d.exists()
        check_output_folder(d)
        key = os.path.realpath(d)
        text = f"{os.getpid()} {_HOST} {uuid.uuid4().hex}\n"
        with _HELD_GUARD:  # threads of this process: one attempt at a time, and no re-entry
            if key in _HELD:
                raise OutputError(f"--out: {d} is in use by another run in this process; wait "
                                  "for it to finish or choose another --out")
            try:
                self._acquire(text)
            except OSError as e:
                raise OutputError(f"--out: cannot lock {d} ({e.strerror or e}); choose a "
                                  "writable --out") from None
            _HELD.add(key)
        self._text = text
        remove_leftovers(d)
        return self

    def _acquire(self, text):
        tmp = self.out_dir / f"{LOCK_NAME}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        try:
            with os.fdopen(fd, "w") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            try:
                os.link(tmp, self.path)  # fails if a lock exists: never two, never empty
                return
            except FileExistsError:
                pass
            except OSError as e:
                if e.errno in _UNSUPPORTED:
                    raise OutputError(f"--out: cannot lock {self.out_dir}: its file system makes "
                                      f"no hard links ({e.strerror}), which the lock needs; "
                                      "choose an --out on a local file system") from None
                raise
            with _folder_mutex(self.out_dir, self.path):
                # a stale lock is replaced only here, under the folder's flock; a lock is
                # otherwise only made by a link (never over another) and removed by its holder
                while True:
                    try:
                        old = self.path.read_text()
                        break
                    except FileNotFoundError:  # released meanwhile: link afresh
                        try:
                            os.link(tmp, self.path)
                            return
                        except FileExistsError:
                            continue
                self._refuse_if_live(old)
                os.replace(tmp, self.path)
        finally:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass

    def _refuse_if_live(self, old):
        """OutputError unless ``old`` (a lock file's text) names a process that has ended;
        sets ``taken_over`` to its pid otherwise (0 for a lock file naming no pid)."""
        d = self.out_dir
        fields = old.split()
        try:
            pid = int(fields[0])
        except (ValueError, IndexError):
            pid = 0  # not a lock this code writes (written by hand, or cut): stale
        host = fields[1] if len(fields) > 1 else _HOST
        if pid and host != _HOST:
            raise OutputError(f"--out: {d} is in use by a run on host {host} (pid {pid}); wait "
                              f"for it to finish, or remove {self.path} if no run uses it")
        if pid and pid != os.getpid() and _pid_alive(pid):
            raise OutputError(f"--out: {d} is in use by another run (pid {pid}); wait for it "
                              "to finish or choose another --out")
        self.taken_over = pid

    def __exit__(self, *exc):
        try:
            if self._text is not None and self.path.read_text() == self._text:
                self.path.unlink()
        except OSError:
            pass
        finally:
            with _HELD_GUARD:
                _HELD.discard(os.path.realpath(self.out_dir))
            self._text = None
        if exc and exc[0] is not None and self._created:
            try:  # a failed run that made the folder and wrote nothing leaves no empty folder
                self.out_dir.rmdir()
            except OSError:
                pass
        return False


#: errno values of a file system that lacks an operation (hard links, flock)
_UNSUPPORTED = tuple(getattr(errno, n) for n in ("EPERM", "ENOTSUP", "EOPNOTSUPP", "ENOSYS")
                     if hasattr(errno, n))
#: this host's name in a lock file (a pid is checked only on its own host)
_HOST = socket.gethostname().split()[0] if socket.gethostname().split() else "localhost"
#: the output folders this process holds (realpath), and the guard of that set
_HELD = set()
_HELD_GUARD = threading.Lock()


@contextlib.contextmanager
def _folder_mutex(d, lock_path):
    """``flock`` on the folder ``d`` itself (released with the descriptor, also when the
    process dies, so it is never stale); a file system without ``flock`` is one line."""
    import fcntl

    fd = os.open(d, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError as e:
            if e.errno not in (*_UNSUPPORTED, errno.ENOLCK):
                raise
            raise OutputError(f"--out: {d} holds a lock ({lock_path}) that may be stale, and "
                              f"its file system has no flock ({e.strerror}) to take it over "
                              f"safely; remove {lock_path} if no run uses it") from None
        yield
    finally:
        os.close(fd)  # releases the flock


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


def os_error_line(e: OSError, out_dir, resumable=False) -> str:
    """One line for an ``OSError`` of a run writing ``out_dir``: the path (the error's, else
    ``out_dir``), what went wrong and what to do (free space, permissions, another --out; a
    resumable study keeps its finished work: rerun with --resume)."""
    path = e.filename if e.filename is not None else out_dir
    what = e.strerror or str(e) or type(e).__name__
    again = (" and rerun with --resume (the finished chunks or units are kept)" if resumable
             else " and rerun")
    if e.errno in (errno.ENOSPC, errno.EDQUOT):
        fix = f"free space on that disk (or choose another --out){again}"
    elif e.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        fix = ("make it writable (or readable, for an input file) or choose another --out"
               + again)
    else:
        fix = f"check that path and its disk{again}"
    return f"{path}: {what}; {fix}"


class OutputError(ValueError):
    """An unusable output folder (one line for the CLI)."""
