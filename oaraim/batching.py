"""The speed helpers every computing layer shares: batch kernels run tile by tile so their
intermediates stay in cache, batch-size buckets, host threads, the kernels' jit, and the
stores XLA must not recompute (``materialize``, ``blocks``).

A layer of its own below ``araim`` (docs/design.md: it imports only ``oaraim.config``), so
that studies, the simulated world and the bench use the same helpers as the receiver
without reaching into ``araim``. Words: a *tile* is a fixed number of geometries (``TILE``)
computed by one compiled program inside a kernel call; a *chunk* (``mc``) is a task of
Monte Carlo realizations, one kernel call or more, one file of a sweep
(docs/conventions.md).


The MHSS kernel holds a few (modes x sources) arrays per geometry; over a large batch each is
hundreds of MB and the kernel becomes memory-bound. ``lax.map`` over fixed-size tiles of
``TILE`` geometries keeps every intermediate small (a (modes x 3 x sources) array of the
bench case is 0.6 MB per tile of 128, a third of a core's 2 MB L2; the tile sizes measured
are in docs/benchmarks.md). Batches larger than one tile are computed in tiles of exactly
this shape, so there a geometry's result does not depend on the caller's batch size (XLA
rounds differently at different shapes); a batch of at most one tile runs at its own shape.
Every geometry is computed independently and the padding geometries are dropped, so changing
``TILE`` moves results only by rounding (last bits), never by more.
"""

import concurrent.futures
import functools
import math
import threading

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.config import default_threads

#: XLA options of every jit that holds the MHSS kernel (``jit_kernel``): prefer 512-bit vectors.
#: XLA:CPU prefers 256-bit vectors by default, also on AVX-512 processors (this project's
#: machines); 512 bits are faster (docs/benchmarks.md) and every output is bit-identical
#: (elementwise IEEE operations give the same lanes at any width; no reduction here runs across
#: the vectorised batch axis; tested in tests/test_mhss.py). Without AVX-512 LLVM uses the
#: widest vectors it has; other backends ignore the option. Other kernels (slopes, EKF, sky)
#: keep XLA's default.
KERNEL_COMPILER_OPTIONS = {"xla_cpu_prefer_vector_width": 512}


def is_traced(tree):
    """Whether any leaf of ``tree`` is a JAX tracer: the call is being traced under a caller's
    ``jit`` or ``vmap`` (the kernels then run inline there, with no host work)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(tree))


def jit_kernel(fn=None, **kwargs):
    """``jax.jit(fn, compiler_options=KERNEL_COMPILER_OPTIONS, **kwargs)``, usable as
    ``jit_kernel(fn, ...)``, as a decorator, or as ``functools.partial(jit_kernel, ...)``.

    JAX accepts compiler options on a top-level jit only (a nested one raises ValueError), so
    a call made inside a caller's trace runs ``fn`` inline there (what a nested jit amounts to
    anyway) and the caller's jit decides the options. ``.jitted`` is the jitted function."""
    if fn is None:
        return functools.partial(jit_kernel, **kwargs)
    jitted = jax.jit(fn, compiler_options=KERNEL_COMPILER_OPTIONS, **kwargs)

    @functools.wraps(fn)
    def call(*args, **kw):
        return fn(*args, **kw) if is_traced((args, kw)) else jitted(*args, **kw)

    call.jitted = jitted
    return call

#: geometries per tile
TILE = 128


def _flatten(arrays, batch_shape):
    """(arrays with one flat leading batch axis, its length n)."""
    n = math.prod(batch_shape)
    if len(batch_shape) == 1:  # already flat: no reshape dispatch per array (~60 us each)
        return [jnp.asarray(x) for x in arrays], n
    return [jnp.asarray(x).reshape((n,) + x.shape[len(batch_shape):]) for x in arrays], n


def _pad_to(flat, size):
    """Pad the flat batch to ``size`` by repeating the first geometry: a real geometry, so no
    special cases inside the kernel; the caller drops the padding."""
    pad = size - flat[0].shape[0]
    if not pad:
        return flat
    return [jnp.concatenate([x, jnp.broadcast_to(x[:1], (pad,) + x.shape[1:])]) for x in flat]


