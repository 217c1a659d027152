"""Seed 002 (ICCPS 2019 WiP): pseudorange outlier detection and exclusion, the 1.4 km drive.

The same EKF-RAIM as seed 000 (``studies.common.ekf_drive``: one drive synthesized, written in
the recorded-drive format, loaded and replayed for the figures; ``--set recording=PATH`` replays
a user's drive; a Monte Carlo of ``--realizations`` runs), on ``sim.drive_seed002()``: the
1.4 km downtown Riverside drive, 5 LTE towers (the seed's "5 LTE base stations"), NIS with
d = N_s (seed 002 section 3), an outlier of +30 m on tower 1 from t = 95 s (the seed's detection
time: its Fig. 3 threshold is exceeded at t = 95 s; the seed names neither tower nor magnitude,
we keep seed 000's tower 1), in the same error world (``sim.ErrorModel()``,
docs/error-world.md). Published: 2D RMSE 8.2 -> 4.8 m (42 %), maximum 2D error 20.4 -> 11.6 m
(43.3 %).

Calibrated (``oaraim calibrate seed002-outlier``, docs/calibration.md): the poster gives
neither the outlier's size nor the error levels of its street, and its six numbers pin two of
them. The outlier's size and the towers' multipath sigma are fitted to the six Monte Carlo
medians (200 runs, seed 0, Nelder-Mead, 41 runs): 30.25 m and 2.065 m (defaults 30.3 m,
2.07 m) give RMSE 8.85 -> 5.13 m (reduction 42.5 %) and maximum 18.3 -> 10.6 m (42.8 %)
against 8.2 -> 4.8 m (42 %) and 20.4 -> 11.6 m (43.3 %): all six within 11 %. The world's
defaults (30 m, 1.5 m) gave 8.53 -> 4.03 m (52 %), 17.8 -> 8.54 m (52.6 %): exclusion removed
too much, the street was too clean. The fitted multipath is above the world's 1.5 m (the
fault-free 2D RMSE is 4.0 m, against 3.2 m at 1.5 m and the 3.17 m of Shamaei and Kassas'
drive): seed 002's drive is downtown Riverside, and the poster names short multipath delays
and LOS blockage as its two error sources. NLOS episodes therefore stay on at the world's
1/250 s per tower (unlike seed 000): the fit leaves their rate loose (a three-parameter
64-run fit moved it from 0.0040 to 0.0041 /s, elasticities <= 0.3 on every number), so it is
not fitted. What stays off: the maximum error without exclusion (-10 %) against the RMSE
without (+8 %): one fault size sets both, and the poster's drive has a larger peak for its RMSE
than ours (ratio 2.5 against 2.1).
"""

from oaraim import sim
from oaraim.studies.base import Calibration, Free, Target
from oaraim.studies.common.ekf_drive import EkfDriveStudy

_MEDIAN = ", Monte Carlo median"


class Seed002Outlier(EkfDriveStudy):
    """The ``seed002-outlier`` study (module docstring): ``EkfDriveStudy`` on
    ``sim.drive_seed002`` with seed 002's published numbers."""

    name = "seed002-outlier"
    title = "Seed 002 outlier exclusion, 1.4 km drive"
    seed_file = "002_435c1f190440c5ec.txt"
    realization = ("one Monte Carlo run of the whole synthesized 1.4 km drive (GNSS period, "
                   "IMU, clock, SOP error world, initial error; both filters)")
    default_realizations = 200
    quick_realizations = 20
    quick_cost_s = 26
    #: ``oaraim calibrate``: the outlier's size, the towers' multipath and the NLOS episode
    #: rate, which the poster leaves open, from its six numbers (Monte Carlo medians)
    calibration = Calibration(
        free=(Free("fault_bias_m", 5.0, 60.0), Free("mp_sigma_m", 0.2, 5.0)),
        targets=tuple(Target(f"^{q}{_MEDIAN}") for q in (
            "2D position RMSE without exclusion", "2D position RMSE with exclusion",
            "2D RMSE reduction by exclusion", "maximum 2D error without exclusion",
            "maximum 2D error with exclusion", "maximum 2D error reduction by exclusion")),
        realizations=200, sets={"sens_mp_sigma_m": "0"})
    #: the fit's values (``oaraim calibrate seed002-outlier``: 200 runs, 41 evaluations,
    #: 30.25 m and 2.065 m -> medians 8.85 / 5.13 m, 42.5 %, 18.3 / 10.6 m, 42.8 % against
    #: 8.2 / 4.8 m, 42 %, 20.4 / 11.6 m, 43.3 %), the study's defaults; NLOS episodes stay at
    #: the world's rate (the poster names LOS blockage; the fit leaves the rate loose)
    calibrated = {"fault_bias_m": 30.3, "mp_sigma_m": 2.07}
    calibrated_to = "the published RMSEs and maximum errors"
    scenario_fn = staticmethod(sim.drive_seed002)
    fig_prefix = "seed002"
    published_detection_s = 95.0
    published_length_km = 1.4
    published_rows = (
        ("rmse_without", "2D position RMSE without exclusion", "m", 8.2),
        ("rmse_with", "2D position RMSE with exclusion", "m", 4.8),
        ("reduction", "2D RMSE reduction by exclusion", "%", 42.0),
        ("max_without", "maximum 2D error without exclusion", "m", 20.4),
        ("max_with", "maximum 2D error with exclusion", "m", 11.6),
        ("max_reduction", "maximum 2D error reduction by exclusion", "%", 43.3),
    )

    def published_reduction_lines(self):
        """Seed 002's 2D RMSE reduction, 42 %."""
        return [("RMSE reduction", 42.0)]
