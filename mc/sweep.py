"""Parameter sweeps: a grid of cells x realizations, resumable, in-process or on Dask.

A sweep is the Cartesian product of named axes (e.g. number of SOPs x sigma_URA^S x P_s^S) with
``realizations`` Monte Carlo draws per cell. A study supplies a picklable ``kernel_factory``
(``coords -> kernel``, ``kernel(keys) -> {name: (batch,) array}``) and reducers that turn the
per-realization outputs of each cell into statistics (``Mean``, ``Max``, ``Min``, ``Histogram``,
``Count``).

Randomness (DESIGN.md). Realization i of a cell uses ``fold_in(fold_in(key(seed), c), i)`` as in
``mc.keys``, where the cell-key id ``c`` is the crc32 of ``"name=repr(value)"`` of the *key axes*
joined by ``;`` in name order. It depends on the axis values, not on grid indices, so a cell
gives the same draws whether the grid is full or narrowed from the CLI, and the cells that
differ only in non-key axes share their draws (common random numbers).

Bit-identity. The kernel is always called with ``batch_size`` keys (default BLOCK = 1024) on
batches aligned in realization index, so each realization's outputs come from the same compiled
program at the same batch position whatever the chunking (XLA's fusion choices depend on the
batch shape: another batch size may change the last bit, see ``kernel_outputs``). The unit of
storage is a block of ``mc.reduce.BLOCK`` realizations; a chunk (one task, one file) is a run
of whole blocks. Floating means are stored as one sum per block (NumPy's sum of a
zero-padded block of BLOCK values, whatever the chunk) and combined with ``math.fsum``, which is
correctly rounded and therefore independent of the order in which chunks finish. Counts, maxima,
minima and histograms are exact. So a cell's statistics are bit-identical for any chunk size,
cell order, worker count, and across kill-and-resume.

Storage (``out_dir``): ``sweep.json`` (the fingerprint of the run, written before any chunk) and
``chunks/CELLHASH_B0_NBLOCKS.npz``, one file per finished (cell, chunk) with its partial sums,
written atomically (temporary file, fsync, ``os.replace``). A killed run leaves only whole files;
``resume=True`` keeps them (even with a different chunk size: files cover block ranges) and
computes only the missing blocks; a different fingerprint (or batch size) is refused.

Non-finite values. NaN in an included realization is an error naming the kernel output (a bug
upstream, DESIGN.md). ``+-inf`` is data (an unavailable geometry): ``Mean`` averages the finite
values only and its ``_count`` says how many; ``Max``/``Min`` see infinities; ``Histogram``
counts them in ``_outside``.
"""

from __future__ import annotations

import collections
import hashlib
import io
import json
import logging
import math
import os
import pickle
import re
import socket
import time
import warnings
import zlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import jax
import numpy as np

from oaraim.mc.keys import MAX_REALIZATIONS, cell_key, realization_keys
from oaraim.mc.reduce import BLOCK
from oaraim.mc.runner import DEFAULT_CHUNK

FORMAT_VERSION = 1
MANIFEST = "sweep.json"
CHUNK_DIR = "chunks"
_CHUNK_RE = re.compile(r"^([0-9a-f]{16})_(\d{10})_(\d{6})\.npz$")
_KERNEL_CACHE_SIZE = 64


# ----------------------------------------------------------------------------------------------
# axes and cell identities


def _plain(name, v):
    """An axis value as a plain Python scalar (bool, int, float or str)."""
    if isinstance(v, np.generic):
        v = v.item()
    if not isinstance(v, bool | int | float | str):
        raise ValueError(f"axis {name!r}: values must be ints, floats or strings, got {v!r} "
                         f"({type(v).__name__})")
    if isinstance(v, float) and math.isnan(v):
        raise ValueError(f"axis {name!r}: NaN is not a valid axis value")
    return v


@dataclass(frozen=True)
class Axis:
    """One sweep axis: a name and its values (plain ints, floats or strings; at least one; no
    duplicates). NumPy scalars are converted to plain Python values."""

    name: str
    values: tuple

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ValueError(f"axis names must be identifiers, got {self.name!r}")
        raw = self.values
        if isinstance(raw, np.ndarray):
            raw = raw.tolist()
        if not isinstance(raw, list | tuple):
            raw = (raw,)
        vals = tuple(_plain(self.name, v) for v in raw)
        if not vals:
            raise ValueError(f"axis {self.name!r} needs at least one value")
        seen = []
        for v in vals:
            if v in seen:
                raise ValueError(f"axis {self.name!r} lists the value {v!r} twice")
            seen.append(v)
        object.__setattr__(self, "values", vals)


def canonical(coords: dict, names: Iterable[str]) -> str:
    """``"a=1;b=0.5"``: the canonical text of ``coords`` restricted to ``names`` (in that order)."""
    return ";".join(f"{n}={coords[n]!r}" for n in names)


