"""The inputs of the MHSS protection levels: the ``Sources`` pytree, the host's broadcasting
and argument checks (clear errors) and the kernel's own checks (``Status.INVALID_INPUT``)."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.araim import linalg
from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.validate import UNIT_ROW_TOLERANCE, batch_source, check_unit_rows, unit_norm

__all__ = ["INPUT_RANGES", "UNIT_ROW_TOLERANCE", "Sources", "broadcast_batch", "check_inputs",
           "check_options", "host_inputs", "in_range", "invalid_input_flags", "prepare_inputs"]


class Sources(NamedTuple):
    """The ranging sources of one or many epochs: the per-source inputs of the MHSS kernels
    (``araim.mhss.protection_levels_kernel``, ``araim.fde.separation_kernel``,
    ``araim.fde.detect_and_exclude_kernel``), a pytree that ``jax.jit`` and ``jax.vmap`` take
    as one argument. Every field broadcasts to the batch shape of ``g``; padding sources
    (``valid`` False) may hold anything and never change a result."""

    g: jax.Array
    """(..., L, 3) line-of-sight rows, ``geometry.geometry_rows`` (east, north, up)."""
    constellation: jax.Array
    """(..., L) integer clock-group index 0..C-1 of each source (GPS 0, Galileo 1, SOP
    constellations after them); C is the length of ``p_const``."""
    var_int_m2: jax.Array
    """(..., L) C_int diagonal: the variance for integrity (m^2, ``araim.error_models``)."""
    var_acc_m2: jax.Array
    """(..., L) C_acc diagonal: the variance for accuracy and continuity (m^2)."""
    b_nom_m: jax.Array
    """(..., L) nominal bias bound b_nom (m, >= 0)."""
    p_sat: jax.Array
    """(..., L) prior probability P_s of a fault of each source, in [0, 1)."""
    valid: jax.Array | None = None
    """(..., L) bool: the sources used (in view, healthy, not padding); None: every source
    (``filled`` makes the array)."""

    def filled(self) -> "Sources":
        """These sources with ``valid`` an array (all True where it was None)."""
        if self.valid is not None:
            return self
        return self._replace(valid=jnp.ones(jnp.shape(self.g)[:-1], bool))

    def broadcast(self) -> "Sources":
        """Every field broadcast to the batch shape of ``g`` ((..., L, 3) and (..., L)), as
        JAX arrays of the kernels' dtypes (float64, int32 labels, bool ``valid``)."""
        s = self.filled()
        g = jnp.asarray(s.g, jnp.float64)
        shape = g.shape[:-1]
        return Sources(g, jnp.broadcast_to(jnp.asarray(s.constellation, jnp.int32), shape),
                       *(jnp.broadcast_to(jnp.asarray(x, jnp.float64), shape) for x in (
                           s.var_int_m2, s.var_acc_m2, s.b_nom_m, s.p_sat)),
                       jnp.broadcast_to(jnp.asarray(s.valid, bool), shape))

    def concat(self, *others: "Sources") -> "Sources":
        """These sources followed by ``others`` along the source axis (e.g. GPS, then the SOP
        towers), each broadcast to its own rows' batch shape first; the batch shapes must
        broadcast together. Labels are kept as given (number SOP constellations after the
        GNSS ones before joining)."""
        parts = [s.broadcast() for s in (self, *others)]
        batch = jnp.broadcast_shapes(*(p.g.shape[:-2] for p in parts))
        out = []
        for field in range(len(Sources._fields)):
            xs = [p[field] for p in parts]
            xs = [jnp.broadcast_to(x, batch + x.shape[-2:] if field == 0 else batch
                                   + x.shape[-1:]) for x in xs]
            out.append(jnp.concatenate(xs, axis=-2 if field == 0 else -1))
        return Sources(*out)

    def pad(self, n_sources: int) -> "Sources":
        """These sources padded to ``n_sources`` along the source axis with invalid sources
        (a unit row, unit variances, zero bias and prior, label 0, ``valid`` False): a fixed L,
        so that batches of different sizes share a compiled kernel; padding never changes a
        result. ValueError if there are more sources than ``n_sources``."""
        s = self.broadcast()
        L = s.g.shape[-2]
        if L > n_sources:
            raise ValueError(f"cannot pad {L} sources to n_sources={n_sources}: pass at least "
                             f"{L}")
        extra = n_sources - L
        batch = s.g.shape[:-2]

        def tail(x, fill):
            pad = jnp.full(batch + (extra,) + x.shape[len(batch) + 1:], fill, x.dtype)
            return jnp.concatenate([x, pad], axis=len(batch))

        return Sources(tail(s.g, 0.0).at[..., L:, 2].set(-1.0),
                       tail(s.constellation, 0), tail(s.var_int_m2, 1.0),
                       tail(s.var_acc_m2, 1.0), tail(s.b_nom_m, 0.0), tail(s.p_sat, 0.0),
                       tail(s.valid, False))

    def select(self, constellations) -> "Sources":
        """These sources with only those of the given constellation labels (ints) valid: the
        others are marked invalid (a constellation with no valid source loses its clock
        column and its P_const event), the source axis unchanged."""
        s = self.broadcast()
        keep = jnp.zeros(s.valid.shape, bool)
        for c in constellations:
            keep = keep | (s.constellation == int(c))
        return s._replace(valid=s.valid & keep)


