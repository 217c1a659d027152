"""Whether an orbit read from a file is one its constellation flies.

The almanac and navigation readers check a record's layout and numbers; these limits check
what the elements mean. A well-formed record with sqrt(A) = 1000 m^1/2 (an orbit 1,000 km from
the Earth's centre, inside the Earth), e = 0.99 or an inclination of 50 rad is no satellite of
GPS or Galileo: the readers refuse it with the file and line (it used to load, and the
satellite vanished from the sky or sat in an impossible place without a word).

The limits are wide around what the constellations fly, so that every real record passes:

* semi-major axis: GPS 26,560 km +- 1,000 km (sqrt(A) 5055.7 .. 5249.8 m^1/2; the broadcast
  files of 2005-2024 in the shared data hold 26,547 .. 26,584 km); Galileo 27,000 .. 30,600 km
  (the nominal 29,600 km +- 1,000 km, extended down to E14 and E18 on their eccentric orbits
  at 27,977 km);
* eccentricity: GPS <= 0.05 (design < 0.02; the data hold <= 0.025), Galileo <= 0.2 (E14/E18
  ~0.16; the others < 0.001);
* inclination 40 .. 70 deg for both (GPS 55 deg, its first block 63 deg; Galileo 56 deg,
  E14/E18 49.8 deg; the data hold 49.8 .. 57.3 deg).
"""

import math
from typing import NamedTuple


class OrbitLimits(NamedTuple):
    """The plausible range of a constellation's orbital elements."""

    name: str
    """The constellation, for messages."""
    a_m: tuple
    """(min, max) semi-major axis, metres."""
    e_max: float
    """Largest eccentricity."""
    i_rad: tuple
    """(min, max) inclination, radians."""


#: by RINEX system letter
ORBIT_LIMITS = {
    "G": OrbitLimits("GPS", (25_560e3, 27_560e3), 0.05,
                     (math.radians(40.0), math.radians(70.0))),
    "E": OrbitLimits("Galileo", (27_000e3, 30_600e3), 0.2,
                     (math.radians(40.0), math.radians(70.0))),
}


def implausible_orbit(system: str, sqrt_a: float, e: float, i_rad: float):
    """``(element, reason)`` for the first of sqrt(A), e and i outside ``ORBIT_LIMITS[system]``
    (element is ``"sqrt_a"``, ``"e"`` or ``"i"``; reason a phrase for the reader's one-line
    error), or None when the orbit is plausible (also for a system without limits)."""
    lim = ORBIT_LIMITS.get(system)
    if lim is None:
        return None
    a = sqrt_a * sqrt_a
    lo, hi = lim.a_m
    if not (sqrt_a > 0.0 and lo <= a <= hi):
        return ("sqrt_a", f"sqrt(A) = {sqrt_a!r} m^1/2 is a semi-major axis of {a / 1e3:,.0f} km, "
                f"not a {lim.name} orbit ({lo / 1e3:,.0f} .. {hi / 1e3:,.0f} km: sqrt(A) "
                f"{math.sqrt(lo):.1f} .. {math.sqrt(hi):.1f})")
    if not 0.0 <= e <= lim.e_max:
        return ("e", f"eccentricity {e!r} is not a {lim.name} orbit's (0 .. {lim.e_max})")
    lo, hi = lim.i_rad
    if not lo <= i_rad <= hi:
        return ("i", f"inclination {i_rad!r} rad ({math.degrees(i_rad):,.1f} deg) is not a "
                f"{lim.name} orbit's ({math.degrees(lo):.0f} .. {math.degrees(hi):.0f} deg)")
    return None
