"""The ``Param`` declarations that several studies repeat word for word, declared once.

A study's table refers to them by name (``"d_min_m": params.BPP_D_MIN_SEED001_M``); where two
studies give a parameter a different default or reason, each keeps its own declaration.
"""

from oaraim.studies.base import Param, in_range, non_negative, positive, probability

#: seed 001's BPP annulus (Figs. 4-5)
BPP_D_MIN_SEED001_M = Param(5.0, non_negative, "BPP inner radius (seed 001: ~5 m)", "m")
BPP_D_MAX_SEED001_M = Param(3000.0, positive, "BPP outer radius (seed 001: ~3 km)", "m")
#: seed 001 Figs. 3-4
MASK_SEED001_DEG = Param(15.0, in_range(0.0, 89.0), "elevation mask (seed 001: 15 deg)", "deg")
#: seed 001 Figs. 4-5 (the seed gives no SOP sigma)
SIGMA_SOP_M = Param(1.0, positive, "SOP pseudorange sigma (seed silent)", "m")
#: seed 001 Fig. 4 and the EKF drives of seeds 000 and 002
P_MD_SILENT = Param(1e-3, probability, "missed-detection probability (seed silent)")


def parse_world(name, v):
    """Parser of a ``world`` parameter: the error world of a synthesis, 'realistic'
    (``sim.ErrorModel()``, docs/error-world.md) or 'clean' (white noise); case-insensitive."""
    s = str(v).strip().lower()
    if s not in ("realistic", "clean"):
        raise ValueError(f"{name} must be 'realistic' or 'clean', got {v!r}")
    return s
