"""Exact derivatives of the PL roots by the implicit function theorem (docs/gradients.md).

A PL solves F(PL, theta) = R(PL) - rhs = 0 with the risk sum of seed 004 eqs. (14)/(16)

    R(x) = sum_j c_j Q(t_j),   t_j = (x - m_j) / s_j,

c_j the priors (2 for the fault-free term), m_j = T_j + b_j the thresholds plus biases and
s_j the sigmas of the modes, rhs the right-hand side (which carries P_NM). F is smooth and
strictly decreasing in x (D = -dR/dx = sum_j c_j phi(t_j) / s_j > 0), so the root is a smooth
function of theta and

    dPL = -(dF/dtheta) dtheta / (dF/dPL)
        = (sum_j [Q(t_j) dc_j + c_j phi(t_j) / s_j dm_j + c_j phi(t_j) t_j / s_j ds_j] - drhs) / D.

``implicit_root`` puts that rule on a root solver as a ``jax.custom_jvp``: the solver's loops
(``lax.while_loop``, ``lax.cond``) are never differentiated, so ``jax.jvp``, ``jax.grad``
(JAX transposes the linear rule) and higher derivatives (the rule calls ``implicit_root`` for
its own primal, so its coefficients are differentiable too) all work, and the forward value is
the solver's, bit for bit. The returned PL lies up to ``FAST_PROOF_TOL_M`` (1e-4 m;
typically ~1e-6 m, ``PL_MARGIN_M``) above the root; the rule takes one Newton step from it to
the root (error ~(PL - root)^2 D'/D) and evaluates the partial derivatives there, so that the
derivative is that of the root (and of the returned PL, which is the root plus a margin that
does not depend on the inputs wherever the solver's fast path settles it): without the step,
its relative error is ~(PL - root) t_j / s_j, 1e-6 for sigmas of a metre.

Where an element is not solved (ignored by the caller, not converged, a non-finite PL) its
tangent is 0, and every coefficient of the rule is finite there, so a cotangent of 0 never
meets an infinity in reverse mode (no NaN reaches a batch).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfc

__all__ = ["implicit_root", "risk_partials"]

_SQRT1_2 = 0.7071067811865476
_INV_SQRT_2PI = 0.3989422804014327  # 1 / sqrt(2 pi)


def risk_partials(x, coef, mean, sd):
    """The partial derivatives of R(x) = sum_j coef_j Q((x - mean_j) / sd_j) (terms on axis 0,
    x of shape mean.shape[1:]): (dR/dcoef_j, dR/dmean_j, dR/dsd_j) of the shape of ``mean``
    and D = -dR/dx >= 0. Q from erfc (accurate in the far tail). x, mean and sd must be finite
    with sd > 0 (the caller masks the elements where they are not)."""
    coef = jnp.broadcast_to(coef, mean.shape)
    t = (x[None] - mean) / sd
    q = 0.5 * erfc(t * _SQRT1_2)
    phi = jnp.exp(-0.5 * t * t) * _INV_SQRT_2PI
    d_mean = coef * phi / sd
    return q, d_mean, d_mean * t, jnp.sum(d_mean, axis=0)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def implicit_root(solve, coef, mean, sd, rhs, start, ignore):
    """``solve(coef, mean, sd, rhs, start, ignore)`` -> (pl, converged), the root of
    sum_j coef_j Q((pl - mean_j) / sd_j) = rhs (terms on axis 0; ``root.solve_pl``'s
    contract), differentiated by the implicit function theorem (module docstring) instead of
    through the solver's iterations. ``start`` and ``ignore`` are passed to the solver and
    carry no derivative; elements that are ignored, not converged or not finite get a zero
    tangent. ``converged`` is boolean (no tangent)."""
    return solve(coef, mean, sd, rhs, start, ignore)


@implicit_root.defjvp
def _implicit_root_jvp(solve, primals, tangents):
    coef, mean, sd, rhs, start, ignore = primals
    d_coef, d_mean, d_sd, d_rhs = tangents[:4]
    pl, converged = implicit_root(solve, *primals)
    good = converged & jnp.isfinite(pl)
    if ignore is not None:
        good = good & ~ignore
    good = good & jnp.all(jnp.isfinite(mean) & (sd > 0), axis=0)
    # finite stand-ins where an element is not solved: the rule's coefficients stay finite
    x = jnp.where(good, pl, 0.0)
    mean_s = jnp.where(good[None], mean, 0.0)
    sd_s = jnp.where(good[None], sd, 1.0)
    # one Newton step from the returned PL (up to FAST_PROOF_TOL_M above the root) to the
    # root itself (to ~(PL - root)^2), where the partial derivatives are taken
    q, _, _, slope = risk_partials(x, coef, mean_s, sd_s)
    excess = jnp.sum(jnp.broadcast_to(coef, mean.shape) * q, axis=0) - rhs
    step_ok = good & (slope > 0)
    x = jnp.where(step_ok, x + excess / jnp.where(step_ok, slope, 1.0), x)
    q, p_mean, p_sd, slope = risk_partials(x, coef, mean_s, sd_s)
    d_coef = jnp.broadcast_to(d_coef, mean.shape)
    num = jnp.sum(q * d_coef + p_mean * d_mean + p_sd * d_sd, axis=0) - d_rhs
    good = good & (slope > 0)
    pl_dot = jnp.where(good, num / jnp.where(good, slope, 1.0), 0.0)
    return (pl, converged), (pl_dot, np.zeros(converged.shape, jax.dtypes.float0))
