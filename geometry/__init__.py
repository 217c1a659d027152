"""Where the transmitters are: line-of-sight geometry, random skies, BPP towers, Earth frames,
GPS time, broadcast ephemerides, almanacs, nominal constellations and the sky of a receiver.

Everything here is a pure JAX function on arrays, batch first, float64.
"""

import jax

jax.config.update("jax_enable_x64", True)

from geometry import gpstime  # noqa: E402
from geometry.almanac import Almanac, AlmanacFileError, read_sem, read_yuma  # noqa: E402
from geometry.ephemeris import (  # noqa: E402
    GALILEO,
    GPS,
    Ephemeris,
    NavigationFileError,
    load_navigation,
)
from geometry.frames import (  # noqa: E402
    azimuth_elevation,
    earth_rotation_correction,
    ecef_to_enu,
    ecef_to_geodetic,
    enu_rotation,
    enu_to_ecef,
    geodetic_to_ecef,
)
from geometry.nominal import galileo_walker, gps_24_slot  # noqa: E402
from geometry.random_sky import Towers, bpp_towers, random_sky  # noqa: E402
from geometry.rows import geometry_rows, geometry_rows_enu  # noqa: E402
from geometry.sky import Sky, sky  # noqa: E402
from geometry.sp3 import PreciseOrbits, SP3Error, read_sp3  # noqa: E402

__all__ = [
    "GALILEO", "GPS", "Almanac", "AlmanacFileError", "Ephemeris", "NavigationFileError",
    "PreciseOrbits", "SP3Error", "Sky", "Towers", "azimuth_elevation", "bpp_towers",
    "earth_rotation_correction", "ecef_to_enu", "ecef_to_geodetic", "enu_rotation",
    "enu_to_ecef", "galileo_walker", "geodetic_to_ecef", "geometry_rows", "geometry_rows_enu",
    "gps_24_slot", "gpstime", "load_navigation", "random_sky", "read_sem", "read_sp3",
    "read_yuma", "sky",
]

from geometry import recording  # noqa: E402
from geometry.recording import (  # noqa: E402
    Recording,
    RecordingError,
    example_recording,
    gnss_matrix,
    load_recording,
    pseudorange_matrix,
    tower_clock_m,
    write_recording,
)

__all__ += [
    "Recording", "RecordingError", "example_recording", "gnss_matrix", "load_recording",
    "pseudorange_matrix", "recording", "tower_clock_m", "write_recording",
]

from geometry import clocks, imu, trajectory  # noqa: E402
from geometry.imu import ImuSpec, vn100  # noqa: E402
from geometry.trajectory import (  # noqa: E402
    SCENARIOS,
    Scenario,
    Segment,
    Trajectory,
    drive_seed000,
    drive_seed002,
    uav_seed004,
)

__all__ += [
    "ImuSpec", "SCENARIOS", "Scenario", "Segment", "Trajectory", "clocks", "drive_seed000",
    "drive_seed002", "imu", "trajectory", "uav_seed004", "vn100",
]

from geometry import atmosphere, rinex_obs  # noqa: E402
from geometry.rinex_obs import ObservationFileError, Observations, read_observations  # noqa: E402

__all__ += ["ObservationFileError", "Observations", "atmosphere", "read_observations",
            "rinex_obs"]
