"""Chi-square snapshot RAIM slopes and slope HPL, seed 001 section 3.1.

State: [east, north, up, c dt] with one receiver clock shared by GPS and SOPs (seed 001 models
the SOP clock biases as known first-order polynomials, section 2.3). With
H = [g, 1], R = diag(sigma^2), B = (H^T R^-1 H)^-1 H^T R^-1 and S = I - H B:

    slope_i = sqrt(B_1i^2 + B_2i^2) sqrt(R_ii) / sqrt(S_ii)          (seed 001, section 3.1)
    HPL     = slope_max sqrt(lambda_det)                              (seed 001, section 3.1)

B_{:,i} = P h_i / sigma_i^2 with P = (H^T R^-1 H)^-1, so with g_i = P h_i:
slope_i^2 = w_i (g_i,E^2 + g_i,N^2) / (1 - w_i h_i . g_i), w_i = 1 / sigma_i^2.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Bool, Float, Real

from oaraim.araim import linalg
from oaraim.araim.chi2 import lambda_det_table
from oaraim.araim.status import Status
from oaraim.araim.validate import (
    check_probability,
    check_sigma,
    check_unit_rows,
    host_values,
    unit_norm,
)
from oaraim.batching import map_tiles

N_STATES = 4  # east, north, up, receiver clock

#: S_ii below this (it lies in [0, 1]) means source i has no redundancy: its fault is
#: unobservable in the residuals, the slope is unbounded and the HPL is inf.
REDUNDANCY_TOLERANCE = 1e-9


class Slopes(NamedTuple):
    """The RAIM slopes of ``slopes`` and ``slopes_kernel``."""

    slopes: jax.Array
    """(..., L) slope_i in metres of horizontal error per unit sqrt(lambda); 0 for invalid
    sources, inf where the status is not OK."""
    slope_max: jax.Array
    """(...) the largest slope; inf where the status is not OK."""
    dof: jax.Array
    """(...) int: degrees of freedom of the residuals, n_valid - 4."""
    status: jax.Array
    """(...) int8 ``araim.Status``."""


class SlopeHPL(NamedTuple):
    """The slope HPL of ``slope_hpl`` and ``slope_hpl_kernel``."""

    hpl_m: jax.Array
    """(...) HPL = slope_max sqrt(lambda_det); inf where status != OK."""
    slope_max: jax.Array
    """(...) the largest slope."""
    slopes: jax.Array
    """(..., L) every source's slope."""
    lambda_det: jax.Array
    """(...) the non-centrality used (depends on dof); inf where status != OK."""
    dof: jax.Array
    """(...) degrees of freedom, n_valid - 4."""
    status: jax.Array
    """(...) int8 ``araim.Status``."""


def _prepare(g, sigma_m, valid):
    g = jnp.asarray(g, jnp.float64)
    sigma_m = jnp.broadcast_to(jnp.asarray(sigma_m, jnp.float64), g.shape[:-1])
    if valid is None:
        valid = jnp.ones(g.shape[:-1], bool)
    valid = jnp.broadcast_to(jnp.asarray(valid, bool), g.shape[:-1])
    return g, sigma_m, valid


def masked_geometry(g, sigma_m, valid):
    """Rows with padding zeroed (padding may hold NaN or inf: 0 * NaN must never reach a sum)
    and the inverse-variance weights, 0 for padding."""
    return jnp.where(valid[..., None], g, 0.0), linalg.inverse_variance_weights(sigma_m, valid)


def _invalid_input(g, sigma_m, valid):
    """(...) bool: a valid source has a non-finite or non-unit row (``mhss.UNIT_ROW_TOLERANCE``)
    or a sigma that is not finite and > 0. Such a geometry gets ``Status.INVALID_INPUT``."""
    gx, gy, gz = g[..., 0], g[..., 1], g[..., 2]
    ok = unit_norm(gx * gx + gy * gy + gz * gz) & (sigma_m > 0) & (sigma_m < jnp.inf)
    return jnp.any(valid & ~ok, axis=-1)


