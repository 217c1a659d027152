"""What a user gives the availability map, parsed and checked before any computation: grid
axes, orbit files, limits, the tower CSV and coastlines (GeoJSON). Errors name the parameter
or the file and line, and say what is expected."""

from pathlib import Path

import numpy as np

from oaraim.geometry import geodetic_to_ecef
from oaraim.readers import MIN_SEPARATION_M, TowerFileError, first_near_pair, read_towers_csv
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


def read_towers(path):
    """Towers of a CSV (lat_deg, lon_deg, height_m, carrier): arrays and the carrier names
    (sorted; carrier k becomes SOP constellation 2 + k). The file is read and checked by
    ``readers.read_towers_csv`` (its format and errors); here, where the towers are placed in
    ECEF (``geometry.geodetic_to_ecef``), a row given twice (two rows of one carrier closer
    than ``readers.MIN_SEPARATION_M``, 1 m) is a ``TowerFileError`` (a ValueError) naming the
    file and line. Returns ``(lat_deg, lon_deg, height_m, carrier_index, names)``."""
    rec = read_towers_csv(path)
    car = rec.carrier.tolist()
    xyz = np.asarray(geodetic_to_ecef(np.radians(rec.lat_deg), np.radians(rec.lon_deg),
                                      rec.height_m))
    near = first_near_pair(xyz, car)
    if near is not None:
        a, b, d = near
        again = "again" if d < 1e-6 else f"again ({d:.3g} m from it)"  # 1e-6: rounding
        raise TowerFileError(f"tower file {path}, line {rec.line[b]}: the tower of line "
                             f"{rec.line[a]} {again}: two rows of carrier {car[b]!r} closer "
                             f"than {MIN_SEPARATION_M:g} m are one transmitter given twice (it "
                             "would count as two independent ranges); one row per transmitter "
                             "(carriers sharing a mast: one row each)")
    names = sorted(set(car))
    return (rec.lat_deg, rec.lon_deg, rec.height_m,
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
