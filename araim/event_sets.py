"""Per-set arithmetic of the event fault-mode conventions (``araim.fault_modes``): sets of at
most two events over the events [sources, constellations] of a batch-last batch, their
per-set arrays built from per-event arrays in blocks (no gathers), long ordered sums with a
stored running sum, and the probability tails of independent events. Every function keeps
the order of its additions and products: the selection's bits do not depend on how the
program is split into loops (docs/design.md, reproducibility)."""

import jax
import jax.numpy as jnp

from oaraim.araim import linalg

__all__ = ["STORED_SUM_TERMS", "event_tails", "merge_equal_sets", "pad_row", "per_set",
           "stored_sum", "suffix_sums"]


def event_tails(p, order: int):
    """(P(exactly k events) for k = 0..order, P(more than order events)) for independent events
    p (E, B), as sums of non-negative terms."""
    dist = [jnp.ones(p.shape[1:])] + [jnp.zeros(p.shape[1:])] * order
    tail = jnp.zeros(p.shape[1:])
    for e in range(p.shape[0]):
        q = p[e]
        tail = tail + dist[order] * q
        dist = [dist[0] * (1 - q)] + [dist[k] * (1 - q) + dist[k - 1] * q
                                      for k in range(1, order + 1)]
    return dist, tail


def pad_row(x, value):
    """x (K, B) with one more row ``value`` (the sentinel slot of the event sets' index lists)."""
    return jnp.concatenate([x, jnp.full((1,) + x.shape[1:], value, x.dtype)], axis=0)


#: ``stored_sum`` stores its running sum after this many terms
STORED_SUM_TERMS = 64


def stored_sum(x, start=None):
    """``linalg.sum_axis(x, 0)`` (or ``start`` + x_0 + x_1 + ..., from the left, with
    ``start``), the running sum written to a buffer and read back every ``STORED_SUM_TERMS``
    terms: the same additions in the same order, in loops of at most that many terms (one
    fused loop over the hundreds of pairs of the consolidated conventions ran 1.6x slower per
    term)."""
    n = x.shape[0]
    if n == 0:
        return linalg.sum_axis(x, 0) if start is None else start
    acc, j = (x[0], 1) if start is None else (start, 0)
    buf = jnp.zeros((n // STORED_SUM_TERMS + 1,) + x.shape[1:], x.dtype)
    for k in range(j, n):
        acc = acc + x[k]
        if (k + 1) % STORED_SUM_TERMS == 0 and k + 1 < n:
            i = (k + 1) // STORED_SUM_TERMS
            buf = jax.lax.dynamic_update_slice_in_dim(buf, acc[None], i, 0)
            acc = buf[i]
    return acc


def per_set(single, first, second, op, r_enum, pair=None):
    """A per-set quantity of ``fault_modes``' event sets (E, B), in their order, from per-event
    arrays (N, B) with the events [sources, constellations]: ``single`` for the one-event
    sets, then for r_enum = 2 the pairs {i, j > i} as op(first_i, second_j) (or ``pair(i)``,
    the (N - 1 - i, B) block of the pairs that start with i). Built from blocks by static
    slices: gathered from padded arrays by the sets' index lists, every (E, B) quantity of the
    selection ran as a scalar loop (measured: the selection 2.4x slower)."""
    if r_enum < 2:
        return single
    n = single.shape[0]
    if pair is None:
        def pair(i):
            return op(first[i][None], second[i + 1:])
    return linalg.blocks([single] + [pair(i) for i in range(n - 1)])


#: the most candidate sets whose ordered sums are written out step by step (unrolled into the
#: program); more run as one ``lax.scan``. The same additions in the same order either way, so
#: the same bits. Measured (2 cores, one thread): Blanch 2012's 78 sets (57 modes) 34-37k PL/s
#: unrolled vs 27-28k as a scan; 40 sources under add-v4.2, order 2 (946 sets): 86 vs 151 PL/s
#: and 60 vs 23 s of compilation (docs/leo.md)
UNROLL_MAX_SETS = 128


def _ordered_fold(step, init, n):
    """``step`` applied for j = 0..n-1 to the carry (``lax.scan``'s (carry, j) -> (carry, _)
    form): unrolled up to ``UNROLL_MAX_SETS`` steps, a scan beyond."""
    if n <= UNROLL_MAX_SETS:
        carry = init
        for j in range(n):
            carry, _ = step(carry, j)
        return carry
    return jax.lax.scan(step, init, jnp.arange(n))[0]


def suffix_sums(tail, ni, n_out, other, idx_t):
    """(T, B): for each slot i, ``tail`` + the P_NM shares ``other[j]`` of the slots j the
    walk reaches after it (more sources out, or as many and not earlier in the enumeration
    ``idx_t``), added in the order j = 0..T-1. ``ni`` (T, B) and ``n_out`` (T, B): sources out
    of each slot. Beyond ``UNROLL_MAX_SETS`` slots one ``lax.scan`` step per slot: one loop body
    in the compiled program instead of T unrolled (T, B) updates (at L = 52 under add-v4.2,
    order 2, T = 1,540: minutes of compilation), the same additions in the same order."""
    idx_t = jnp.asarray(idx_t)

    def step(suffix, j):
        nj = jax.lax.dynamic_index_in_dim(n_out, j, keepdims=True)
        oj = jax.lax.dynamic_index_in_dim(other, j, keepdims=True)
        after = (nj > ni) | ((nj == ni) & (idx_t <= j)[:, None])
        return suffix + jnp.where(after, oj, 0.0), None

    return _ordered_fold(step, jnp.broadcast_to(tail, ni.shape).astype(other.dtype),
                         ni.shape[0])


def merge_equal_sets(code, sel, pr):
    """(dup, merged), both (T, B): the selected sets ``sel`` with equal exclusion codes
    ``code`` are one mode. ``dup``: an earlier selected set has the code; ``merged``: the sum
    of the priors ``pr`` of the selected sets sharing the code, added in the order j = 0..T-1
    (unrolled or one scan, as ``suffix_sums``)."""
    ar = jnp.arange(code.shape[0])

    def step(carry, j):
        dup, merged = carry
        cj = jax.lax.dynamic_index_in_dim(code, j, keepdims=True)
        sj = jax.lax.dynamic_index_in_dim(sel, j, keepdims=True)
        pj = jax.lax.dynamic_index_in_dim(pr, j, keepdims=True)
        same = (cj == code) & sj & sel
        return (dup | (same & (ar > j)[:, None]), merged + jnp.where(same, pj, 0.0)), None

    return _ordered_fold(step, (jnp.zeros(sel.shape, bool), jnp.zeros(pr.shape, pr.dtype)),
                         code.shape[0])
