"""With against without SOPs: the GNSS-only maps a run with SOPs stores beside its own
(``sop_difference=yes``), their differences (with minus without) and the coverage table."""

import numpy as np

from oaraim.araim import availability as av


def point_maps(available, hpl_m, vpl_m):
    """Per grid point: availability (share of epochs), 99.5 % HPL and VPL (inf where more
    than 0.5 % of the epochs have no PL)."""
    return (av.availability(available, axis=-1), av.pl_percentile(hpl_m, 99.5),
            av.pl_percentile(vpl_m, 99.5))


def pl_difference(with_m, without_m):
    """PL with minus without SOPs where both are finite, NaN elsewhere (never inf - inf)."""
    both = np.isfinite(with_m) & np.isfinite(without_m)
    return np.where(both, np.where(both, with_m, 0.0) - np.where(both, without_m, 0.0), np.nan)


def _median(x):
    x = np.asarray(x)[np.isfinite(x)]
    return float(np.median(x)) if x.size else None


def coverage_table(lats, target, with_maps, gnss_maps):
    """Rows (quantity, GNSS only, GNSS + SOPs, with - without) as formatted text for the
    figure, and the metrics (numbers) of the same comparison."""
    def cov(avail):
        return (100.0 * av.coverage(avail, lats, target) if np.any(np.abs(lats) < 90)
                else float("nan"))

    (a_w, h_w, v_w), (a_g, h_g, v_g) = with_maps, gnss_maps
    values = [
        ("coverage (% of area at availability >= target)", "pct", cov(a_g), cov(a_w)),
        ("mean availability (%)", "pct", 100 * float(a_g.mean()), 100 * float(a_w.mean())),
        ("lowest availability (%)", "pct", 100 * float(a_g.min()), 100 * float(a_w.min())),
        ("median 99.5 % VPL over the points (m)", "m", _median(v_g), _median(v_w)),
        ("median 99.5 % HPL over the points (m)", "m", _median(h_g), _median(h_w)),
        ("points with a computable 99.5 % VPL", "n", int(np.isfinite(v_g).sum()),
         int(np.isfinite(v_w).sum())),
    ]
    rows, metrics = [], {}
    keys = ("coverage", "availability_mean", "availability_min", "vpl_995_median",
            "hpl_995_median", "points_vpl_995_computable")
    for key, (q, kind, g, w) in zip(keys, values, strict=True):
        d = None if g is None or w is None else w - g
        fmt = (lambda x: "-" if x is None else f"{x:.3f}") if kind != "n" else str  # noqa: E731
        sign = "" if d is None or kind == "n" else "+" if d >= 0 else ""
        rows.append({"quantity": q, "gnss_only": fmt(g), "with_sops": fmt(w),
                     "difference": sign + fmt(d)})
        unit = "_pct" if kind == "pct" else "_m" if kind == "m" else ""
        metrics.update({f"{key}_gnss_only{unit}": g, f"{key}_with_sops{unit}": w,
                        f"{key}_difference{unit}": d})
    return rows, metrics
