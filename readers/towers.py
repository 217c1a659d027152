"""Tower CSV files: the transmitters (SOP towers) a user gives the availability maps.

A tower file is a UTF-8 CSV with a header naming (at least) the columns ``lat_deg``,
``lon_deg``, ``height_m`` and ``carrier``, one row per transmitter (carriers sharing a mast:
one row each); other columns are allowed and ignored, blank lines are skipped, and a UTF-8
byte-order mark (Excel's "CSV UTF-8") is accepted::

    lat_deg,lon_deg,height_m,carrier
    50.01,0.0,40,A
    50.0,0.02,30,B

``read_towers_csv`` returns what the file holds, checked (``TowerRecords``). A transmitter
given twice (two rows of one carrier closer than ``transmitters.MIN_SEPARATION_M``) is found
where the towers are placed in ECEF (``studies.availability_map.read_towers`` with
``geometry.geodetic_to_ecef`` and ``transmitters.first_near_pair``): the distance is one of
positions, which this layer does not compute.
"""

import csv
import io
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

__all__ = ["TOWER_COLUMNS", "TowerFileError", "TowerRecords", "read_towers_csv"]

#: the columns a tower file must have (its header names them; others are ignored)
TOWER_COLUMNS = ("lat_deg", "lon_deg", "height_m", "carrier")


class TowerFileError(ValueError):
    """A tower CSV that cannot be used: names the file and the line."""


class TowerRecords(NamedTuple):
    """The rows of a tower CSV, in file order (n rows; blank lines skipped)."""

    lat_deg: np.ndarray
    """Geodetic latitude (deg), float64 (n,), in [-90, 90]."""
    lon_deg: np.ndarray
    """Longitude (deg), float64 (n,), in [-180, 360] as written."""
    height_m: np.ndarray
    """Height above the WGS-84 ellipsoid (m), float64 (n,), in [-500, 9000]."""
    carrier: np.ndarray
    """The carrier of each row (its clock group), str (n,), not empty."""
    line: np.ndarray
    """The file line of each row (1 is the header), int (n,): for messages about a row."""


def read_towers_csv(path: str | Path) -> TowerRecords:
    """The towers of a CSV file (module docstring: the format), checked: bytes that are not
    UTF-8, a control character, broken quoting, a missing column or no row, a short or long
    row, a non-number, a value out of range (lat_deg in [-90, 90], lon_deg in [-180, 360],
    height_m in [-500, 9000] m), an empty carrier or a last line without its line break (a
    file cut short) is a ``TowerFileError`` (a ValueError) of one line naming the file and the
    line."""
    need = TOWER_COLUMNS
    raw = Path(path).read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise TowerFileError(f"tower file {path}, line {line}: not UTF-8 text (byte {e.start}); "
                             "save it as CSV with the columns " + ", ".join(need)) from None
    control = re.search(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]", text)
    if control:
        line = text.count("\n", 0, control.start()) + 1
        raise TowerFileError(f"tower file {path}, line {line}: control character "
                             f"{control.group()!r}: not a text CSV")
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    try:
        header = next(reader, None)
        body = [(reader.line_num, row) for row in reader]
    except csv.Error as e:
        raise TowerFileError(f"tower file {path}, line {reader.line_num}: not CSV ({e})") from None
    header = [h.strip() for h in header] if header else []
    if not body or any(c not in header for c in need):
        raise TowerFileError(f"tower file {path}, line 1: needs a header with the columns "
                             f"{', '.join(need)} and at least one row; got "
                             f"{header if header else 'an empty file'}")
    if not text.endswith(("\n", "\r")):
        raise TowerFileError(f"tower file {path}, line {text.count(chr(10)) + 1}: the last line "
                             "does not end with a line break: the file is truncated")
    col = {c: header.index(c) for c in need}
    lat, lon, h, car, line_of = [], [], [], [], []
    for i, row in body:
        if not any(x.strip() for x in row):
            continue  # a blank line
        if len(row) != len(header):
            raise TowerFileError(f"tower file {path}, line {i}: {len(row)} fields where the "
                                 f"header has {len(header)} ({', '.join(header)})")
        r = {c: row[col[c]].strip() for c in need}
        try:
            la, lo, hh = float(r["lat_deg"]), float(r["lon_deg"]), float(r["height_m"])
        except ValueError:
            raise TowerFileError(f"tower file {path}, line {i}: lat_deg, lon_deg and height_m "
                                 f"must be numbers, got {r}") from None
        if not (-90 <= la <= 90 and -180 <= lo <= 360 and -500 <= hh <= 9000):
            raise TowerFileError(f"tower file {path}, line {i}: lat_deg in [-90, 90], lon_deg "
                                 f"in [-180, 360], height_m in [-500, 9000] m; got {r}")
        if not r["carrier"]:
            raise TowerFileError(f"tower file {path}, line {i}: empty carrier")
        lat.append(la)
        lon.append(lo)
        h.append(hh)
        car.append(r["carrier"])
        line_of.append(i)
    return TowerRecords(np.array(lat, np.float64), np.array(lon, np.float64),
                        np.array(h, np.float64), np.array(car, dtype=str),
                        np.array(line_of, dtype=int))
