"""What a receiver computes from one epoch: WNLS, chi-square RAIM slopes and HPL.

Pure JAX functions, batch first, float64. Failures are data: ``inf`` with a ``Status``.
"""

import jax

jax.config.update("jax_enable_x64", True)

from araim.chi2 import detection_threshold, lambda_det_table, noncentrality  # noqa: E402
from araim.slopes import SlopeHPL, Slopes, slope_hpl, slopes  # noqa: E402
from araim.status import Status  # noqa: E402
from araim.wnls import WNLSResult, wnls  # noqa: E402

__all__ = [
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
