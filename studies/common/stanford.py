"""Stanford diagrams (position error against protection level), as the WAAS and EGNOS
performance reports draw them: log axes, the four regions shaded and each region's epochs
counted.

With an alert limit AL, an epoch with a position error PE and a protection level PL is

- *normal operation*: PL <= AL and PE <= PL;
- *misleading information* (MI): PL <= AL and PL < PE <= AL;
- *hazardously misleading information* (HMI): PL <= AL < PE;
- *unavailable*: PL > AL or the PL not computable (inf); of these, the epochs with PE > PL
  ("unavailable and MI" in the reports) are counted apart too.

An epoch without a position (PE not finite) is in none and is counted as ``no_position``.
``<=`` matches the availability criterion (``araim.availability``: HPL <= HAL). The studies
count the regions (``stanford_counts``) in their results; the figure reads those counts.
"""

from typing import NamedTuple

import numpy as np

#: the regions in the order they are listed, with their shading (WAAS / EGNOS style)
REGIONS = {"normal": ("normal operation", "#d9f0d3"),
           "mi": ("MI", "#fdae6b"),
           "hmi": ("HMI", "#de2d26"),
           "unavailable": ("unavailable", "#fff3a0")}
#: the axes of every Stanford diagram, metres (fixed, so diagrams compare by eye); errors or
#: PLs outside are drawn at the nearest edge and said so in the figure
AXIS_M = (1e-2, 1e3)
#: histogram bins per decade
BINS_PER_DECADE = 20


def stanford_counts(pe_m, pl_m, al_m):
    """Epochs per region (module docstring) as plain ints: normal, mi, hmi, unavailable,
    unavailable_mi (PE > a finite PL > AL), pl_not_computable, no_position, epochs."""
    pe, pl = np.asarray(pe_m, float), np.asarray(pl_m, float)
    pos = np.isfinite(pe)
    ok = pos & np.isfinite(pl) & (pl <= al_m)
    return {"normal": int(np.sum(ok & (pe <= pl))),
            "mi": int(np.sum(ok & (pe > pl) & (pe <= al_m))),
            "hmi": int(np.sum(ok & (pe > al_m))),
            "unavailable": int(np.sum(pos & ~ok)),
            "unavailable_mi": int(np.sum(pos & ~ok & np.isfinite(pl) & (pe > pl))),
            "pl_not_computable": int(np.sum(pos & ~np.isfinite(pl))),
            "no_position": int(np.sum(~pos)), "epochs": int(pe.size)}


class StanfordLabels(NamedTuple):
    """The texts of one Stanford diagram."""

    error: str
    """The x axis: the position error, e.g. "HPE (m)"."""
    pl: str
    """The y axis: the protection level, e.g. "HPL (m)"."""
    title: str
    """The panel title (the notes on PLs that could not be computed follow it)."""


def draw_stanford(fig, ax, pe_m, pl_m, al_m, counts, labels: StanfordLabels):
    """One Stanford diagram on ``ax``: the four regions shaded and labelled with their stored
    ``counts`` (``stanford_counts``), the epochs as a 2-D histogram on log axes (``AXIS_M``,
    ``BINS_PER_DECADE``), PLs that could not be computed on the top edge."""
    error_label, pl_label, title = labels
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import LogLocator

    lo, hi = AXIS_M
    al = float(al_m)
    pe, pl = np.asarray(pe_m, float), np.asarray(pl_m, float)
    for key, xs, ys in (("normal", (lo, al, lo), (lo, al, al)),
                        ("mi", (lo, al, al, lo), (lo, lo, al, lo)),
                        ("hmi", (al, hi, hi, al), (lo, lo, al, al)),
                        ("unavailable", (lo, hi, hi, lo), (al, al, hi, hi))):
        ax.fill(xs, ys, color=REGIONS[key][1], alpha=0.55, lw=0, zorder=0)
    ax.plot([lo, hi], [lo, hi], color="k", lw=0.8, zorder=2)
    ax.axvline(al, color="k", lw=0.8, ls="--", zorder=2)
    ax.axhline(al, color="k", lw=0.8, ls="--", zorder=2)
    pos = np.isfinite(pe)
    edge = hi * 10 ** (-0.5 / BINS_PER_DECADE)  # the middle of the top / right bin
    x = np.clip(pe[pos], lo, edge)
    y = np.clip(np.where(np.isfinite(pl[pos]), pl[pos], edge), lo, edge)
    bins = np.logspace(np.log10(lo), np.log10(hi),
                       int(round(BINS_PER_DECADE * np.log10(hi / lo))) + 1)
    mesh = None
    if x.size:
        h, xb, yb = np.histogram2d(x, y, bins=(bins, bins))
        h = np.where(h > 0, h, np.nan)
        mesh = ax.pcolormesh(xb, yb, h.T, norm=LogNorm(vmin=1, vmax=max(2, counts["epochs"])),
                             cmap="viridis", zorder=3)
        fig.colorbar(mesh, ax=ax, label="epochs per bin (log; scale to all epochs)", pad=0.02,
                     shrink=0.8,
                     ticks=LogLocator(subs=(1.0, 2.0, 5.0)), format="%g")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")
    ax.set_xlabel(error_label)
    ax.set_ylabel(pl_label)
    n = max(counts["epochs"] - counts["no_position"], 1)
    txt = dict(fontsize=7, zorder=4, color="0.25")
    ax.text(lo * 1.5, lo * 40, "normal\noperation", ha="left", va="bottom", **txt)
    ax.text(al * 0.8, lo * 1.5, "MI", ha="right", va="bottom", **txt)
    ax.text(hi * 0.7, lo * 1.5, "HMI", ha="right", va="bottom", **txt)
    ax.text(hi * 0.7, hi * 0.7, "unavailable", ha="right", va="top", **txt)
    from matplotlib.patches import Patch

    handles = []
    for key, (label, colour) in REGIONS.items():
        extra = (f", of which PE > PL {counts['unavailable_mi']:,}"
                 if key == "unavailable" and counts["unavailable_mi"] else "")
        handles.append(Patch(facecolor=colour, alpha=0.55, edgecolor="k", lw=0.4,
                             label=f"{label}: {counts[key]:,} ({100 * counts[key] / n:.3g} %)"
                                   f"{extra}"))
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2,
              fontsize=7, frameon=False, title="epochs per region", title_fontsize=7)
    notes = []
    if counts["pl_not_computable"]:
        notes.append(f"{counts['pl_not_computable']:,} PLs not computable: top edge")
    if counts["no_position"]:
        notes.append(f"{counts['no_position']:,} epochs without a position: not drawn")
    if np.any(pe[pos] < lo) or np.any(pe[pos] > hi) or np.any(pl[np.isfinite(pl)] > hi) \
            or np.any(pl[np.isfinite(pl)] < lo):
        notes.append(f"values beyond {lo:g}-{hi:g} m drawn at the edge")
    ax.set_title(title + ("\n" + "; ".join(notes) if notes else ""), fontsize=8)
    return mesh
