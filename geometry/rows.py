"""Line-of-sight rows of the measurement Jacobian (seed 001 section 2.4)."""

import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Array, Float, Real


def geometry_rows(az_rad: Real[ArrayLike, "..."], el_rad: Real[ArrayLike, "..."]
                  ) -> Float[Array, "... 3"]:
    """Position part of the pseudorange Jacobian rows, seed 001 section 2.4.

    Row of transmitter l in the receiver's local East, North, Up frame:
    ``[-cos(el) sin(az), -cos(el) cos(az), -sin(el)]``, i.e. minus the unit vector from the
    receiver to the transmitter. Azimuth is measured clockwise from north.

    Args:
      az_rad: azimuths, shape ``(..., L)``.
      el_rad: elevations, shape ``(..., L)`` (broadcast against ``az_rad``).

    Returns:
      ``(..., L, 3)`` rows [east, north, up]. The receiver clock column (a 1 per row) is added by
      the solvers, which know how sources map to clocks.
    """
    az_rad, el_rad = jnp.broadcast_arrays(jnp.asarray(az_rad), jnp.asarray(el_rad))
    cos_el = jnp.cos(el_rad)
    return jnp.stack(
        [-cos_el * jnp.sin(az_rad), -cos_el * jnp.cos(az_rad), -jnp.sin(el_rad)], axis=-1
    )


def geometry_rows_enu(tx_enu_m: Real[ArrayLike, "*#batch L 3"],
                      rx_enu_m: Real[ArrayLike, "*#batch 3"] | None = None
                      ) -> Float[Array, "*batch L 3"]:
    """The same rows from transmitter positions in a local ENU frame.

    Args:
      tx_enu_m: ``(..., L, 3)`` transmitter positions [east, north, up] in metres.
      rx_enu_m: ``(..., 3)`` receiver position; the frame origin if omitted.

    Returns:
      ``(..., L, 3)``: ``(rx - tx) / |rx - tx|``, equal to ``geometry_rows(az, el)``.
    """
    tx_enu_m = jnp.asarray(tx_enu_m)
    if rx_enu_m is not None:
        tx_enu_m = tx_enu_m - jnp.asarray(rx_enu_m)[..., None, :]
    return -tx_enu_m / jnp.linalg.norm(tx_enu_m, axis=-1, keepdims=True)
