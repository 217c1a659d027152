"""Where the chunks of a parameter sweep are computed: the kernel calls of one chunk
(``kernel_outputs``, ``compute_chunk``), host threads in this process (``run_threads``) and
Dask (``run_dask``, ``check_scheduler``)."""

import collections
import logging
import socket
import threading
from typing import NamedTuple

import jax
import numpy as np

from oaraim.mc.grid import canonical
from oaraim.mc.keys import cell_key, realization_keys
from oaraim.mc.reduce import BLOCK

_KERNEL_CACHE_SIZE = 64

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


class ChunkTask(NamedTuple):
    """One chunk of one cell of a sweep: what ``compute_chunk`` computes (picklable, so a Dask
    task carries it)."""

    coords: dict
    """The cell: axis name -> value."""
    key_id: int
    """The cell's key index (``mc.keys.cell_key``; cells that differ only in axes that do not
    change the draws share it)."""
    seed: int
    """The study seed."""
    b0: int
    """The chunk's first block (of ``BLOCK`` realizations)."""
    nblocks: int
    """Its blocks."""
    realizations: int
    """Realizations per cell: outputs past the last one are excluded."""
    batch_size: int
    """Keys per kernel call (the compiled shape)."""
    reducers: tuple
    """The sweep's reducers (``mc.reduce``)."""


def compute_chunk(kernel, chunk: ChunkTask):
    """Partial statistics of blocks ``chunk.b0 .. chunk.b0 + chunk.nblocks - 1`` of one cell.

    The kernel sees ``batch_size`` keys per call (``kernel_outputs``); outputs past the cell's
    last realization are excluded. Returns ``{"r{i}.{field}": array}`` over the reducers.
    """
    coords, key_id, seed, b0, nblocks, realizations, batch_size, reducers = chunk
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


def _remote_chunk(kernel_factory, factory_id, chunk: ChunkTask):
    """Dask task: ``compute_chunk`` with the worker's cached kernel."""
    return compute_chunk(_worker_kernel(kernel_factory, factory_id, chunk.coords), chunk)



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


class WarmAhead:
    """Compiles the kernels of the cells to come on one background thread while the chunks
    run (a context manager): for a kernel with a ``warm(batch_size)`` method, which traces
    and compiles what a call with ``batch_size`` keys runs without running it.

    A sweep thread that meets a kernel not compiled yet waits for its trace (Python, one
    core) and so does the other, which needs the same program at the same cell: measured on
    seed 004 Fig. 4 (12 programs of ~1.3 s), the two cores were 27 % idle. Warming in task
    order overlaps the traces with the chunks. Nothing is computed and no result changes.
    A failure stops the warming and is left to the chunk that meets it (the same call raises
    there, with its own message)."""

    def __init__(self, kernel_factory, coords_in_order, batch_size):
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._run, args=(kernel_factory, list(coords_in_order), int(batch_size)),
            name="oaraim-warm", daemon=True)

    def _run(self, kernel_factory, coords_in_order, batch_size):
        for coords in coords_in_order:
            if self._stop.is_set():
                return
            try:
                kernel_factory(dict(coords)).warm(batch_size)
            except Exception:  # noqa: BLE001 - the chunk that meets it raises it
                return

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def run_threads(tasks, kernel_of, args_of, finished, threads):
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
                inflight[pool.submit(compute_chunk, kernel_of(task), args_of(task))] = task

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


def run_dask(tasks, kernel_factory, factory_id, args_of, finished, workers, scheduler,
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
                fut = client.submit(_remote_chunk, kernel_factory, factory_id, args_of(task),
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
