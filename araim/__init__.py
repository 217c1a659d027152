"""What a receiver computes from one epoch: WNLS, chi-square RAIM slopes and HPL, and the
ARAIM / OARAIM multiple-hypothesis solution-separation protection levels with FDE.

Pure JAX functions, batch first, float64. Failures are data: ``inf`` with a ``Status``.
"""

import jax

jax.config.update("jax_enable_x64", True)

from araim import error_models  # noqa: E402
from araim.budget import BUDGET_LPV200, BUDGET_SEED004_TABLE_I, IntegrityBudget  # noqa: E402
from araim.chi2 import detection_threshold, lambda_det_table, noncentrality  # noqa: E402
from araim.fde import FDEResult, Separation, detect_and_exclude, solution_separation  # noqa: E402
from araim.mhss import MHSSResult, protection_levels  # noqa: E402
from araim.slopes import SlopeHPL, Slopes, slope_hpl, slopes  # noqa: E402
from araim.status import Status  # noqa: E402
from araim.wnls import WNLSResult, wnls  # noqa: E402

__all__ = [
    "BUDGET_LPV200",
    "BUDGET_SEED004_TABLE_I",
    "FDEResult",
    "IntegrityBudget",
    "MHSSResult",
    "Separation",
    "detect_and_exclude",
    "error_models",
    "protection_levels",
    "solution_separation",
    "SlopeHPL",
    "Slopes",
    "Status",
    "WNLSResult",
    "detection_threshold",
    "lambda_det_table",
    "noncentrality",
    "slope_hpl",
    "slopes",
    "wnls",
]

from araim import ekf, ekf_raim  # noqa: E402
from araim.ekf import EkfParams, EkfState, ekf_init, ekf_predict, ekf_step, ekf_update, run_ekf  # noqa: E402,E501
from araim.ekf_raim import (  # noqa: E402
    DriveSummary,
    RaimConfig,
    drive_setup,
    monte_carlo_drive,
    run_ekf_raim,
    simulate_drive,
)

__all__ += [
    "DriveSummary", "EkfParams", "EkfState", "RaimConfig", "drive_setup", "ekf", "ekf_init",
    "ekf_predict", "ekf_raim", "ekf_step", "ekf_update", "monte_carlo_drive", "run_ekf",
    "run_ekf_raim", "simulate_drive",
]

from araim import snapshot  # noqa: E402
from araim.snapshot import MonitorReplay, ReplayResult, replay, replay_metrics  # noqa: E402

__all__ += ["MonitorReplay", "ReplayResult", "replay", "replay_metrics", "snapshot"]