def cell_key_id(coords: dict, key_axes: Iterable[str]) -> int:
    """The cell-key id of a cell (``mc.keys.cell_key``'s ``cell``): crc32 of the canonical text of
    its key-axis values, names sorted. Cells that agree on every key axis share their draws."""
    return zlib.crc32(canonical(coords, sorted(key_axes)).encode("utf-8"))


def _cell_hash(cell_text: str) -> str:
    return hashlib.sha1(cell_text.encode("utf-8")).hexdigest()[:16]


# ----------------------------------------------------------------------------------------------
# reducers


def _where_mask(out, where, n, ctx):
    if where is None:
        return np.ones(n, bool)
    m = _output(out, where, n, ctx)
    if m.dtype != bool:
        raise TypeError(f"kernel output {where!r} is used as a `where` mask and must be boolean, "
                        f"got dtype {m.dtype} ({ctx})")
    return m


def _output(out, name, n, ctx):
    """The first n values of kernel output ``name`` (1-D, at least n long), as NumPy."""
    if name not in out:
        raise KeyError(f"the kernel returned no output {name!r} ({ctx}); it returned: "
                       + ", ".join(sorted(out)))
    v = np.asarray(out[name])
    if v.ndim != 1 or v.shape[0] < n:
        raise ValueError(f"kernel output {name!r} must have shape (chunk,), got {v.shape} ({ctx})")
    return v[:n]


def _check_no_nan(name, v, include, ctx):
    if v.dtype.kind == "f" and np.isnan(v[include]).any():
        raise FloatingPointError(
            f"kernel output {name!r} is NaN for an included realization ({ctx}); NaN is a bug "
            "upstream: return inf with a status code for an unavailable result (DESIGN.md)")


@dataclass(frozen=True)
class Mean:
    """Mean of output ``name`` over the included realizations with a finite value.

    Dataset variables ``{name}_mean`` (float64; NaN only when the count is 0) and ``{name}_count``
    (int64, the realizations that entered the mean). ``where`` names a boolean output: only
    realizations where it is True are included. NaN in an included realization raises.
    """

    name: str
    where: str | None = None

    def inputs(self):
        return (self.name,) + ((self.where,) if self.where else ())

    def variables(self):
        return {f"{self.name}_mean": (), f"{self.name}_count": ()}

    def partial(self, out, valid, nblocks, ctx):
        n = valid.size
        v = _output(out, self.name, n, ctx).astype(np.float64)
        inc = valid & _where_mask(out, self.where, n, ctx)
        _check_no_nan(self.name, v, inc, ctx)
        keep = inc & np.isfinite(v)
        x = np.where(keep, v, 0.0).reshape(nblocks, BLOCK)
        # one NumPy sum per zero-padded block: the same numbers in the same layout whatever the
        # chunk, so the same bits
        return {"sum": np.array([np.sum(row) for row in x]),
                "count": keep.reshape(nblocks, BLOCK).sum(axis=1).astype(np.int64)}

    def empty(self, n_blocks):
        return {"sum": np.zeros(n_blocks), "count": np.zeros(n_blocks, np.int64)}

    def accumulate(self, state, part, b0):
        nb = part["sum"].size
        state["sum"][b0:b0 + nb] = part["sum"]
        state["count"][b0:b0 + nb] = part["count"]

    def finish(self, state):
        n = int(state["count"].sum())
        mean = math.fsum(state["sum"].tolist()) / n if n else float("nan")
        return {f"{self.name}_mean": np.float64(mean), f"{self.name}_count": np.int64(n)}


@dataclass(frozen=True)
class Max:
    """Largest value of output ``name`` over the included realizations (``{name}_max``, float64;
    -inf when nothing is included; +inf values count). NaN in an included realization raises."""

    name: str
    where: str | None = None
    _sign = 1.0

    def inputs(self):
        return (self.name,) + ((self.where,) if self.where else ())

    def _var(self):
        return f"{self.name}_{'max' if self._sign > 0 else 'min'}"

    def variables(self):
        return {self._var(): ()}

    def partial(self, out, valid, nblocks, ctx):
        n = valid.size
        v = _output(out, self.name, n, ctx).astype(np.float64)
        inc = valid & _where_mask(out, self.where, n, ctx)
        _check_no_nan(self.name, v, inc, ctx)
        s = self._sign
        ext = s * np.max(s * v[inc]) if inc.any() else -s * np.inf
        return {"value": np.array([ext], np.float64)}

    def empty(self, n_blocks):
        return {"value": np.array([-self._sign * np.inf])}

    def accumulate(self, state, part, b0):
        pick = np.maximum if self._sign > 0 else np.minimum
        state["value"] = pick(state["value"], part["value"])

    def finish(self, state):
        return {self._var(): np.float64(state["value"][0])}


@dataclass(frozen=True)
class Min(Max):
    """Smallest value of output ``name`` over the included realizations (``{name}_min``, float64;
    +inf when nothing is included). NaN in an included realization raises."""

    _sign = -1.0


