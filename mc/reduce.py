"""Reductions over realizations: one family of reducers for sweeps and for streamed chunks.

A reducer (``Mean``, ``Max``, ``Min``, ``Histogram``, ``EmpiricalCDF``, ``Count``, ``Values``)
names a per-realization output and is used two ways, always through the same arithmetic:

- In a sweep (``mc.sweep.run_sweep``), the engine turns each chunk's outputs into a *partial*
  (``partial``), folds partials into a cell's state (``empty``, ``accumulate``) and finishes the
  state into dataset variables (``finish``).
- Streamed on the host (``mc.run_chunked``'s ``on_chunk``): ``update(start, values, mask)``
  feeds one chunk, ``merge`` joins two streams, ``result()`` gives the same variables, and each
  reducer has its own conveniences (``Mean.mean``, ``Histogram.counts``,
  ``EmpiricalCDF.quantile``, ...).

Bit-identity (DESIGN.md, Reproducibility). The unit is a block of ``BLOCK`` consecutive
realizations; a chunk is a run of whole blocks (``mc.runner`` and ``mc.sweep`` guarantee it).
A floating mean keeps one NumPy sum per zero-padded block and combines the block sums with
``math.fsum``, which is correctly rounded and so independent of chunking and of the order in
which chunks arrive; counts, extrema, histograms and cdf counts are exact.

Non-finite values. NaN in an included realization raises, naming the output (a bug upstream,
DESIGN.md). ``+-inf`` is data (an unavailable geometry): ``Mean`` averages the finite values
only and counts them; ``Max``/``Min`` see infinities; ``Histogram`` counts them in ``outside``;
``EmpiricalCDF`` never counts inf below a finite grid point, so it lowers the cdf everywhere,
as an availability must.
"""

import math
from dataclasses import dataclass, field

import numpy as np

BLOCK = 1024


