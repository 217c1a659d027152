"""Where the transmitters are: line-of-sight geometry, random skies, BPP towers.

Everything here is a pure JAX function on arrays, batch first, float64.
"""

import jax

jax.config.update("jax_enable_x64", True)

from geometry.random_sky import Towers, bpp_towers, random_sky  # noqa: E402
from geometry.rows import geometry_rows, geometry_rows_enu  # noqa: E402

__all__ = ["Towers", "bpp_towers", "geometry_rows", "geometry_rows_enu", "random_sky"]
