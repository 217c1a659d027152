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
import contextlib
import hashlib
import pickle
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from oaraim.config import default_threads
from oaraim.mc.grid import Axis, canonical, cell_key_id
from oaraim.mc.grid import cells as grid_cells
from oaraim.mc.keys import MAX_REALIZATIONS, check_seed
from oaraim.mc.reduce import BLOCK, REDUCERS, Count, EmpiricalCDF, Histogram, Max, Mean, Min, Values
from oaraim.mc.runner import DEFAULT_CHUNK
from oaraim.mc.sweep_backends import (
    ChunkTask,
    WarmAhead,
    check_scheduler,
    compute_chunk,
    kernel_outputs,
    run_dask,
    run_threads,
)
from oaraim.mc.sweep_store import (
    CHUNK_DIR,
    CHUNK_RE,
    FORMAT_VERSION,
    MANIFEST,
    chunk_bytes,
    chunk_name,
    prepare_out_dir,
    read_chunk,
    write_atomic,
)
from oaraim.mc.sweep_store import normalized as _normalized

__all__ = [
    "CHUNK_DIR", "MANIFEST", "REDUCERS", "Axis", "ChunkTask", "Count", "Draws", "EmpiricalCDF",
    "Execution", "Histogram", "Max", "Mean", "Min", "Storage", "SweepResult", "Values",
    "canonical", "cell_key_id", "check_scheduler", "compute_chunk", "kernel_outputs",
    "run_sweep",
]


class Draws(NamedTuple):
    """What a sweep draws in each cell: all of it is part of the run's identity (a resume must
    match it).

    Attributes:
      realizations: draws per cell.
      seed: study seed.
      key_axes: axes whose values change the draws; the others reuse them.
      batch_size: keys per kernel call, the one shape the kernel is compiled for (a multiple
        of BLOCK). XLA may round differently at another batch size, so a resume must use the
        same.
    """

    realizations: int
    seed: int
    key_axes: tuple = ()
    batch_size: int = BLOCK


class Storage(NamedTuple):
    """Where a sweep keeps its files and what a resume must match.

    Attributes:
      out_dir: folder for ``sweep.json`` and ``chunks/`` (created if missing).
      fingerprint: JSON-able dict of everything that determines the results (a study's name,
        parameters, seed, realizations); a resume must match it.
      resume: keep the finished chunks of an earlier run with the same fingerprint and compute
        only the missing ones; without it, earlier chunk files in ``out_dir`` are deleted.
    """

    out_dir: str | Path
    fingerprint: dict
    resume: bool = False


class Execution(NamedTuple):
    """Where and how the chunks of a sweep are computed; none of it changes a result.

    Attributes:
      threads: in-process only: chunks computed side by side on this many host threads
        (None: ``oaraim.config.default_threads()``, ``OARAIM_THREADS`` or 2). XLA runs one
        chunk's programs on ~1.6 of 2 cores; two chunks at a time use both. Each chunk is
        computed exactly as alone and the reductions are order-free.
      workers: start a local Dask cluster of this many single-threaded worker processes.
      scheduler: address of an existing Dask scheduler (``tcp://HOST:8786``; its workers must
        have this package). Give ``workers`` or ``scheduler``, not both.
      scheduler_timeout_s: how long to try to reach ``scheduler``.
      chunk_size: realizations per task and chunk file (None: ``mc.runner.DEFAULT_CHUNK``;
        rounded up to a multiple of the batch size, capped at the rounded-up realizations). It
        may change between a run and its resume.
    """

    threads: int | None = None
    workers: int | None = None
    scheduler: str | None = None
    scheduler_timeout_s: float = 10.0
    chunk_size: int | None = None


@dataclass
class SweepResult:
    """``dataset``: dims = axis names in declared order, coords = axis values, one variable per
    reducer output; attrs ``realizations``, ``seed``, ``key_axes``. ``chunks_computed`` and
    ``chunks_reused`` count (cell, chunk) files; ``wall_s`` is the whole call."""

    dataset: xarray.Dataset  # noqa: F821 - imported where the dataset is built
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
                         "Histogram, EmpiricalCDF, Count, Values)")
    seen = {}
    for r in reducers:
        if not isinstance(r, REDUCERS):
            raise TypeError(f"reducers must be mc.sweep.Mean/Max/Min/Histogram/EmpiricalCDF/Count/"
                            f"Values, got {r!r}")
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


