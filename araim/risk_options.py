"""The options of ``araim.integrity_risk`` as objects: how a risk is sampled (``Sampling``),
which scenario is estimated (``Scenario``) and which ramp is followed (``Ramp``). They live
apart from the estimator so that its module stays one concern; ``integrity_risk`` exports
them."""

from typing import NamedTuple

__all__ = ["DEFAULT_SAMPLING", "Ramp", "Sampling", "Scenario"]


class Sampling(NamedTuple):
    """How the risk of a scenario is estimated (static: sizes of the compiled programs)."""

    n_samples: int = 2000
    """Samples of the final estimate."""
    ce_samples: int = 1000
    """Samples of each cross-entropy round."""
    ce_rounds: int = 2
    """Cross-entropy rounds that move the proposal mean."""
    crude: bool = False
    """Plain Monte Carlo (mu = 0, no rounds) instead of importance sampling."""
    nominal_bias: str = "worst"
    """The nominal bias: b_nom with the sign of u^T S^(0) ("worst") or "zero"."""
    exclusion: bool = True
    """Count wrong-exclusion HMI (the receiver excludes); False: detection only."""


#: the sampling of the study's defaults
DEFAULT_SAMPLING = Sampling()


class Scenario(NamedTuple):
    """One fault scenario of a geometry and the magnitude of its fault."""

    kind: int
    """FAULT_FREE, SINGLE (``source``), CONSTELLATION or PAIR (``constellation``)."""
    direction: int
    """HORIZONTAL or VERTICAL."""
    x: float
    """Magnitude in units of A_det (``scale="det"``) or A_PL (``scale="pl"``), >= 0."""
    source: int = -1
    """The faulty source of a SINGLE scenario."""
    constellation: int = -1
    """The faulty constellation of a CONSTELLATION or PAIR scenario."""
    scale: str = "det"
    """"det" (A_det) or "pl" (A_PL)."""


class Ramp(NamedTuple):
    """A ramp fault on one source: rate x t at t = epoch_s, 2 epoch_s, ..., duration_s."""

    source: int
    """The source that ramps."""
    direction: int
    """HORIZONTAL or VERTICAL."""
    rate_mps: float
    """Ramp rate (m/s, >= 0)."""
    duration_s: float
    """How long the ramp is followed (s, > 0)."""
    epoch_s: float
    """Epoch interval (s, > 0)."""
