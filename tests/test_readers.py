"""The readers layer (``oaraim.readers``): its face, what it leaves out of an import, the names
kept in ``oaraim.geometry`` for code written before the move, and the orbits geometry makes of
the readers' records."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from oaraim import geometry, readers

ROOT = Path(__file__).resolve().parents[1]

#: names that lived in oaraim.geometry before the readers were a layer; they must stay the very
#: objects of oaraim.readers (not copies: an ``except geometry.NavigationFileError`` must catch
#: what the readers raise)
KEPT_IN_GEOMETRY = (
    "GALILEO", "GPS", "MIN_SEPARATION_M", "AlmanacFileError", "ClockFileError",
    "NavigationFileError", "ObservationFileError", "ObservationTable", "Observations",
    "PreciseClocks", "PreciseOrbits", "SP3Error", "check_navigation_file", "first_near_pair",
    "galileo_nav", "gpstime", "read_clock_rinex", "read_observation_table", "read_observations",
    "read_sp3", "rinex_clk", "rinex_obs", "FORMAT_NAME", "FORMAT_VERSION", "Recording",
    "RecordingError", "gnss_matrix", "load_recording", "pseudorange_matrix", "tower_clock_m",
    "validate_recording", "write_recording", "recording",
)


def test_every_name_of_the_face_resolves():
    for name in readers.__all__:
        assert getattr(readers, name) is not None, name


def test_the_old_geometry_names_are_the_readers_objects():
    for name in KEPT_IN_GEOMETRY:
        assert getattr(geometry, name) is getattr(readers, name), name


def test_importing_the_readers_loads_neither_geometry_nor_pandas():
    """The layer imports only oaraim.constants of the package, and the recordings' pandas on
    first use: measured in a fresh interpreter."""
    code = ("import sys, oaraim.readers as r; "
            "print(sorted(m for m in sys.modules if m.startswith('oaraim.')"
            " and not m.startswith(('oaraim.readers', 'oaraim.constants', 'oaraim.config',"
            " 'oaraim._compile_cache')))); print('pandas' in sys.modules); "
            "r.load_recording; print('pandas' in sys.modules)")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), *sys.path]))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         cwd="/", check=True).stdout.split("\n")
    assert out[:3] == ["[]", "False", "True"], out


def test_geometry_makes_its_orbits_of_the_readers_records(shared_data):
    """``geometry.load_navigation`` and ``geometry.read_yuma`` hold exactly the records the
    readers return: every record, field for field."""
    nav = shared_data / "nav" / "brdc1820.10n"
    recs = readers.read_navigation(nav, systems=("G",))
    eph = geometry.load_navigation(nav, systems=("G",))
    assert int(eph.n_records.sum()) == recs.records["sv"].size == 421  # the file's records
    assert list(eph.prns) == sorted(set(recs.records["sv"]))
    healthy_toe = np.sort(recs.records["toe_s"][recs.records["health"] == 0])
    np.testing.assert_array_equal(np.sort(eph.toe_healthy_s), healthy_toe)

    yuma = shared_data / "almanac" / "almyuma_01jan2020.txt"
    records = readers.read_yuma_records(yuma)
    alm = geometry.read_yuma(yuma)
    for field in records._fields:
        np.testing.assert_array_equal(getattr(alm.records, field), getattr(records, field))
    assert alm.prns.size == records.prn.size == 31
