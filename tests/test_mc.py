"""mc/: keys, chunking, streaming reductions, storage; bit-identity for any chunk size."""

import json

import jax
import numpy as np
import pytest
import xarray as xr

from oaraim import mc
from oaraim.mc.keys import realization_keys
from oaraim.mc.reduce import BLOCK, EmpiricalCDF, Histogram, Mean
from oaraim.mc.runner import ChunkPlan, run_chunked


def _key_data(keys):
    return np.asarray(jax.random.key_data(keys))


def test_realization_key_depends_only_on_seed_cell_index():
    whole = _key_data(realization_keys(7, 3, 0, 100))
    part = _key_data(realization_keys(7, 3, 40, 20))
    np.testing.assert_array_equal(whole[40:60], part)
    other_cell = _key_data(realization_keys(7, 4, 0, 100))
    other_seed = _key_data(realization_keys(8, 3, 0, 100))
    assert not np.any(np.all(whole == other_cell, axis=-1))
    assert not np.any(np.all(whole == other_seed, axis=-1))
    assert len({tuple(k) for k in whole}) == 100


@pytest.mark.parametrize("seed", [0, 2**31 - 1, 2**40 + 3])
@pytest.mark.parametrize("cell", [3, 2**31 + 5, 2**32 - 1])
def test_realization_keys_are_fold_in_of_the_cell_key_op_by_op(seed, cell):
    """The one compiled call gives the keys of the definition, fold_in(fold_in(key(seed),
    cell), i), composed op by op, up to the last index 2^32 - 1."""
    base = jax.random.fold_in(jax.random.key(seed), cell)
    for start, count in ((0, 5), (2**32 - 3, 3)):
        want = np.stack([_key_data(jax.random.fold_in(base, i))
                         for i in range(start, start + count)])
        np.testing.assert_array_equal(_key_data(realization_keys(seed, cell, start, count)),
                                      want)


def test_realization_index_range_is_checked():
    with pytest.raises(ValueError, match="2\\^32"):
        realization_keys(0, 0, 2**32 - 1, 2)


def test_chunk_plan_rounds_to_blocks_and_covers_every_realization():
    plan = ChunkPlan(5000, 3000)
    assert plan.chunk_size == 3 * BLOCK
    chunks = list(plan.chunks())
    assert chunks == [(0, 3072), (3072, 1928)]
    assert ChunkPlan(10, 65536).chunk_size == BLOCK  # never more than the rounded-up count
    with pytest.raises(ValueError, match="realizations"):
        ChunkPlan(0)


@jax.jit
def _toy_kernel(keys):
    x = jax.vmap(lambda k: jax.random.normal(k, (3,)))(keys)
    return {"x0": x[:, 0], "norm": jax.numpy.linalg.norm(x, axis=-1)}


@pytest.mark.parametrize("chunk", [1024, 3072, 8192])
def test_outputs_and_means_bit_identical_for_any_chunk_size(chunk):
    n = 9000
    ref_mean = Mean("norm")
    ref = run_chunked(_toy_kernel, n, seed=1, chunk_size=2048, keep=("x0", "norm"),
                      on_chunk=lambda s, o: ref_mean.update(s, o["norm"]))
    m = Mean("norm")
    got = run_chunked(_toy_kernel, n, seed=1, chunk_size=chunk, keep=("x0", "norm"),
                      on_chunk=lambda s, o: m.update(s, o["norm"]))
    for k in ref:
        assert got[k].shape == (n,)
        np.testing.assert_array_equal(got[k], ref[k])
    assert m.mean == ref_mean.mean  # bit-identical, not approximately equal
    # The mean of |N(0, I_3)| is 2 sqrt(2/pi) = 1.5958; its sd is 0.673, so the standard
    # error at n = 9000 is 0.0071: 5 standard errors is 0.036.
    assert abs(m.mean - 2 * np.sqrt(2 / np.pi)) < 0.036


def test_mean_skips_non_finite_and_masked_values_and_reports_share():
    m = Mean("norm")
    v = np.arange(2 * BLOCK, dtype=float)
    v[5] = np.inf
    mask = np.ones(v.size, bool)
    mask[:10] = False
    m.update(0, v, mask)
    keep = mask & np.isfinite(v)
    assert m.count == keep.sum()
    assert m.share == keep.sum() / v.size
    assert m.mean == pytest.approx(v[keep].mean(), rel=1e-15)
    with pytest.raises(ValueError, match="multiple"):
        m.update(100, v)


def test_mean_combines_blocks_in_index_order_whatever_the_arrival_order():
    rng = np.random.default_rng(0)
    v = rng.standard_normal(4 * BLOCK) * 1e8
    a, b = Mean("v"), Mean("v")
    a.update(0, v)
    b.update(2 * BLOCK, v[2 * BLOCK:])
    b.update(0, v[: 2 * BLOCK])
    assert a.mean == b.mean


def test_empirical_cdf_hand_case():
    cdf = EmpiricalCDF("x", [0.0, 1.0, 2.0, 3.0])
    cdf.update(0, np.array([1.0, 2.5, np.inf, 0.5]))
    np.testing.assert_array_equal(cdf.counts, [0, 2, 2, 3])
    assert cdf.value_at(1.0) == 0.5
    assert cdf.quantile(0.75) == 3.0
    assert cdf.quantile(1.0) == np.inf  # the inf sample is never <= a grid point
    with pytest.raises(FloatingPointError, match="NaN"):
        cdf.update(0, np.array([np.nan]))


def test_histogram_hand_case():
    h = Histogram("x", [0.0, 1.0, 2.0])
    h.update(0, np.array([0.2, 1.0, 2.0, 5.0, np.inf]))
    np.testing.assert_array_equal(h.counts, [1, 2])
    assert h.outside == 2 and h.total == 5


def test_write_results_roundtrip(tmp_path):
    ds = xr.Dataset({"a": ("x", np.arange(3.0))}, coords={"x": [0, 1, 2]})
    summary = {"study": "t", "rows": [], "metrics": {"m": np.inf, "n": np.float64(2.0)}}
    prov = mc.provenance("t", {"p": 1}, 0, 3, 0.1)
    mc.write_results(tmp_path / "t", ds, summary, prov)
    back = xr.open_zarr(tmp_path / "t" / "data.zarr", consolidated=False)
    np.testing.assert_array_equal(back["a"].values, [0, 1, 2])
    s = json.loads((tmp_path / "t" / "summary.json").read_text())
    assert s["metrics"] == {"m": "inf", "n": 2.0}
    p = json.loads((tmp_path / "t" / "provenance.json").read_text())
    assert {"parameters", "seed", "versions", "git_commit", "wall_time_s"} <= set(p)
    assert p["versions"]["jax"]
