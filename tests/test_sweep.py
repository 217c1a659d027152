"""mc.sweep: per-cell results bit-identical for any chunking, cell order, grid narrowing and
resume; reducers against plain NumPy on the raw per-realization outputs."""

import functools
import json
import math
import warnings
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

from oaraim.mc.keys import realization_keys
from oaraim.mc.reduce import BLOCK
from oaraim.mc.sweep import (
    Axis,
    Count,
    Draws,
    Execution,
    Histogram,
    Max,
    Mean,
    Min,
    Storage,
    Values,
    cell_key_id,
    run_sweep,
)

EDGES = tuple(np.linspace(-2.0, 2.0, 9))
REDUCERS = (Mean("r", where="pos"), Mean("r_inf"), Max("r"), Max("r_inf"), Min("x0"),
            Histogram("x0", EDGES), Count("pos"), Count("big", where="pos"))
AXES = (Axis("a", (1, 2, 3)), Axis("b", (0.5, 1.0)))


@jax.jit
def toy_kernel(keys, a, b):
    """Per realization: 3 standard normals and something nonlinear of them; ``r_inf`` is inf
    for about 7 % of realizations (an 'unavailable' result)."""
    x = jax.vmap(lambda k: jax.random.normal(k, (3,)))(keys)
    r = a * jnp.sqrt(jnp.sum(x * x, axis=-1)) + b * jnp.sin(3.0 * x[:, 0]) * jnp.exp(x[:, 2])
    return {"r": r, "x0": x[:, 0], "pos": x[:, 1] > 0.0, "big": r > 2.0,
            "r_inf": jnp.where(x[:, 2] > 1.5, jnp.inf, r)}


def toy_factory(coords):
    return functools.partial(toy_kernel, a=float(coords["a"]), b=float(coords["b"]))


def _sweep(factory, axes, n, reducers, *, out_dir, fingerprint, seed, key_axes=(),
           batch_size=BLOCK, resume=False, threads=None, workers=None, scheduler=None,
           chunk_size=None, scheduler_timeout_s=10.0, **kw):
    """``run_sweep`` with its draws, storage and execution options gathered into their
    objects."""
    return run_sweep(factory, axes, reducers, Draws(n, seed, key_axes, batch_size),
                     storage=Storage(out_dir, fingerprint, resume=resume),
                     execution=Execution(threads=threads, workers=workers, scheduler=scheduler,
                                         scheduler_timeout_s=scheduler_timeout_s,
                                         chunk_size=chunk_size), **kw)


def _run(tmp_path, name="out", axes=AXES, n=5000, chunk=2048, key_axes=("a",), **kw):
    kw.setdefault("fingerprint", {"toy": 1})
    return _sweep(toy_factory, axes, n, kw.pop("reducers", REDUCERS), seed=kw.pop("seed", 3),
                  key_axes=key_axes, out_dir=tmp_path / name, chunk_size=chunk,
                  progress=False, **kw)


def _assert_cells_equal(ds_a, ds_b, **cell):
    """Every variable of one cell bit-identical in two datasets."""
    for var in ds_a.data_vars:
        a, b = ds_a[var].sel(**cell).values, ds_b[var].sel(**cell).values
        assert np.array_equal(a, b), (var, cell, a, b)


