"""What a receiver computes from one epoch: WNLS, chi-square RAIM slopes and HPL, and the
ARAIM / OARAIM multiple-hypothesis solution-separation protection levels with FDE.

Pure JAX functions, batch first, float64. Failures are data: ``inf`` with a ``Status``. Each
receiver function comes twice: a host function (``protection_levels``, ``solution_separation``,
``detect_and_exclude``, ``slopes``, ``slope_hpl``, ``wnls``: NumPy input, argument checks with
clear errors, batch-size buckets, host threads) and the jit-safe kernel it runs
(``protection_levels_kernel``, ``separation_kernel``, ``detect_and_exclude_kernel``,
``slopes_kernel``, ``slope_hpl_kernel``, ``wnls_kernel``), callable inside ``jax.jit`` and
``jax.vmap``, inputs as a ``Sources`` pytree for the MHSS kernels, bad inputs returned as
``Status.INVALID_INPUT``.
"""

if __name__ != "oaraim.araim":  # the source folder is importable from the checkout's root
    raise ImportError(f"import oaraim.araim, not {__name__}: the folder araim/ installs as "
                      "oaraim.araim (pip install -e .), which also enables JAX's float64 mode")

from oaraim.araim import error_models
from oaraim.araim.budget import (
    BUDGET_LPV200,
    BUDGET_LPV200_MAAST,
    BUDGET_SEED004_TABLE_I,
    IntegrityBudget,
    exposure_probability,
)
from oaraim.araim.chi2 import detection_threshold, lambda_det_table, noncentrality
from oaraim.araim.epoch import (
    ISM_GALILEO,
    ISM_GPS,
    ISM_SOP,
    EpochLevels,
    EpochOptions,
    Ism,
    epoch_protection_levels,
)
from oaraim.araim.fault_modes import CONVENTIONS as FAULT_MODE_CONVENTIONS
from oaraim.araim.fault_modes import FaultModeRule
from oaraim.araim.fde import (
    FDEResult,
    Separation,
    detect_and_exclude,
    detect_and_exclude_kernel,
    separation_kernel,
    solution_separation,
)
from oaraim.araim.mhss import (
    MHSSOptions,
    MHSSResult,
    Sources,
    protection_levels,
    protection_levels_kernel,
    protection_levels_priors_kernel,
    switch_flags_kernel,
)
from oaraim.araim.position_opt import PositionOptimization
from oaraim.araim.slopes import SlopeHPL, Slopes, slope_hpl, slope_hpl_kernel, slopes, slopes_kernel
from oaraim.araim.status import Status
from oaraim.araim.wnls import WNLSOptions, WNLSResult, wnls, wnls_kernel

__all__ = [
    "BUDGET_LPV200",
    "BUDGET_LPV200_MAAST",
    "BUDGET_SEED004_TABLE_I",
    "EpochLevels",
    "EpochOptions",
    "FAULT_MODE_CONVENTIONS",
    "FDEResult",
    "ISM_GALILEO",
    "ISM_GPS",
    "ISM_SOP",
    "Ism",
    "FaultModeRule",
    "IntegrityBudget",
    "MHSSOptions",
    "MHSSResult",
    "PositionOptimization",
    "Separation",
    "Sources",
    "detect_and_exclude",
    "detect_and_exclude_kernel",
    "epoch_protection_levels",
    "error_models",
    "exposure_probability",
    "protection_levels",
    "protection_levels_kernel",
    "protection_levels_priors_kernel",
    "separation_kernel",
    "solution_separation",
    "switch_flags_kernel",
    "SlopeHPL",
    "Slopes",
    "Status",
    "WNLSOptions",
    "WNLSResult",
    "detection_threshold",
    "lambda_det_table",
    "noncentrality",
    "slope_hpl",
    "slope_hpl_kernel",
    "slopes",
    "slopes_kernel",
    "wnls",
    "wnls_kernel",
]

from oaraim.araim import ekf, ekf_raim
from oaraim.araim.ekf import (
    EkfInputs,
    EkfParams,
    EkfState,
    ekf_init,
    ekf_predict,
    ekf_step,
    ekf_update,
    run_ekf,
)
from oaraim.araim.ekf_raim import RaimConfig, RaimOptions, run_ekf_raim

__all__ += [
    "EkfInputs", "EkfParams", "EkfState", "RaimConfig", "RaimOptions", "ekf", "ekf_init",
    "ekf_predict", "ekf_raim", "ekf_step", "ekf_update", "run_ekf", "run_ekf_raim",
]

from oaraim.araim import snapshot  # noqa: E402
from oaraim.araim.snapshot import (  # noqa: E402
    MonitorReplay,
    ReplayConfig,
    ReplayResult,
    ReplaySources,
    replay,
    replay_metrics,
)

__all__ += ["MonitorReplay", "ReplayConfig", "ReplayResult", "ReplaySources", "replay",
            "replay_metrics", "snapshot"]

from oaraim.araim import filter_monitor  # noqa: E402
from oaraim.araim.filter_monitor import (  # noqa: E402
    BankOptions,
    BankSources,
    FilterMonitorEpoch,
    LinearModel,
    run_ekf_monitor,
    run_linear_monitor,
    separation_monitor,
)

__all__ += ["BankOptions", "BankSources", "FilterMonitorEpoch", "LinearModel", "filter_monitor",
            "run_ekf_monitor", "run_linear_monitor", "separation_monitor"]

# the EKF bank's HPL and its gradient with respect to the tower positions (a namespace)
from oaraim.araim import filter_gradients  # noqa: E402

__all__ += ["filter_gradients"]

# the filter bank's conditional integrity risk (docs/filter-integrity.md); a namespace too
from oaraim.araim import filter_risk  # noqa: E402
from oaraim.araim.filter_risk import epoch_risk_bound  # noqa: E402

__all__ += ["epoch_risk_bound", "filter_risk"]

# What the other layers use, through this face only (tools/structure.py: "imports past a
# package's face"); ``mhss``, ``availability`` and ``integrity_risk`` are namespaces.
from oaraim.araim import availability, integrity_risk, mhss  # noqa: E402
from oaraim.araim.added_source import added_source_slope_max  # noqa: E402
from oaraim.araim.fault_modes import fault_mode_rule, fault_modes_batch_last  # noqa: E402
from oaraim.araim.mhss import required_order  # noqa: E402
from oaraim.araim.slopes import slope_hpl_tiled  # noqa: E402
from oaraim.araim.validate import (  # noqa: E402
    check_int,
    check_positive,
    check_probability,
    check_range,
)

__all__ += ["added_source_slope_max", "availability", "check_int", "check_positive",
            "check_probability", "check_range", "ekf_replay", "fault_mode_rule",
            "fault_modes_batch_last", "integrity_risk", "mhss", "required_order",
            "slope_hpl_tiled"]


def __getattr__(name):
    # ``ekf_replay`` reads recordings (pandas, ~0.5 s to import): loaded on first use (PEP 562)
    if name == "ekf_replay":
        import importlib

        return importlib.import_module("oaraim.araim.ekf_replay")
    raise AttributeError(f"module 'oaraim.araim' has no attribute {name!r}")

from oaraim.araim import leo_errors  # noqa: E402
from oaraim.araim.leo_errors import (  # noqa: E402
    LEO_CLOCKS,
    LEO_ISM,
    LEO_SIGNALS,
    LeoSignal,
    leo_labels,
    leo_variances,
)

__all__ += ["LEO_CLOCKS", "LEO_ISM", "LEO_SIGNALS", "LeoSignal", "leo_errors", "leo_labels",
            "leo_variances"]
