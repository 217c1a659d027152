"""Where the transmitters are: line-of-sight geometry, random skies, BPP towers, Earth frames,
the orbits of broadcast ephemerides and almanacs, nominal constellations and the sky of a
receiver; a recording's local frame and the sensor models (IMU, clocks) a receiver and the
simulated world (``oaraim.sim``) share.

Everything here is a pure JAX function on arrays, batch first, float64. The files are read by
``oaraim.readers`` (the layer below): ``load_navigation``, ``read_yuma`` and ``read_sem`` read
there and make orbits of the records here.

Moved to ``oaraim.readers`` (the file readers are a layer of their own): ``gpstime``,
``rinex_obs``, ``rinex_clk``, ``galileo_nav``, ``recording`` and the names of their files
(``read_observations``, ``read_sp3``, ``load_recording``, ...). They stay importable from
here, as the same objects, for code written before the move (``geometry.read_sp3 is
readers.read_sp3``); the package itself imports them from ``oaraim.readers``. The frame
helpers of ``geometry.recording`` (``truth_enu``, ``transmitters_enu_m``, ``to_enu_m``,
``origin_ecef_m``) are ``geometry.recording_frame``'s, and the pseudorange-model names that
``geometry.rinex_obs`` re-exported are ``geometry.pseudorange_model``'s.
"""

if __name__ != "oaraim.geometry":  # the source folder is importable from the checkout's root
    raise ImportError(f"import oaraim.geometry, not {__name__}: the folder geometry/ installs as "
                      "oaraim.geometry (pip install -e .), which also enables JAX's float64 mode")

from oaraim.geometry.almanac_orbits import Almanac, read_sem, read_yuma
from oaraim.geometry.broadcast_orbits import Ephemeris, load_navigation
from oaraim.geometry.frames import (
    az_el_from_rotation,
    azimuth_elevation,
    earth_rotation_correction,
    ecef_to_enu,
    ecef_to_geodetic,
    enu_rotation,
    enu_to_ecef,
    geodetic_to_ecef,
    normal_gravity_mps2,
)
from oaraim.geometry.nominal import galileo_walker, gps_24_slot
from oaraim.geometry.random_sky import Towers, bpp_towers, random_sky
from oaraim.geometry.rows import geometry_rows, geometry_rows_enu
from oaraim.geometry.sky import Sky, ephemeris_gaps, look_angles, satellites, sky
from oaraim.readers import (  # moved: kept importable from here (see the docstring)
    GALILEO,
    GPS,
    AlmanacFileError,
    NavigationFileError,
    PreciseOrbits,
    SP3Error,
    gpstime,
    read_sp3,
)

__all__ = [
    "GALILEO", "GPS", "Almanac", "AlmanacFileError", "Ephemeris", "NavigationFileError",
    "PreciseOrbits", "SP3Error", "Sky", "Towers", "az_el_from_rotation", "azimuth_elevation",
    "bpp_towers",
    "earth_rotation_correction", "ecef_to_enu", "ecef_to_geodetic", "enu_rotation",
    "ephemeris_gaps", "look_angles", "satellites",
    "enu_to_ecef", "galileo_walker", "geodetic_to_ecef", "geometry_rows", "geometry_rows_enu",
    "gps_24_slot", "gpstime", "load_navigation", "normal_gravity_mps2", "random_sky", "read_sem",
    "read_sp3",
    "read_yuma", "sky",
]

# The recordings' reader and writer (``oaraim.readers``) need pandas (~0.5 s to import):
# ``recording`` and its names, moved to ``oaraim.readers`` and kept here, load on first use
# (PEP 562), so `import oaraim.geometry` does not pay for them.
_RECORDING_NAMES = ("FORMAT_NAME", "FORMAT_VERSION", "Recording", "RecordingError",
                    "gnss_matrix", "load_recording", "pseudorange_matrix", "tower_clock_m",
                    "validate_recording", "write_recording")
#: ``epoch_geometry`` and ``recording_frame`` take recordings too: the same, for their modules
#: and ``EpochGeometry``
_EPOCH_GEOMETRY_NAMES = ("EpochGeometry",)
__all__ += ["recording", *_RECORDING_NAMES, "epoch_geometry", *_EPOCH_GEOMETRY_NAMES,
            "recording_frame"]


def __getattr__(name):
    import importlib

    if name == "recording" or name in _RECORDING_NAMES:
        return getattr(importlib.import_module("oaraim.readers"), name)
    for module_name, names in (("epoch_geometry", _EPOCH_GEOMETRY_NAMES),
                               ("recording_frame", ())):
        if name == module_name or name in names:
            module = importlib.import_module(f"oaraim.geometry.{module_name}")
            return module if name == module_name else getattr(module, name)
    raise AttributeError(f"module 'oaraim.geometry' has no attribute {name!r}")


# the IMU model and the atmosphere live in oaraim.errors; their names stay here for users
from oaraim.errors import ImuSpec, imu, vn100  # noqa: E402
from oaraim.geometry import clocks  # noqa: E402

__all__ += ["ImuSpec", "clocks", "imu", "vn100"]

from oaraim.errors import atmosphere  # noqa: E402
from oaraim.readers import (  # noqa: E402  (moved: kept importable from here)
    ObservationFileError,
    Observations,
    ObservationTable,
    read_observation_table,
    read_observations,
    rinex_obs,
)

__all__ += ["ObservationFileError", "ObservationTable", "Observations", "atmosphere",
            "read_observation_table", "read_observations", "rinex_obs"]

from oaraim.geometry import beidou_nav, sis_error  # noqa: E402
from oaraim.geometry.sis_error import SISError, compare_broadcast_precise  # noqa: E402
from oaraim.readers import (  # noqa: E402  (moved: kept importable from here)
    ClockFileError,
    PreciseClocks,
    galileo_nav,
    read_clock_rinex,
    rinex_clk,
)

__all__ += ["ClockFileError", "PreciseClocks", "SISError", "beidou_nav",
            "compare_broadcast_precise", "galileo_nav", "read_clock_rinex", "rinex_clk",
            "sis_error"]

from oaraim.geometry import leo  # noqa: E402
from oaraim.geometry.leo import (  # noqa: E402
    LEO_PRESETS,
    TleConstellation,
    TleFileError,
    WalkerConstellation,
    WalkerShell,
    combine_skies,
    leo_constellation,
    leo_sky,
    walker_tle_text,
)

__all__ += ["LEO_PRESETS", "TleConstellation", "TleFileError", "WalkerConstellation",
            "WalkerShell", "combine_skies", "leo", "leo_constellation", "leo_sky",
            "walker_tle_text"]

# What the other layers use, through this face only (tools/structure.py: "imports past a
# package's face"); ``frames`` and ``dual_frequency`` are namespaces.
from oaraim.geometry import dual_frequency, frames, pseudorange_model  # noqa: E402
from oaraim.geometry.sky import azimuth, elevation, line_of_sight, resolve_source  # noqa: E402
from oaraim.readers import (  # noqa: E402  (moved: kept importable from here)
    MIN_SEPARATION_M,
    check_navigation_file,
    first_near_pair,
)

__all__ += ["MIN_SEPARATION_M", "azimuth", "check_navigation_file", "dual_frequency",
            "elevation", "first_near_pair", "frames", "line_of_sight", "pseudorange_model",
            "resolve_source"]
