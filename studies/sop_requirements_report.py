"""The ``sop-requirements`` study's results: dataset, summary rows and figures."""

from typing import NamedTuple

import numpy as np
import xarray as xr

from oaraim.studies.base import StudyResult
from oaraim.studies.common import seed004 as c
from oaraim.studies.common.plotting import P_S_SOP_LABEL, SIGMA_URA_SOP_LABEL, categorical_ticks


def within_one_step(root, bound, grid=c.SIGMA_GRID_M):
    """True where the Newton root lies in [grid boundary, next grid value) (both NaN, or the
    root beyond the grid with the boundary its last value, count as agreeing)."""
    grid = np.asarray(grid, float)
    root, bound = np.asarray(root, float), np.asarray(bound, float)
    nxt = np.array([grid[min(np.searchsorted(grid, b) + 1, grid.size - 1)]
                    if np.isfinite(b) else np.nan for b in bound.ravel()]).reshape(bound.shape)
    last = np.isfinite(bound) & (bound == grid[-1])
    ok = (root >= bound - 1e-9) & ((root < nxt) | (last & (root >= grid[-1])))
    none = np.isnan(bound) & (np.isnan(root) | (root < grid[0]))
    return ok | none


class RequirementsOutcome(NamedTuple):
    """What a run of ``studies.sop_requirements`` computed, the input of ``finish``."""

    roots: np.ndarray
    """(n_sops, p_s_sop) m: the largest sigma_URA^S that still reduces the HPL (Newton)."""
    steps: np.ndarray
    """(n_sops, p_s_sop): Newton steps per root."""
    evals_newton: int
    """Evaluations the roots cost."""
    bound: np.ndarray
    """(n_sops, check_p_s) m: Fig. 4's grid boundary."""
    evals_grid: int
    """Evaluations the grid boundaries cost."""
    sens: np.ndarray
    """(3, map_n_sops, map_p_s_sop, map_sigma_ura_sop_m): mean HPL m and its derivatives."""


def finish(params, d, realizations, outcome: RequirementsOutcome):
    """The ``StudyResult`` of ``studies.sop_requirements`` from its ``outcome``: roots, grid
    boundaries and sensitivity maps."""
    roots, steps, evals_newton, bound, evals_grid, sens = outcome
    ns, ps, cps = params["n_sops"], params["p_s_sop"], params["check_p_s"]
    jc = [int(np.argmin(np.abs(np.log(np.asarray(ps)) - np.log(p)))) for p in cps]
    matched = np.isclose(np.asarray(ps)[jc], cps, rtol=1e-9)
    r_at = roots[:, jc]
    agree = within_one_step(r_at, bound) | ~matched[None]
    ds = xr.Dataset(
        {"largest_reducing_sigma_ura_sop_m": (("n_sops", "p_s_sop"), roots),
         "newton_steps": (("n_sops", "p_s_sop"), steps),
         "grid_boundary_sigma_ura_sop_m": (("n_sops", "check_p_s"), bound),
         "root_within_one_grid_step": (("n_sops", "check_p_s"), agree),
         "map_mean_hpl_sop_m": (("map_n_sops", "map_p_s_sop", "map_sigma_ura_sop_m"), sens[0]),
         "map_dhpl_dsigma": (("map_n_sops", "map_p_s_sop", "map_sigma_ura_sop_m"), sens[1]),
         "map_dhpl_dlog10_p_s_m": (("map_n_sops", "map_p_s_sop", "map_sigma_ura_sop_m"),
                                   sens[2])},
        coords={"n_sops": list(ns), "p_s_sop": list(ps), "check_p_s": list(cps),
                "map_n_sops": list(params["map_n_sops"]),
                "map_p_s_sop": list(params["map_p_s_sop"]),
                "map_sigma_ura_sop_m": list(params["map_sigma_ura_sop_m"]),
                "sigma_grid_m": list(c.SIGMA_GRID_M)},
        attrs={"realizations": int(realizations), "tol_m": c.TOL_M,
               "evaluations_newton": int(evals_newton), "evaluations_grid": int(evals_grid),
               "sky_source": d["table"]["description"]})
    per_root = evals_newton / max(roots.size, 1)
    per_grid = evals_grid / max(bound.size, 1)
    rows = [{"quantity": "Newton roots within one grid step of Fig. 4's grid boundary "
                         "(same draws)", "unit": "%", "published": 100.0,
             "reproduced": 100.0 * float(np.mean(agree)),
             "note": f"{bound.size} (n, P_s^S) pairs at P_s^S = "
                     + ", ".join(f"{p:g}" for p in cps) + f"; {realizations} draws"},
            {"quantity": "evaluations per boundary: Newton (values + derivatives) / grid",
             "unit": "-", "published": None, "reproduced": per_root / per_grid,
             "note": f"{per_root:.1f} against {per_grid:.0f} (26 grid values)"}]
    j4 = [j for j, p in enumerate(ps) if np.isclose(p, 1e-4)]
    if j4:
        for i, n in enumerate(ns):
            rows.append({"quantity": f"largest sigma_URA^S still reducing the mean HPL at "
                                     f"P_s^S = 1e-4, {n} SOPs", "unit": "m", "published": None,
                         "reproduced": float(roots[i, j4[0]]),
                         "note": "Fig. 4 gives no number; NaN: none, inf: beyond 25 m"})
    metrics = {"roots_m": {str(n): [None if not np.isfinite(r) else round(float(r), 4)
                                    for r in roots[i]] for i, n in enumerate(ns)},
               "p_s_sop": list(ps), "evaluations_newton": int(evals_newton),
               "evaluations_grid": int(evals_grid), "sky_source": d["table"]["description"],
               "mean_newton_steps": float(np.mean(steps))}
    return StudyResult(ds, rows, metrics)