def run_sweep(kernel_factory: Callable, axes, reducers, draws: Draws, *, storage: Storage,
              execution: Execution | None = None, progress: bool = True,
              description: str = "") -> SweepResult:
    """Run every cell of the grid ``axes`` for ``draws.realizations`` draws and reduce.

    Args:
      kernel_factory: picklable ``coords -> kernel`` (``coords``: dict axis name -> value);
        ``kernel(keys)`` maps a ``(batch_size,)`` key array to a dict of ``(batch_size,)``
        arrays. Built once per cell and process.
      axes: ``Axis`` objects, in grid order.
      reducers: ``Mean``, ``Max``, ``Min``, ``Histogram``, ``EmpiricalCDF``, ``Count``,
        ``Values`` of kernel outputs (``mc.reduce``).
      draws: a ``Draws``: realizations per cell, the study seed, the axes whose values change
        the draws (``key_axes``) and the keys per kernel call (``batch_size``).
      storage: a ``Storage``: the output folder, the run's fingerprint, resume or not.
      execution: an ``Execution``: host threads, or Dask workers or scheduler, and the chunk
        size (default: in-process, ``OARAIM_THREADS`` threads, ``DEFAULT_CHUNK``).
      progress: show one bar (cells, realizations/s, ETA) and a final line on stderr.
      description: label of the bar.
    """
    if not isinstance(draws, Draws):
        raise TypeError(f"draws must be an mc.sweep.Draws(realizations, seed, key_axes, "
                        f"batch_size), got {draws!r}")
    realizations, seed, key_axes, batch_size = draws
    t0 = time.perf_counter()
    axes = tuple(axes)
    reducers = tuple(reducers)
    key_axes = tuple(key_axes)
    if not isinstance(storage, Storage):
        raise TypeError(f"storage must be an mc.sweep.Storage(out_dir, fingerprint, resume), "
                        f"got {storage!r}")
    if execution is None:
        execution = Execution()
    if not isinstance(execution, Execution):
        raise TypeError(f"execution must be an mc.sweep.Execution(threads, workers, scheduler, "
                        f"...), got {execution!r}")
    out_dir, fingerprint, resume = storage
    threads, workers, scheduler, scheduler_timeout_s, chunk_size = execution
    if chunk_size is None:
        chunk_size = DEFAULT_CHUNK
    _check_args(axes, realizations, reducers, key_axes, workers, scheduler)
    seed = check_seed(seed, "seed")
    if threads is None:
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
    shape, cells = grid_cells(axes, key_axes)

    engine = {"format": FORMAT_VERSION, "block": BLOCK, "seed": int(seed),
              "realizations": realizations, "batch_size": batch_size,
              "axes": {a.name: list(a.values) for a in axes},
              "axis_order": [a.name for a in axes], "key_axes": sorted(key_axes),
              "reducers": [repr(r) for r in reducers]}
    manifest = {"fingerprint": _normalized(fingerprint), "engine": _normalized(engine)}
    if scheduler is not None:
        check_scheduler(scheduler, scheduler_timeout_s)  # before touching out_dir
    prepare_out_dir(out_dir, manifest, resume)
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
            m = CHUNK_RE.match(f.name)
            if not m:
                continue
            ci, b0, nb = by_hash.get(m.group(1)), int(m.group(2)), int(m.group(3))
            if ci is None or nb < 1 or b0 + nb > n_blocks or covered[ci, b0:b0 + nb].any():
                f.unlink()  # not of this grid, or overlapping: recompute
                continue
            parts = read_chunk(f, meta_of(ci, b0, nb), reducers)
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
        write_atomic(chunk_dir / chunk_name(cells[ci].hash, b0, nb),
                      chunk_bytes(meta_of(ci, b0, nb), parts))
        absorb(ci, b0, nb, parts)
        chunks_left[ci] -= 1
        bar.advance(n_real(b0, nb), cells=int(chunks_left[ci] == 0))

    def args_of(task):
        ci, b0, nb = task
        c = cells[ci]
        return ChunkTask(c.coords, c.key_id, int(seed), b0, nb, realizations, batch_size, reducers)

    with bar:
        if tasks and distributed:
            run_dask(tasks, kernel_factory, factory_id, args_of, finished, workers, scheduler,
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

            warm = contextlib.nullcontext()
            if tasks and hasattr(kernel_of(tasks[0]), "warm"):
                order = dict.fromkeys(ci for ci, _, _ in tasks)  # the cells in task order
                warm = WarmAhead(kernel_factory, [cells[ci].coords for ci in order], batch_size)
            with warm:
                if threads > 1 and len(tasks) > 1:
                    run_threads(tasks, kernel_of, args_of, finished, threads)
                else:
                    for task in tasks:
                        finished(task, compute_chunk(kernel_of(task), args_of(task)))
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
        # freed now, so that the next reducer's arrays can reuse the memory (a 1 x 1 deg map
        # keeps 0.7 GB of values; see oaraim.config.small_pages_for_numpy)
        del per_cell
        for st in states:
            st[i] = None
        if hasattr(r, "coords"):
            coords.update(r.coords())
    import xarray as xr  # ~0.3 s to import: here, not on `import oaraim.mc`

    return xr.Dataset(data, coords=coords,
                      attrs={"realizations": int(realizations), "seed": int(seed),
                             "key_axes": list(key_axes), "block": BLOCK})
