"""Slopes after adding one transmitter at many candidate elevations (seed 001 Fig. 3).

Adding a row h with weight w to a fixed geometry is a rank-one update of the normal matrix
(Sherman-Morrison), so the sweep over elevations needs no new factorisation (DESIGN.md,
performance notes). With P0 = (H0^T W0 H0)^-1, a_i = P0 h_i, u = P0 h, q = h^T u, c = w/(1+w q):

    P h_i   = a_i - c u (h . a_i)              (base source i)
    P h     = u / (1 + w q)                    (the added source)
    h_i^T P h_i = h_i . a_i - c (h . a_i)^2

and slope_i^2 = w_i ((P h_i)_E^2 + (P h_i)_N^2) / (1 - w_i h_i^T P h_i), seed 001 section 3.1.
The added row h(el) = cos(el) [-sin az, -cos az, 0, 0] + sin(el) [0, 0, -1, 0] + [0, 0, 0, 1] is
linear in (cos el, sin el), so u(el) is a combination of three solves done once per geometry.
"""

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Array, Bool, Float

from oaraim.araim import linalg
from oaraim.araim.slopes import REDUNDANCY_TOLERANCE, masked_geometry


@jax.jit
def added_source_slope_max(g: Float[ArrayLike, "B M 3"], sigma_m: Float[ArrayLike, "B M"],
                           az_added_rad: Float[ArrayLike, " B"],
                           el_grid_rad: Float[ArrayLike, " E"],
                           sigma_added_m: Float[ArrayLike, "#B"] | Float[ArrayLike, ""],
                           valid: Bool[ArrayLike, "B M"]
                           ) -> tuple[Float[Array, "B E"], Bool[Array, " B"]]:
    """Maximum slope after adding one source at azimuth ``az_added`` and each grid elevation.

    Args:
      g: ``(B, M, 3)`` rows of the base geometry; sigma_m ``(B, M)`` standard deviations.
      az_added_rad: ``(B,)`` azimuth of the added transmitter.
      el_grid_rad: ``(E,)`` candidate elevations.
      sigma_added_m: standard deviation of the added source (scalar or ``(B,)``).
      valid: ``(B, M)`` mask of the base sources.

    Returns:
      ``(slope_max (B, E), base_ok (B,))``: slope_max is ``inf`` where a source has no
      redundancy; base_ok is False where the base geometry itself is singular (then every
      slope_max of that row is ``inf``).
    """
    g, w = masked_geometry(g, sigma_m, valid)  # w: (B, M)
    w_add = (1.0 / jnp.asarray(sigma_added_m, jnp.float64) ** 2) * jnp.ones_like(az_added_rad)
    gx, gy, gz = g[..., 0], g[..., 1], g[..., 2]
    one = jnp.ones_like(gx)
    lower, base_ok = linalg.cholesky(linalg.normal_entries([gx, gy, gz, one], w))
    a = linalg.cholesky_solve(linalg.expand_last(lower), [gx, gy, gz, one])  # 4 x (B, M)
    s0 = gx * a[0] + gy * a[1] + gz * a[2] + a[3]  # h_i^T P0 h_i

    sa, ca = jnp.sin(az_added_rad), jnp.cos(az_added_rad)
    zero = jnp.zeros_like(sa)
    p_a = linalg.cholesky_solve(lower, [-sa, -ca, zero, zero])  # P0 [-sin az, -cos az, 0, 0]
    p_b = linalg.cholesky_solve(lower, [zero, zero, -jnp.ones_like(sa), zero])
    p_c = linalg.cholesky_solve(lower, [zero, zero, zero, jnp.ones_like(sa)])

    ce, se = jnp.cos(el_grid_rad)[None, :], jnp.sin(el_grid_rad)[None, :]  # (1, E)
    u = [ce * p_a[k][:, None] + se * p_b[k][:, None] + p_c[k][:, None] for k in range(4)]
    hx, hy, hz = -ce * sa[:, None], -ce * ca[:, None], -se * jnp.ones_like(sa)[:, None]
    q = hx * u[0] + hy * u[1] + hz * u[2] + u[3]  # (B, E)
    wa = w_add[:, None]
    c = wa / (1.0 + wa * q)

    # h . a_i for every base source and elevation: (B, E, M)
    d_a = -sa[:, None] * a[0] - ca[:, None] * a[1]  # (B, M) coefficient of cos(el)
    d = ce[..., None] * d_a[:, None, :] - se[..., None] * a[2][:, None, :] + a[3][:, None, :]
    cd = c[..., None] * d
    ge = a[0][:, None, :] - u[0][..., None] * cd
    gn = a[1][:, None, :] - u[1][..., None] * cd
    wi = w[:, None, :]
    s_ii = 1.0 - wi * (s0[:, None, :] - cd * d)
    redundant = s_ii > REDUNDANCY_TOLERANCE
    base_slope2 = wi * (ge**2 + gn**2) / jnp.where(redundant, s_ii, 1.0)
    base_slope2 = jnp.where(valid[:, None, :], jnp.where(redundant, base_slope2, jnp.inf), 0.0)

    s_new = 1.0 / (1.0 + wa * q)
    new_slope2 = jnp.where(s_new > REDUNDANCY_TOLERANCE,
                           wa * (u[0] ** 2 + u[1] ** 2) * s_new, jnp.inf)
    slope2 = jnp.maximum(jnp.max(base_slope2, axis=-1), new_slope2)
    slope_max = jnp.where(base_ok[:, None], jnp.sqrt(slope2), jnp.inf)
    return slope_max, base_ok
