"""Random geometries of seed 001 section 3.3: a uniform random sky and BPP cellular towers."""

from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Array, Float, PRNGKeyArray, Real


def random_sky(key: PRNGKeyArray, n_sats: int, mask_rad: Real[ArrayLike, ""],
               batch_shape: Sequence[int] = ()
               ) -> tuple[Float[Array, "*batch N"], Float[Array, "*batch N"]]:
    """Random satellite sky of seed 001 section 3.3.

    az ~ U(0, 2 pi), el ~ U(mask, pi/2), independently per satellite. The paper notes this is not
    the distribution of a real constellation and is used for its simplicity.

    Args:
      key: a ``jax.random`` key.
      n_sats: number of satellites per sky (static).
      mask_rad: elevation mask in radians, in [0, pi/2).
      batch_shape: leading batch shape (static).

    Returns:
      ``(az_rad, el_rad)``, each of shape ``(*batch_shape, n_sats)``.
    """
    k_az, k_el = jax.random.split(key)
    shape = (*tuple(batch_shape), int(n_sats))
    az_rad = jax.random.uniform(k_az, shape, jnp.float64, 0.0, 2.0 * jnp.pi)
    el_rad = jax.random.uniform(k_el, shape, jnp.float64, mask_rad, 0.5 * jnp.pi)
    return az_rad, el_rad


class Towers(NamedTuple):
    """Cellular towers around a receiver at the origin of a local ENU frame."""

    az_rad: jax.Array  # (..., N) clockwise from north
    el_rad: jax.Array  # (..., N) atan(h / d)
    range_m: jax.Array  # (..., N) sqrt(d^2 + h^2)
    distance_m: jax.Array  # (..., N) horizontal distance d
    height_m: jax.Array  # (..., N) height above the receiver h
    enu_m: jax.Array  # (..., N, 3) [d sin az, d cos az, h]


def bpp_towers(key: PRNGKeyArray, n_towers: int, d_min_m: Real[ArrayLike, ""],
               d_max_m: Real[ArrayLike, ""], h_min_m: Real[ArrayLike, ""] = 0.0,
               h_max_m: Real[ArrayLike, ""] = 0.0, batch_shape: Sequence[int] = ()) -> Towers:
    """Binomial point process of N towers in the annulus B_o(d_min, d_max), seed 001 section 3.3.

    Each tower is uniform in *area* over the annulus (so d^2 is uniform on
    [d_min^2, d_max^2]), its azimuth is uniform on [0, 2 pi), its height uniform on
    [h_min, h_max]; elevation atan(h / d) and range sqrt(d^2 + h^2) follow (DESIGN.md corrects
    seed 004's sqrt(d + h)). Seed 001 takes d_min ~ 5 m (far field of an 800 MHz, 1 m array) and
    d_max ~ 3 km (reliable LTE tracking); its Fig. 4 puts all towers at 0 deg elevation
    (h_min = h_max = 0).

    Returns:
      ``Towers`` with arrays of shape ``(*batch_shape, n_towers)``.
    """
    k_d, k_az, k_h = jax.random.split(key, 3)
    shape = (*tuple(batch_shape), int(n_towers))
    u = jax.random.uniform(k_d, shape, jnp.float64)
    distance_m = jnp.sqrt(d_min_m**2 + u * (d_max_m**2 - d_min_m**2))
    az_rad = jax.random.uniform(k_az, shape, jnp.float64, 0.0, 2.0 * jnp.pi)
    height_m = jax.random.uniform(k_h, shape, jnp.float64, h_min_m, h_max_m)
    el_rad = jnp.arctan2(height_m, distance_m)
    range_m = jnp.hypot(distance_m, height_m)
    enu_m = jnp.stack(
        [distance_m * jnp.sin(az_rad), distance_m * jnp.cos(az_rad), height_m], axis=-1
    )
    return Towers(az_rad, el_rad, range_m, distance_m, height_m, enu_m)