def slopes_kernel(g: Float[ArrayLike, "*batch L 3"], sigma_m: Float[ArrayLike, "*batch L"],
                  valid: Bool[ArrayLike, "*batch L"]) -> Slopes:
    """The RAIM slopes of ``slopes`` as a pure JAX function of arrays of one batch shape: g
    (..., L, 3), sigma_m and valid (..., L) (standard deviations in metres, bool). Callable
    inside ``jax.jit`` and ``jax.vmap`` (one program, no tiling). A geometry with a
    non-finite or non-unit row or a sigma that is not finite and > 0 at a valid source gets
    ``Status.INVALID_INPUT`` and infinite slopes; nothing raises."""
    invalid = _invalid_input(g, sigma_m, valid)
    g, w = masked_geometry(g, sigma_m, valid)
    gx, gy, gz = g[..., 0], g[..., 1], g[..., 2]
    one = jnp.ones_like(gx)
    lower, nonsingular = linalg.cholesky(linalg.normal_entries([gx, gy, gz, one], w))
    x = linalg.cholesky_solve(linalg.expand_last(lower), [gx, gy, gz, one])
    s_ii = 1.0 - w * (gx * x[0] + gy * x[1] + gz * x[2] + x[3])
    redundant = s_ii > REDUNDANCY_TOLERANCE
    slope2 = w * (x[0] ** 2 + x[1] ** 2) / jnp.where(redundant, s_ii, 1.0)
    slopes = jnp.where(valid, jnp.where(redundant, jnp.sqrt(slope2), jnp.inf), 0.0)

    n_valid = jnp.sum(valid, axis=-1)
    dof = n_valid - N_STATES
    too_few = dof < 1
    undetectable = jnp.any(valid & ~redundant, axis=-1)
    status = jnp.where(
        invalid,
        Status.INVALID_INPUT,
        jnp.where(too_few, Status.TOO_FEW_SOURCES,
                  jnp.where(~nonsingular, Status.SINGULAR_GEOMETRY,
                            jnp.where(undetectable, Status.UNDETECTABLE_FAULT, Status.OK))),
    ).astype(jnp.int8)
    failed = status != Status.OK
    slopes = jnp.where(failed[..., None] & valid, jnp.inf, slopes)
    slope_max = jnp.where(failed, jnp.inf, jnp.max(slopes, axis=-1))
    return Slopes(slopes, slope_max, dof, status)


#: geometries per tile of the public ``slopes`` and ``slope_hpl`` (``oaraim.batching.map_tiles``).
#: Measured with M + N = 9, batch 262,144, 2 cores, one call (XLA spreads it), 3 rounds
#: of best of 3: untiled 3.0-3.1M HPL/s; tiles of 1024 / 2048 / 4096 / 8192 / 16384: 3.5M /
#: 4.0M / 4.5-4.7M / 4.7-4.9M / 5.0-5.1M (two host threads over 4096-16384 tiles: 3.8-4.2M,
#: slower). Tiles of >= 4096 gave HPLs bit-identical to the untiled call there; 1024 and 2048
#: differed by up to 4.7e-13 relative (XLA compiles small shapes differently).
SLOPE_TILE = 16384


@jax.jit
def _slopes_tiled(g, sigma_m, valid):
    return map_tiles(lambda *xs: slopes_kernel(*xs), (g, sigma_m, valid),
                     g.shape[:-2], tile=SLOPE_TILE)


def _slope_hpl_body(g: Float[ArrayLike, "*batch L 3"], sigma_m: Float[ArrayLike, "*batch L"],
                    valid: Bool[ArrayLike, "*batch L"],
                    lambda_table: Float[ArrayLike, " dof"]) -> SlopeHPL:
    """The slope HPL of ``slope_hpl`` as a jitted JAX function of arrays
    of one batch shape (one program, no tiling; inline under a caller's ``jit`` or ``vmap``):
    ``slope_hpl_kernel(g, sigma_m, valid, lambda_table) -> SlopeHPL`` with g (..., L, 3), sigma_m
    (metres) and valid (..., L), and ``lambda_table`` the non-centralities by dof
    (``araim.lambda_det_table(p_fa, p_md, max_dof)``). Bad inputs give ``Status.INVALID_INPUT``
    and an infinite HPL, as ``slopes_kernel``."""
    slopes, slope_max, dof, status = slopes_kernel(g, sigma_m, valid)
    lam = lambda_table[jnp.clip(dof, 0, lambda_table.shape[0] - 1)]
    ok = status == Status.OK
    hpl = jnp.where(ok, slope_max * jnp.sqrt(jnp.where(ok, lam, 1.0)), jnp.inf)
    return SlopeHPL(hpl, slope_max, slopes, jnp.where(ok, lam, jnp.inf), dof, status)


slope_hpl_kernel = jax.jit(_slope_hpl_body)


