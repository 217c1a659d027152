"""Result storage: ``OUT/STUDY/`` holds data.zarr, summary.json, provenance.json and figures."""

import datetime as _dt
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

PACKAGES = ("oaraim", "jax", "jaxlib", "numpy", "scipy", "xarray", "zarr", "matplotlib")


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, float) and not np.isfinite(x):
        return None if np.isnan(x) else ("inf" if x > 0 else "-inf")
    return x


def write_json(path, obj):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(_jsonable(obj), indent=2, allow_nan=False) + "\n")
    os.replace(tmp, path)  # atomic: a reader never sees half a file


def read_summary(path):
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


def write_results(out_dir, dataset, summary, provenance_dict):
    """Write one study's results; data first, summary last (its presence marks completion)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        # zarr 3 warns that fixed-length string arrays (e.g. tower or satellite names) have no
        # Zarr V3 specification yet; zarr and xarray read them back exactly (tested), and the
        # warning says nothing a user can act on
        warnings.filterwarnings("ignore", message=".*does not have a Zarr V3 specification")
        dataset.to_zarr(out_dir / "data.zarr", mode="w", consolidated=False)
    write_json(out_dir / "provenance.json", provenance_dict)
    write_json(out_dir / "summary.json", summary)