def plot(ds, out_dir):
    """The study's two figures from its stored dataset; returns their paths."""
    import matplotlib.pyplot as plt

    paths = []
    fig, ax = plt.subplots(figsize=(7.0, 4.6))
    ps = ds["p_s_sop"].values
    cps = ds["check_p_s"].values
    for i, n in enumerate(ds["n_sops"].values):
        r = ds["largest_reducing_sigma_ura_sop_m"].values[i]
        line, = ax.plot(ps, np.where(np.isfinite(r), r, np.nan), "o-", ms=4,
                        label=f"{n} SOPs (Newton)")
        b = ds["grid_boundary_sigma_ura_sop_m"].values[i]
        ax.plot(cps, b, "s", mfc="none", ms=9, color=line.get_color())
    ax.plot([], [], "ks", mfc="none", label="Fig. 4 grid boundary (same draws)")
    ax.set_xscale("log")
    ax.set_xlabel(P_S_SOP_LABEL)
    ax.set_ylabel(r"largest $\sigma_{\mathrm{URA}}^{S}$ still lowering the mean HPL (m)")
    ax.set_title(f"SOP requirements ({ds.attrs['realizations']} draws; Newton "
                 f"{ds.attrs['evaluations_newton']} evaluations, grid "
                 f"{ds.attrs['evaluations_grid']})", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    p = f"{out_dir}/sop_requirements.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)

    mn = ds["map_n_sops"].values
    fig, axes = plt.subplots(2, len(mn), figsize=(4.6 * len(mn), 7.0), squeeze=False,
                             layout="constrained")
    sig = ds["map_sigma_ura_sop_m"].values
    mp = ds["map_p_s_sop"].values
    for col, n in enumerate(mn):
        for row, (var, what) in enumerate((
                ("map_dhpl_dsigma", r"$\partial$ mean HPL / $\partial\sigma_{\mathrm{URA}}^{S}$"
                 " (m/m)"),
                ("map_dhpl_dlog10_p_s_m", r"$\partial$ mean HPL / $\partial\log_{10}P_{s}^{S}$"
                 " (m)"))):
            ax = axes[row, col]
            z = ds[var].values[col]
            lim = float(np.nanmax(np.abs(z))) or 1.0
            im = ax.pcolormesh(np.arange(sig.size), np.arange(mp.size), z, cmap="RdBu_r",
                               vmin=-lim, vmax=lim, shading="nearest")
            categorical_ticks(ax.xaxis, sig)
            categorical_ticks(ax.yaxis, mp, powers_of_ten=True)
            ax.tick_params(labelsize=7)
            ax.set_xlabel(SIGMA_URA_SOP_LABEL)
            ax.set_ylabel(P_S_SOP_LABEL)
            ax.set_title(f"{n} SOPs: {what}", fontsize=9)
            fig.colorbar(im, ax=ax, label="symmetric scale: +- the panel's largest |value|")
    p = f"{out_dir}/sop_requirements_sensitivity.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths
