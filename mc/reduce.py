"""Streaming reductions over realizations, bit-identical for any chunking.

Integer counts (histograms, cdf counts) are exact, so their order does not matter. Floating
sums are formed per fixed block of ``BLOCK`` consecutive realizations and the block sums are
combined in block-index order at the end (DESIGN.md, Reproducibility): chunk boundaries must fall
on block boundaries, which ``mc.runner`` guarantees.

Reducers are plain NumPy objects fed on the host with ``update(start, values, mask)`` where
``start`` is the index of the first realization in ``values``.
"""

import numpy as np

BLOCK = 1024


class Histogram:
    """Counts of values in fixed bins ``edges`` (NumPy's convention: the last bin is closed).

    Values outside the edges and non-finite values are counted in ``outside``.
    """

    def __init__(self, edges):
        self.edges = np.asarray(edges, float)
        self.counts = np.zeros(len(self.edges) - 1, np.int64)
        self.outside = 0
        self.total = 0

    def update(self, start, values, mask=None):
        v = np.asarray(values, float).ravel()
        if mask is not None:
            v = v[np.asarray(mask).ravel()]
        counts, _ = np.histogram(v[np.isfinite(v)], self.edges)
        self.counts += counts
        self.outside += v.size - int(counts.sum())
        self.total += v.size

    def merge(self, other):
        self.counts += other.counts
        self.outside += other.outside
        self.total += other.total


class EmpiricalCDF:
    """Empirical cdf on a fixed grid: ``counts[k] = #{x <= grid[k]}``.

    ``inf`` (an unavailable geometry, DESIGN.md) is never <= a finite grid point, so it lowers the
    cdf everywhere, as an availability must. NaN is rejected: it is a bug upstream.
    """

    def __init__(self, grid):
        self.grid = np.asarray(grid, float)
        if np.any(np.diff(self.grid) <= 0):
            raise ValueError("EmpiricalCDF grid must be strictly increasing")
        self.counts = np.zeros(self.grid.size, np.int64)
        self.total = 0

    def update(self, start, values, mask=None):
        v = np.asarray(values, float).ravel()
        if mask is not None:
            v = v[np.asarray(mask).ravel()]
        if np.isnan(v).any():
            raise FloatingPointError("NaN reached an empirical cdf: a kernel returned NaN")
        self.counts += np.searchsorted(np.sort(v), self.grid, side="right")
        self.total += v.size

    def merge(self, other):
        self.counts += other.counts
        self.total += other.total

    def cdf(self):
        return self.counts / max(self.total, 1)

    def value_at(self, x):
        """P(X <= x) for x on the grid (exact count); raises if x is not a grid point."""
        k = np.flatnonzero(np.isclose(self.grid, x, rtol=0, atol=1e-12))
        if k.size != 1:
            raise KeyError(f"{x} is not a point of the cdf grid")
        return self.counts[k[0]] / max(self.total, 1)

    def quantile(self, p):
        """Smallest grid point whose cdf reaches p (inf if none)."""
        k = np.searchsorted(self.counts, p * self.total - 1e-9 * self.total, side="left")
        return float(self.grid[k]) if k < self.grid.size else float("inf")


class Mean:
    """Mean of the finite (and masked-in) values, from block sums combined in index order.

    Also reports ``share``: the fraction of realizations that entered the mean (DESIGN.md: means
    over realizations where every compared quantity is finite, stating that share).
    """

    def __init__(self):
        self.blocks = {}  # block index -> (sum, sum of squares, count, seen)

    def update(self, start, values, mask=None):
        v = np.asarray(values, float).ravel()
        keep = np.isfinite(v)
        if mask is not None:
            keep &= np.asarray(mask, bool).ravel()
        if start % BLOCK:
            raise ValueError(f"chunks must start on a multiple of {BLOCK}, got {start}")
        x = np.where(keep, v, 0.0)
        for b in range(0, v.size, BLOCK):
            xb, kb = x[b : b + BLOCK], keep[b : b + BLOCK]
            self.blocks[(start + b) // BLOCK] = (
                float(np.sum(xb)), float(np.sum(xb * xb)), int(np.sum(kb)), int(kb.size))

    def merge(self, other):
        self.blocks.update(other.blocks)

    def _totals(self):
        s = s2 = 0.0
        n = seen = 0
        for b in sorted(self.blocks):
            bs, bs2, bn, bseen = self.blocks[b]
            s += bs
            s2 += bs2
            n += bn
            seen += bseen
        return s, s2, n, seen

    @property
    def count(self):
        return self._totals()[2]

    @property
    def share(self):
        _, _, n, seen = self._totals()
        return n / seen if seen else float("nan")

    @property
    def mean(self):
        s, _, n, _ = self._totals()
        return s / n if n else float("nan")

    @property
    def std_error(self):
        s, s2, n, _ = self._totals()
        if n < 2:
            return float("nan")
        var = max(s2 / n - (s / n) ** 2, 0.0) * n / (n - 1)
        return (var / n) ** 0.5
