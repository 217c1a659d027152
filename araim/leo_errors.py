"""LEO constellations on the receiver's side: the ISM presets (``LEO_ISM``, ``araim.Ism``
objects of the receiver's configuration), the clock options (``LEO_CLOCKS``) and the
constellation labels of LEO sources (``leo_labels``). The LEO error model (``LeoSignal``,
``LEO_SIGNALS``, ``leo_variances``, ``sigma_iono_leo_m``, ``sigma_elevation_leo_m``) lives in
``errors.leo``; this module re-exports its names for users of ``araim.leo_errors``.
"""

import numpy as np
from jaxtyping import Int32

from oaraim.araim.epoch import Ism
from oaraim.errors import (
    KLOBUCHAR_TAU_VERT_MID_M,
    LEO_SIGNALS,
    LeoSignal,
    leo_variances,
    sigma_elevation_leo_m,
    sigma_iono_leo_m,
)

__all__ = ["KLOBUCHAR_TAU_VERT_MID_M", "LEO_CLOCKS", "LEO_ISM", "LEO_SIGNALS", "LeoSignal",
           "leo_labels", "leo_variances", "sigma_elevation_leo_m", "sigma_iono_leo_m"]

#: the clock options of a LEO constellation
LEO_CLOCKS = ("constellation", "satellite")


#: ISM presets of a LEO constellation (sigma_URA, sigma_URE, b_nom, P_s, P_const):
#: - ``tle``: ephemeris from public two-line element sets: SGP4 from a Starlink TLE is ~1 km
#:   off after 6 h (median 3-D error; Jankovic, arXiv:2605.19850, 2026, abstract: "~1 km at
#:   6 h to ~38 km at 7 d"), taken whole as the range error (1,000 m);
#: - ``estimated``: an operator-estimated, broadcast ephemeris and clock of GPS quality, the
#:   baseline of Oak, Pullen, Lo et al. (ION, "GNSS Augmentation for Advanced RAIM by
#:   Constellations of LEO Satellites with Degraded Performance": LEO "not far below the
#:   values currently provided by GPS"): sigma_URA 1 m, sigma_URE 2/3 of it (ADD);
#: - ``degraded-20x``: the same paper's worst case, sigma_URA 20 times GPS's (20 m).
#: b_nom 0 (seed 004's SOP choice), P_s 1e-5 (GPS's, the papers' baseline), P_const 1e-4
#: (seed 004 Table I's SOP and the ADD's Galileo value); P_s is the sensitivity study's axis.
LEO_ISM = {
    "tle": Ism(1000.0, 1000.0, 0.0, 1e-5, 1e-4),
    "estimated": Ism(1.0, 2.0 / 3.0, 0.0, 1e-5, 1e-4),
    "degraded-20x": Ism(20.0, 40.0 / 3.0, 0.0, 1e-5, 1e-4),
}


def leo_labels(n: int, first_label: int, clocks: str = "constellation"
               ) -> Int32[np.ndarray, " n"]:
    """Constellation labels (n,) of n LEO sources: all ``first_label`` (one clock) or
    ``first_label + 0..n-1`` (one clock per satellite)."""
    if clocks not in LEO_CLOCKS:
        raise ValueError(f"clocks must be one of {', '.join(LEO_CLOCKS)}, got {clocks!r}")
    if clocks == "constellation":
        return np.full(n, first_label, np.int32)
    return (first_label + np.arange(n)).astype(np.int32)