def _unit_rows(g, axis):
    """``unit_norm`` of the rows of g (3 entries along ``axis``), the squares written out."""
    parts = [jax.lax.index_in_dim(g, a, axis % g.ndim, keepdims=False) for a in range(3)]
    return unit_norm(parts[0] * parts[0] + parts[1] * parts[1] + parts[2] * parts[2])


def invalid_input_flags(g, constellation, var_int, var_acc, b_nom, p_sat, valid, C):
    """(B,) bool, True where a valid source of the geometry fails a check of
    ``check_inputs`` (a range of ``INPUT_RANGES``, the constellation label, the
    line-of-sight row): such a geometry gets status INVALID_INPUT, and a host wrapper that
    sees one runs ``check_inputs`` to name it. Batch-last (L, 3, B) and (L, B) inputs
    (``project``'s), C constellation slots; one fused elementwise pass and one OR over the
    sources written out (``linalg.max_axis`` on booleans). Stored (``linalg.materialize``), as
    is the status made from it (docs/benchmarks.md, "Input checks")."""
    ok = (constellation >= 0) & (constellation < C) & _unit_rows(g, 1)
    for x, (lo, lo_ok, hi) in zip((var_int, var_acc, b_nom, p_sat), INPUT_RANGES.values(),
                                  strict=True):
        ok = ok & in_range(x, lo, lo_ok, hi)
    return linalg.max_axis(valid & ~ok, 0)


def prepare_inputs(sources: Sources, p_const, *, check_sources=True
                   ) -> tuple[Sources, jax.Array]:
    """The sources broadcast to the batch shape of ``sources.g`` (JAX arrays, ``valid``
    filled) and p_const to (..., C), checked on the host (``check_sources=False``: p_const
    only; the caller checks the per-source arrays, as ``protection_levels`` does with the
    kernel's ``invalid_input_flags``): (Sources, p_const).

    Raises ValueError naming the argument when a valid source has a non-positive or non-finite
    variance, a negative bias, a probability outside [0, 1), or a constellation label outside
    0..C-1 with C = p_const.shape[-1].
    """
    sources = Sources(*sources)
    g = jnp.asarray(sources.g, jnp.float64)
    if g.ndim < 2 or g.shape[-1] != 3:
        raise ValueError(f"g must have shape (..., L, 3) (geometry rows), got {g.shape}")
    p_const = jnp.asarray(p_const, jnp.float64)
    if p_const.ndim == 0:
        raise ValueError("p_const must have a last axis of one entry per constellation (..., C)")
    C = p_const.shape[-1]
    p_const = jnp.broadcast_to(p_const, _const_shape(p_const, g.shape[:-2]))
    s = sources._replace(g=g).broadcast()
    arrays = {name: getattr(s, name) for name in INPUT_RANGES}
    try:
        check_inputs(arrays, p_const, s.constellation, s.valid, C, check_sources, s.g)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        pass  # traced: the caller validates outside jit
    return s, p_const


#: what a valid source's value must satisfy: (lowest, whether the lowest is allowed, upper
#: bound, exclusive)
INPUT_RANGES = {"var_int_m2": (0.0, False, np.inf), "var_acc_m2": (0.0, False, np.inf),
                 "b_nom_m": (0.0, True, np.inf), "p_sat": (0.0, True, 1.0)}


def broadcast_batch(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid):
    """The eight kernel inputs broadcast to g's batch shape (``(..., L, 3)``, ``(..., L)``,
    ``(..., C)``), as the list ``oaraim.batching.map_tiles`` takes, and that batch shape."""
    batch = g.shape[:-2]
    L, C = g.shape[-2], p_const.shape[-1]
    arrays = [jnp.broadcast_to(x, batch + s) for x, s in (
        (g, (L, 3)), (constellation, (L,)), (var_int, (L,)), (var_acc, (L,)), (b_nom, (L,)),
        (p_sat, (L,)), (p_const, (C,)), (valid, (L,)))]
    return arrays, batch


def check_options(budget, all_in_view_weighting):
    """The static options every MHSS entry point takes, checked before any tracing: the budget
    is an ``IntegrityBudget`` and the all-in-view weighting "int" or "acc" (ValueError)."""
    if not isinstance(budget, IntegrityBudget):
        raise ValueError("budget must be an araim.IntegrityBudget, e.g. "
                         "araim.BUDGET_SEED004_TABLE_I")
    if all_in_view_weighting not in ("int", "acc"):
        raise ValueError("all_in_view_weighting must be 'int' or 'acc', "
                         f"got {all_in_view_weighting!r}")


