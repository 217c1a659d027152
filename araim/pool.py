"""``KernelPool``: one worker process per core, each pinned to its core, for the batched kernels.

Why processes. XLA:CPU runs a program on its own intra-op thread pool, one thread per core the
process may use. Two host threads each running half a batch (``araim.batching.map_threads``)
therefore share one pool, and the pool's scheduling costs CPU time: the MHSS kernel takes
~4-5 CPU-us per PL that way against 2.9-3.1 on one core alone (measured 2026-12-02, 9 GPS +
4 SOPs, 512-bit vectors). A process pinned to one core before JAX starts gets a pool of one
thread, and two such processes, one per core, gave 271k + 272k = 543k PL/s against ~400k for
the two threads (same day, batch 65,536). A pinned process with two host threads does not help:
its one pool thread serialises them (224k PL/s).

How. ``KernelPool(workers)`` starts ``workers`` Python processes (``subprocess``, not
``multiprocessing``: nothing of the caller's ``__main__`` is re-imported, so scripts without a
``__name__ == "__main__"`` guard work). Each pins itself with ``os.sched_setaffinity`` to one of
the CPUs this process may use, before it imports JAX, and then waits for work on a pipe.
``map`` writes the batch once into a shared memory file (``/dev/shm``; every worker maps it and
the name is removed at once, so nothing is left behind even if the processes are killed), and
each worker computes its part: whole chunks of ``araim.batching.CHUNK`` at the same positions as
in one call, so the results are bit-identical to ``fn(*arrays)`` in this process (tested). The
outputs come back over the pipe (they are ~10x smaller than the inputs for the MHSS kernel).
Each worker compiles a kernel once per input shape and static arguments, like a jit.

Failures. An exception inside ``fn`` comes back as ``PoolError`` with the worker's traceback and
the pool stays usable. A worker that dies (killed, out of memory) closes the pool and raises
``PoolError`` naming it and its exit code; so does an interrupt (Ctrl-C) during ``map``, since
the workers' replies would no longer match the requests. Nothing is retried silently.
"""

import importlib
import math
import mmap
import os
import subprocess
import sys
import tempfile
import threading
import weakref
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np

from araim.batching import CHUNK
from araim.validate import check_int

#: seconds a worker may take to import JAX and the toolkit and report ready
START_TIMEOUT_S = 300.0
#: seconds ``close`` waits for a worker to exit before killing it
STOP_TIMEOUT_S = 10.0
#: byte alignment of every array in the shared file (a cache line; what XLA:CPU asks of inputs)
_ALIGN = 64


class PoolError(RuntimeError):
    """A worker of a ``KernelPool`` failed to start, raised, or died."""


