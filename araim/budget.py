"""Integrity and continuity budgets of ARAIM / OARAIM (seed 004 Table I, the ADD).

Probabilities are per approach / per hour exactly as the source defines them; the solver only
needs the six numbers. Presets:

- ``BUDGET_SEED004_TABLE_I``: seed 004 Table I read by its *symbols* (DESIGN.md: the table swaps
  the words "vertical" and "horizontal"): PHMI_H = 9.9e-8, PHMI_V = 1e-9, P_FA_H = 9.9e-8,
  P_FA_V = 1e-9, P_thresh = 6e-8. This is MAAST's horizontal-ARAIM preset, although the text says
  LPV-200. P_EMT is not in Table I: the ADD value 1e-5 is used.
- ``BUDGET_LPV200``: the vertical-guidance (LPV-200) allocation of the WG-C ARAIM Technical
  Subgroup Airborne Algorithm Description Document (ADD) v2.0/v3.0, Table 1 of constants:
  PHMI_VERT = 9.8e-8, PHMI_HOR = 2e-9, P_FA_VERT = 3.9e-6, P_FA_HOR = 9e-8, P_THRES = 8e-8,
  P_EMT = 1e-5.
- ``BUDGET_LPV200_MAAST``: the LPV-200 allocation of Stanford's MAAST for ARAIM
  (``main_maast_araim.m`` of its 2018 release and of ``stanford-gps-lab/maast_for_araim_2``):
  PHMI_VERT = 9.8e-8, PHMI_HOR = 2e-9, P_FA_VERT = 3.9e-6, P_FA_HOR = 9e-7, P_THRES = 6e-8,
  P_EMT = 1e-5. It differs from the ADD table in P_FA_HOR (9e-7 against 9e-8) and P_THRES
  (6e-8 against 8e-8).
"""

from dataclasses import asdict, dataclass

import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Float, Real

from oaraim.araim.validate import check_probability


@dataclass(frozen=True)
class IntegrityBudget:
    """Integrity (PHMI) and false-alarm (P_FA) allocations, P_thresh and P_EMT.

    Attributes:
      phmi_v, phmi_h: integrity budget of the vertical and horizontal PLs (eqs. 14, 16).
      p_fa_v, p_fa_h: false-alarm budget of the vertical and horizontal tests (eq. 12).
      p_thresh: bound on the probability of unmonitored fault modes (eq. 8).
      p_emt: fault modes with prior >= p_emt enter the effective monitor threshold (ADD).
      n_es_int, n_es_cont: numbers of effective samples over the exposure (ADD v4.2; MAAST's
        ``N_es_int``, ``N_es_cont``; its LPV-200 preset uses 25 and 25): the right-hand sides
        of the PL equations are divided by ``n_es_int`` after the P_NM scaling, the false-alert
        budgets of the thresholds by ``n_es_cont``. 1 and 1 (the default): off.
    """

    phmi_v: float
    phmi_h: float
    p_fa_v: float
    p_fa_h: float
    p_thresh: float
    p_emt: float = 1e-5
    n_es_int: float = 1.0
    n_es_cont: float = 1.0

    def __post_init__(self):
        for name, value in asdict(self).items():
            if name.startswith("n_es"):
                if not (isinstance(value, int | float) and np.isfinite(value) and value >= 1):
                    raise ValueError(f"budget.{name} must be a number >= 1 (effective samples), "
                                     f"got {value!r}")
                object.__setattr__(self, name, float(value))
                continue
            object.__setattr__(self, name, check_probability(f"budget.{name}", value))
        if self.p_thresh >= self.phmi_v + self.phmi_h:
            raise ValueError(
                f"budget.p_thresh ({self.p_thresh}) must be below phmi_v + phmi_h "
                f"({self.phmi_v + self.phmi_h}): the unmonitored risk would exhaust the "
                "integrity budget of eqs. (14) and (16)")


#: seed 004 Table I by its symbols (DESIGN.md), P_EMT from the ADD
BUDGET_SEED004_TABLE_I = IntegrityBudget(
    phmi_v=1e-9, phmi_h=9.9e-8, p_fa_v=1e-9, p_fa_h=9.9e-8, p_thresh=6e-8, p_emt=1e-5)

#: LPV-200 allocation of the ARAIM ADD (v2.0/v3.0, Table 1)
BUDGET_LPV200 = IntegrityBudget(
    phmi_v=9.8e-8, phmi_h=2e-9, p_fa_v=3.9e-6, p_fa_h=9e-8, p_thresh=8e-8, p_emt=1e-5)

#: LPV-200 allocation of MAAST for ARAIM (main_maast_araim.m, 2018 and 2024 releases)
BUDGET_LPV200_MAAST = IntegrityBudget(
    phmi_v=9.8e-8, phmi_h=2e-9, p_fa_v=3.9e-6, p_fa_h=9e-7, p_thresh=6e-8, p_emt=1e-5)


def exposure_probability(p_instantaneous: Real[ArrayLike, "..."],
                         exposure_s: Real[ArrayLike, "..."],
                         mean_fault_duration_s: Real[ArrayLike, "..."]
                         ) -> Float[np.ndarray, "..."] | float:
    """The prior of a fault over an exposure window, ADD v4.2 (MAAST 2024: ``p (1 + tau)``,
    tau = T_exp / MFD): P (1 + T_exp / MFD), the probability that a fault with instantaneous
    probability P and mean duration MFD is present at some time within T_exp. Pass the result
    as ``p_sat`` / ``p_const``.

    The ADD keeps the instantaneous prior in the PL equation and caps each term at the
    exposure prior (P_inst min(Q, P_exp / P_inst)); using P_exp as the term's weight, as this
    does, is never smaller (conservative) and keeps the PL equation smooth for the solver.
    Off by default: the studies use instantaneous priors (T_exp = 0)."""
    tau = np.asarray(exposure_s, np.float64) / np.asarray(mean_fault_duration_s, np.float64)
    if np.any(~np.isfinite(tau)) or np.any(tau < 0):
        raise ValueError("exposure_s and mean_fault_duration_s must be finite, >= 0 and > 0")
    p = np.asarray(p_instantaneous, np.float64) * (1.0 + tau)
    if np.any(p >= 1.0):
        raise ValueError(f"the exposure prior P (1 + T_exp / MFD) reaches {float(np.max(p))} "
                         ">= 1: shorten the exposure or lower P")
    return p