@dataclass(frozen=True)
class Histogram:
    """Counts of output ``name`` in the bins ``edges`` (NumPy's convention: the last bin is
    closed). ``{name}_hist`` (int64, extra dimension ``{name}_bin`` with coordinates
    ``{name}_bin_lo``/``{name}_bin_hi``) and ``{name}_outside`` (included realizations outside
    the edges or infinite). NaN in an included realization raises."""

    name: str
    edges: tuple
    where: str | None = None

    def __post_init__(self):
        e = tuple(float(x) for x in np.asarray(self.edges, float).ravel())
        if len(e) < 2 or not all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
            raise ValueError(f"Histogram({self.name!r}): edges must be at least two finite, "
                             f"strictly increasing numbers, got {self.edges!r}")
        object.__setattr__(self, "edges", e)

    def inputs(self):
        return (self.name,) + ((self.where,) if self.where else ())

    def variables(self):
        return {f"{self.name}_hist": (f"{self.name}_bin",), f"{self.name}_outside": ()}

    def coords(self):
        e = np.asarray(self.edges)
        return {f"{self.name}_bin_lo": (f"{self.name}_bin", e[:-1]),
                f"{self.name}_bin_hi": (f"{self.name}_bin", e[1:])}

    def partial(self, out, valid, nblocks, ctx):
        n = valid.size
        v = _output(out, self.name, n, ctx).astype(np.float64)
        inc = valid & _where_mask(out, self.where, n, ctx)
        _check_no_nan(self.name, v, inc, ctx)
        x = v[inc]
        counts, _ = np.histogram(x[np.isfinite(x)], np.asarray(self.edges))
        return {"counts": counts.astype(np.int64),
                "outside": np.array([x.size - int(counts.sum())], np.int64)}

    def empty(self, n_blocks):
        return {"counts": np.zeros(len(self.edges) - 1, np.int64),
                "outside": np.zeros(1, np.int64)}

    def accumulate(self, state, part, b0):
        state["counts"] += part["counts"]
        state["outside"] += part["outside"]

    def finish(self, state):
        return {f"{self.name}_hist": state["counts"].copy(),
                f"{self.name}_outside": np.int64(state["outside"][0])}


@dataclass(frozen=True)
class Count:
    """Number of realizations where the boolean output ``name`` is True (``{name}_count``,
    int64); with ``where``, only among the realizations where that output is True."""

    name: str
    where: str | None = None

    def inputs(self):
        return (self.name,) + ((self.where,) if self.where else ())

    def variables(self):
        return {f"{self.name}_count": ()}

    def partial(self, out, valid, nblocks, ctx):
        n = valid.size
        v = _output(out, self.name, n, ctx)
        if v.dtype != bool:
            raise TypeError(f"Count({self.name!r}) needs a boolean kernel output, got dtype "
                            f"{v.dtype} ({ctx})")
        inc = valid & _where_mask(out, self.where, n, ctx)
        return {"count": np.array([np.count_nonzero(v & inc)], np.int64)}

    def empty(self, n_blocks):
        return {"count": np.zeros(1, np.int64)}

    def accumulate(self, state, part, b0):
        state["count"] += part["count"]

    def finish(self, state):
        return {f"{self.name}_count": np.int64(state["count"][0])}


@dataclass(frozen=True)
class Values:
    """Every realization's value of output ``name``, kept (not reduced): ``{name}`` with the
    extra dimension ``dim`` of length ``n`` (the sweep's realizations). For deterministic grids
    whose realizations are not samples but elements (e.g. longitude x epoch of an availability
    map, ``index_kernel``). Stored with ``dtype``; realizations past ``n`` are not kept. NaN in
    a float output raises (a bug upstream, DESIGN.md); infinities are data."""

    name: str
    n: int
    dtype: str = "float64"
    dim: str = "realization"

    def inputs(self):
        return (self.name,)

    def variables(self):
        return {self.name: (self.dim,)}

    def partial(self, out, valid, nblocks, ctx):
        v = _output(out, self.name, valid.size, ctx)
        if np.issubdtype(v.dtype, np.floating):
            _check_no_nan(self.name, v, valid, ctx)
        return {"values": np.where(valid, v, np.zeros((), v.dtype)).astype(self.dtype)}

    def empty(self, n_blocks):
        return {"values": np.zeros(n_blocks * BLOCK, self.dtype)}

    def accumulate(self, state, part, b0):
        v = part["values"]
        state["values"][b0 * BLOCK:b0 * BLOCK + v.size] = v

    def finish(self, state):
        return {self.name: state["values"][:self.n].copy()}


REDUCERS = (Mean, Max, Min, Histogram, Count, Values)


# ----------------------------------------------------------------------------------------------
# one chunk of one cell (runs in this process or on a Dask worker)

_WORKER_KERNELS: collections.OrderedDict = collections.OrderedDict()


