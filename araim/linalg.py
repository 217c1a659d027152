"""Unrolled small dense linear algebra on batch arrays.

The systems of snapshot RAIM are tiny (4 to 8 states) and come in batches of millions. Writing
the Cholesky factorisation out entry by entry on arrays of the batch shape lets XLA fuse the
whole solve into a few elementwise loops; ``jnp.linalg`` on (B, 4, 4) stacks is several times
slower on CPU (DESIGN.md, performance notes). Loops below are Python loops over the static
matrix size, unrolled at trace time.
"""

import jax
import jax.numpy as jnp

# the stores XLA must not recompute live in the neutral speed layer; the kernels of araim
# reach them as linalg.materialize and linalg.blocks
from oaraim.batching import blocks, materialize  # noqa: F401

#: a pivot smaller than this fraction of the largest diagonal entry marks the matrix singular
#: (condition number beyond ~1e10). The design columns here are all dimensionless (unit-vector
#: components and clock indicators), so the largest diagonal entry is the natural scale; a
#: tolerance relative to each column's own diagonal would accept a column that is pure rounding
#: noise (e.g. east = -cos(el) sin(pi) ~ 1e-16 for azimuths all 0 or 180 deg).
RELATIVE_PIVOT_TOLERANCE = 1e-10


def unrolled(op):
    """A reduction ``reduce(x, axis)`` over a short static axis written out as elementwise
    ``op`` of its slices, in index order: XLA fuses and vectorises them over the trailing batch
    axis, which it does not do for a reduce over a non-minor axis (measured: the MHSS
    single-mode kernel ran 2.2x faster on CPU this way). An empty axis gives zeros."""
    def reduce(x, axis):
        if x.shape[axis] == 0:
            return jnp.zeros(x.shape[:axis] + x.shape[axis + 1:], x.dtype)
        out = jax.lax.index_in_dim(x, 0, axis, keepdims=False)
        for m in range(1, x.shape[axis]):
            out = op(out, jax.lax.index_in_dim(x, m, axis, keepdims=False))
        return out
    return reduce


sum_axis = unrolled(jnp.add)
max_axis = unrolled(jnp.maximum)
min_axis = unrolled(jnp.minimum)
any_axis = unrolled(jnp.logical_or)
prod_axis = unrolled(jnp.multiply)


def sqrt0(x):
    """jnp.sqrt(x), bit for bit (NaN stays NaN), with derivative 0 where x <= 0: sqrt's
    derivative is infinite at 0, and in reverse mode the zero cotangent of a masked or
    identically zero entry (mode 0's solution separation, a padding source's spread) times
    that infinity is a NaN that poisons the whole gradient (the "double where")."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), jax.lax.stop_gradient(jnp.sqrt(x)))


def inverse_variance_weights(sigma_m, valid):
    """w = 1 / sigma^2 for valid sources and 0 for padding (whatever its sigma holds)."""
    return jnp.where(valid, 1.0 / jnp.where(valid, sigma_m, 1.0) ** 2, 0.0)


def normal_entries(cols, w):
    """Entries N[j][k] = sum_l w_l c_j,l c_k,l of the weighted normal matrix.

    Args:
      cols: K arrays of shape (..., L), the columns of the design matrix.
      w: weights, (..., L).

    Returns:
      K x K nested list of arrays of shape (...); symmetric, each entry computed once.
    """
    k = len(cols)
    wc = [w * c for c in cols]
    n = [[None] * k for _ in range(k)]
    for i in range(k):
        for j in range(i + 1):
            n[i][j] = n[j][i] = jnp.sum(wc[i] * cols[j], axis=-1)
    return n


def cholesky(n, scale=None):
    """Unrolled Cholesky factor of a symmetric K x K matrix given as nested lists.

    Returns:
      (lower, ok): ``lower[i][j]`` for j <= i, and a boolean array, False where a pivot fell
      below ``RELATIVE_PIVOT_TOLERANCE`` times ``scale`` (default: the largest diagonal entry;
      singular or indefinite). Where not ok, the factor holds finite placeholder values:
      callers mask the results.
    """
    k = len(n)
    lower = [[None] * k for _ in range(k)]
    ok = None
    if scale is None:
        scale = n[0][0]
        for j in range(1, k):
            scale = jnp.maximum(scale, n[j][j])
    for j in range(k):
        pivot = n[j][j]
        for m in range(j):
            pivot = pivot - lower[j][m] ** 2
        good = pivot > RELATIVE_PIVOT_TOLERANCE * scale
        ok = good if ok is None else ok & good
        d = jnp.sqrt(jnp.where(good, pivot, 1.0))
        lower[j][j] = d
        for i in range(j + 1, k):
            s = n[i][j]
            for m in range(j):
                s = s - lower[i][m] * lower[j][m]
            lower[i][j] = s / d
    return lower, ok


def cholesky_solve(lower, rhs):
    """Solve (L L^T) x = rhs for K right-hand-side components given as a list of arrays.

    ``rhs[k]`` may carry extra trailing axes (e.g. one solve per source row, shape (..., L));
    the factor entries broadcast against them after adding that axis.
    """
    k = len(lower)
    y = [None] * k
    for i in range(k):
        s = rhs[i]
        for m in range(i):
            s = s - lower[i][m] * y[m]
        y[i] = s / lower[i][i]
    x = [None] * k
    for i in reversed(range(k)):
        s = y[i]
        for m in range(i + 1, k):
            s = s - lower[m][i] * x[m]
        x[i] = s / lower[i][i]
    return x


def expand_last(entries):
    """Add a trailing axis to every entry of a nested list (to broadcast over source rows)."""
    return [[None if e is None else e[..., None] for e in row] for row in entries]