def in_range(x, lo, lo_ok, hi):
    """x lies in the range (NaN never does)."""
    return ((x >= lo) if lo_ok else (x > lo)) & (x < hi)


def check_inputs(arrays, p_const, constellation, valid, C, check_sources=True, g=None):
    """ValueError naming the first argument out of range at a valid source, with its batch
    index and source. Fast path: the minimum and maximum over every source, valid or not (two
    passes without temporaries); the masked elementwise test only when that fails, to find a
    valid offender and its value. ``g`` (..., L, 3): rows of valid sources finite, norm
    within UNIT_ROW_TOLERANCE of 1."""
    pc = np.asarray(p_const)
    if not np.all((pc >= 0) & (pc < 1)):
        raise ValueError("p_const must lie in [0, 1), got "
                         f"{float(pc[~((pc >= 0) & (pc < 1))][0])!r}")
    if not check_sources:
        return
    v = None
    for name, (lo, lo_ok, hi) in INPUT_RANGES.items():
        x = np.asarray(arrays[name])
        if x.size == 0 or (in_range(x.min(), lo, lo_ok, hi) and in_range(x.max(), lo, lo_ok,
                                                                            hi)):
            continue
        v = np.asarray(valid) if v is None else v
        bad = v & ~in_range(x, lo, lo_ok, hi)
        if bad.any():
            value = float(x[bad].ravel()[0])
            raise ValueError(f"{name} of a valid source is invalid at {batch_source(bad)}: "
                             f"{value!r} (variances must be finite and > 0 (m^2), biases >= 0 "
                             "(m), probabilities in [0, 1))")
    lab = np.asarray(constellation)
    if lab.size and (lab.min() < 0 or lab.max() >= C):
        v = np.asarray(valid) if v is None else v
        bad = v & ((lab < 0) | (lab >= C))
        if np.any(bad):
            raise ValueError(f"constellation labels must be integers in 0..{C - 1} "
                             f"(p_const has {C} entries), got {int(lab[bad].ravel()[0])} at "
                             f"{batch_source(bad)}")
    if g is not None:
        check_unit_rows(g, valid)


def _const_shape(p_const, batch):
    """The shape p_const (..., C) takes for sources of batch shape ``batch``, or a ValueError
    naming both shapes."""
    try:
        np.broadcast_shapes(p_const.shape[:-1], batch)
    except ValueError:
        raise ValueError(f"p_const of shape {p_const.shape} does not broadcast to the sources' "
                         f"batch shape {batch}: give it (..., C) with the sources' batch axes "
                         "(or none)") from None
    if len(p_const.shape) - 1 > len(batch) or np.broadcast_shapes(p_const.shape[:-1],
                                                                   batch) != batch:
        raise ValueError(f"p_const of shape {p_const.shape} has batch axes beyond the sources' "
                         f"{batch}: give it (..., C) with the sources' batch axes (or none)")
    return batch + p_const.shape[-1:]


def host_inputs(g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat, p_const, valid):
    """The receiver's arguments as flat NumPy arrays, broadcast to the batch shape of ``g``:
    ([g (n, L, 3), constellation (n, L) int32, var_int, var_acc, b_nom, p_sat (n, L),
    p_const (n, C), valid (n, L) bool], batch shape). Checks the shapes and P_const (the
    per-source checks run inside the kernel, ``invalid_input_flags``). NumPy, not jnp: each jnp
    conversion or broadcast is a dispatch (~30-60 us), which a single-geometry call cannot
    afford; the kernel's call moves the arrays to the device at once."""
    g = np.asarray(g, np.float64)
    if g.ndim < 2 or g.shape[-1] != 3:
        raise ValueError(f"g must have shape (..., L, 3) (geometry rows), got {g.shape}")
    shape = g.shape[:-1]
    batch = shape[:-1]
    p_const = np.asarray(p_const, np.float64)
    if p_const.ndim == 0:
        raise ValueError("p_const must have a last axis of one entry per constellation (..., C)")
    C = p_const.shape[-1]
    p_const = np.broadcast_to(p_const, _const_shape(p_const, batch))
    check_inputs({}, p_const, None, None, C, check_sources=False)
    valid = np.ones(shape, bool) if valid is None else np.broadcast_to(
        np.asarray(valid, bool), shape)
    arrays = [g, np.broadcast_to(np.asarray(constellation, np.int32), shape)]
    arrays += [np.broadcast_to(np.asarray(x, np.float64), shape)
               for x in (var_int_m2, var_acc_m2, b_nom_m, p_sat)]
    arrays += [p_const, valid]
    n = int(np.prod(batch, dtype=np.int64))
    return [np.ascontiguousarray(x.reshape((n,) + x.shape[len(batch):])) for x in arrays], batch