def _raw(coords, n, seed=3, key_axes=("a",)):
    """Per-realization outputs of one cell, computed as the engine does (batches of 1024)."""
    keys = realization_keys(seed, cell_key_id(coords, key_axes), 0, -(-n // BLOCK) * BLOCK)
    out = [toy_factory(coords)(keys[s:s + BLOCK]) for s in range(0, keys.shape[0], BLOCK)]
    return {k: np.concatenate([np.asarray(o[k]) for o in out])[:n] for k in out[0]}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("ref"), chunk=2048)


def test_reducers_against_numpy_on_raw_outputs(reference):
    ds = reference.dataset
    assert ds["r_mean"].dims == ("a", "b") and ds["x0_hist"].dims == ("a", "b", "x0_bin")
    assert ds.attrs["realizations"] == 5000 and ds.attrs["seed"] == 3
    np.testing.assert_array_equal(ds["x0_bin_lo"].values, EDGES[:-1])
    for a in (1, 2, 3):
        for b in (0.5, 1.0):
            o = _raw({"a": a, "b": b}, 5000)
            cell = ds.sel(a=a, b=b)
            pos = o["pos"]
            assert cell["r_count"] == pos.sum()
            assert cell["r_mean"] == pytest.approx(np.mean(o["r"][pos]), rel=1e-13)
            fin = np.isfinite(o["r_inf"])
            assert 0 < (~fin).sum() < 1000
            assert cell["r_inf_count"] == fin.sum()  # Mean skips inf and says how many it kept
            assert cell["r_inf_mean"] == pytest.approx(np.mean(o["r_inf"][fin]), rel=1e-13)
            assert cell["r_max"] == o["r"].max() and cell["r_inf_max"] == np.inf
            assert cell["x0_min"] == o["x0"].min()
            counts, _ = np.histogram(o["x0"], EDGES)
            np.testing.assert_array_equal(cell["x0_hist"].values, counts)
            assert cell["x0_outside"] == 5000 - counts.sum()
            assert cell["pos_count"] == pos.sum()
            assert cell["big_count"] == (o["big"] & pos).sum()


def _hand_factory(coords):
    """Three realizations by hand; the padding of the chunk holds NaN, which must never count."""
    def kernel(keys):
        n = keys.shape[0]
        v = np.full(n, np.nan)
        v[:3] = [1.0, 5.0, -2.0]
        w = np.zeros(n, bool)
        w[[0, 2]] = True
        return {"v": v, "w": w}
    return kernel


def test_reducers_hand_case_ignore_padding(tmp_path):
    reducers = (Mean("v", where="w"), Max("v"), Min("v"), Histogram("v", (0.0, 2.0, 6.0)),
                Count("w"))
    res = _sweep(_hand_factory, (Axis("k", (0,)),), 3, reducers, seed=0, out_dir=tmp_path,
                    fingerprint={}, progress=False)
    c = res.dataset.sel(k=0)
    assert c["v_mean"] == -0.5 and c["v_count"] == 2
    assert c["v_max"] == 5.0 and c["v_min"] == -2.0
    np.testing.assert_array_equal(c["v_hist"].values, [1, 1])
    assert c["v_outside"] == 1 and c["w_count"] == 2
    res = _sweep(_hand_factory, (Axis("k", (0,)),), 3, (Max("v", where="w"),
                    Min("v", where="w")), seed=0, out_dir=tmp_path, fingerprint={},
                    progress=False)
    assert res.dataset["v_max"].item() == 1.0 and res.dataset["v_min"].item() == -2.0


def _empty_where_factory(coords):
    return lambda keys: {"v": np.ones(keys.shape[0]), "w": np.zeros(keys.shape[0], bool)}


def test_reducers_with_nothing_included(tmp_path):
    res = _sweep(_empty_where_factory, (Axis("k", (0,)),), 10,
                    (Mean("v", where="w"), Max("v", where="w"), Min("v", where="w"),
                     Histogram("v", (0.0, 2.0), where="w")), seed=0, out_dir=tmp_path,
                    fingerprint={}, progress=False)
    c = res.dataset.sel(k=0)
    assert np.isnan(c["v_mean"]) and c["v_count"] == 0
    assert c["v_max"] == -np.inf and c["v_min"] == np.inf
    assert c["v_hist"].sum() == 0 and c["v_outside"] == 0


def _nan_factory(coords):
    def kernel(keys):
        v = np.ones(keys.shape[0])
        v[1] = np.nan
        return {"v": v, "w": np.arange(keys.shape[0]) != 1}
    return kernel


def test_nan_in_an_included_realization_is_an_error_naming_the_output(tmp_path):
    with pytest.raises(FloatingPointError, match="'v'.*NaN"):
        _sweep(_nan_factory, (Axis("k", (0,)),), 10, (Mean("v"),), seed=0,
                  out_dir=tmp_path, fingerprint={}, progress=False)
    res = _sweep(_nan_factory, (Axis("k", (0,)),), 10, (Mean("v", where="w"),), seed=0,
                    out_dir=tmp_path, fingerprint={}, progress=False)
    assert res.dataset["v_mean"].item() == 1.0 and res.dataset["v_count"].item() == 9


@pytest.mark.parametrize("chunk", [1024, 3072, 8192])
def test_bit_identical_for_any_chunk_size(tmp_path, reference, chunk):
    res = _run(tmp_path, chunk=chunk)
    xr.testing.assert_identical(res.dataset, reference.dataset)
    assert res.chunk_size == min(chunk, 5 * BLOCK)


@pytest.mark.parametrize("threads", [1, 3])
def test_bit_identical_for_any_number_of_threads(tmp_path, reference, threads):
    """The reference runs on the default 2 host threads; one thread and three give the same
    bits (chunks finish in another order, reductions are order-free)."""
    res = _run(tmp_path, threads=threads)
    xr.testing.assert_identical(res.dataset, reference.dataset)
    assert res.threads == threads and reference.threads == 2


_BROKEN = {"k": 2}


def _failing_factory(coords):
    def kernel(keys):
        if int(coords["k"]) == _BROKEN["k"]:
            raise RuntimeError(f"cell k={_BROKEN['k']} broke")
        return {"v": jnp.full(keys.shape[0], float(coords["k"]))}
    return kernel


def test_an_error_in_a_thread_is_raised_and_a_resume_completes(tmp_path):
    kw = dict(seed=0, out_dir=tmp_path, fingerprint={}, progress=False, threads=2)
    axes = (Axis("k", (0, 1, 2, 3, 4, 5)),)
    _BROKEN["k"] = 2
    try:
        with pytest.raises(RuntimeError, match="cell k=2 broke"):
            _sweep(_failing_factory, axes, 1024, (Mean("v"),), **kw)
    finally:
        _BROKEN["k"] = None
    res = _sweep(_failing_factory, axes, 1024, (Mean("v"),), resume=True, **kw)
    assert res.chunks_reused + res.chunks_computed == 6 and res.chunks_computed >= 1
    assert res.dataset["v_mean"].values.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]


