"""Seed 002 (ICCPS 2019 WiP): pseudorange outlier detection and exclusion, the 1.4 km drive.

The same EKF-RAIM as seed 000 (``studies.common.ekf_drive``: one drive synthesized, written in
the recorded-drive format, loaded and replayed for the figures; ``--set recording=PATH`` replays
a user's drive; a Monte Carlo of ``--realizations`` runs), on ``sim.drive_seed002()``: the
1.4 km downtown Riverside drive, 5 LTE towers (the seed's "5 LTE base stations"), NIS with
d = N_s (seed 002 section 3), an outlier of +30 m on tower 1 from t = 95 s (the seed's detection
time: its Fig. 3 threshold is exceeded at t = 95 s; the seed names neither tower nor magnitude,
we keep seed 000's tower 1 and our 30 m NLOS choice), in the same error world
(``sim.ErrorModel()``, docs/error-world.md). Published: 2D RMSE 8.2 -> 4.8 m (42 %),
maximum 2D error 20.4 -> 11.6 m (43.3 %).
"""

from oaraim import sim
from oaraim.studies.common.ekf_drive import EkfDriveStudy


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
