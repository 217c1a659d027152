"""oaraim.batching.map_threads on a trivial kernel: the in-program part slices, the padding,
the kept thread pools and a nested call (a part that splits again must not wait for a pool
thread it occupies itself)."""

import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim.batching import map_threads, map_tiles, slice_rows

TILE = 8


def _kernel(x, y):
    return {"sum": x[:, 0] + y, "prod": x * y[:, None]}


_fn = jax.jit(lambda x, y: map_tiles(_kernel, (x, y), (x.shape[0],), tile=TILE))
_part_fn = jax.jit(lambda start, x, y, size: map_tiles(
    _kernel, slice_rows((x, y), start, size), (size,), tile=TILE), static_argnames="size")


def _inputs(n):
    rng = np.random.default_rng(n)
    return jnp.asarray(rng.normal(size=(n, 3))), jnp.asarray(rng.normal(size=n))


def _part(start, size, x, y):
    return _part_fn(start, x, y, size=size)


def test_parts_sliced_in_program_equal_one_call():
    for n, threads in ((5 * TILE + 3, 2), (9 * TILE, 3), (4 * TILE, 2), (TILE + 1, 2)):
        x, y = _inputs(n)
        want = _fn(x, y)
        for part_fn in (None, _part):
            got = map_threads(_fn, (x, y), (n,), threads, tile=TILE, part_fn=part_fn)
            for k in want:
                assert got[k].shape == want[k].shape
                assert np.array_equal(np.asarray(got[k]), np.asarray(want[k])), (n, threads, k)


def test_batch_shape_is_restored():
    x, y = _inputs(6 * TILE)
    got = map_threads(lambda a, b: _fn(a.reshape(-1, 3), b.reshape(-1)),
                      (x.reshape(2, 3 * TILE, 3), y.reshape(2, 3 * TILE)), (2, 3 * TILE), 2,
                      tile=TILE, part_fn=_part)
    assert got["sum"].shape == (2, 3 * TILE) and got["prod"].shape == (2, 3 * TILE, 3)
    np.testing.assert_array_equal(np.asarray(got["sum"]).ravel(), np.asarray(_fn(x, y)["sum"]))


def test_nested_split_runs_without_waiting_for_itself():
    """Both pool threads busy with parts whose kernel splits again: the inner split runs its
    parts in the calling thread (a shared pool of 2 would otherwise deadlock)."""
    x, y = _inputs(8 * TILE)

    def outer_part(start, size, x, y):
        xs, ys = x[start:start + size], y[start:start + size]
        return map_threads(_fn, (xs, ys), (size,), 2, tile=TILE, part_fn=_part)

    result = {}
    t = threading.Thread(target=lambda: result.setdefault("out", map_threads(
        _fn, (x, y), (8 * TILE,), 2, tile=TILE, part_fn=outer_part)))
    t.start()
    t.join(60)
    assert not t.is_alive(), "nested map_threads deadlocked"
    np.testing.assert_array_equal(np.asarray(result["out"]["sum"]), np.asarray(_fn(x, y)["sum"]))


def test_the_old_araim_batching_names_still_work_and_warn():
    """``oaraim.araim.batching`` (the helpers' home before ``oaraim.batching``) keeps its
    names, renamed ones included (``CHUNK``, ``map_chunks``, ``chunk=``), each with a
    DeprecationWarning naming the new one."""
    import warnings

    from oaraim import batching
    from oaraim.araim import batching as old

    with pytest.warns(DeprecationWarning, match="oaraim.batching.TILE"):
        assert old.CHUNK == batching.TILE
    with pytest.warns(DeprecationWarning, match="oaraim.batching.map_tiles"):
        map_chunks = old.map_chunks
    x, y = _inputs(3 * TILE + 2)
    got = map_chunks(_kernel, (x, y), (x.shape[0],), chunk=TILE)
    want = batching.map_tiles(_kernel, (x, y), (x.shape[0],), tile=TILE)
    np.testing.assert_array_equal(got["sum"], want["sum"])
    with pytest.warns(DeprecationWarning, match="oaraim.batching.bucket"):
        assert old.bucket(200, chunk=128) == batching.bucket(200, tile=128)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AttributeError, match="no attribute 'nothing'"):
            old.nothing  # noqa: B018