def test_bit_identical_for_any_chunk_size_at_a_bigger_batch(tmp_path):
    ref = _run(tmp_path, "ref", chunk=2048, batch_size=2048)
    for chunk in (4096, 6144):
        xr.testing.assert_identical(_run(tmp_path, chunk=chunk, batch_size=2048).dataset,
                                    ref.dataset)


def test_one_cell_alone_and_any_cell_order_give_the_same_cell(tmp_path, reference):
    alone = _run(tmp_path, "alone", axes=(Axis("a", (2,)), Axis("b", (1.0,))))
    _assert_cells_equal(alone.dataset, reference.dataset, a=2, b=1.0)
    shuffled = _run(tmp_path, "shuffled", axes=(Axis("a", (3, 1, 2)), Axis("b", (1.0, 0.5))))
    for a in (1, 2, 3):
        for b in (0.5, 1.0):
            _assert_cells_equal(shuffled.dataset, reference.dataset, a=a, b=b)
    swapped = _run(tmp_path, "swapped", axes=(Axis("b", (0.5, 1.0)), Axis("a", (1, 2, 3))))
    assert swapped.dataset["r_mean"].dims == ("b", "a")
    xr.testing.assert_identical(swapped.dataset.transpose("a", "b", "x0_bin"),
                                reference.dataset)


def test_key_axes_change_the_draws_and_other_axes_share_them(tmp_path, reference):
    ds = reference.dataset  # key_axes = ("a",): cells with the same a share their draws
    assert cell_key_id({"a": 2, "b": 0.5}, ["a"]) == zlib.crc32(b"a=2")
    assert cell_key_id({"a": 2, "b": 0.5}, ["b", "a"]) == zlib.crc32(b"a=2;b=0.5")
    for a in (1, 2, 3):  # x0 and pos do not depend on b: identical across b
        cell = ds.sel(a=a)
        for var in ("x0_min", "x0_hist", "pos_count"):
            assert np.array_equal(cell[var].sel(b=0.5).values, cell[var].sel(b=1.0).values)
    assert len(set(ds["x0_min"].sel(b=0.5).values.tolist())) == 3  # a changes the draws
    both = _run(tmp_path, key_axes=("a", "b"))
    assert both.dataset["x0_min"].sel(a=1, b=0.5) != both.dataset["x0_min"].sel(a=1, b=1.0)
    # no key axis at all: every cell shares one set of draws
    none = _run(tmp_path, "none", key_axes=())
    assert len(set(none.dataset["x0_min"].values.ravel().tolist())) == 1


_CALLS = []


def _recording_factory(coords):
    _CALLS.append(("factory", coords["a"]))
    k = toy_factory(coords)

    def kernel(keys):
        _CALLS.append(("call", keys.shape))
        return k(keys)
    return kernel


