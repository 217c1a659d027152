"""Checkpoints of a study that is not a sweep: each finished unit of work in its own file.

A study whose run is a sequence of stages (an optimiser's starts, a root per grid point)
wraps each stage in ``Checkpoint.unit(name, compute)``: the first run computes the unit and
writes its value to ``OUT/STUDY/checkpoints/NAME.npz`` atomically (temporary file, fsync,
``os.replace``: ``mc.sweep_store.write_atomic``); a resumed run (``--resume``) reads it back
instead of computing it. ``identity.json`` beside the units holds what determines them
(study, parameters, seed, realizations, the package version and git commit); a resume whose
identity differs is refused with one line naming each difference. Values are trees of dicts,
lists, tuples, None, bools, ints, floats, strings and NumPy arrays, stored exactly (arrays in
the ``.npz``, the tree as JSON beside them: a float's repr round-trips its bits), so a resumed
run is bit-identical to an uninterrupted one. ``NoCheckpoint`` computes every unit, for
``Study.run`` outside the command line.
"""

import io
import json
import re
from pathlib import Path

import numpy as np

from oaraim.mc.store import git_commit, package_versions
from oaraim.mc.sweep_store import (
    differences,
    normalized,
    read_json_or_none,
    remove_partial_writes,
    write_atomic,
)

FORMAT_VERSION = 1
IDENTITY = "identity.json"
FOLDER = "checkpoints"
#: a unit's name: letters, digits, '-', '_', '.', '=' (it is a file name)
UNIT_RE = re.compile(r"^[A-Za-z0-9_.=-]{1,120}$")


def identity(study, params, seed, realizations):
    """What determines a checkpointed run's units (a resume must match all of it): the study,
    its parameters, the seed, the realizations, and the code (oaraim's version and commit)."""
    return normalized({"format": FORMAT_VERSION, "study": study, "params": params,
                       "seed": int(seed), "realizations": int(realizations),
                       "code": {"oaraim": package_versions().get("oaraim"),
                                "commit": git_commit()}})


def encode(value, arrays):
    """``value`` as a JSON tree, its arrays appended to ``arrays`` (referenced by index)."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if value is None or type(value) in (int, float, str):
        return value
    if isinstance(value, np.generic) and value.dtype.kind in "iufU":  # np.float64, np.int64...
        return {"scalar": value.item()}
    if isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
        arrays.append(value)
        return {"array": len(arrays) - 1}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise TypeError("a checkpointed dict needs string keys")
        return {"dict": {k: encode(v, arrays) for k, v in value.items()}}
    if isinstance(value, list | tuple):
        items = [encode(v, arrays) for v in value]
        return {"tuple": items} if isinstance(value, tuple) else {"list": items}
    raise TypeError(f"a checkpoint cannot store a {type(value).__name__}; give arrays, numbers, "
                    "strings, None, lists, tuples or dicts")


def decode(tree, arrays):
    """The inverse of ``encode``."""
    if not isinstance(tree, dict):
        return tree
    if "array" in tree:
        return arrays[f"a{tree['array']}"]
    if "scalar" in tree:
        return tree["scalar"]
    if "dict" in tree:
        return {k: decode(v, arrays) for k, v in tree["dict"].items()}
    if "tuple" in tree:
        return tuple(decode(v, arrays) for v in tree["tuple"])
    return [decode(v, arrays) for v in tree["list"]]


def unit_bytes(value) -> bytes:
    """A unit's value as the bytes of an ``.npz`` (its tree under ``__tree__``)."""
    arrays = []
    tree = encode(value, arrays)
    buf = io.BytesIO()
    np.savez(buf, __tree__=np.array(json.dumps(tree, allow_nan=True)),
             **{f"a{i}": a for i, a in enumerate(arrays)})
    return buf.getvalue()


