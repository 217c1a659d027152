"""The receiver-side GNSS and SOP error models, kept under this name for users:
``araim.error_models.gnss_variances(el)`` is ``oaraim.errors.gnss_variances(el)``.

The models live in ``oaraim.errors`` (``errors.gnss``: the ADD dual-frequency airborne model
of seed 004 App. A; ``errors.sop``: the terrestrial SOPs'); this module re-exports their names.
"""

from oaraim.errors import (
    AIRBORNE_MODELS,
    F_L1_HZ,
    F_L5_HZ,
    URE_OVER_URA,
    gnss_variances,
    iono_free_factor,
    sigma_multipath_m,
    sigma_noise_m,
    sigma_tropo_m,
    sigma_user_airborne_m,
    sigma_user_ed259a_m,
    sop_variances,
)

__all__ = [
    "AIRBORNE_MODELS", "F_L1_HZ", "F_L5_HZ", "URE_OVER_URA", "gnss_variances",
    "iono_free_factor", "sigma_multipath_m", "sigma_noise_m", "sigma_tropo_m",
    "sigma_user_airborne_m", "sigma_user_ed259a_m", "sop_variances",
]
