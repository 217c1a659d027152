"""What a user gives the availability map, parsed and checked before any computation: grid
axes, orbit files, limits, the tower CSV and coastlines (GeoJSON). Errors name the parameter
or the file and line, and say what is expected."""

import csv
import io
import re
from pathlib import Path

import numpy as np

from oaraim.geometry import geodetic_to_ecef
from oaraim.readers import MIN_SEPARATION_M, first_near_pair
from oaraim.studies.base import in_range, keyword_or_file, positive

# ------------------------------------------------------------------------------------ grids


def parse_grid(lo, hi):
    """A grid axis in degrees: ``START:STOP:STEP`` (STOP included when on the grid) or a
    comma-separated list; values within [lo, hi], sorted, no duplicates."""

    def parse(name, v):
        if isinstance(v, list | tuple):
            vals = [float(x) for x in v]
        else:
            s = str(v).strip()
            try:
                if ":" in s:
                    a, b, step = (float(x) for x in s.split(":"))
                    if step <= 0 or b < a:
                        raise ValueError
                    n = int(np.floor((b - a) / step + 1e-9)) + 1
                    vals = [round(a + k * step, 9) for k in range(n)]
                else:
                    vals = [float(x) for x in s.split(",")]
            except ValueError:
                raise ValueError(f"{name} takes START:STOP:STEP (e.g. -90:90:10) or a comma "
                                 f"list of degrees, got {v!r}") from None
        if not vals or any(not (lo <= x <= hi) for x in vals):
            raise ValueError(f"{name} values must lie in [{lo}, {hi}] deg, got {v!r}")
        if len(set(vals)) != len(vals):
            raise ValueError(f"{name} lists a value twice: {v!r}")
        return tuple(sorted(vals))

    return parse


def parse_orbits(default_file):
    """'auto' (``default_file`` from the data registry, fetched if missing), 'nominal' (the
    built-in constellation), 'none', or a YUMA / SEM almanac or RINEX navigation file, read
    and checked now (a malformed file or an implausible orbit names its file and line before
    anything is written)."""
    keywords = ("auto", "nominal", "none")
    path_or_keyword = keyword_or_file(keywords,
                                      f"almanac or navigation file ('auto': {default_file})")

    def parse(name, v):
        s = path_or_keyword(name, v)
        if s not in keywords:
            from oaraim.geometry import resolve_source

            resolve_source(s, (name,) if name in ("gps", "galileo") else ("gps", "galileo"))
        return s

    return parse


def parse_limit(name, v):
    """'preset' (the service level's value), 'none' (not applied) or metres > 0."""
    s = str(v).strip()
    if s in ("preset", "none"):
        return s
    return positive(name, s)


def parse_target(name, v):
    """'preset' (the service level's integrity target) or a probability in [1e-9, 1]."""
    s = str(v).strip()
    return s if s == "preset" else in_range(1e-9, 1.0)(name, s)


def parse_towers(name, v):
    """'none' or a tower CSV (``read_towers``), read and checked now; returns its path."""
    s = str(v).strip()
    if s == "none":
        return s
    p = Path(s).expanduser()
    if not p.is_file():
        raise ValueError(f"{name} must be 'none' or a CSV file with columns lat_deg, lon_deg, "
                         f"height_m, carrier; got {v!r} (not found)")
    read_towers(p)  # checked now, before any computation
    return str(p.resolve())


class TowerFileError(ValueError):
    """A tower CSV that cannot be used: names the file and the line."""


def read_towers(path):
    """Towers of a CSV (lat_deg, lon_deg, height_m, carrier): arrays and the carrier names
    (sorted; carrier k becomes SOP constellation 2 + k). UTF-8, a byte-order mark accepted
    (Excel's "CSV UTF-8"); bytes that are not UTF-8, broken quoting, a short or long row, a
    non-number, a value out of range, a row given twice (two rows of one carrier closer than
    ``readers.MIN_SEPARATION_M``, 1 m) or a last line without its line break (a
    file cut short) is a ``TowerFileError`` (a ValueError) naming the file and line."""
    need = ("lat_deg", "lon_deg", "height_m", "carrier")
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
    xyz = np.asarray(geodetic_to_ecef(np.radians(lat), np.radians(lon), np.asarray(h, float)))
    near = first_near_pair(xyz, car)
    if near is not None:
        a, b, d = near
        again = "again" if d < 1e-6 else f"again ({d:.3g} m from it)"  # 1e-6: rounding
        raise TowerFileError(f"tower file {path}, line {line_of[b]}: the tower of line "
                             f"{line_of[a]} {again}: two rows of carrier {car[b]!r} closer "
                             f"than {MIN_SEPARATION_M:g} m are one transmitter given twice (it "
                             "would count as two independent ranges); one row per transmitter "
                             "(carriers sharing a mast: one row each)")
    names = sorted(set(car))
    return (np.array(lat), np.array(lon), np.array(h),
            np.array([names.index(c) for c in car]), names)


def parse_geojson(name, v):
    """'none' or a GeoJSON file of coastlines (LineString, MultiLineString, Polygon or
    MultiPolygon features in lon/lat degrees, e.g. Natural Earth's coastline)."""
    s = str(v).strip()
    if s == "none":
        return s
    p = Path(s).expanduser()
    try:
        read_lines(p)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{name} must be 'none' or a GeoJSON file of lines or polygons in "
                         f"lon/lat degrees; {s!r}: {e}") from None
    return str(p.resolve())


def read_lines(path):
    """Polylines (list of (N, 2) lon/lat arrays) of a GeoJSON file."""
    import json

    doc = json.loads(Path(path).read_text())
    feats = doc["features"] if doc.get("type") == "FeatureCollection" else [doc]
    lines = []
    for f in feats:
        g = f.get("geometry", f)
        t, c = g["type"], g["coordinates"]
        if t == "LineString":
            parts = [c]
        elif t in ("MultiLineString", "Polygon"):
            parts = c
        elif t == "MultiPolygon":
            parts = [ring for poly in c for ring in poly]
        else:
            continue
        lines += [np.asarray(x, float)[:, :2] for x in parts if len(x) > 1]
    if not lines:
        raise ValueError("no LineString/Polygon geometry found")
    return lines
