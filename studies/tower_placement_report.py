"""The ``tower-placement`` study's results: dataset, summary rows and figures."""

from typing import NamedTuple

import numpy as np
import xarray as xr

from oaraim.studies.base import StudyResult


class PlacementOutcome(NamedTuple):
    """What a run of ``studies.tower_placement`` computed, the input of ``finish``."""

    rand: np.ndarray
    """(placements, towers, 3) ENU m: the random placements."""
    q_rand: np.ndarray
    """(placements,): their objective."""
    runs: list
    """One ``descend`` per start: (towers, objective, surrogate and objective per
    iteration)."""
    free: tuple
    """The best of ``runs``."""
    sites: np.ndarray
    """(sites, 3) ENU m: the candidate sites."""
    greedy: np.ndarray
    """Indices of the sites greedy + swap selected."""
    q_greedy: float
    """Their objective."""
    swaps: list
    """The greedy + swap history."""
    exh: tuple | None
    """The exhaustive search (best indices, best objective, every subset's objective), None
    when there were more subsets than the limit."""
    refined: tuple
    """The ``descend`` of the greedy selection within its refinement radius."""
    maps: dict
    """{name: (north, east) HPL map m} for the figures."""
    q_gps: float
    """The objective of GPS alone."""


def median_index(q):
    """Index of the upper median of ``q`` (the placement the study shows as "median")."""
    return int(np.argsort(q, kind="stable")[len(q) // 2])


def finish(params, sky, prob, outcome: PlacementOutcome):
    """The ``StudyResult`` of a run of ``studies.tower_placement`` (its ``run`` computes the
    ``outcome``: random placements and their objective, the descents, the selections, maps)."""
    (rand, q_rand, runs, free, sites, greedy, q_greedy, swaps, exh, refined, maps,
     q_gps) = outcome
    n_it = params["iterations"]
    box = params["box_half_m"]
    i_med = median_index(q_rand)
    q_med = float(q_rand[i_med])
    ds = xr.Dataset(
        {"random_objective": ("placement", q_rand),
         "random_towers_enu_m": (("placement", "tower", "enu"), rand),
         "descent_surrogate": (("start", "iteration"), np.stack([r[2] for r in runs])),
         "descent_objective": (("start", "iteration"), np.stack([r[3] for r in runs])),
         "optimised_towers_enu_m": (("tower", "enu"), free[0]),
         "random_median_towers_enu_m": (("tower", "enu"), rand[i_med]),
         "candidate_sites_enu_m": (("site", "enu"), sites),
         "greedy_selected": ("site", np.isin(np.arange(len(sites)), greedy)),
         "exhaustive_selected": ("site", np.isin(np.arange(len(sites)),
                                                 exh[0] if exh else [])),
         "refined_towers_enu_m": (("selected", "enu"), refined[0]),
         "receivers_enu_m": (("receiver", "enu"), prob.receivers),
         **{f"map_{k}_m": (("map_north", "map_east"), v) for k, v in maps.items()}},
        coords={"iteration": np.arange(n_it), "enu": ["east", "north", "up"],
                "map_east": np.linspace(-box, box, maps["gps_only"].shape[1]),
                "map_north": np.linspace(-box, box, maps["gps_only"].shape[0])},
        attrs={"sky_source": sky["description"], "box_half_m": box,
               "objective": f"{prob.label} over receivers x epochs", "unit": prob.unit,
               "objective_gps_only": q_gps, "objective_random_median": q_med,
               "objective_random_best": float(np.min(q_rand)), "objective_optimised": free[1],
               "objective_greedy": q_greedy, "objective_exhaustive": exh[1] if exh else np.nan,
               "objective_refined": refined[1]})
    if not exh:
        gap = float("nan")
    elif prob.kind == "hpl":  # relative, in %
        gap = 100.0 * (q_greedy / exh[1] - 1.0)
    else:  # an unavailability is already a share: the difference, in percentage points
        gap = q_greedy - exh[1]
    n_sub = len(exh[2]) if exh else 0
    setting = (f"{params['grid_n']}^2 receivers in +-{params['region_half_m']:g} m x "
               f"{sky['az_rad'].shape[0]} epochs; sigma_URA^S {params['sigma_ura_sop_m']:g} m, "
               f"P_s^S {params['p_s_sop']:g}; {sky['description']}")
    lab, unit = prob.label, prob.unit
    rows = [
        {"quantity": f"{lab}, GPS only", "unit": unit, "published": None,
         "reproduced": q_gps, "note": setting},
        {"quantity": f"{lab}, {params['n_towers']} random towers (median of "
                     f"{len(q_rand)} placements)", "unit": unit, "published": None,
         "reproduced": q_med,
         "note": f"towers uniform in +-{box:g} m at {params['tower_h_m']:g} m"},
        {"quantity": f"{lab}, best random placement", "unit": unit, "published": None,
         "reproduced": float(np.min(q_rand)), "note": ""},
        {"quantity": f"{lab}, gradient-optimised placement", "unit": unit,
         "published": None, "reproduced": free[1],
         "note": f"projected Adam on the smooth surrogate (tau {params['tau_m']:g} m), "
                 f"{params['starts']} starts x {n_it} steps from the best random placements"},
        {"quantity": f"{lab}, best {params['n_select']} of {len(sites)} sites "
                     "(exhaustive search)", "unit": unit, "published": None,
         "reproduced": exh[1] if exh else float("nan"),
         "note": f"{n_sub} subsets" if exh else "more subsets than exhaustive_limit"},
        {"quantity": f"{lab}, greedy + swap selection", "unit": unit, "published": None,
         "reproduced": q_greedy, "note": f"{len(swaps) - 1} improving swaps"},
        {"quantity": "greedy + swap above the exhaustive best",
         "unit": "%" if prob.kind == "hpl" else "percentage points",
         "published": None, "reproduced": gap,
         "note": "target: within 1 % on the small cases"},
        {"quantity": f"{lab}, selection refined by gradient (towers within "
                     f"{params['refine_radius_m']:g} m of their sites)", "unit": unit,
         "published": None, "reproduced": refined[1], "note": ""},
    ]
    metrics = {"objective": f"{lab} over receivers x epochs (an HPL that cannot be computed "
                            "counts as 1000 m)",
               "evaluations": int(prob.evaluations), "epochs": int(sky["az_rad"].shape[0]),
               "receivers": int(prob.receivers.shape[0]), "sky_source": sky["description"],
               "greedy_sites": [int(i) for i in greedy],
               "exhaustive_sites": [int(i) for i in exh[0]] if exh else None,
               "optimised_towers_enu_m": np.round(free[0], 2).tolist(),
               "improvement_over_random_median_pct":
                   100.0 * (1.0 - free[1] / q_med) if q_med > 0 else float("nan")}
    return StudyResult(ds, rows, metrics)


def plot(ds, out_dir):
    """The two figures of the study from its stored dataset; returns their paths."""
    import matplotlib.pyplot as plt

    a = ds.attrs
    box = a["box_half_m"]
    paths = []
    fig, axes = plt.subplots(1, 3, figsize=(13.0, 4.4), sharey=True, layout="constrained")
    maps = [("gps_only", "GPS only", None),
            ("random_median", "median random placement",
             ds["random_median_towers_enu_m"].values),
            ("optimised", "gradient-optimised", ds["optimised_towers_enu_m"].values)]
    vals = [np.minimum(ds[f"map_{k}_m"].values, 1e3) for k, _, _ in maps]
    vmin, vmax = float(np.nanmin(vals)), float(np.nanmax(vals))
    rx = ds["receivers_enu_m"].values
    for ax, (k, title, towers) in zip(axes, maps, strict=True):
        im = ax.pcolormesh(ds["map_east"].values / 1e3, ds["map_north"].values / 1e3,
                           np.minimum(ds[f"map_{k}_m"].values, 1e3), vmin=vmin, vmax=vmax,
                           shading="nearest", cmap="viridis")
        ax.plot(rx[:, 0] / 1e3, rx[:, 1] / 1e3, "w.", ms=3)
        if towers is not None:
            ax.plot(towers[:, 0] / 1e3, towers[:, 1] / 1e3, "r^", ms=9, label="towers")
            ax.legend(fontsize=8, loc="lower right")
        q = a[f"objective_{k}"]
        ax.set_title(f"{title}\n{a['objective']} (dots): {q:.2f} {a['unit']}",
                     fontsize=9)
        ax.set_xlabel("east (km)")
        ax.set_xlim(-box / 1e3, box / 1e3)
        ax.set_aspect("equal")
    axes[0].set_ylabel("north (km)")
    fig.colorbar(im, ax=axes, label="99.5 % HPL over the day at each point (m)", shrink=0.85)
    p = f"{out_dir}/tower_placement_maps.png"
    fig.savefig(p, dpi=110, bbox_inches="tight")
    plt.close(fig)
    paths.append(p)

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11.0, 4.0))
    for i in range(ds.sizes["start"]):
        ax.plot(ds["descent_objective"].values[i], "-", label=f"start {i + 1}: objective")
        ax.plot(ds["descent_surrogate"].values[i], ":", color=ax.lines[-1].get_color(),
                label=f"start {i + 1}: surrogate")
    ax.axhline(a["objective_random_median"], color="gray", ls="--", lw=0.8, label="random median")
    ax.set_xlabel("gradient step")
    ax.set_ylabel(f"objective and surrogate ({a['unit']})")
    ax.set_title("free placement: convergence", fontsize=9)
    ax.legend(fontsize=7)
    sites = ds["candidate_sites_enu_m"].values / 1e3
    bx.plot(sites[:, 0], sites[:, 1], "ko", mfc="none", label="candidate sites")
    g = ds["greedy_selected"].values
    e = ds["exhaustive_selected"].values
    bx.plot(sites[e, 0], sites[e, 1], "bs", ms=11, mfc="none",
            label=f"exhaustive best: {a['objective_exhaustive']:.2f} {a['unit']}")
    bx.plot(sites[g, 0], sites[g, 1], "r^", ms=7,
            label=f"greedy + swap: {a['objective_greedy']:.2f} {a['unit']}")
    ref = ds["refined_towers_enu_m"].values / 1e3
    bx.plot(ref[:, 0], ref[:, 1], "g*", ms=9,
            label=f"refined: {a['objective_refined']:.2f} {a['unit']}")
    bx.plot(rx[:, 0] / 1e3, rx[:, 1] / 1e3, ".", color="gray", ms=3)
    bx.set_xlim(-box / 1e3, box / 1e3)
    bx.set_ylim(-box / 1e3, box / 1e3)
    bx.set_aspect("equal")
    bx.set_xlabel("east (km)")
    bx.set_ylabel("north (km)")
    bx.set_title("selection among the candidate sites", fontsize=9)
    bx.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    p = f"{out_dir}/tower_placement_convergence.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths
