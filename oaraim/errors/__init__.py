"""The error models, in one home: what the receiver assumes and what the simulated world draws.

One module per error source, each importing only ``oaraim.constants`` (a layer below
``geometry``, so every layer that computes may use it):

- ``errors.gnss``: the ADD dual-frequency airborne model of a satellite's C_int and C_acc
  (``gnss_variances``; the troposphere, multipath, noise and user terms; ``AIRBORNE_MODELS``);
- ``errors.sop``: the terrestrial SOPs' model (``sop_variances``, seed 004 App. A);
- ``errors.leo``: a LEO downlink as an SOP constellation (``leo_variances``, ``LeoSignal``);
- ``errors.atmosphere``: the broadcast (Klobuchar) ionosphere and the MOPS troposphere, their
  delays and the residual sigmas of single-frequency users;
- ``errors.imu``: the IMU's white noise and Gauss-Markov biases (``ImuSpec``, ``vn100``);
- ``errors.sis``: the signal-in-space error of broadcast against precise orbits and clocks
  (``SISError``, ``sis_errors``);
- ``errors.world``: the parameters of the simulated world's errors (``ErrorModel`` of the
  towers, ``GnssErrorModel`` of the satellites); ``oaraim.sim`` draws them.

Names say the quantity, the term and the unit, the same way in every module:

- ``sigma_<term>[_<model>]_m``: a 1-sigma in metres of one error term (``tropo``,
  ``multipath``, ``noise``, ``user``, ``iono``, ``elevation``) of one model where several
  exist (``airborne``, ``ed259a``, ``klobuchar``, ``leo``), a function of elevation in radians;
- ``<source>_variances``: the ``(var_int_m2, var_acc_m2)`` diagonals of C_int and C_acc of a
  source family (``gnss``, ``sop``, ``leo``), what ``araim.protection_levels`` takes;
- ``<model>_delay_m``: a correction (``klobuchar``, ``tropo``), metres, positive late;
- configurations are NamedTuples (``ImuSpec``, ``LeoSignal``, ``ErrorModel``,
  ``GnssErrorModel``); constants carry their unit (``F_L1_HZ``) and their source.

The earlier homes keep their names as re-exports of this one: ``araim.error_models``
(``araim.error_models.gnss_variances(el)``), ``araim.leo_errors``, ``geometry.atmosphere``,
``geometry.imu`` (``geometry.ImuSpec``, ``geometry.vn100``), ``geometry.SISError`` and
``sim.ErrorModel``, ``sim.GnssErrorModel``.
"""

from oaraim.errors import atmosphere, gnss, imu, leo, sis, sop, world
from oaraim.errors.atmosphere import (
    iono_obliquity,
    klobuchar_delay_m,
    sigma_iono_klobuchar_m,
    tropo_delay_m,
)
from oaraim.errors.gnss import (
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
)
from oaraim.errors.imu import ImuSpec, vn100
from oaraim.errors.leo import (
    KLOBUCHAR_TAU_VERT_MID_M,
    LEO_SIGNALS,
    LeoSignal,
    leo_variances,
    sigma_elevation_leo_m,
    sigma_iono_leo_m,
)
from oaraim.errors.sis import SISError, sis_errors
from oaraim.errors.sop import sop_variances
from oaraim.errors.world import LTE_URBAN_POSITION_RMSE_M, ErrorModel, GnssErrorModel

__all__ = [
    "AIRBORNE_MODELS", "F_L1_HZ", "F_L5_HZ", "KLOBUCHAR_TAU_VERT_MID_M", "LEO_SIGNALS",
    "LTE_URBAN_POSITION_RMSE_M", "URE_OVER_URA", "ErrorModel", "GnssErrorModel", "ImuSpec",
    "LeoSignal", "SISError", "atmosphere", "gnss", "gnss_variances", "imu", "iono_free_factor",
    "iono_obliquity", "klobuchar_delay_m", "leo", "leo_variances", "sis", "sis_errors",
    "sigma_elevation_leo_m", "sigma_iono_klobuchar_m", "sigma_iono_leo_m", "sigma_multipath_m",
    "sigma_noise_m", "sigma_tropo_m", "sigma_user_airborne_m", "sigma_user_ed259a_m", "sop",
    "sop_variances", "tropo_delay_m", "vn100", "world",
]
