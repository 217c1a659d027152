"""What ``map_kernel`` reads of one latitude row, as two objects: the row's arrays
(``MapRowInputs``, a pytree the kernel traces) and its static layout and receiver
(``MapConfig``, hashable: part of the compiled program)."""

from typing import NamedTuple

import jax

from oaraim.araim import MHSSOptions

__all__ = ["MapConfig", "MapRowInputs"]


class MapRowInputs(NamedTuple):
    """The arrays of one latitude row that ``map_kernel`` reads (a pytree: traced)."""

    lat_rad: object
    """The row's latitude (rad)."""
    lons_rad: jax.Array
    """(N,) the users' longitudes (rad)."""
    h_m: object
    """The users' height (m)."""
    sat_ecef: jax.Array
    """(T, S, 3) satellite positions at the epochs (m)."""
    sat_ok: jax.Array
    """(T, S) usable orbits."""
    sat_const: jax.Array
    """(S,) constellation codes (GPS 0, Galileo 1)."""
    mask_rad: object
    """Elevation mask (rad)."""
    gnss: dict
    """The GNSS ISM values (``sigma_ura_gps_m``, ..., ``p_sat_gal``)."""
    sop: dict
    """The SOP annulus and ISM (``d_min_m``, ..., ``p_s_sop``)."""
    towers: dict | None
    """The row's CSV tower slots and LEO slots, or None."""
    p_const: jax.Array
    """(C,) P_const per constellation."""


class MapConfig(NamedTuple):
    """The static layout and receiver of ``map_kernel`` (hashable: part of the program)."""

    n_slots: int
    """GNSS slots of the compacted sky."""
    n_sops: int
    """SOP slots (BPP towers or the row's CSV towers)."""
    bpp: bool
    """BPP towers drawn per user (else the row's tower slots)."""
    budget: object
    """The ``araim.IntegrityBudget`` of the service level."""
    requirements: object
    """The service level's criteria (``araim.availability``)."""
    airborne_model: str
    """The GNSS user error model (``araim.error_models.AIRBORNE_MODELS``)."""
    mhss: MHSSOptions
    """The MHSS options (order, fault-mode rule, position estimator)."""