def test_kernel_built_once_per_cell_and_always_sees_batch_size_keys(tmp_path):
    _CALLS.clear()
    _sweep(_recording_factory, AXES, 2500, REDUCERS, seed=3, key_axes=("a",),
              out_dir=tmp_path, fingerprint={}, chunk_size=2048, progress=False)
    assert sorted(c for c in _CALLS if c[0] == "factory") == [("factory", a) for a in
                                                               (1, 1, 2, 2, 3, 3)]
    assert {c for c in _CALLS if c[0] == "call"} == {("call", (1024,))}  # default batch
    assert sum(c[0] == "call" for c in _CALLS) == 6 * 3  # 2500 -> 3 padded batches
    _CALLS.clear()
    res = _sweep(_recording_factory, AXES, 2500, REDUCERS, seed=3, key_axes=("a",),
                    out_dir=tmp_path, fingerprint={}, chunk_size=1024, batch_size=2048,
                    progress=False)
    assert res.chunk_size == 2048 and res.batch_size == 2048  # chunks hold whole batches
    assert {c for c in _CALLS if c[0] == "call"} == {("call", (2048,))}
    assert sum(c[0] == "call" for c in _CALLS) == 6 * 2


_WARMS = []


class _WarmKernel:
    """The toy kernel with a ``warm`` that records its calls (and raises at a = 2, b = 1.0
    when ``_WARMS`` starts with "fail")."""

    def __init__(self, coords):
        self.coords, self.kernel = coords, toy_factory(coords)

    def __call__(self, keys):
        return self.kernel(keys)

    def warm(self, batch_size):
        _WARMS.append((self.coords["a"], self.coords["b"], batch_size))
        if _WARMS[0] == "fail" and (self.coords["a"], self.coords["b"]) == (2, 1.0):
            raise RuntimeError("warm broke")


@pytest.mark.parametrize("fail", [False, True])
def test_kernels_are_warmed_ahead_in_task_order_and_change_nothing(tmp_path, reference, fail):
    """A kernel's ``warm`` is called for every cell in task order, with the batch size, from
    a background thread; the results are the reference's; a warm that raises only stops the
    warming."""
    _WARMS[:] = ["fail"] if fail else []
    res = _sweep(_WarmKernel, AXES, 5000, REDUCERS, seed=3, key_axes=("a",),
                 out_dir=tmp_path, fingerprint={"toy": 1}, chunk_size=2048, progress=False)
    xr.testing.assert_identical(res.dataset, reference.dataset)
    cells = [(a, b, BLOCK) for a in (1, 2, 3) for b in (0.5, 1.0)]
    assert _WARMS == (["fail"] + cells[:4] if fail else cells)


def _chunk_files(out):
    return sorted((out / "chunks").glob("*.npz"))


def test_resume_recomputes_only_missing_chunks_even_with_another_chunk_size(tmp_path,
                                                                              reference):
    first = _run(tmp_path, chunk=1024)
    files = _chunk_files(tmp_path / "out")
    assert first.chunks_computed == len(files) == 6 * 5 and first.chunks_reused == 0
    for f in files[::3]:  # "killed": ten chunks never written
        f.unlink()
    again = _run(tmp_path, chunk=2048, resume=True)
    assert again.chunks_reused == 20 and 0 < again.chunks_computed < 30
    xr.testing.assert_identical(again.dataset, reference.dataset)
    done = _run(tmp_path, chunk=4096, resume=True)  # nothing left to do
    assert done.chunks_computed == 0
    xr.testing.assert_identical(done.dataset, reference.dataset)


def test_resume_recomputes_a_damaged_chunk_file(tmp_path, reference):
    _run(tmp_path)
    victim = _chunk_files(tmp_path / "out")[4]
    victim.write_bytes(victim.read_bytes()[:100])  # cannot happen with atomic writes; still safe
    (tmp_path / "out" / "chunks" / ".stray.npz.123.tmp").write_bytes(b"half")
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        res = _run(tmp_path, resume=True)
    assert any("unreadable chunk" in str(x.message) for x in w)
    assert res.chunks_computed == 1
    assert not list((tmp_path / "out" / "chunks").glob("*.tmp"))
    xr.testing.assert_identical(res.dataset, reference.dataset)


def test_resume_with_other_parameters_refuses_and_says_why(tmp_path):
    _run(tmp_path, fingerprint={"study": "toy", "params": {"sigma": 1.0}})
    with pytest.raises(ValueError, match=r"params\.sigma.*--out.*--resume"):
        _run(tmp_path, fingerprint={"study": "toy", "params": {"sigma": 2.0}}, resume=True)
    with pytest.raises(ValueError, match="realizations"):
        _run(tmp_path, n=6000, fingerprint={"study": "toy", "params": {"sigma": 1.0}},
             resume=True)
    with pytest.raises(ValueError, match="axes"):
        _run(tmp_path, axes=(Axis("a", (1,)), Axis("b", (0.5,))),
             fingerprint={"study": "toy", "params": {"sigma": 1.0}}, resume=True)
    with pytest.raises(ValueError, match="batch_size"):
        _run(tmp_path, batch_size=2048, fingerprint={"study": "toy", "params": {"sigma": 1.0}},
             resume=True)
    # without --resume a different run starts afresh and clears the old chunk files
    res = _run(tmp_path, n=1000, fingerprint={"study": "toy", "params": {"sigma": 2.0}})
    assert len(_chunk_files(tmp_path / "out")) == res.chunks_computed == 6
    manifest = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert manifest["fingerprint"]["params"]["sigma"] == 2.0
    # resume with no earlier run just runs
    fresh = _run(tmp_path, "fresh", n=1000, resume=True)
    assert fresh.chunks_computed == 6 and fresh.chunks_reused == 0


