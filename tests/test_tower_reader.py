"""The tower CSV reader of the readers layer (``readers.read_towers_csv``): what a hand-written
file holds, and each malformed file as one line naming the file, the line and the problem. The
duplicate-transmitter check stays where the towers are placed in ECEF (the availability map's
``read_towers``); its cases are in tests/test_availability_map.py."""

import numpy as np
import pytest

from oaraim import readers
from oaraim.studies import availability_map as am

#: a hand-written file: an extra column (ignored), spaces around values, a blank line, two
#: carriers on one mast (two rows), longitudes written east of 180
GOOD = ("name,lat_deg,lon_deg,height_m,carrier\n"
        "north, 50.01, 0.0, 40, A\n"
        "\n"
        "east,50.0,359.98,30,B\n"
        "mast,50.01,0.0,40,B\n")


def test_a_good_file_is_its_rows_in_file_order(tmp_path):
    f = tmp_path / "towers.csv"
    f.write_text(GOOD)
    rec = readers.read_towers_csv(f)
    assert isinstance(rec, readers.TowerRecords)
    assert rec.lat_deg.dtype == rec.lon_deg.dtype == rec.height_m.dtype == np.float64
    assert rec.lat_deg.tolist() == [50.01, 50.0, 50.01]
    assert rec.lon_deg.tolist() == [0.0, 359.98, 0.0]  # as written: not wrapped
    assert rec.height_m.tolist() == [40.0, 30.0, 40.0]
    assert rec.carrier.tolist() == ["A", "B", "B"]
    assert rec.line.tolist() == [2, 4, 5]  # the blank line 3 is skipped, not counted as a row


def test_the_study_reads_through_the_reader(tmp_path):
    """The availability map's ``read_towers`` is the reader plus the ECEF duplicate check:
    the same arrays, carriers as indices of the sorted names, the same error class."""
    f = tmp_path / "towers.csv"
    f.write_text(GOOD)
    rec = readers.read_towers_csv(f)
    lat, lon, h, car, names = am.read_towers(f)
    assert np.array_equal(lat, rec.lat_deg) and np.array_equal(lon, rec.lon_deg)
    assert np.array_equal(h, rec.height_m)
    assert names == ["A", "B"] and car.tolist() == [0, 1, 1]
    assert am.TowerFileError is readers.TowerFileError
    assert issubclass(readers.TowerFileError, ValueError)


def test_a_row_given_twice_is_read_and_refused_where_it_is_placed(tmp_path):
    """The reader returns both rows (a distance is geometry); the study refuses them."""
    f = tmp_path / "towers.csv"
    f.write_text(GOOD + "again,50.01,0.0,40,A\n")
    assert readers.read_towers_csv(f).carrier.tolist() == ["A", "B", "B", "A"]
    with pytest.raises(readers.TowerFileError, match=r"line 6: the tower of line 2 again"):
        am.read_towers(f)


@pytest.mark.parametrize("content, message", [
    # a bad column: the header lacks one the reader needs
    ("lat_deg,lon_deg,height,carrier\n50,0,40,A\n",
     r"towers\.csv, line 1: needs a header with the columns lat_deg, lon_deg, height_m, "
     r"carrier and at least one row; got \['lat_deg', 'lon_deg', 'height', 'carrier'\]"),
    # a bad value in a column: not a number
    (GOOD + "x,50.2,0.1,forty,A\n",
     r"towers\.csv, line 6: lat_deg, lon_deg and height_m must be numbers"),
    # a value out of range, one per column
    (GOOD + "x,90.5,0.1,40,A\n", r"towers\.csv, line 6: lat_deg in \[-90, 90\], lon_deg in "
                                 r"\[-180, 360\], height_m in \[-500, 9000\] m; got"),
    (GOOD + "x,50.2,-180.5,40,A\n", r"towers\.csv, line 6: lat_deg in \[-90, 90\]"),
    (GOOD + "x,50.2,0.1,9000.5,A\n", r"towers\.csv, line 6: lat_deg in \[-90, 90\]"),
    (GOOD + "x,50.2,0.1,40, \n", r"towers\.csv, line 6: empty carrier"),
    (GOOD + "x,50.2,0.1,40\n", r"towers\.csv, line 6: 4 fields where the header has 5"),
])
def test_each_malformed_file_is_one_line_naming_file_line_and_problem(tmp_path, content,
                                                                      message):
    f = tmp_path / "towers.csv"
    f.write_text(content)
    with pytest.raises(readers.TowerFileError, match=message) as e:
        readers.read_towers_csv(f)
    assert "\n" not in str(e.value) and str(f) in str(e.value)


def test_the_range_limits_themselves_are_accepted(tmp_path):
    f = tmp_path / "towers.csv"
    f.write_text("lat_deg,lon_deg,height_m,carrier\n-90,-180,-500,A\n90,360,9000,A\n")
    rec = readers.read_towers_csv(f)
    assert rec.lat_deg.tolist() == [-90.0, 90.0] and rec.height_m.tolist() == [-500.0, 9000.0]