def read_unit(path: Path):
    """(True, value) of a unit file, (False, None) if it is missing or not a whole file."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k != "__tree__"}
            return True, decode(json.loads(str(z["__tree__"])), arrays)
    except Exception:  # noqa: BLE001 - missing or unreadable: compute it again
        return False, None


class NoCheckpoint:
    """Computes every unit and stores nothing (``Study.run`` outside ``oaraim run``)."""

    resumed = False
    computed = 0
    reused = 0

    def unit(self, name, compute):
        """``compute()``."""
        return compute()


class Checkpoint:
    """Units of one run in ``out_dir/checkpoints/`` (module docstring).

    ``ident`` is the run's ``identity(...)``. Without ``resume`` the units of an earlier run
    there are deleted first (a fresh run). With ``resume`` a folder whose ``identity.json``
    differs is refused (``ValueError``, one line naming each difference and the fix); the
    units it holds are reused. ``computed`` and ``reused`` count the units of this run.
    """

    def __init__(self, out_dir, ident, resume=False):
        self.folder = Path(out_dir) / FOLDER
        self.resumed = bool(resume)
        self.computed = 0
        self.reused = 0
        self.folder.mkdir(parents=True, exist_ok=True)
        remove_partial_writes(self.folder)
        path = self.folder / IDENTITY
        old = read_json_or_none(path)
        units = [f for f in self.folder.iterdir() if f.suffix == ".npz"]
        if resume and units:
            if old is None:
                raise ValueError(f"cannot resume into {self.folder}: it holds checkpoints but no "
                                 f"readable {IDENTITY} to check them against; drop --resume to "
                                 "start afresh or pick another --out")
            diffs = differences(old, ident)
            if diffs:
                raise ValueError(f"cannot resume into {self.folder}: it holds a run with "
                                 f"different {'; '.join(diffs)}. --resume continues the same "
                                 "run only: drop --resume to start afresh (its checkpoints are "
                                 "deleted) or pick another --out")
        if not resume:
            for f in units:
                f.unlink()
        if old != ident:
            write_atomic(path, (json.dumps(ident, indent=2, sort_keys=True) + "\n").encode())

    def unit(self, name, compute):
        """The value of unit ``name``: read from its file when a resumed run finds it, else
        ``compute()``, written atomically before it is returned."""
        if not UNIT_RE.match(name):
            raise ValueError(f"checkpoint unit name {name!r} must match {UNIT_RE.pattern}")
        path = self.folder / f"{name}.npz"
        if self.resumed:
            ok, value = read_unit(path)
            if ok:
                self.reused += 1
                return value
        value = compute()
        write_atomic(path, unit_bytes(value))
        self.computed += 1
        return value

    def remove_if_nothing_finished(self):
        """After a failed run: remove the folder (``identity.json``) if it holds no finished
        unit, so a run that failed on its first unit leaves nothing half-made."""
        try:
            remove_partial_writes(self.folder)
            if any(f.suffix == ".npz" for f in self.folder.iterdir()):
                return
            (self.folder / IDENTITY).unlink(missing_ok=True)
            self.folder.rmdir()
        except OSError:
            pass  # the original error is the one to report

    def provenance(self):
        """What provenance.json records of the checkpoints: resumed, units computed, reused."""
        return {"resumed": self.resumed, "units_computed": self.computed,
                "units_reused": self.reused, "folder": str(self.folder)}


def counted_unit(checkpoint, counter, name, compute):
    """``checkpoint.unit(name, compute)`` for work that counts its own cost in
    ``counter.evaluations`` (a metric of the run): the unit stores the evaluations it cost
    beside its value, and a unit read back instead of computed adds them to the counter, so
    the count is the same whether the run was resumed or not. Returns the value."""
    before = counter.evaluations

    def run():
        value = compute()
        return {"value": value, "evaluations": counter.evaluations - before}

    out = checkpoint.unit(name, run)
    counter.evaluations = before + int(out["evaluations"])
    return out["value"]