def test_fresh_run_ignores_results_of_an_earlier_run(tmp_path, reference):
    _run(tmp_path, seed=99)
    res = _run(tmp_path)  # same folder, other seed, no resume
    assert res.chunks_reused == 0
    xr.testing.assert_identical(res.dataset, reference.dataset)


@pytest.mark.parametrize("kwargs, match", [
    (dict(axes=(Axis("a", (1,)), Axis("a", (2,)))), "declared twice"),
    (dict(key_axes=("c",)), "key axis 'c'"),
    (dict(n=0), "realizations"),
    (dict(workers=0), "workers"),
    (dict(threads=0), "threads"),
    (dict(workers=2, scheduler="tcp://127.0.0.1:1"), "not both"),
    (dict(reducers=(Mean("r"), Mean("r"))), "both produce"),
    (dict(reducers=()), "at least one reducer"),
    (dict(scheduler="tcp://127.0.0.1:1"), "cannot reach the Dask scheduler"),
    (dict(scheduler="no-port-here"), "cannot reach the Dask scheduler"),
])
def test_bad_arguments_are_clear_errors(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        _run(tmp_path, **kwargs)


def test_axis_values_are_checked():
    assert Axis("a", np.array([1, 2])).values == (1, 2)
    assert type(Axis("a", (np.float64(0.5),)).values[0]) is float
    assert Axis("s", "x").values == ("x",)
    with pytest.raises(ValueError, match="twice"):
        Axis("a", (1, 1.0))
    with pytest.raises(ValueError, match="at least one"):
        Axis("a", ())
    with pytest.raises(ValueError, match="NaN"):
        Axis("a", (math.nan,))


def test_missing_kernel_output_is_named(tmp_path):
    with pytest.raises(KeyError, match="'nope'.*r_inf"):
        _run(tmp_path, reducers=(Mean("nope"),))


class _IndexKernel:
    """An index kernel (realization i of cell a is the element i of a deterministic grid):
    returns 10 a + i and the first word of the cell's key."""

    index_kernel = True

    def __init__(self, coords):
        self.a = int(coords["a"])

    def __call__(self, idx, key):
        word = jax.random.key_data(key).ravel()[-1].astype(jnp.int64)
        return {"v": 10.0 * self.a + jnp.asarray(idx, jnp.float64),
                "k": jnp.full(idx.shape, word), "even": idx % 2 == 0}


def test_index_kernel_and_values_keep_every_realization_for_any_chunking(tmp_path):
    """Values keeps realization i of each cell at position i (whatever the chunk), an index
    kernel sees the indices and its cell's key (mc.keys.cell_key of the key-axis id)."""
    from oaraim.mc.keys import cell_key

    n = 2500  # three blocks, the last one partial
    axes = (Axis("a", (1, 2)),)
    red = (Values("v", n), Values("k", n, "int64"), Values("even", n, "bool"), Mean("v"))
    runs = [_sweep(_IndexKernel, axes, n, red, seed=7, key_axes=("a",),
                      out_dir=tmp_path / f"c{c}", fingerprint={"i": 1}, chunk_size=c,
                      progress=False).dataset for c in (1024, 3072)]
    for ds in runs:
        assert ds["v"].dims == ("a", "realization")
        np.testing.assert_array_equal(ds["v"].values, [10.0 + np.arange(n), 20.0 + np.arange(n)])
        np.testing.assert_array_equal(ds["even"].values[0], np.arange(n) % 2 == 0)
        for i, a in enumerate((1, 2)):
            want = np.asarray(jax.random.key_data(cell_key(7, cell_key_id({"a": a}, ("a",)))))
            assert np.all(ds["k"].values[i] == want.ravel()[-1].astype(np.int64))
        assert ds["v_mean"].values[0] == np.mean(10.0 + np.arange(n))
    xr.testing.assert_identical(runs[0], runs[1])