def usable_cpus():
    """The CPUs this process may run on (``os.sched_getaffinity``), or ``range(os.cpu_count())``
    where the platform has no affinity call (then workers are not pinned)."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return list(range(os.cpu_count() or 1))


def _shared_dir():
    """Where the shared file lives: ``/dev/shm`` (memory) where it exists, else the temp dir."""
    shm = Path("/dev/shm")
    return str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None


class _State:
    """What ``close`` needs, kept apart from the pool so ``weakref.finalize`` can reach it."""

    def __init__(self):
        self.procs = []  # subprocess.Popen per worker
        self.tx = []  # Connection: requests to worker i
        self.rx = []  # Connection: replies of worker i
        self.mm = None  # the shared mmap
        self.capacity = 0  # its size in bytes


def _shutdown(state):
    for tx in state.tx:
        try:
            tx.send(("stop",))
        except (OSError, ValueError):
            pass
    for p in state.procs:
        try:
            p.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    for c in state.tx + state.rx:
        c.close()
    if state.mm is not None:
        state.mm.close()
    state.procs, state.tx, state.rx, state.mm, state.capacity = [], [], [], None, 0


def _module_function(fn):
    """(module, name) by which a worker imports ``fn``; it must be a module-level function."""
    module, name = getattr(fn, "__module__", None), getattr(fn, "__qualname__", "")
    try:
        found = getattr(importlib.import_module(module), name, None) if module else None
    except ImportError:
        found = None
    if found is not fn:
        raise ValueError(f"KernelPool.map needs a function defined at module level (workers "
                         f"import it by name), got {fn!r}; define it with def at the top level "
                         "of an importable module")
    return module, name


class KernelPool:
    """Worker processes, one per core, each pinned to its core, that run a batch kernel on
    equal parts of a batch (module docstring: why and how).

    Args:
      workers: number of processes; default one per CPU this process may use.
      pin: pin worker i to the i-th usable CPU (round robin when there are more workers than
        CPUs). Off, each worker's XLA uses every core and the workers contend.

    Use as a context manager or call ``close``; a pool left open is closed when it is garbage
    collected or at exit. One ``map`` runs at a time (calls from several threads queue).
    """

    def __init__(self, workers=None, *, pin=True):
        cpus = usable_cpus()
        n = len(cpus) if workers is None else check_int("workers", workers, 1)
        self.cpus = [cpus[i % len(cpus)] for i in range(n)] if pin else [None] * n
        self.worker_info = []  # per worker: dict(pid=, cpus=) as the worker reports them
        self._state = _State()
        self._finalizer = weakref.finalize(self, _shutdown, self._state)
        self._lock = threading.Lock()
        self._closed = False
        self._ready = False
        try:
            for cpu in self.cpus:
                self._spawn(cpu)
        except BaseException:
            self.close()
            raise

    @property
    def workers(self):
        return len(self.cpus)

    def _spawn(self, cpu):
        req_r, req_w = os.pipe()
        rep_r, rep_w = os.pipe()
        pin = (f"os.sched_setaffinity(0, {{{cpu}}})"
               if cpu is not None and hasattr(os, "sched_setaffinity") else "pass")
        boot = (f"import os; {pin}; from araim.pool import _worker_main; "
                f"_worker_main({req_r}, {rep_w})")
        env = dict(os.environ)
        # the worker imports this very toolkit, wherever this process found it
        root = str(Path(__file__).resolve().parent.parent)
        env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get(
            "PYTHONPATH", "").split(os.pathsep) if p])
        env["OARAIM_THREADS"] = "1"
        try:
            proc = subprocess.Popen([sys.executable, "-c", boot], pass_fds=(req_r, rep_w),
                                    env=env, stdin=subprocess.DEVNULL, stdout=2)
        finally:
            os.close(req_r)
            os.close(rep_w)
        self._state.procs.append(proc)
        self._state.tx.append(Connection(req_w, readable=False))
        self._state.rx.append(Connection(rep_r, writable=False))

    def _died(self, i, doing):
        p = self._state.procs[i]
        try:
            code = p.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            code = None
        self.close()
        return PoolError(f"pool worker {i} (pid {p.pid}) exited with code {code} while "
                         f"{doing}; its error output, if any, is above. The pool is closed and "
                         "nothing of this call was returned: create a new KernelPool (or call "
                         "without a pool) and rerun")

    def _recv(self, i, doing, timeout=None):
        rx = self._state.rx[i]
        try:
            if timeout is not None and not rx.poll(timeout):
                self.close()
                raise PoolError(f"pool worker {i} did not answer within {timeout:.0f} s while "
                                f"{doing}; the pool is closed")
            return rx.recv()
        except (EOFError, OSError):
            raise self._died(i, doing) from None

    def _send(self, i, msg, doing):
        try:
            self._state.tx[i].send(msg)
        except (BrokenPipeError, OSError):
            raise self._died(i, doing) from None

    def _check_open(self):
        if self._closed:
            raise PoolError("this KernelPool is closed; create a new one")

    def _wait_ready(self):
        if self._ready:
            return
        for i in range(self.workers):
            reply = self._recv(i, "starting (importing JAX and araim)", START_TIMEOUT_S)
            self.worker_info.append(dict(pid=reply[1], cpus=reply[2]))
        self._ready = True

    def _reserve(self, nbytes):
        """A shared file of at least ``nbytes`` mapped here and in every worker."""
        st = self._state
        if nbytes <= st.capacity:
            return st.mm
        size = max(nbytes, 2 * st.capacity)
        size = -(-size // mmap.PAGESIZE) * mmap.PAGESIZE
        fd, path = tempfile.mkstemp(prefix="oaraim-pool-", dir=_shared_dir())
        try:
            os.ftruncate(fd, size)
            mm = mmap.mmap(fd, size)
            try:
                for i in range(self.workers):
                    self._send(i, ("attach", path), "mapping the shared memory")
                for i in range(self.workers):
                    reply = self._recv(i, "mapping the shared memory")
                    if reply[0] != "ok":
                        raise PoolError(f"pool worker {i} could not map {path}: {reply[1]}")
            except BaseException:
                mm.close()
                raise
        finally:
            os.close(fd)
            os.unlink(path)  # every mapping stays valid; nothing is left in /dev/shm
        if st.mm is not None:
            st.mm.close()
        st.mm, st.capacity = mm, size
        return mm

    def map(self, fn, arrays, batch_shape, static=None, chunk=CHUNK):
        """``fn(*arrays, **static)`` computed by the workers, each on equal parts of whole chunks.

        ``fn`` is a module-level function (workers import it by name) taking arrays with one
        flat leading batch axis and returning a pytree of arrays with that leading axis (as
        ``araim.batching.map_chunks`` kernels do); ``static`` holds its picklable keyword
        arguments. Returns the pytree with ``batch_shape`` restored, as NumPy arrays.

        A batch of at least ``2 workers`` chunks is split into ``workers`` parts of equal whole
        chunks (padding with the first geometry, dropped afterwards); a smaller batch goes to
        as many workers as it has pairs of chunks, or whole to the first worker. Every geometry
        is therefore computed by the same compiled chunk program as in one call, bit-identical.
        """
        module, name = _module_function(fn)
        static = {} if static is None else dict(static)
        arrays = [np.asarray(x) for x in arrays]
        batch_shape = tuple(batch_shape)
        n = math.prod(batch_shape)
        flat = [x.reshape((n,) + x.shape[len(batch_shape):]) for x in arrays]
        n_chunks = -(-n // chunk)
        parts = max(1, min(self.workers, n_chunks // 2))
        per = n if parts == 1 else -(-n_chunks // parts) * chunk
        total = per * parts
        layout, offset = [], 0
        for x in flat:
            layout.append((offset, x.dtype.str, (total,) + x.shape[1:]))
            offset += -(-(total * x[:1].nbytes) // _ALIGN) * _ALIGN
        with self._lock:
            self._check_open()
            try:
                self._wait_ready()
                mm = self._reserve(max(offset, 1))
                for i in range(parts):  # write part i, then let worker i start on it
                    lo, hi = i * per, (i + 1) * per
                    for x, (off, dtype, shape) in zip(flat, layout):
                        dst = np.ndarray(shape, dtype, buffer=mm, offset=off)[lo:hi]
                        m = max(0, min(hi, n) - lo)
                        dst[:m] = x[lo:lo + m]
                        dst[m:] = x[:1]  # padding: a real geometry, dropped below
                        del dst
                    self._send(i, ("map", layout, lo, hi, module, name, static),
                               f"receiving part {i} of the batch")
                replies = [self._recv(i, f"computing part {i} of the batch")
                           for i in range(parts)]
            except PoolError:
                raise
            except BaseException:  # an interrupt: the replies would be out of step
                self.close()
                raise
        for i, reply in enumerate(replies):
            if reply[0] != "ok":
                raise PoolError(f"{module}.{name} raised in pool worker {i}: {reply[1]}\n"
                                f"--- the worker's traceback ---\n{reply[2]}")
        import jax

        outs = [r[1] for r in replies]
        return jax.tree.map(
            lambda *ys: np.concatenate(ys)[:n].reshape(batch_shape + ys[0].shape[1:]), *outs)

    def close(self):
        """Stop the workers (killed after ``STOP_TIMEOUT_S``) and free the shared memory.
        Idempotent."""
        self._closed = True
        self._finalizer()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        state = "closed" if self._closed else f"{self.workers} workers on CPUs {self.cpus}"
        return f"KernelPool({state})"


def _worker_main(request_fd, reply_fd):
    """A worker's loop (started by ``KernelPool._spawn``, already pinned)."""
    import traceback

    import jax

    rx = Connection(request_fd, writable=False)
    tx = Connection(reply_fd, readable=False)
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    tx.send(("ready", os.getpid(), cpus))
    mm = None
    while True:
        try:
            msg = rx.recv()
        except (EOFError, OSError):  # the pool's process is gone
            return
        if msg[0] == "stop":
            return
        if msg[0] == "attach":
            try:
                with open(msg[1], "r+b") as f:
                    new = mmap.mmap(f.fileno(), 0)
                if mm is not None:
                    try:
                        mm.close()
                    except BufferError:  # an array still refers to it: freed with that array
                        pass
                mm = new
                tx.send(("ok",))
            except Exception as e:
                tx.send(("error", f"{type(e).__name__}: {e}"))
            continue
        _, layout, lo, hi, module, name, static = msg
        try:
            fn = getattr(importlib.import_module(module), name)
            xs = [np.ndarray(shape, dtype, buffer=mm, offset=off)[lo:hi]
                  for off, dtype, shape in layout]
            out = jax.block_until_ready(fn(*xs, **static))
            out = jax.tree.map(np.array, out)  # copies: nothing refers to the shared file
            del xs
            tx.send(("ok", out))
        except Exception as e:
            tx.send(("error", f"{type(e).__name__}: {e}", traceback.format_exc()))
