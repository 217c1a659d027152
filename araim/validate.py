"""Checks of user-supplied parameters, run before any computation.

Each check raises ``ValueError`` whose message names the field, the value and the valid range,
so the CLI can print it as one line and exit with status 2.
"""

import math

import numpy as np


def check_probability(name: str, value: object) -> float:
    """A probability strictly inside (0, 1)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a probability in (0, 1), got {value!r}") from None
    if not (0.0 < v < 1.0):
        raise ValueError(f"{name} must be a probability in (0, 1), got {value!r}")
    return v


def check_positive(name: str, value: object, allow_zero: bool = False) -> float:
    """A finite positive number (or non-negative with ``allow_zero``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    ok = math.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value!r}")
    return v


def check_int(name: str, value: object, minimum: int, maximum: int | None = None) -> int:
    """An integer in [minimum, maximum]."""
    try:
        v = int(value)
        if v != float(value):
            raise ValueError
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an integer, got {value!r}") from None
    if v < minimum or (maximum is not None and v > maximum):
        rng = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        raise ValueError(f"{name} must be an integer {rng}, got {value!r}")
    return v


def check_range(name: str, value: object, lo: float, hi: float) -> float:
    """A number in the closed interval [lo, hi]."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [{lo}, {hi}], got {value!r}") from None
    if not (lo <= v <= hi):
        raise ValueError(f"{name} must be a number in [{lo}, {hi}], got {value!r}")
    return v


def check_sigma(sigma_m, valid):
    """Reject non-positive or non-finite standard deviations of *valid* sources (padding rows
    may hold anything). Silently skipped for traced values inside jit."""
    try:
        s, v = np.asarray(sigma_m), np.asarray(valid)
    except Exception:  # a tracer: the caller validates outside jit
        return
    bad_mask = v & ~(np.isfinite(s) & (s > 0))
    if np.any(bad_mask):
        bad = s[bad_mask].ravel()[0]
        where = f" at {batch_source(bad_mask)}" if bad_mask.ndim else ""
        raise ValueError(
            f"sigma_m must be finite and > 0 (standard deviations, metres), got {bad!r}{where}")


def check_finite_sources(name: str, x, valid, what: str):
    """ValueError naming ``name``, the batch index and the source where an entry of a valid
    source is not finite: ``x`` is ``(..., L)`` or ``(..., L, k)`` (a row per source), ``valid``
    ``(..., L)``; ``what`` says what the values are (units). Padding may hold anything."""
    a, v = np.asarray(x), np.asarray(valid, bool)
    ok = np.isfinite(a) if a.ndim == v.ndim else np.all(np.isfinite(a), axis=-1)
    bad = v & ~ok
    if np.any(bad):
        value = a[bad][0]
        raise ValueError(f"{name} of a valid source is not finite at {batch_source(bad)}: "
                         f"{np.asarray(value).tolist()!r} ({what}; or mark the source invalid)")


#: a line-of-sight row of a valid source must have a Euclidean norm within this of 1 (rows
#: printed to 4 decimals, as the ADD's Appendix D, are within 1e-4; a (0, 0, 0) row or an
#: unnormalised vector is refused)
UNIT_ROW_TOLERANCE = 1e-3


def unit_norm(n2):
    """Squared row norms n2 (NumPy or JAX) finite with the norm within ``UNIT_ROW_TOLERANCE``
    of 1: (1 - tol)^2 <= n2 <= (1 + tol)^2 (no sqrt; NaN and inf fail). The one row test of
    the receiver functions, on the host (``check_unit_rows``) and inside their kernels."""
    return (n2 >= (1.0 - UNIT_ROW_TOLERANCE) ** 2) & (n2 <= (1.0 + UNIT_ROW_TOLERANCE) ** 2)


def check_unit_rows(g, valid):
    """ValueError naming ``g``, the batch index and the source where the line-of-sight row of a
    valid source is not finite or its norm is not within ``UNIT_ROW_TOLERANCE`` of 1: the
    check and the message of every receiver function that takes rows (``protection_levels``,
    ``solution_separation``, ``slopes``, ``slope_hpl``). NumPy on the host; rows of padding
    sources may hold anything."""
    gn = np.asarray(g)
    with np.errstate(invalid="ignore", over="ignore"):  # NumPy: no compilation per shape
        ok = unit_norm(np.einsum("...i,...i->...", gn, gn))
    if ok.all():
        return
    bad = np.asarray(valid, bool) & ~ok
    if np.any(bad):
        raise ValueError(
            f"g (line-of-sight rows) of a valid source is not a unit vector at "
            f"{batch_source(bad)}: {gn[bad][0].tolist()} (rows must be finite with norm within "
            f"{UNIT_ROW_TOLERANCE} of 1: geometry.geometry_rows, or mark the source invalid)")


def host_values(*arrays):
    """The arrays as NumPy, or None when one is a tracer (the call is being traced under
    ``jit``/``vmap``: the kernel reports bad inputs as ``Status.INVALID_INPUT`` instead)."""
    import jax

    try:
        return [np.asarray(a) for a in arrays]
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None


def batch_source(bad) -> str:
    """'batch index (i, j), source l' of the first True of a boolean (..., L) array: where a
    host check found an unusable input (the error messages of the receiver functions)."""
    idx = tuple(int(i) for i in np.argwhere(np.asarray(bad))[0])
    return f"batch index {idx[:-1]}, source {idx[-1]}"
