"""What the world does: simulated drives and flights (truth trajectory, measurements and their
errors) and synthesized recordings.

``sim.measurement`` is the one measurement model (pseudoranges, receiver clock, IMU, and the
error world's parameters as one ``ErrorModel`` pytree) that every simulated drive, flight and
recording draws from; ``sim.trajectory`` the scenarios (truth motion, tower layouts);
``sim.drive`` the Monte Carlo drives through the receiver's EKF-RAIM; ``sim.gnss`` the GNSS +
SOP epochs of the snapshot studies; ``sim.recordings`` simulated runs in the recorded-data
format.

Layering: ``sim`` imports ``geometry``, ``mc`` (the named key streams) and, to run a receiver
over a simulated drive, ``araim``; ``araim`` and ``geometry`` never import ``sim``.
"""

if __name__ != "oaraim.sim":  # the source folder is importable from the checkout's root
    raise ImportError(f"import oaraim.sim, not {__name__}: the folder sim/ installs as "
                      "oaraim.sim (pip install -e .), which also enables JAX's float64 mode")

# the world's error parameters live in oaraim.errors (errors.world); sim draws them
from oaraim.errors import ErrorModel, GnssErrorModel
from oaraim.sim import drive, gnss, measurement, recordings, trajectory
from oaraim.sim.drive import (
    DriveSetup,
    DriveSummary,
    DriveTrace,
    InitialDraw,
    drive_setup,
    initial_draw,
    monte_carlo_drive,
    simulate_drive,
)
from oaraim.sim.gnss import (
    SnapshotWorld,
    epoch_times,
    gnss_errors,
    gnss_sop_errors,
    pseudoranges,
    scenario_geometry,
    to_recording,
)
from oaraim.sim.measurement import (
    EpochMeasurements,
    EpochTowers,
    EpochTruth,
    ReceiverSensors,
    WorldState,
    calibrate,
    clock_fit,
    drive_epoch,
    fault_bias_m,
    pseudorange_from_range,
    pseudorange_sample,
    pseudorange_true,
    sop_errors,
)
from oaraim.sim.recordings import example_recording, synthesize_recording
from oaraim.sim.trajectory import (
    SCENARIOS,
    Scenario,
    Segment,
    Trajectory,
    drive_seed000,
    drive_seed002,
    uav_seed004,
)

__all__ = [
    "DriveSetup", "DriveSummary", "DriveTrace", "EpochMeasurements", "EpochTowers",
    "EpochTruth", "ErrorModel", "GnssErrorModel", "InitialDraw", "ReceiverSensors", "SCENARIOS",
    "Scenario", "Segment", "SnapshotWorld", "Trajectory", "WorldState", "calibrate",
    "clock_fit", "drive", "drive_epoch", "drive_seed000", "drive_seed002", "drive_setup",
    "epoch_times", "example_recording", "fault_bias_m", "gnss", "gnss_errors",
    "gnss_sop_errors", "initial_draw", "measurement", "monte_carlo_drive",
    "pseudorange_from_range", "pseudorange_sample", "pseudorange_true", "pseudoranges",
    "recordings", "scenario_geometry", "simulate_drive", "sop_errors", "synthesize_recording",
    "to_recording", "trajectory", "uav_seed004",
]

from oaraim.sim import faults, filter_drive  # noqa: E402
from oaraim.sim.faults import FaultScenario, draw_faults, fault_profile_m, no_fault  # noqa: E402
from oaraim.sim.filter_drive import (  # noqa: E402
    FilterDriveConfig,
    FilterDriveSummary,
    FilterDriveTrace,
    simulate_filter_drive,
    tower_error_states,
)

__all__ += ["FaultScenario", "FilterDriveConfig", "FilterDriveSummary", "FilterDriveTrace",
            "draw_faults", "fault_profile_m", "faults", "filter_drive", "no_fault",
            "simulate_filter_drive", "tower_error_states"]

# the drive's conditional risk estimate (docs/filter-integrity.md); a namespace
from oaraim.sim import filter_risk  # noqa: E402

__all__ += ["filter_risk"]