def _worker_kernel(kernel_factory, factory_id, coords):
    """The kernel of ``coords``, built once per process (LRU of the last 64 cells)."""
    key = (factory_id, canonical(coords, sorted(coords)))
    k = _WORKER_KERNELS.get(key)
    if k is None:
        k = kernel_factory(dict(coords))
        _WORKER_KERNELS[key] = k
        while len(_WORKER_KERNELS) > _KERNEL_CACHE_SIZE:
            _WORKER_KERNELS.popitem(last=False)
    else:
        _WORKER_KERNELS.move_to_end(key)
    return k


def kernel_outputs(kernel, key_id, seed, start, n, batch_size):
    """Outputs of realizations ``start .. start + n - 1`` of one cell, NumPy, each ``(n,)``.

    A kernel with the attribute ``index_kernel = True`` is called as ``kernel(indices, key)``
    with the realization indices ``(batch_size,)`` (int64) and the cell's key
    (``mc.keys.cell_key``) instead of one key per realization: for grids whose realizations are
    elements (longitude x epoch) and whose randomness, if any, is not per realization.

    The kernel is called with exactly ``batch_size`` keys per call, on batches aligned to
    multiples of ``batch_size`` in realization index (the first and last may reach outside the
    range and are trimmed). So realization i is always computed by the same compiled program at
    the same position of its batch, whatever the chunk: XLA's fusion choices depend on the batch
    shape, and a different batch size can change results in the last bit (measured: 121-292 of
    1024 values of a sqrt + sin * exp kernel differ between batches of 1024, 2048 and 4096).
    """
    first = (start // batch_size) * batch_size
    parts = []
    base = cell_key(seed, key_id) if getattr(kernel, "index_kernel", False) else None
    for s in range(first, start + n, batch_size):
        if base is None:
            out = kernel(realization_keys(seed, key_id, s, batch_size))
        else:  # a deterministic grid: realization indices and the cell's key
            out = kernel(np.arange(s, s + batch_size, dtype=np.int64), base)
        out = jax.device_get(out)
        for name, v in out.items():
            v = np.asarray(v)
            if v.ndim < 1 or v.shape[0] != batch_size:
                raise ValueError(f"kernel output {name!r} must have shape ({batch_size},) for "
                                 f"{batch_size} keys, got {v.shape}")
        parts.append(out)
    lo = start - first
    return {name: np.concatenate([np.asarray(p[name]) for p in parts])[lo:lo + n]
            for name in parts[0]}


def compute_chunk(kernel, coords, key_id, seed, b0, nblocks, realizations, batch_size,
                  reducers):
    """Partial statistics of blocks ``b0 .. b0 + nblocks - 1`` of one cell.

    The kernel sees ``batch_size`` keys per call (``kernel_outputs``); outputs past the cell's
    last realization are excluded. Returns ``{"r{i}.{field}": array}`` over the reducers.
    """
    start = b0 * BLOCK
    n = nblocks * BLOCK
    out = kernel_outputs(kernel, key_id, seed, start, n, batch_size)
    valid = np.arange(start, start + n) < realizations
    ctx = f"cell {canonical(coords, coords)}, realizations {start}..{start + n - 1}"
    parts = {}
    for i, r in enumerate(reducers):
        for field, arr in r.partial(out, valid, nblocks, ctx).items():
            parts[f"r{i}.{field}"] = np.asarray(arr)
    return parts


def _remote_chunk(kernel_factory, factory_id, coords, *args):
    """Dask task: ``compute_chunk`` with the worker's cached kernel."""
    return compute_chunk(_worker_kernel(kernel_factory, factory_id, coords), coords, *args)


# ----------------------------------------------------------------------------------------------
# storage


def _write_atomic(path: Path, data: bytes):
    """Write ``data`` to ``path`` so that a reader (or a resume after SIGKILL) sees either the
    whole new file or none: temporary file in the same folder, fsync, rename."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _chunk_name(cell_hash, b0, nblocks):
    return f"{cell_hash}_{b0:010d}_{nblocks:06d}.npz"


def _chunk_bytes(meta: dict, parts: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, __meta__=np.array(json.dumps(meta, sort_keys=True)), **parts)
    return buf.getvalue()


def _read_chunk(path: Path, meta: dict, reducers):
    """The partials stored in ``path``, or None if it is not a whole file of this sweep."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if json.loads(str(z["__meta__"])) != meta:
                return None
            parts = {k: z[k] for k in z.files if k != "__meta__"}
    except Exception:  # noqa: BLE001 - unreadable: recompute it
        return None
    nb = meta["nblocks"]
    for i, r in enumerate(reducers):
        for field, template in r.empty(nb).items():  # a partial has the shapes of empty(nb)
            got = parts.get(f"r{i}.{field}")
            if got is None or got.shape != template.shape or got.dtype != template.dtype:
                return None
    return parts


def _normalized(obj):
    from oaraim.mc.store import _jsonable

    return json.loads(json.dumps(_jsonable(obj), sort_keys=True, allow_nan=False,
                                 default=str))


def _differences(old, new, prefix=""):
    """Dotted paths where two JSON trees differ, with both values."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new)):
            p = f"{prefix}{k}"
            if k not in old:
                out.append(f"{p} (new: {json.dumps(new[k])})")
            elif k not in new:
                out.append(f"{p} (was {json.dumps(old[k])}, now absent)")
            else:
                out += _differences(old[k], new[k], p + ".")
        return out
    if old != new:
        return [f"{prefix.rstrip('.') or 'value'} (was {json.dumps(old)}, now {json.dumps(new)})"]
    return []


# ----------------------------------------------------------------------------------------------
# the sweep


@dataclass
class SweepResult:
    """``dataset``: dims = axis names in declared order, coords = axis values, one variable per
    reducer output; attrs ``realizations``, ``seed``, ``key_axes``. ``chunks_computed`` and
    ``chunks_reused`` count (cell, chunk) files; ``wall_s`` is the whole call."""

    dataset: "xarray.Dataset"
    chunks_computed: int
    chunks_reused: int
    wall_s: float
    out_dir: Path
    cells: int
    chunk_size: int
    batch_size: int = BLOCK
    workers: int | None = None
    scheduler: str | None = None
    realizations_computed: int = 0
    threads: int = 1


@dataclass(frozen=True)
class _Cell:
    index: tuple
    coords: dict
    text: str
    hash: str
    key_id: int


def _check_args(axes, realizations, reducers, key_axes, workers, scheduler):
    if not axes:
        raise ValueError("a sweep needs at least one axis")
    for a in axes:
        if not isinstance(a, Axis):
            raise TypeError(f"axes must be mc.sweep.Axis objects, got {a!r}")
    names = [a.name for a in axes]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"axis {dup[0]!r} is declared twice")
    bad = sorted(set(key_axes) - set(names))
    if bad:
        raise ValueError(f"key axis {bad[0]!r} is not an axis of the sweep (axes: "
                         f"{', '.join(names)})")
    if not isinstance(realizations, int | np.integer) or not 1 <= realizations <= MAX_REALIZATIONS:
        raise ValueError(f"realizations must be an integer in [1, 2^32], got {realizations!r}")
    if not reducers:
        raise ValueError("a sweep needs at least one reducer (mc.sweep.Mean, Max, Min, "
                         "Histogram, Count)")
    seen = {}
    for r in reducers:
        if not isinstance(r, REDUCERS):
            raise TypeError(f"reducers must be mc.sweep.Mean/Max/Min/Histogram/Count, got {r!r}")
        for var in r.variables():
            if var in seen or var in names:
                other = seen.get(var, "an axis")
                raise ValueError(f"{r!r} and {other!r} both produce the dataset variable {var!r}")
            seen[var] = r
    if workers is not None and scheduler is not None:
        raise ValueError("give either workers=N (a local Dask cluster) or scheduler=ADDRESS (an "
                         "existing one), not both")
    if workers is not None and (not isinstance(workers, int | np.integer) or workers < 1):
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler.strip()):
        raise ValueError(f"scheduler must be an address such as tcp://HOST:8786, got "
                         f"{scheduler!r}")


def _round_up(n, m):
    return max(m, -(-n // m) * m)


def _cells(axes, key_axes):
    shape = tuple(len(a.values) for a in axes)
    names = [a.name for a in axes]
    cells = []
    for idx in np.ndindex(*shape):
        coords = {a.name: a.values[i] for a, i in zip(axes, idx, strict=True)}
        text = canonical(coords, names)
        cells.append(_Cell(tuple(int(i) for i in idx), coords, text, _cell_hash(text),
                           cell_key_id(coords, key_axes)))
    return shape, cells


def _factory_id(kernel_factory, distributed: bool):
    """A digest naming the kernel factory in the workers' kernel caches (None in-process, where
    the factory need not be picklable)."""
    try:
        return hashlib.sha1(pickle.dumps(kernel_factory)).hexdigest()
    except Exception as e:  # noqa: BLE001
        if not distributed:
            return None
        try:  # Dask ships functions with cloudpickle, which also takes closures
            import cloudpickle

            return hashlib.sha1(cloudpickle.dumps(kernel_factory)).hexdigest()
        except Exception:  # noqa: BLE001
            raise TypeError(
                f"kernel_factory {kernel_factory!r} cannot be pickled ({e}); Dask workers need "
                "a module-level function or a functools.partial of one with plain-data "
                "arguments") from None


def _missing_runs(covered: np.ndarray):
    """(b0, length) of the maximal runs of uncovered blocks."""
    runs, b, n = [], 0, covered.size
    while b < n:
        if covered[b]:
            b += 1
            continue
        e = b
        while e < n and not covered[e]:
            e += 1
        runs.append((b, e - b))
        b = e
    return runs


def _prepare_out_dir(out_dir: Path, manifest: dict, resume: bool):
    """Check or write the manifest; clear chunk files of an earlier run unless resuming."""
    chunk_dir = out_dir / CHUNK_DIR
    chunk_dir.mkdir(parents=True, exist_ok=True)
    mpath = out_dir / MANIFEST
    old = None
    if mpath.exists():
        try:
            old = json.loads(mpath.read_text())
        except (OSError, ValueError):
            old = None
    for f in chunk_dir.iterdir():  # half-written files of a killed run
        if f.name.endswith(".tmp"):
            f.unlink(missing_ok=True)
    if resume:
        has_chunks = any(_CHUNK_RE.match(f.name) for f in chunk_dir.iterdir())
        if old is None and has_chunks:
            raise ValueError(f"{out_dir} holds chunk files but no readable {MANIFEST}, so they "
                             "cannot be checked against this run; pick another --out or drop "
                             "--resume to start afresh")
        if old is not None:
            for part in ("fingerprint", "engine"):
                diffs = _differences(old.get(part), manifest[part])
                if diffs:
                    raise ValueError(
                        f"cannot resume into {out_dir}: it holds a run with different "
                        f"parameters: {'; '.join(diffs)}. --resume continues a run with the "
                        "same parameters only (a narrowed or changed axis is a new run): pick "
                        "another --out, or drop --resume to start afresh")
    else:
        for f in chunk_dir.iterdir():
            if _CHUNK_RE.match(f.name):
                f.unlink()
    if old != manifest:
        _write_atomic(mpath, (json.dumps(manifest, indent=2, sort_keys=True) + "\n").encode())


def run_sweep(kernel_factory: Callable, axes, realizations: int, reducers, *, seed: int,
              key_axes=(), out_dir, fingerprint: dict, chunk_size: int = DEFAULT_CHUNK,
              batch_size: int = BLOCK, resume: bool = False, workers: int | None = None,
              scheduler: str | None = None,
              progress: bool = True, description: str = "",
              scheduler_timeout_s: float = 10.0, threads: int | None = None) -> SweepResult:
    """Run every cell of the grid ``axes`` for ``realizations`` draws and reduce.

    Args:
      kernel_factory: picklable ``coords -> kernel`` (``coords``: dict axis name -> value);
        ``kernel(keys)`` maps a ``(batch_size,)`` key array to a dict of ``(batch_size,)``
        arrays. Built once per cell and process.
      axes: ``Axis`` objects, in grid order.
      realizations: draws per cell.
      reducers: ``Mean``, ``Max``, ``Min``, ``Histogram``, ``Count`` of kernel outputs.
      seed: study seed.
      key_axes: axes whose values change the draws; the others reuse them.
      out_dir: folder for ``sweep.json`` and ``chunks/``.
      fingerprint: JSON-able dict of everything that determines the results; a resume must
        match it.
      chunk_size: realizations per task and chunk file (rounded up to a multiple of
        ``batch_size``, capped at the rounded-up ``realizations``). It never changes a result,
        and may change between a run and its resume.
      batch_size: keys per kernel call, the one shape the kernel is compiled for (a multiple
        of BLOCK). Part of the run's identity: XLA may round differently at another batch
        size, so a resume must use the same.
      resume: keep the finished chunks of an earlier run with the same fingerprint and compute
        only the missing ones; without it, earlier chunk files in ``out_dir`` are deleted.
      workers: start a local Dask cluster of this many single-threaded worker processes.
      scheduler: address of an existing Dask scheduler (its workers must have this package).
      progress: show one bar (cells, realizations/s, ETA) and a final line on stderr.
      description: label of the bar.
      scheduler_timeout_s: how long to try to reach ``scheduler``.
      threads: in-process only: chunks computed side by side on this many host threads
        (default ``araim.batching.default_threads()``: ``OARAIM_THREADS`` or 2). XLA runs one
        chunk's programs on ~1.6 of the 2 cores; two chunks at a time use both. Results do not
        depend on it (each chunk is computed exactly as alone; reductions are order-free).
    """
    t0 = time.perf_counter()
    axes = tuple(axes)
    reducers = tuple(reducers)
    key_axes = tuple(key_axes)
    _check_args(axes, realizations, reducers, key_axes, workers, scheduler)
    if threads is None:
        from oaraim.araim.batching import default_threads

        threads = default_threads()
    if not isinstance(threads, int | np.integer) or threads < 1:
        raise ValueError(f"threads must be an integer >= 1, got {threads!r}")
    threads = 1 if (workers is not None or scheduler is not None) else int(threads)
    realizations = int(realizations)
    batch_size = _round_up(int(batch_size), BLOCK)
    chunk_size = min(_round_up(int(chunk_size), batch_size),
                     _round_up(realizations, batch_size))
    blocks_per_chunk = chunk_size // BLOCK
    n_blocks = -(-realizations // BLOCK)
    distributed = workers is not None or scheduler is not None
    factory_id = _factory_id(kernel_factory, distributed)
    out_dir = Path(out_dir)
    shape, cells = _cells(axes, key_axes)

    engine = {"format": FORMAT_VERSION, "block": BLOCK, "seed": int(seed),
              "realizations": realizations, "batch_size": batch_size,
              "axes": {a.name: list(a.values) for a in axes},
              "axis_order": [a.name for a in axes], "key_axes": sorted(key_axes),
              "reducers": [repr(r) for r in reducers]}
    manifest = {"fingerprint": _normalized(fingerprint), "engine": _normalized(engine)}
    if scheduler is not None:
        check_scheduler(scheduler, scheduler_timeout_s)  # before touching out_dir
    _prepare_out_dir(out_dir, manifest, resume)
    chunk_dir = out_dir / CHUNK_DIR

    # what is there already
    states = [[r.empty(n_blocks) for r in reducers] for _ in cells]
    covered = np.zeros((len(cells), n_blocks), bool)
    by_hash = {c.hash: i for i, c in enumerate(cells)}

    def meta_of(ci, b0, nb):
        return {"cell": cells[ci].text, "b0": b0, "nblocks": nb, "realizations": realizations,
                "seed": int(seed), "reducers": engine["reducers"]}

    def absorb(ci, b0, nb, parts):
        for i, r in enumerate(reducers):
            r.accumulate(states[ci][i], {k.split(".", 1)[1]: v for k, v in parts.items()
                                         if k.startswith(f"r{i}.")}, b0)
        covered[ci, b0:b0 + nb] = True

    reused = 0
    if resume:
        for f in sorted(chunk_dir.iterdir()):
            m = _CHUNK_RE.match(f.name)
            if not m:
                continue
            ci, b0, nb = by_hash.get(m.group(1)), int(m.group(2)), int(m.group(3))
            if ci is None or nb < 1 or b0 + nb > n_blocks or covered[ci, b0:b0 + nb].any():
                f.unlink()  # not of this grid, or overlapping: recompute
                continue
            parts = _read_chunk(f, meta_of(ci, b0, nb), reducers)
            if parts is None:
                warnings.warn(f"ignoring unreadable chunk file {f}; recomputing it", stacklevel=2)
                f.unlink()
                continue
            absorb(ci, b0, nb, parts)
            reused += 1

    tasks = []  # (cell index, b0, nblocks), cell by cell
    for ci in range(len(cells)):
        for b0, length in _missing_runs(covered[ci]):
            for s in range(b0, b0 + length, blocks_per_chunk):
                tasks.append((ci, s, min(blocks_per_chunk, b0 + length - s)))

    def n_real(b0, nb):
        return min(realizations, (b0 + nb) * BLOCK) - b0 * BLOCK

    todo_real = sum(n_real(b0, nb) for _, b0, nb in tasks)
    chunks_left = np.zeros(len(cells), int)
    for ci, _, _ in tasks:
        chunks_left[ci] += 1

    from oaraim.mc.progress import SweepProgress

    bar = SweepProgress(len(cells), todo_real, description or "sweep", enabled=progress)
    bar.cells_done(int(np.sum(chunks_left == 0)))

    def finished(task, parts):
        ci, b0, nb = task
        _write_atomic(chunk_dir / _chunk_name(cells[ci].hash, b0, nb),
                      _chunk_bytes(meta_of(ci, b0, nb), parts))
        absorb(ci, b0, nb, parts)
        chunks_left[ci] -= 1
        bar.advance(n_real(b0, nb), cells=int(chunks_left[ci] == 0))

    def args_of(task):
        ci, b0, nb = task
        c = cells[ci]
        return c.coords, c.key_id, int(seed), b0, nb, realizations, batch_size, reducers

    with bar:
        if tasks and distributed:
            _run_dask(tasks, kernel_factory, factory_id, args_of, finished, workers, scheduler,
                      scheduler_timeout_s)
        else:
            kernels = collections.OrderedDict()

            def kernel_of(task):
                """Built once per cell: tasks come cell by cell, so the last few suffice."""
                c = cells[task[0]]
                if c.text not in kernels:
                    kernels[c.text] = kernel_factory(dict(c.coords))
                    while len(kernels) > 4:
                        kernels.popitem(last=False)
                return kernels[c.text]

            if threads > 1 and len(tasks) > 1:
                _run_threads(tasks, kernel_of, args_of, finished, threads)
            else:
                for task in tasks:
                    finished(task, compute_chunk(kernel_of(task), *args_of(task)))
        if not covered.all():  # cannot happen: every missing block had a task
            raise RuntimeError("internal error: some blocks of the sweep were never computed")

        ds = _dataset(axes, shape, cells, reducers, states, realizations, seed, key_axes)
        wall_s = time.perf_counter() - t0
        where = f"{workers} local Dask workers" if workers else (
            f"Dask scheduler {scheduler}" if scheduler else
            f"in-process, {threads} thread{'s' if threads > 1 else ''}")
        bar.final_line(f"{description or 'sweep'}: {len(cells)} cells x {realizations:,} "
                       f"realizations, {len(tasks)} chunks computed ({where}), {reused} reused, "
                       f"{wall_s:.1f} s; chunk files in {chunk_dir}")
    return SweepResult(ds, len(tasks), reused, wall_s, out_dir, len(cells), chunk_size,
                       batch_size=batch_size,
                       workers=workers, scheduler=scheduler, realizations_computed=todo_real,
                       threads=threads)


def _dataset(axes, shape, cells, reducers, states, realizations, seed, key_axes):
    dims = tuple(a.name for a in axes)
    coords = {a.name: list(a.values) for a in axes}
    data = {}
    for i, r in enumerate(reducers):
        per_cell = [r.finish(states[ci][i]) for ci in range(len(cells))]
        for var, extra in r.variables().items():
            first = np.asarray(per_cell[0][var])
            arr = np.empty(shape + first.shape, first.dtype)
            for c, res in zip(cells, per_cell, strict=True):
                arr[c.index] = res[var]
            data[var] = (dims + tuple(extra), arr)
        if hasattr(r, "coords"):
            coords.update(r.coords())
    import xarray as xr  # ~0.3 s to import: here, not on `import oaraim.mc`

    return xr.Dataset(data, coords=coords,
                      attrs={"realizations": int(realizations), "seed": int(seed),
                             "key_axes": list(key_axes), "block": BLOCK})


def _scheduler_error(address, e):
    msg = str(e).splitlines()[0] if str(e) else type(e).__name__
    return ValueError(f"cannot reach the Dask scheduler at {address!r} ({msg}); start one with "
                      "`dask scheduler` and its workers with `dask worker ADDRESS`, or use "
                      "--workers N for a local cluster")


def check_scheduler(address: str, timeout_s: float = 10.0):
    """Fail fast, with one clear line, on a malformed or unreachable scheduler address (before
    any Dask client exists: a client that failed to connect complains again at exit)."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port

    try:
        scheme, loc = parse_address(address)
        if scheme == "tcp":
            host, port = parse_host_port(loc)
            with socket.create_connection((host, int(port)), timeout=timeout_s):
                pass
    except Exception as e:  # noqa: BLE001 - malformed or unreachable: the user's address
        raise _scheduler_error(address, e) from None


