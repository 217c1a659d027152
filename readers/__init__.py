"""File readers: what the GNSS and recorded-data files hold, as arrays and NamedTuples, checked.

RINEX 2/3 observation files (``read_observations``, ``read_observation_table``), RINEX 2/3
navigation files (``read_navigation``: the broadcast records; ``navigation_extras``: the
Klobuchar coefficients and T_GD; ``read_beidou_records``), YUMA/SEM almanacs
(``read_yuma_records``, ``read_sem_records``), SP3 precise orbits (``read_sp3``), RINEX clock
files (``read_clock_rinex``), tower CSVs (``read_towers_csv``: the SOP transmitters of the
availability maps) and recorded drives and flights (``load_recording``, ``write_recording``;
the format: ``readers.recording``). Every malformed file is an error (a
``ValueError``) naming the file, the line and how to fix it. GPS time (``gpstime``) is the time
scale the readers read every epoch into.

The readers compute nothing of the geometry: ``oaraim.geometry`` makes orbits of the records
(``geometry.load_navigation``, ``geometry.read_yuma``, ``geometry.read_sem`` read and propagate
in one call) and frames of a recording (``geometry.recording_frame``). This layer imports only
``oaraim.constants`` of the package (docs/design.md, "Layers").
"""

if __name__ != "oaraim.readers":  # the source folder is importable from the checkout's root
    raise ImportError(f"import oaraim.readers, not {__name__}: the folder readers/ installs as "
                      "oaraim.readers (pip install -e .)")

from oaraim.readers import galileo_nav, gpstime, orbit_limits, rinex_clk, rinex_obs
from oaraim.readers.almanac import (
    AlmanacFileError,
    AlmanacRecords,
    read_sem_records,
    read_yuma_records,
)
from oaraim.readers.beidou_nav import GEO_PRNS, BeidouRecords, read_beidou_records
from oaraim.readers.navigation import (
    DEFAULT_MAX_AGE_S,
    GALILEO,
    GALILEO_SOURCES,
    GPS,
    RECORD_FIELDS,
    SYSTEM_CODES,
    SYSTEM_NAMES,
    NavigationFileError,
    NavigationRecords,
    check_navigation_file,
    read_navigation,
)
from oaraim.readers.navigation_extras import NavigationExtras, navigation_extras, tgd_at
from oaraim.readers.observation_table import ObservationTable
from oaraim.readers.orbit_limits import ORBIT_LIMITS, implausible_orbit
from oaraim.readers.rinex_clk import ClockFileError, PreciseClocks, read_clock_rinex
from oaraim.readers.rinex_obs import (
    ObservationFileError,
    ObservationFileWarning,
    Observations,
    check_observation_file,
    read_observation_table,
    read_observations,
)
from oaraim.readers.sp3 import PreciseOrbits, SP3Error, read_sp3
from oaraim.readers.towers import TOWER_COLUMNS, TowerFileError, TowerRecords, read_towers_csv
from oaraim.readers.transmitters import MIN_SEPARATION_M, first_near_pair

__all__ = [
    "DEFAULT_MAX_AGE_S", "GALILEO", "GALILEO_SOURCES", "GEO_PRNS", "GPS", "MIN_SEPARATION_M",
    "ORBIT_LIMITS", "RECORD_FIELDS", "SYSTEM_CODES", "SYSTEM_NAMES", "TOWER_COLUMNS",
    "AlmanacFileError", "AlmanacRecords", "BeidouRecords", "ClockFileError", "NavigationExtras",
    "NavigationFileError", "NavigationRecords", "ObservationFileError", "ObservationFileWarning",
    "ObservationTable", "Observations", "PreciseClocks", "PreciseOrbits", "SP3Error",
    "TowerFileError", "TowerRecords", "check_navigation_file", "check_observation_file",
    "first_near_pair", "galileo_nav", "gpstime", "implausible_orbit", "navigation_extras",
    "orbit_limits", "read_beidou_records", "read_clock_rinex", "read_navigation",
    "read_observation_table", "read_observations", "read_sem_records", "read_sp3",
    "read_towers_csv", "read_yuma_records", "rinex_clk", "rinex_obs", "tgd_at",
]

# The recordings' reader and writer need pandas (~0.5 s to import): ``recording`` and its
# names load on first use (PEP 562), so `import oaraim.readers` does not pay for them.
_RECORDING_NAMES = ("FORMAT_NAME", "FORMAT_VERSION", "EpochMatrix", "Recording",
                    "RecordingError", "RecordingWarning", "epochs", "gnss_matrix",
                    "jpl_quaternion_matrix", "load_recording", "pseudorange_matrix",
                    "sort_recording", "t_gps_s", "tower_clock_m", "transmitters_ecef_m",
                    "validate_recording", "write_recording")
__all__ += ["recording", *_RECORDING_NAMES]


def __getattr__(name):
    if name == "recording" or name in _RECORDING_NAMES:
        import importlib

        module = importlib.import_module("oaraim.readers.recording")
        return module if name == "recording" else getattr(module, name)
    raise AttributeError(f"module 'oaraim.readers' has no attribute {name!r}")