def _unflatten(out, batch_shape, n):
    """Drop the padding and restore ``batch_shape`` on every output leaf."""
    return jax.tree.map(lambda y: y[:n].reshape(tuple(batch_shape) + y.shape[1:]), out)


#: batch sizes below one tile that the host wrappers compile for (``bucket``)
SMALL_BUCKETS = (1, 4, 16, 64)


def bucket(n, tile=TILE):
    """The batch size a host wrapper runs ``n`` geometries at: the smallest of 1, 4, 16, 64,
    ``tile``, then ``m`` whole tiles with m = 2, 3 or m in {4, 5, 6, 7} x 2^k, that holds n.

    Every new batch shape compiles the kernel again (10-25 s for MHSS); with buckets a user's
    arbitrary batch sizes share a handful of compiled programs (five up to one tile, four per
    doubling above) at most 25 % extra work above one tile. Batches of one geometry stay
    at their own size (the latency of a single call).
    """
    n = int(n)
    if n <= 0:
        return 0
    if n <= tile:
        return next((b for b in SMALL_BUCKETS if n <= b < tile), tile)
    m = -(-n // tile)
    if m > 3:
        step = 1 << (m.bit_length() - 3)  # m in [4 step, 8 step)
        m = -(-m // step) * step
    return m * tile


def pad_rows(flat, size):
    """Flat batch-first NumPy arrays padded to ``size`` rows by repeating the first row (a real
    geometry, as ``_pad_to``); the caller drops the padding (``unpad``)."""
    pad = size - flat[0].shape[0]
    if not pad:
        return flat
    return [np.concatenate([x, np.broadcast_to(x[:1], (pad,) + x.shape[1:])]) for x in flat]


def unpad(out, batch_shape, n):
    """The first ``n`` rows of every leaf of ``out`` with ``batch_shape`` restored, one compiled
    program for all leaves (a dispatch per leaf costs ~15 us each); nothing when there is no
    padding and the batch is flat."""
    batch_shape = tuple(int(b) for b in batch_shape)
    if batch_shape == (n,) and all(y.shape[0] == n for y in jax.tree.leaves(out)):
        return out
    return _unflatten_jit(out, batch_shape, n)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _unflatten_jit(out, batch_shape, n):
    return _unflatten(out, batch_shape, n)


def map_tiles(fn, arrays, batch_shape, tile=TILE):
    """Apply ``fn`` to arrays whose leading axes are ``batch_shape`` in tiles of ``tile``.

    ``fn`` takes the arrays with one flattened leading batch axis and returns a pytree of
    arrays with that leading axis; the result has ``batch_shape`` restored.
    """
    flat, n = _flatten(arrays, batch_shape)
    if n <= tile:
        return _unflatten(fn(*flat), batch_shape, n)
    n_tiles = -(-n // tile)
    flat = _pad_to(flat, n_tiles * tile)
    stacked = [x.reshape((n_tiles, tile) + x.shape[1:]) for x in flat]
    out = jax.lax.map(lambda xs: fn(*xs), stacked)
    out = jax.tree.map(lambda y: y.reshape((n_tiles * tile,) + y.shape[2:]), out)
    return _unflatten(out, batch_shape, n)


def map_threads(fn, arrays, batch_shape, threads=None, tile=TILE, part_fn=None):
    """``fn(*arrays)`` for a jitted batch-first ``fn`` that evaluates in ``map_tiles`` tiles,
    run as ``threads`` equal parts side by side on host threads (JAX releases the GIL while
    XLA runs), outputs concatenated.

    The parts start at multiples of ``tile`` and hold whole tiles (the batch is padded as
    ``map_tiles`` pads it, and the padding dropped), and each part has more than one tile, so
    every geometry is computed in the same tile, at the same position, by the same compiled
    tile program as in one call: the results are bit-identical to ``fn(*arrays)`` (tested).
    Batches of fewer than ``2 threads`` tiles are one call, and so is a call traced inside
    the caller's ``jit`` (threads cannot share a trace).

    ``part_fn(start, size, *flat)``, if given, computes ``fn`` on rows [start, start + size)
    of the flat arrays and slices them inside its own jit (``slice_rows``; ``start`` traced,
    so one compilation serves every part): the parts are then not copied out of the batch
    first. Measured on the bench case (65,536 geometries, 2 parts): the copies took 6.7 ms of
    a ~85 ms call.
    """
    threads = default_threads() if threads is None else int(threads)
    n_tiles = -(-math.prod(batch_shape) // tile)
    traced = is_traced(arrays)
    if threads <= 1 or n_tiles < 2 * threads or traced:  # under a caller's jit: inline
        return fn(*arrays)
    per = -(-n_tiles // threads) * tile  # geometries per part, whole tiles
    flat, n = _flatten(arrays, batch_shape)
    flat = _pad_to(flat, per * threads)

    def part(i):
        if part_fn is not None:
            return jax.block_until_ready(part_fn(i * per, per, *flat))
        return jax.block_until_ready(fn(*(x[i * per:(i + 1) * per] for x in flat)))

    if threading.current_thread().name.startswith(_THREAD_PREFIX):  # nested: no free thread
        outs = [part(i) for i in range(threads)]
    else:
        outs = list(_executor(threads).map(part, range(threads)))
    return _join(outs, tuple(batch_shape), n)


_THREAD_PREFIX = "oaraim-part"
_EXECUTORS = {}
_EXECUTORS_LOCK = threading.Lock()


def _executor(threads):
    """A thread pool per thread count, kept for the process (starting the threads cost ~1-2 ms
    per call, measured); its idle threads end with the interpreter. A part that
    calls ``map_threads`` again runs that call's parts itself (its pool may be the one it
    occupies: tested)."""
    with _EXECUTORS_LOCK:
        if threads not in _EXECUTORS:
            _EXECUTORS[threads] = concurrent.futures.ThreadPoolExecutor(
                threads, thread_name_prefix=_THREAD_PREFIX)
        return _EXECUTORS[threads]


@functools.partial(jax.jit, static_argnums=(1, 2))
def _join(outs, batch_shape, n):
    """The parts' outputs concatenated, padding dropped, ``batch_shape`` restored: one program
    (one copy per output) instead of a dispatch per output and step (~2 ms per call at the
    bench's 9 outputs, measured)."""
    return _unflatten(jax.tree.map(lambda *ys: jnp.concatenate(ys), *outs), batch_shape, n)


def slice_rows(arrays, start, size):
    """Rows [start, start + size) of each flat batch-first array, for use inside a jit with a
    traced ``start`` (the ``part_fn`` of ``map_threads``); XLA fuses the slice into the
    kernel's first read of its inputs."""
    return [jax.lax.dynamic_slice_in_dim(x, start, size) for x in arrays]


def materialize(x):
    """Identity (NaN stays NaN) that XLA computes once and stores. XLA's fusion duplicates a
    cheap elementwise producer into every consumer, also into one that broadcasts it; here that
    repeated a whole unrolled solve for every element of an (L, L, B) product (measured: most
    of the kernel). A division is 'expensive' for XLA and is never duplicated that way."""
    if not jnp.issubdtype(x.dtype, jnp.floating):  # labels and masks: exact through float64
        y = x.astype(jnp.float64)
        return (y / (y == y).astype(y.dtype)).astype(x.dtype)
    return x / (x == x).astype(x.dtype)


def blocks(parts):
    """jnp.concatenate(parts, axis=0), written as in-place updates of one buffer: XLA fuses a
    concatenation with the computations of its parts into one loop that branches on every
    element (measured: a scalar loop, 10x slower than the parts alone); an update slice loops
    over its part only."""
    out = jnp.zeros((sum(p.shape[0] for p in parts),) + parts[0].shape[1:], parts[0].dtype)
    start = 0
    for p in parts:
        out = jax.lax.dynamic_update_slice_in_dim(out, p, start, axis=0)
        start += p.shape[0]
    return out