def _run_threads(tasks, kernel_of, args_of, finished, threads):
    """Compute the tasks on ``threads`` host threads (JAX releases the GIL while XLA runs),
    at most 2 x threads in flight; each result is written here, in this thread, as it
    completes. An exception (or Ctrl-C) cancels what has not started and is re-raised once the
    running chunks end; every chunk finished before is already on disk."""
    import concurrent.futures as cf

    pending = iter(tasks)
    inflight = {}
    with cf.ThreadPoolExecutor(threads, thread_name_prefix="oaraim-sweep") as pool:
        def submit_next():
            task = next(pending, None)
            if task is not None:
                inflight[pool.submit(compute_chunk, kernel_of(task), *args_of(task))] = task

        try:
            for _ in range(2 * threads):
                submit_next()
            while inflight:
                done, _ = cf.wait(inflight, return_when=cf.FIRST_COMPLETED)
                for fut in sorted(done, key=inflight.get):
                    task = inflight.pop(fut)
                    finished(task, fut.result())  # re-raises the chunk's exception
                    submit_next()
        except BaseException:
            for fut in inflight:
                fut.cancel()
            raise


def _run_dask(tasks, kernel_factory, factory_id, args_of, finished, workers, scheduler,
              timeout_s):
    """Submit one task per (cell, chunk) to Dask; write each result here as it completes."""
    import distributed

    cluster = None
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout=f"{float(timeout_s)}s")
        except Exception as e:  # noqa: BLE001 - any failure to connect is the user's address
            raise _scheduler_error(scheduler, e) from None
    else:
        cluster = distributed.LocalCluster(n_workers=int(workers), threads_per_worker=1,
                                           processes=True, dashboard_address=None,
                                           silence_logs=logging.ERROR)
        client = distributed.Client(cluster)
    try:
        slots = max(1, sum(client.nthreads().values()))
        window = 4 * slots  # bounded in flight: results are written as they come
        pending = iter(tasks)
        done = distributed.as_completed()
        owner = {}

        def submit_next():
            task = next(pending, None)
            if task is not None:
                fut = client.submit(_remote_chunk, kernel_factory, factory_id, *args_of(task),
                                    pure=False)
                owner[fut.key] = task
                done.add(fut)

        for _ in range(window):
            submit_next()
        for fut in done:
            parts = fut.result()  # re-raises a worker's exception here
            finished(owner.pop(fut.key), parts)
            fut.release()
            submit_next()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