@jax.jit
def slope_hpl_tiled(g: Float[ArrayLike, "*batch L 3"], sigma_m: Float[ArrayLike, "*batch L"],
                    valid: Bool[ArrayLike, "*batch L"],
                    lambda_table: Float[ArrayLike, " dof"]) -> SlopeHPL:
    """``slope_hpl_kernel`` in tiles of ``SLOPE_TILE`` (batches of at most one tile at their
    own shape): what ``slope_hpl`` runs after its argument checks, and what ``oaraim bench``
    times. Arguments and result as ``slope_hpl_kernel``."""
    return map_tiles(lambda *xs: _slope_hpl_body(*xs, lambda_table), (g, sigma_m, valid),
                     g.shape[:-2], tile=SLOPE_TILE)


def slopes(g: Real[ArrayLike, "*batch L 3"],
           sigma_m: Real[ArrayLike, "*#batch #L"] | Real[ArrayLike, ""],
           valid: Bool[ArrayLike, "*#batch #L"] | None = None) -> Slopes:
    """RAIM slopes of every source, seed 001 section 3.1 (weighted, one receiver clock).

    Args:
      g: ``(..., L, 3)`` geometry rows from ``geometry.geometry_rows`` (east, north, up).
      sigma_m: pseudorange *standard deviations* in metres (seed 001's sqrt(R_ii)),
        broadcastable to ``(..., L)``.
      valid: ``(..., L)`` bool, the sources used; padding rows are False. Default: all.

    Returns:
      ``Slopes``: per-source slopes (0 for invalid sources), their maximum, dof and status. Where
      the status is not OK the maximum is ``inf``.

    Raises:
      ValueError naming the argument, the batch index and the source when a valid source has a
      line-of-sight row that is not finite or not a unit vector (norm within
      ``mhss.UNIT_ROW_TOLERANCE`` of 1), or a sigma that is not finite and > 0. Under ``jit``
      such a geometry gets ``Status.INVALID_INPUT`` (slopes and maximum inf) instead.
    """
    g, sigma_m, valid = _prepare(g, sigma_m, valid)
    return _named_invalid_input(_slopes_tiled(g, sigma_m, valid), g, sigma_m, valid)


def _named_invalid_input(result, g, sigma_m, valid):
    """``result`` when no geometry has ``Status.INVALID_INPUT``; otherwise the ValueError of the
    host checks, naming the argument, the batch index and the source. The kernel flags, the
    host names: a clean batch pays one pass over the (...) statuses, not over every row.
    Traced (the caller is under ``jit``): ``result``, the status says it."""
    host = host_values(result.status)
    if host is None or not np.any(host[0] == Status.INVALID_INPUT):
        return result
    check_sigma(sigma_m, valid)
    check_unit_rows(g, valid)
    raise AssertionError("the kernel's INVALID_INPUT and the host checks disagree")


def slope_hpl(g: Real[ArrayLike, "*batch L 3"],
              sigma_m: Real[ArrayLike, "*#batch #L"] | Real[ArrayLike, ""],
              p_fa: float, p_md: float,
              valid: Bool[ArrayLike, "*#batch #L"] | None = None) -> SlopeHPL:
    """Slope-based HPL of chi-square snapshot RAIM, seed 001 section 3.1.

    HPL = slope_max sqrt(lambda_det), where lambda_det is the non-centrality of the residual
    chi-square statistic (dof = n_valid - 4) that gives missed-detection probability P_MD at the
    threshold set by P_FA (``araim.chi2``).

    Args:
      g: ``(..., L, 3)`` geometry rows.
      sigma_m: pseudorange standard deviations in metres (not variances), broadcastable to
        ``(..., L)``.
      p_fa, p_md: false-alarm and missed-detection probabilities, Python floats in (0, 1).
      valid: ``(..., L)`` mask of the sources used.

    Returns:
      ``SlopeHPL``. ``hpl_m`` is ``inf`` with a ``Status`` where fewer than 5 sources are valid,
      the geometry is singular, or some source's fault is undetectable; never NaN.

    Raises:
      ValueError as ``slopes`` does for an unusable row or sigma of a valid source; under
      ``jit`` that geometry gets ``Status.INVALID_INPUT`` and an infinite HPL instead.
    """
    p_fa = check_probability("p_fa", p_fa)
    p_md = check_probability("p_md", p_md)
    g, sigma_m, valid = _prepare(g, sigma_m, valid)
    n_sources = g.shape[-2]
    table = lambda_det_table(p_fa, p_md, max(n_sources - N_STATES, 1))
    return _named_invalid_input(slope_hpl_tiled(g, sigma_m, valid, jnp.asarray(table)),
                                g, sigma_m, valid)
