"""The 11 LTE towers of the seed 004 UAV flight, as data (seed 004 section VII-A, Fig. 5).

What the seed gives: 11 LTE towers heard on four carriers, 739, 1955, 2125 and 2145 MHz,
"channels allocated for the U.S. cellular providers AT&T, T-Mobile, and Verizon" (VII-A); the
towers' locations were "mapped prior to the experiment" and are drawn on the map of Fig. 5
only, with numbers (SOP 1 ... 11) that fix the order in which SOPs are added (VII-D). No
coordinates, no per-tower carrier.

What we chose (before any result, documented here, not fitted):

- carrier -> operator: 739 MHz (LTE band 17 downlink) and 1955 MHz (band 2, PCS downlink)
  AT&T, 2125 MHz T-Mobile and 2145 MHz Verizon (both band 4/66, AWS downlink); seed 004 lists
  the four frequencies and the three operators in that order; the assignment is our
  reading of that order;
- towers per carrier 3, 2, 3, 3 (AT&T 5 on two carriers, T-Mobile 3, Verizon 3): 11 in all;
- SOP constellations by operator (eq. 3: the towers of one operator share a common clock term,
  so one clock state per operator; the two AT&T carriers are one network);
- SOP numbering operator by operator (AT&T 1-5, T-Mobile 6-8, Verizon 9-11), so that SOP 1
  alone is a new constellation (Fig. 7, Theorem 1; Fig. 8: +1 SOP raises the HPL, Theorem 2)
  and SOPs 1 and 2 share a clock (Fig. 8: two SOPs reduce it). That is the only numbering
  under which the seed's Fig. 8 statements hold for 2 SOPs;
- positions: a semi-urban macro-cell layout around the flight (which spans about 180 m x 210 m
  from the origin, ``sim.uav_seed004``): each operator's towers spread over all azimuths (a
  network covers the area around itself), distances 0.6-2.9 km (macro-cell inter-site
  distances in a semi-urban area are 1-3 km), heights 20-35 m above the take-off point; the
  azimuth/distance pairs were picked by hand, converted to ENU and rounded to 10 m. They are
  plausible, not the seed's: the map of Fig. 5 has no scale we could read.
"""

from typing import NamedTuple

import numpy as np

#: operators in SOP-constellation order (seed 004 VII-A)
OPERATORS = ("AT&T", "T-Mobile", "Verizon")
#: carrier frequencies heard on the flight (seed 004 VII-A)
CARRIERS_MHZ = (739, 1955, 2125, 2145)


class Tower(NamedTuple):
    """One row of the tower table."""

    sop: int
    """SOP number (the order in which SOPs are added, seed 004 VII-D)."""
    operator: str
    """Network operator: the SOP constellation (one clock state)."""
    carrier_mhz: int
    """LTE carrier frequency, MHz."""
    east_m: float
    """East of the flight's origin (downtown Riverside, CA), m."""
    north_m: float
    """North of the origin, m."""
    up_m: float
    """Antenna height above the origin, m."""


#: the table (module docstring for how it was made)
TOWERS = (
    Tower(1, "AT&T", 739, 380.0, 1030.0, 30.0),
    Tower(2, "AT&T", 739, 1090.0, -1300.0, 25.0),
    Tower(3, "AT&T", 739, -870.0, -230.0, 28.0),
    Tower(4, "AT&T", 1955, -1480.0, 1760.0, 35.0),
    Tower(5, "AT&T", 1955, 2700.0, 720.0, 22.0),
    Tower(6, "T-Mobile", 2125, -230.0, -1280.0, 30.0),
    Tower(7, "T-Mobile", 2125, -570.0, 400.0, 20.0),
    Tower(8, "T-Mobile", 2125, 1530.0, 1290.0, 32.0),
    Tower(9, "Verizon", 2145, 560.0, -210.0, 25.0),
    Tower(10, "Verizon", 2145, -1920.0, -1610.0, 30.0),
    Tower(11, "Verizon", 2145, -130.0, 1490.0, 27.0),
)


def towers_enu_m():
    """(11, 3) tower positions, ENU from the flight's origin, in SOP order."""
    return np.asarray([[t.east_m, t.north_m, t.up_m] for t in TOWERS], np.float64)


def tower_operators():
    """The operator (SOP constellation) of each tower, in SOP order."""
    return [t.operator for t in TOWERS]
