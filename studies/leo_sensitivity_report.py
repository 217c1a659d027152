"""The ``leo-sensitivity`` study's summary and figure (reads what the run computed)."""

import numpy as np

from oaraim.studies.base import StudyResult


def finish(params, ds, realizations):
    """Summary rows (no paper prints these numbers: ``published`` None), metrics and the
    dataset."""
    rows, metrics = [], {}
    for c in ds.constellation.values:
        for n in ds.n_leo.values:
            sel = ds.sel(constellation=c, n_leo=n)
            share = float(sel.share_n_in_view)
            for p in ds.p_s_leo.values:
                r = float(sel.sigma_boundary_m.sel(p_s_leo=p))
                key = f"{c}_n{int(n)}_ps{p:g}"
                metrics[f"sigma_boundary_m_{key}"] = None if np.isnan(r) else r
            best = sel.vpl_change_m.min()
            metrics[f"vpl_change_min_m_{c}_n{int(n)}"] = (None if np.isnan(float(best))
                                                          else float(best))
            metrics[f"share_n_in_view_{c}_n{int(n)}"] = share
            p0 = float(ds.p_s_leo.values[0])
            r0 = float(sel.sigma_boundary_m.sel(p_s_leo=p0))
            rows.append({"quantity": f"{c}, {int(n)} LEO used: largest sigma_URA^LEO still "
                         f"lowering the mean VPL (P_s^LEO {p0:g})", "unit": "m",
                         "published": None, "reproduced": r0,
                         "note": f"Newton on exact derivatives; {100 * share:.1f} % of the "
                         f"users see >= {int(n)} (none: NaN); inf: still helps at "
                         "128 m (the largest probe), NaN: not even at 0.25 m"})
    metrics["realizations"] = int(realizations)
    metrics["fault_modes"] = params["fault_modes"]
    ds = ds.assign_attrs(fault_modes=params["fault_modes"])
    metrics["boundary_evaluations"] = int(ds.boundary_evaluations.sum())
    return StudyResult(ds, rows, metrics, {})


def plot(ds, out_dir):
    """leo_sensitivity.png: per constellation (rows) and n (columns) the mean VPL change
    (m, diverging, fixed scale -5..5 m; grey: no user sees n, or no PL) over sigma_URA^LEO x
    P_s^LEO, with the Newton boundary (black)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import TwoSlopeNorm

    cs, ns = list(ds.constellation.values), list(ds.n_leo.values)
    sig = np.asarray(ds.sigma_ura_leo_m.values, float)
    ps = np.asarray(ds.p_s_leo.values, float)
    size = (max(3.6 * len(ns) + 1.2, 7.0), 2.9 * len(cs) + 0.8)
    fig, axes = plt.subplots(len(cs), len(ns), figsize=size, squeeze=False, sharex=True,
                             sharey=True, layout="constrained")
    norm = TwoSlopeNorm(vmin=-5.0, vcenter=0.0, vmax=5.0)
    cmap = matplotlib.colormaps["RdBu_r"].copy()
    cmap.set_bad("0.8")
    mesh = None
    for i, c in enumerate(cs):
        for j, n in enumerate(ns):
            ax = axes[i, j]
            z = np.asarray(ds.vpl_change_m.sel(constellation=c, n_leo=n).values, float)
            mesh = ax.pcolormesh(np.arange(sig.size + 1), np.arange(ps.size + 1),
                                 np.ma.masked_invalid(z), cmap=cmap, norm=norm)
            root = np.asarray(ds.sigma_boundary_m.sel(constellation=c, n_leo=n).values)
            x = np.interp(np.log(np.clip(root, sig[0], sig[-1])), np.log(sig),
                          np.arange(sig.size) + 0.5)
            fin = np.isfinite(root)
            ax.plot(x[fin], np.arange(ps.size)[fin] + 0.5, "k-o", ms=3, lw=1.2)
            ax.set_xticks(np.arange(sig.size) + 0.5, [f"{s:g}" for s in sig], fontsize=7)
            ax.set_yticks(np.arange(ps.size) + 0.5, [f"{p:.0e}" for p in ps], fontsize=7)
            share = float(ds.share_n_in_view.sel(constellation=c, n_leo=n))
            ax.set_title(f"{c}, n = {int(n)} ({100 * share:.0f} % of users)", fontsize=9)
            if i == len(cs) - 1:
                ax.set_xlabel("sigma_URA^LEO (m)")
            if j == 0:
                ax.set_ylabel("P_s^LEO")
    fig.colorbar(mesh, ax=axes, label="mean VPL change (m); < 0: LEO helps", shrink=0.8)
    fig.suptitle(f"GPS + Galileo + n LEO satellites ({ds.attrs.get('fault_modes', '')}, "
                 "LPV-200): mean VPL change\n"
                 "black: largest sigma_URA^LEO still lowering it (Newton); grey: no user sees n",
                 fontsize=10)
    path = f"{out_dir}/leo_sensitivity.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path]
