"""Iterated weighted nonlinear least squares (WNLS), seed 001 section 2.4.

    z_l = |r - r_l| + c dt_{k(l)} + v_l,   v_l ~ N(0, sigma_l^2)

with one clock bias per clock group k (one receiver clock for seed 001; one per constellation
when SOP clocks are estimated, seed 004). Gauss-Newton with a fixed iteration count (jit and vmap
friendly): x <- x + (H^T W H)^-1 H^T W (z - h(x)), H = [(r - r_l)^T / |r - r_l|, e_k(l)^T],
W = R^-1. A clock group with no valid source keeps its clock at the initial value (its column is
dropped by a unit diagonal), as DESIGN.md asks for absent constellations.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Bool, Float, Int, Real

from oaraim.araim.linalg import inverse_variance_weights
from oaraim.araim.status import Status
from oaraim.araim.validate import (
    batch_source,
    check_finite_sources,
    check_sigma,
    host_values,
)


class WNLSOptions(NamedTuple):
    """The static settings of ``wnls`` and ``wnls_kernel``."""

    n_clocks: int = 1
    """Number of clock groups C (one clock bias each)."""
    n_iter: int = 10
    """Fixed number of Gauss-Newton iterations."""
    tol_m: float = 1e-4
    """The last step must be below this for status OK (else NOT_CONVERGED), metres."""


def _wnls_options(options):
    """``options`` (None: the defaults) as a checked ``WNLSOptions``."""
    if options is None:
        return WNLSOptions()
    if not isinstance(options, WNLSOptions):
        raise ValueError(f"options must be an araim.WNLSOptions, got {type(options).__name__}")
    return WNLSOptions(int(options.n_clocks), int(options.n_iter), options.tol_m)


class WNLSResult(NamedTuple):
    """The solution of ``wnls`` and ``wnls_kernel``."""

    position_m: jax.Array
    """(..., 3) receiver position, the frame of the transmitter positions."""
    clock_m: jax.Array
    """(..., C) clock biases times c, metres."""
    residual_m: jax.Array
    """(..., L) z - h(x_hat); 0 for invalid sources."""
    wsse: jax.Array
    """(...) sum of weighted squared residuals: chi-square, dof = n - 3 - C."""
    dof: jax.Array
    """(...) n_valid - 3 - n_clocks_used."""
    last_step_m: jax.Array
    """(...) norm of the last Gauss-Newton step."""
    covariance_m2: jax.Array
    """(..., 3 + C, 3 + C) (H^T W H)^-1 at the solution."""
    status: jax.Array
    """(...) int8 Status."""


def _design(x, tx_pos_m, clock_onehot):
    diff = x[..., None, :3] - tx_pos_m
    rng = jnp.linalg.norm(diff, axis=-1)
    safe_rng = jnp.where(rng > 0, rng, 1.0)
    u = diff / safe_rng[..., None]
    clock = jnp.sum(clock_onehot * x[..., None, 3:], axis=-1)
    return jnp.concatenate([u, clock_onehot], axis=-1), rng + clock


def _normal(h, w, empty):
    hw = h * w[..., None]
    n = jnp.einsum("...li,...lj->...ij", hw, h)
    k = n.shape[-1]
    pad = jnp.concatenate([jnp.zeros(empty.shape[:-1] + (3,)), empty.astype(n.dtype)], axis=-1)
    return n + pad[..., None, :] * jnp.eye(k), hw


def _invalid_input(pr, tx, sigma, x0, valid, clock_index, n_clocks):
    """(...) bool: a valid source with a non-finite pseudorange or transmitter position, a
    sigma that is not finite and > 0 or a clock group outside 0..n_clocks-1, or a non-finite
    initial state. Such a geometry gets ``Status.INVALID_INPUT``."""
    ok = (jnp.isfinite(pr) & jnp.all(jnp.isfinite(tx), axis=-1) & (sigma > 0)
          & (sigma < jnp.inf) & (clock_index >= 0) & (clock_index < n_clocks))
    return jnp.any(valid & ~ok, axis=-1) | ~jnp.all(jnp.isfinite(x0), axis=-1)


def _wnls_kernel(pr, tx, sigma, x0, valid, clock_index, n_clocks, n_iter, tol_m):
    invalid = _invalid_input(pr, tx, sigma, x0, valid, clock_index, n_clocks)
    # an unusable input is replaced too, so the iteration stays finite; its outputs are inf
    valid_ok = valid & ~invalid[..., None]
    x0 = jnp.where(invalid[..., None], 0.0, x0)
    pr = jnp.where(valid_ok, pr, 0.0)
    tx = jnp.where(valid_ok[..., None], tx, 0.0)
    sigma = jnp.where(valid_ok, sigma, 1.0)
    # padding rows may hold anything (NaN, inf): replace them before any arithmetic
    pr = jnp.where(valid, pr, 0.0)
    tx = jnp.where(valid[..., None], tx, 0.0)
    w = inverse_variance_weights(sigma, valid)
    onehot = (clock_index[..., None] == jnp.arange(n_clocks)) & valid[..., None]
    empty = ~jnp.any(onehot, axis=-2)
    onehot = onehot.astype(jnp.float64)

    def body(_, carry):
        x, step_norm, singular = carry
        h, pred = _design(x, tx, onehot)
        n, hw = _normal(h, w, empty)
        rhs = jnp.einsum("...li,...l->...i", hw, pr - pred)
        chol = jnp.linalg.cholesky(n)
        ok = jnp.all(jnp.isfinite(chol), axis=(-2, -1))
        safe = jnp.where(ok[..., None, None], chol, jnp.eye(n.shape[-1]))
        dx = jax.scipy.linalg.cho_solve((safe, True), rhs[..., None])[..., 0]
        dx = jnp.where(ok[..., None], dx, 0.0)
        return x + dx, jnp.linalg.norm(dx, axis=-1), singular | ~ok

    init = (x0, jnp.full(x0.shape[:-1], jnp.inf), jnp.zeros(x0.shape[:-1], bool))
    x, step_norm, singular = jax.lax.fori_loop(0, n_iter, body, init)

    h, pred = _design(x, tx, onehot)
    n, _ = _normal(h, w, empty)
    chol = jnp.linalg.cholesky(n)
    ok = jnp.all(jnp.isfinite(chol), axis=(-2, -1)) & ~singular
    safe = jnp.where(ok[..., None, None], chol, jnp.eye(n.shape[-1]))
    cov = jax.scipy.linalg.cho_solve((safe, True), jnp.broadcast_to(jnp.eye(n.shape[-1]), n.shape))
    cov = jnp.where(ok[..., None, None], cov, jnp.inf)
    resid = jnp.where(valid, pr - pred, 0.0)
    wsse = jnp.sum(w * resid**2, axis=-1)
    n_states = 3 + jnp.sum(~empty, axis=-1)
    n_valid = jnp.sum(valid, axis=-1)
    status = jnp.where(
        invalid,
        Status.INVALID_INPUT,
        jnp.where(n_valid < n_states, Status.TOO_FEW_SOURCES,
                  jnp.where(~ok, Status.SINGULAR_GEOMETRY,
                            jnp.where(step_norm > tol_m, Status.NOT_CONVERGED, Status.OK))),
    ).astype(jnp.int8)

    def unusable(a, extra_axes):  # inf where the input is unusable: nothing is claimed
        return jnp.where(invalid.reshape(invalid.shape + (1,) * extra_axes), jnp.inf, a)

    return WNLSResult(unusable(x[..., :3], 1), unusable(x[..., 3:], 1),
                      jnp.where(invalid[..., None] & valid, jnp.inf, resid), unusable(wsse, 0),
                      n_valid - n_states, unusable(step_norm, 0), unusable(cov, 2), status)


_wnls_jit = jax.jit(_wnls_kernel, static_argnames=("n_clocks", "n_iter"))


def wnls_kernel(pseudorange_m: Float[ArrayLike, "*batch L"],
                tx_pos_m: Float[ArrayLike, "*#batch L 3"], sigma_m: Float[ArrayLike, "*batch L"],
                x0_m: Float[ArrayLike, "*batch state"], valid: Bool[ArrayLike, "*batch L"],
                clock_index: Int[ArrayLike, "*batch L"],
                options: WNLSOptions | None = None) -> WNLSResult:
    """The WNLS solution of ``wnls`` as a jitted JAX function of arrays already broadcast to
    one batch shape (no host conversion or checks): callable inside ``jax.jit`` and
    ``jax.vmap``. pseudorange_m, sigma_m, valid, clock_index ``(..., L)``; tx_pos_m
    ``(..., L, 3)``; x0_m ``(..., 3 + n_clocks)``; ``options`` (``WNLSOptions``: n_clocks,
    n_iter, tol_m) static. An unusable input of a valid source (or a non-finite x0_m) gives
    ``Status.INVALID_INPUT`` with infinite outputs, never an exception inside the trace."""
    n_clocks, n_iter, tol_m = _wnls_options(options)
    return _wnls_jit(pseudorange_m, tx_pos_m, sigma_m, x0_m, valid, clock_index,
                     n_clocks=n_clocks, n_iter=n_iter, tol_m=tol_m)


def wnls(pseudorange_m: Real[ArrayLike, "*batch L"], tx_pos_m: Real[ArrayLike, "*#batch L 3"],
         sigma_m: Real[ArrayLike, "*#batch #L"] | Real[ArrayLike, ""],
         x0_m: Real[ArrayLike, "*#batch state"] | None = None,
         valid: Bool[ArrayLike, "*#batch #L"] | None = None,
         clock_index: Int[ArrayLike, "*#batch #L"] | Int[ArrayLike, ""] | None = None,
         options: WNLSOptions | None = None) -> WNLSResult:
    """Batched iterated WNLS position and clock solution (seed 001 section 2.4).

    Args:
      pseudorange_m: ``(..., L)`` measured pseudoranges, metres.
      tx_pos_m: ``(..., L, 3)`` transmitter positions in any Cartesian frame (ECEF or local ENU);
        the solution is in the same frame.
      sigma_m: pseudorange standard deviations, broadcastable to ``(..., L)``; W = diag(1/sigma^2).
      x0_m: ``(..., 3)`` or ``(..., 3 + n_clocks)`` initial state; default the frame origin and
        zero clocks (the Earth's centre converges for GNSS in ECEF in ~6 iterations).
      valid: ``(..., L)`` mask of sources used.
      clock_index: ``(..., L)`` int clock group of each source in 0..n_clocks-1; default all 0.
      options: ``WNLSOptions`` (static; None: the defaults): the number of clock groups
        n_clocks (1), of Gauss-Newton iterations n_iter (10) and the convergence tolerance
        tol_m (1e-4 m: the last step must be below it for status OK, else NOT_CONVERGED).

    Returns:
      ``WNLSResult``. A singular step is skipped (the state stays finite) and flagged
      SINGULAR_GEOMETRY; the covariance is then inf.

    Raises:
      ValueError naming the argument, the batch index and the source when a valid source has a
      non-finite pseudorange or transmitter position, a sigma that is not finite and > 0 or a
      clock group outside 0..n_clocks-1, or when ``x0_m`` is not finite. Under ``jit`` such a
      geometry gets ``Status.INVALID_INPUT`` instead: position, clocks, residuals of valid
      sources, wsse, last step and covariance inf, never NaN.
    """
    options = _wnls_options(options)
    n_clocks = options.n_clocks
    pr = jnp.asarray(pseudorange_m, jnp.float64)
    tx = jnp.asarray(tx_pos_m, jnp.float64)
    shape = pr.shape
    sigma = jnp.broadcast_to(jnp.asarray(sigma_m, jnp.float64), shape)
    valid = jnp.ones(shape, bool) if valid is None else jnp.broadcast_to(jnp.asarray(valid), shape)
    if clock_index is None:
        clock_index = jnp.zeros(shape, jnp.int32)
    clock_index = jnp.broadcast_to(jnp.asarray(clock_index, jnp.int32), shape)
    batch = shape[:-1]
    if x0_m is None:
        x0 = jnp.zeros(batch + (3 + n_clocks,))
    else:
        x0 = jnp.asarray(x0_m, jnp.float64)
        if x0.shape[-1] == 3:
            x0 = jnp.concatenate([x0, jnp.zeros(x0.shape[:-1] + (n_clocks,))], axis=-1)
        x0 = jnp.broadcast_to(x0, batch + (3 + n_clocks,))
    res = wnls_kernel(pr, tx, sigma, x0, valid, clock_index, options)
    host = host_values(res.status)
    if host is not None and np.any(host[0] == Status.INVALID_INPUT):
        _name_invalid_input(pr, tx, sigma, x0, valid, clock_index, int(n_clocks))
    return res


def _name_invalid_input(pr, tx, sigma, x0, valid, clock_index, n_clocks):
    """The ValueError of the first unusable input the kernel flagged (``_invalid_input``),
    naming the argument, the batch index and the source. Run only when a geometry has
    ``Status.INVALID_INPUT``, so a clean batch pays nothing on the host."""
    check_finite_sources("pseudorange_m", pr, valid, "metres")
    check_finite_sources("tx_pos_m", tx, valid, "transmitter positions, metres")
    check_sigma(sigma, valid)
    lab, v = np.asarray(clock_index), np.asarray(valid)
    bad = v & ((lab < 0) | (lab >= n_clocks))
    if np.any(bad):
        raise ValueError(f"clock_index must be an integer in 0..{n_clocks - 1} (n_clocks = "
                         f"{n_clocks}), got {int(lab[bad][0])} at {batch_source(bad)}")
    x0n = np.asarray(x0)
    bad0 = ~np.all(np.isfinite(x0n), axis=-1)
    if np.any(bad0):
        where = tuple(int(i) for i in np.argwhere(bad0)[0])
        raise ValueError(f"x0_m (the initial state) is not finite at batch index {where}: "
                         f"{x0n[where].tolist()}")
    raise AssertionError("the kernel's INVALID_INPUT and the host checks disagree")
