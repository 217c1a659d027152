"""Shape buckets and the single-dispatch path of the host wrappers (oaraim.batching.bucket,
araim.protection_levels): arbitrary batch sizes share a few compiled programs, padding changes
no bit, and max_order=None decided inside the kernel equals required_order's choice."""

import numpy as np
import pytest

from oaraim import araim
from oaraim.araim import mhss
from oaraim.araim.fault_modes import fault_mode_rule, to_batch_last
from oaraim.batching import TILE, bucket
from oaraim.bench import mhss_bench_inputs

KEYS = ("g", "constellation", "var_int_m2", "var_acc_m2", "b_nom_m", "p_sat", "p_const",
        "valid")
BUDGET = araim.BUDGET_SEED004_TABLE_I


def test_bucket_sizes_by_hand():
    """1, 4, 16, 64, one tile; then m tiles, m = 2, 3 and {4, 5, 6, 7} x 2^k."""
    assert TILE == 128
    want = {0: 0, 1: 1, 2: 4, 4: 4, 5: 16, 16: 16, 17: 64, 64: 64, 65: 128, 128: 128,
            129: 256, 256: 256, 257: 384, 385: 512, 512: 512, 513: 640, 897: 1024,
            1025: 1280, 1281: 1536, 1537: 1792, 1793: 2048, 2049: 2560, 65_536: 65_536,
            65_537: 81_920}
    assert {n: bucket(n) for n in want} == want
    for n in range(TILE + 1, 40 * TILE, 37):  # above one tile: at most 25 % padding
        b = bucket(n)
        assert b % TILE == 0 and n <= b <= 1.25 * n + TILE, n


@pytest.fixture(scope="module")
def case():
    x = mhss_bench_inputs(16, seed=9)
    return {k: np.asarray(v) for k, v in x.items()}


def _pl(x, n, **kw):
    return araim.protection_levels(araim.Sources(*(x[k][:n] for k in KEYS[:6]), x["valid"][:n]),
                                   x["p_const"][:n], BUDGET,
                                   araim.MHSSOptions(fault_modes="grouped", **kw))


def test_batches_of_one_bucket_share_one_program_and_bits(case):
    """Batches of 5..16 geometries run the bucket-16 program: one compilation at most, and
    every geometry's outputs are the bits of the full 16-geometry batch (the padding repeats
    geometry 0 and is dropped; the kernel never mixes geometries)."""
    full = _pl(case, 16, max_order=1)
    before = mhss.kernel_cache_size()
    for n in (5, 9, 13, 16):
        got = _pl(case, n, max_order=1)
        for name, a, b in zip(got._fields, got, full, strict=True):
            assert a.shape[0] == n and np.array_equal(np.asarray(a), np.asarray(b)[:n]), name
    assert mhss.kernel_cache_size() - before <= 1
    def three_by_four(x):
        return x[:12].reshape((3, 4) + x.shape[1:])

    one = araim.MHSSOptions(1, fault_modes="grouped")
    two_d = araim.protection_levels(
        araim.Sources(*(three_by_four(case[k]) for k in KEYS[:6]), three_by_four(case["valid"])),
        three_by_four(case["p_const"]), BUDGET, one)
    assert two_d.hpl_m.shape == (3, 4)
    assert np.array_equal(np.asarray(two_d.hpl_m).ravel(), np.asarray(full.hpl_m)[:12])
    bad = case["var_acc_m2"][:12].reshape(3, 4, -1).copy()
    bad[2, 1, 5] = np.nan  # named by its place in the caller's batch, not in the flat one
    with pytest.raises(ValueError, match=r"var_acc_m2 .* batch index \(2, 1\), source 5"):
        araim.protection_levels(
            araim.Sources(*(three_by_four(case[k]) for k in KEYS[:3]), bad,
                          *(three_by_four(case[k]) for k in KEYS[4:6]),
                          three_by_four(case["valid"])),
            three_by_four(case["p_const"]), BUDGET, one)


def test_max_order_none_in_one_call_equals_the_explicit_order(case):
    """Table I (P(> 1 faulty constellation) = 4.5e-8 <= P_thresh): order 1 in one call, the
    bits of max_order=1. With P_const^S = 1e-3 the SOP constellation and GPS faulty together
    exceed P_thresh: the kernel flags it and the batch runs again at required_order's 2."""
    auto = _pl(case, 3)
    fixed = _pl(case, 3, max_order=1)
    assert set(np.asarray(auto.order).tolist()) == {1}
    for name, a, b in zip(auto._fields, auto, fixed, strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b)), name
    hot = dict(case, p_const=np.broadcast_to([1e-4, 1e-3], case["p_const"].shape).copy())
    assert mhss.required_order(hot["valid"][:3], hot["constellation"][:3], hot["p_sat"][:3],
                               hot["p_const"][:3], BUDGET, fault_modes="grouped") == 2
    auto = _pl(hot, 3)
    fixed = _pl(hot, 3, max_order=2)
    assert set(np.asarray(auto.order).tolist()) == {2}
    for name, a, b in zip(auto._fields, auto, fixed, strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b)), name


@pytest.mark.parametrize("rule", ["grouped", "add-v4.2"])
def test_order_flags_are_required_orders_test(rule):
    """``higher_order_flags`` (the kernel's per-geometry 'needs more than order 1') against
    ``required_order`` of each geometry alone, on random batches spanning orders 1 and 2:
    random validity, labels over 3 constellations, P_s 1e-6..1e-2, P_const 1e-9..1e-3."""
    import jax

    rng = np.random.default_rng(11)
    n, n_src, n_const = 48, 9, 3
    valid = rng.random((n, n_src)) < 0.85
    lab = rng.integers(0, n_const, (n, n_src)).astype(np.int32)
    p_sat = 10.0 ** rng.uniform(-6, -2, (n, n_src))
    p_const = 10.0 ** rng.uniform(-9, -3, (n, n_const))
    r = fault_mode_rule(rule)
    flags = np.asarray(jax.jit(mhss.higher_order_flags, static_argnums=(4, 5, 6))(
        to_batch_last(valid, 1), to_batch_last(lab, 1), to_batch_last(p_sat, 1),
        to_batch_last(p_const, 1), BUDGET, r, 1))
    orders = np.array([mhss.required_order(valid[i:i + 1], lab[i:i + 1], p_sat[i:i + 1],
                                           p_const[i:i + 1], BUDGET, fault_modes=r)
                       for i in range(n)])
    assert 0 < flags.sum() < n  # both kinds in the batch
    np.testing.assert_array_equal(flags, orders > 1)
