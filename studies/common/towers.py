"""The BPP tower annulus of seed 001 section 3 and seed 004 section III-D as one object: the
four numbers every tower draw takes (``geometry.bpp_towers``), so a kernel takes one
argument for them."""

from typing import NamedTuple

__all__ = ["BppAnnulus"]


class BppAnnulus(NamedTuple):
    """Where BPP towers are drawn around the user: distances in [d_min_m, d_max_m] and
    heights in [h_min_m, h_max_m] (a pytree of four numbers: traced inside a kernel)."""

    d_min_m: object
    """Inner radius (m)."""
    d_max_m: object
    """Outer radius (m)."""
    h_min_m: object
    """Lowest tower height above the user (m)."""
    h_max_m: object
    """Highest tower height above the user (m)."""

    @classmethod
    def of(cls, params: dict) -> "BppAnnulus":
        """The annulus of a study's parameters (``d_min_m``, ``d_max_m``, ``h_min_m``,
        ``h_max_m``)."""
        return cls(params["d_min_m"], params["d_max_m"], params["h_min_m"], params["h_max_m"])