class _Stream:
    """Streaming on the host for a reducer of this module: the partials of the chunks fed with
    ``update``, finished with the reducer's own ``empty``/``accumulate``/``finish``."""

    def update(self, start, values, mask=None):
        """Feed the outputs ``values`` of realizations ``start, start + 1, ...`` (``start`` a
        multiple of ``BLOCK``); ``mask`` (same length) leaves realizations out."""
        if start % BLOCK:
            raise ValueError(f"chunks must start on a multiple of {BLOCK}, got {start}")
        v = np.asarray(values).ravel()
        n = v.size
        nblocks = max(1, -(-n // BLOCK))
        padded = np.zeros(nblocks * BLOCK, v.dtype)
        padded[:n] = v
        valid = np.zeros(nblocks * BLOCK, bool)
        valid[:n] = True if mask is None else np.asarray(mask, bool).ravel()
        ctx = f"realizations {start}..{start + n - 1}"
        part = self.partial({self.name: padded}, valid, nblocks, ctx)
        self._parts[start // BLOCK] = (nblocks, part, n, int(np.count_nonzero(valid)))

    def merge(self, other):
        """Add the chunks another stream of the same reducer has seen."""
        self._parts.update(other._parts)

    def result(self):
        """The reducer's variables (``finish``) over every chunk fed so far."""
        n_blocks = max((b0 + nb for b0, (nb, _, _, _) in self._parts.items()), default=1)
        state = self.empty(n_blocks)
        for b0 in sorted(self._parts):
            self.accumulate(state, self._parts[b0][1], b0)
        return self.finish(state)

    @property
    def seen(self):
        """Values fed so far, masked or not."""
        return sum(p[2] for p in self._parts.values())

    @property
    def total(self):
        """Values fed so far that the masks let in."""
        return sum(p[3] for p in self._parts.values())


class _Summed(_Stream):
    """A reducer whose cell state is integer counts: a chunk's partial adds to every one."""

    def accumulate(self, state, part, b0):
        """Fold one chunk's partial (first block ``b0``) into a cell's state."""
        for k, v in part.items():
            state[k] += v


def _stream_state():
    return field(default_factory=dict, init=False, repr=False, compare=False, hash=False)


def _where_mask(out, where, n, ctx):
    if where is None:
        return np.ones(n, bool)
    m = _output(out, where, n, ctx)
    if m.dtype != bool:
        raise TypeError(f"kernel output {where!r} is used as a `where` mask and must be boolean, "
                        f"got dtype {m.dtype} ({ctx})")
    return m


def _output(out, name, n, ctx):
    """The first n values of kernel output ``name`` (1-D, at least n long), as NumPy."""
    if name not in out:
        raise KeyError(f"the kernel returned no output {name!r} ({ctx}); it returned: "
                       + ", ".join(sorted(out)))
    v = np.asarray(out[name])
    if v.ndim != 1 or v.shape[0] < n:
        raise ValueError(f"kernel output {name!r} must have shape (chunk,), got {v.shape} ({ctx})")
    return v[:n]


def _check_no_nan(name, v, include, ctx):
    if v.dtype.kind == "f" and np.isnan(v[include]).any():
        raise FloatingPointError(
            f"kernel output {name!r} is NaN for an included realization ({ctx}); NaN is a bug "
            "upstream: return inf with a status code for an unavailable result (DESIGN.md)")


@dataclass(frozen=True)
class Mean(_Stream):
    """Mean of output ``name`` over the included realizations with a finite value.

    Dataset variables ``{name}_mean`` (float64; NaN only when the count is 0) and ``{name}_count``
    (int64, the realizations that entered the mean). ``where`` names a boolean output: only
    realizations where it is True are included. NaN in an included realization raises.
    """

    name: str
    where: str | None = None
    _parts: dict = _stream_state()

    def inputs(self):
        """The kernel outputs this reducer reads."""
        return (self.name,) + ((self.where,) if self.where else ())

    def variables(self):
        """The dataset variables it produces: {name: extra dimensions}."""
        return {f"{self.name}_mean": (), f"{self.name}_count": ()}

    def partial(self, out, valid, nblocks, ctx):
        """Partial statistics of one chunk (``valid``: the realizations inside the run)."""
        n = valid.size
        v = _output(out, self.name, n, ctx).astype(np.float64)
        inc = valid & _where_mask(out, self.where, n, ctx)
        _check_no_nan(self.name, v, inc, ctx)
        keep = inc & np.isfinite(v)
        x = np.where(keep, v, 0.0).reshape(nblocks, BLOCK)
        # one NumPy sum per zero-padded block: the same numbers in the same layout whatever the
        # chunk, so the same bits
        return {"sum": np.array([np.sum(row) for row in x]),
                "count": keep.reshape(nblocks, BLOCK).sum(axis=1).astype(np.int64)}

    def empty(self, n_blocks):
        """A cell's state before any chunk (``n_blocks`` blocks of ``BLOCK``)."""
        return {"sum": np.zeros(n_blocks), "count": np.zeros(n_blocks, np.int64)}

    def accumulate(self, state, part, b0):
        """Fold one chunk's partial (first block ``b0``) into a cell's state."""
        nb = part["sum"].size
        state["sum"][b0:b0 + nb] = part["sum"]
        state["count"][b0:b0 + nb] = part["count"]

    def finish(self, state):
        """The dataset variables of one cell from its state."""
        n = int(state["count"].sum())
        mean = math.fsum(state["sum"].tolist()) / n if n else float("nan")
        return {f"{self.name}_mean": np.float64(mean), f"{self.name}_count": np.int64(n)}

    @property
    def count(self):
        """Streamed: the values that entered the mean (included and finite)."""
        return int(self.result()[f"{self.name}_count"])

    @property
    def mean(self):
        """Streamed: the mean of the included finite values (NaN if there is none)."""
        return float(self.result()[f"{self.name}_mean"])

    @property
    def share(self):
        """Streamed: the fraction of the values fed that entered the mean (DESIGN.md: means
        over the realizations where every compared quantity is finite, stating that share)."""
        seen = self.seen
        return self.count / seen if seen else float("nan")


@dataclass(frozen=True)
class Max(_Stream):
    """Largest value of output ``name`` over the included realizations (``{name}_max``, float64;
    -inf when nothing is included; +inf values count). NaN in an included realization raises."""

    name: str
    where: str | None = None
    _parts: dict = _stream_state()
    _sign = 1.0

    def inputs(self):
        """The kernel outputs this reducer reads."""
        return (self.name,) + ((self.where,) if self.where else ())

    def _var(self):
        return f"{self.name}_{'max' if self._sign > 0 else 'min'}"

    def variables(self):
        """The dataset variables it produces: {name: extra dimensions}."""
        return {self._var(): ()}

    def partial(self, out, valid, nblocks, ctx):
        """Partial statistics of one chunk (``valid``: the realizations inside the run)."""
        n = valid.size
        v = _output(out, self.name, n, ctx).astype(np.float64)
        inc = valid & _where_mask(out, self.where, n, ctx)
        _check_no_nan(self.name, v, inc, ctx)
        s = self._sign
        ext = s * np.max(s * v[inc]) if inc.any() else -s * np.inf
        return {"value": np.array([ext], np.float64)}

    def empty(self, n_blocks):
        """A cell's state before any chunk (``n_blocks`` blocks of ``BLOCK``)."""
        return {"value": np.array([-self._sign * np.inf])}

    def accumulate(self, state, part, b0):
        """Fold one chunk's partial (first block ``b0``) into a cell's state."""
        pick = np.maximum if self._sign > 0 else np.minimum
        state["value"] = pick(state["value"], part["value"])

    def finish(self, state):
        """The dataset variables of one cell from its state."""
        return {self._var(): np.float64(state["value"][0])}


@dataclass(frozen=True)
class Min(Max):
    """Smallest value of output ``name`` over the included realizations (``{name}_min``, float64;
    +inf when nothing is included). NaN in an included realization raises."""

    _sign = -1.0


@dataclass(frozen=True)
class Histogram(_Summed):
    """Counts of output ``name`` in the bins ``edges`` (NumPy's convention: the last bin is
    closed). ``{name}_hist`` (int64, extra dimension ``{name}_bin`` with coordinates
    ``{name}_bin_lo``/``{name}_bin_hi``) and ``{name}_outside`` (included realizations outside
    the edges or infinite). NaN in an included realization raises."""

    name: str
    edges: tuple
    where: str | None = None
    _parts: dict = _stream_state()

    def __post_init__(self):
        e = tuple(float(x) for x in np.asarray(self.edges, float).ravel())
        if len(e) < 2 or not all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
            raise ValueError(f"Histogram({self.name!r}): edges must be at least two finite, "
                             f"strictly increasing numbers, got {self.edges!r}")
        object.__setattr__(self, "edges", e)

    def inputs(self):
        """The kernel outputs this reducer reads."""
        return (self.name,) + ((self.where,) if self.where else ())

    def variables(self):
        """The dataset variables it produces: {name: extra dimensions}."""
        return {f"{self.name}_hist": (f"{self.name}_bin",), f"{self.name}_outside": ()}

    def coords(self):
        """Extra dataset coordinates: the bin edges."""
        e = np.asarray(self.edges)
        return {f"{self.name}_bin_lo": (f"{self.name}_bin", e[:-1]),
                f"{self.name}_bin_hi": (f"{self.name}_bin", e[1:])}

    def partial(self, out, valid, nblocks, ctx):
        """Partial statistics of one chunk (``valid``: the realizations inside the run)."""
        n = valid.size
        v = _output(out, self.name, n, ctx).astype(np.float64)
        inc = valid & _where_mask(out, self.where, n, ctx)
        _check_no_nan(self.name, v, inc, ctx)
        x = v[inc]
        counts, _ = np.histogram(x[np.isfinite(x)], np.asarray(self.edges))
        return {"counts": counts.astype(np.int64),
                "outside": np.array([x.size - int(counts.sum())], np.int64)}

    def empty(self, n_blocks):
        """A cell's state before any chunk (``n_blocks`` blocks of ``BLOCK``)."""
        return {"counts": np.zeros(len(self.edges) - 1, np.int64),
                "outside": np.zeros(1, np.int64)}

    def finish(self, state):
        """The dataset variables of one cell from its state."""
        return {f"{self.name}_hist": state["counts"].copy(),
                f"{self.name}_outside": np.int64(state["outside"][0])}

    @property
    def counts(self):
        """Streamed: counts per bin."""
        return self.result()[f"{self.name}_hist"]

    @property
    def outside(self):
        """Streamed: included values outside the edges or infinite."""
        return int(self.result()[f"{self.name}_outside"])


@dataclass(frozen=True)
class EmpiricalCDF(_Summed):
    """Empirical cdf of output ``name`` on a fixed ``grid``: ``{name}_cdf_count[k]`` = the
    included realizations with a value <= ``grid[k]`` (int64, extra dimension ``{name}_grid``)
    and ``{name}_cdf_total`` (the included realizations). Exact counts. ``inf`` (an unavailable
    geometry) is never <= a finite grid point, so it lowers the cdf everywhere, as an
    availability must; NaN in an included realization raises (a bug upstream)."""

    name: str
    grid: tuple
    where: str | None = None
    _parts: dict = _stream_state()

    def __post_init__(self):
        g = tuple(float(x) for x in np.asarray(self.grid, float).ravel())
        if not g or np.any(np.diff(g) <= 0):
            raise ValueError("EmpiricalCDF grid must be strictly increasing")
        object.__setattr__(self, "grid", g)

    def inputs(self):
        """The kernel outputs this reducer reads."""
        return (self.name,) + ((self.where,) if self.where else ())

    def variables(self):
        """The dataset variables it produces: {name: extra dimensions}."""
        return {f"{self.name}_cdf_count": (f"{self.name}_grid",), f"{self.name}_cdf_total": ()}

    def coords(self):
        """Extra dataset coordinates: the grid."""
        return {f"{self.name}_grid": (f"{self.name}_grid", np.asarray(self.grid))}

    def partial(self, out, valid, nblocks, ctx):
        """Partial statistics of one chunk (``valid``: the realizations inside the run)."""
        n = valid.size
        v = _output(out, self.name, n, ctx).astype(np.float64)
        inc = valid & _where_mask(out, self.where, n, ctx)
        _check_no_nan(self.name, v, inc, ctx)
        x = np.sort(v[inc])
        return {"counts": np.searchsorted(x, np.asarray(self.grid), side="right").astype(np.int64),
                "total": np.array([x.size], np.int64)}

    def empty(self, n_blocks):
        """A cell's state before any chunk (``n_blocks`` blocks of ``BLOCK``)."""
        return {"counts": np.zeros(len(self.grid), np.int64), "total": np.zeros(1, np.int64)}

    def finish(self, state):
        """The dataset variables of one cell from its state."""
        return {f"{self.name}_cdf_count": state["counts"].copy(),
                f"{self.name}_cdf_total": np.int64(state["total"][0])}

    @property
    def counts(self):
        """Streamed: ``counts[k]`` = values <= ``grid[k]``."""
        return self.result()[f"{self.name}_cdf_count"]

    def cdf(self):
        """Streamed: the cdf on the grid."""
        return self.counts / max(self.total, 1)

    def value_at(self, x):
        """Streamed: P(X <= x) for x on the grid (exact count); raises if x is not a grid point."""
        k = np.flatnonzero(np.isclose(np.asarray(self.grid), x, rtol=0, atol=1e-12))
        if k.size != 1:
            raise KeyError(f"{x} is not a point of the cdf grid")
        return self.counts[k[0]] / max(self.total, 1)

    def quantile(self, p):
        """Streamed: the smallest grid point whose cdf reaches p (inf if none)."""
        total = self.total
        k = np.searchsorted(self.counts, p * total - 1e-9 * total, side="left")
        return float(self.grid[k]) if k < len(self.grid) else float("inf")


@dataclass(frozen=True)
class Count(_Summed):
    """Number of realizations where the boolean output ``name`` is True (``{name}_count``,
    int64); with ``where``, only among the realizations where that output is True."""

    name: str
    where: str | None = None
    _parts: dict = _stream_state()

    def inputs(self):
        """The kernel outputs this reducer reads."""
        return (self.name,) + ((self.where,) if self.where else ())

    def variables(self):
        """The dataset variables it produces: {name: extra dimensions}."""
        return {f"{self.name}_count": ()}

    def partial(self, out, valid, nblocks, ctx):
        """Partial statistics of one chunk (``valid``: the realizations inside the run)."""
        n = valid.size
        v = _output(out, self.name, n, ctx)
        if v.dtype != bool:
            raise TypeError(f"Count({self.name!r}) needs a boolean kernel output, got dtype "
                            f"{v.dtype} ({ctx})")
        inc = valid & _where_mask(out, self.where, n, ctx)
        return {"count": np.array([np.count_nonzero(v & inc)], np.int64)}

    def empty(self, n_blocks):
        """A cell's state before any chunk (``n_blocks`` blocks of ``BLOCK``)."""
        return {"count": np.zeros(1, np.int64)}

    def finish(self, state):
        """The dataset variables of one cell from its state."""
        return {f"{self.name}_count": np.int64(state["count"][0])}


@dataclass(frozen=True)
class Values(_Stream):
    """Every realization's value of output ``name``, kept (not reduced): ``{name}`` with the
    extra dimension ``dim`` of length ``n`` (the sweep's realizations). For deterministic grids
    whose realizations are not samples but elements (e.g. longitude x epoch of an availability
    map, ``index_kernel``). Stored with ``dtype``; realizations past ``n`` are not kept. NaN in
    a float output raises (a bug upstream, DESIGN.md); infinities are data."""

    name: str
    n: int
    dtype: str = "float64"
    dim: str = "realization"
    _parts: dict = _stream_state()

    def inputs(self):
        """The kernel outputs this reducer reads."""
        return (self.name,)

    def variables(self):
        """The dataset variables it produces: {name: extra dimensions}."""
        return {self.name: (self.dim,)}

    def partial(self, out, valid, nblocks, ctx):
        """Partial statistics of one chunk (``valid``: the realizations inside the run)."""
        v = _output(out, self.name, valid.size, ctx)
        if np.issubdtype(v.dtype, np.floating):
            _check_no_nan(self.name, v, valid, ctx)
        return {"values": np.where(valid, v, np.zeros((), v.dtype)).astype(self.dtype)}

    def empty(self, n_blocks):
        """A cell's state before any chunk (``n_blocks`` blocks of ``BLOCK``)."""
        return {"values": np.zeros(n_blocks * BLOCK, self.dtype)}

    def accumulate(self, state, part, b0):
        """Fold one chunk's partial (first block ``b0``) into a cell's state."""
        v = part["values"]
        state["values"][b0 * BLOCK:b0 * BLOCK + v.size] = v

    def finish(self, state):
        """The dataset variables of one cell from its state: a view of it (the state is not
        used after; ``mc.sweep`` copies the cells into one array and frees the states)."""
        return {self.name: state["values"][:self.n]}


#: the reducer types ``mc.sweep.run_sweep`` accepts
REDUCERS = (Mean, Max, Min, Histogram, EmpiricalCDF, Count, Values)
