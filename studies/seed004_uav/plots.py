"""Figures 6-9 of the seed004-uav study, drawn from its stored ``data.zarr`` only."""

import json

import numpy as np
import xarray as xr

from oaraim.studies.common.stanford import StanfordLabels, draw_stanford

#: Stanford-diagram configurations of Fig. 9
STANFORD_SOPS = (0, 1, 2, 4, 8)


def plot_uav(out_dir):
    """fig6_hpe_hpl.png, fig7_detection_sensitivity.png, fig8_hpl_reduction.png and
    fig9_stanford.png (seed 004 Figs. 6-9) from ``out_dir/data.zarr``; returns their paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
    a = ds.attrs
    t = ds["t_s"].values
    n_sops = ds["n_sops"].values
    hpl, hpe = ds["hpl_m"].values, ds["hpe_m"].values
    files = []
    # Fig. 6
    fig, ax = plt.subplots(figsize=(7, 3.6))
    if "hpl_excl_m" in ds:
        ax.plot(t, ds["hpl_excl_m"].values, color="tab:red", lw=1,
                label="HPL (MHSS, detection and exclusion)")
        ax.plot(t, ds["hpe_excl_m"].values, color="tab:blue", lw=0.8, label="HPE")
    else:
        ax.plot(t, hpl[-1], color="tab:red", lw=1, label="HPL (MHSS all-in-view)")
        ax.plot(t, hpe[-1], color="tab:blue", lw=0.8, label="HPE")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("m")
    ax.set_title(f"Seed 004 Fig. 6: GPS + {n_sops[-1]} SOPs ({a['sky_source']})", fontsize=8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{out_dir}/fig6_hpe_hpl.png", dpi=130)
    plt.close(fig)
    files.append("fig6_hpe_hpl.png")
    # Fig. 7
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5.4), sharex=True)
    ratio = (ds["fault_sep_gps_m"].values[:, :2]
             / np.maximum(ds["fault_thr_gps_m"].values[:, :2], 1e-9))
    q = int(np.argmax(np.max(ratio, 0)))  # the horizontal axis with the largest tau
    lab = "EN"[q]
    a1.plot(t, ds["fault_sep_gps_m"].values[:, q], color="tab:blue", lw=1.6,
            label=f"|dx_{lab}| GPS only")
    a1.plot(t, ds["fault_sep_sop1_m"].values[:, q], color="tab:orange", ls="--", lw=1,
            label=f"|dx_{lab}| GPS + SOP 1")
    a1.plot(t, ds["fault_thr_gps_m"].values[:, q], color="tab:blue", lw=0.8, ls=":",
            label="threshold GPS only")
    a1.plot(t, ds["fault_thr_sop1_m"].values[:, q], color="tab:orange", lw=0.8, ls="-.",
            label="threshold GPS + SOP 1")
    a1.set_ylabel("m")
    a1.set_title(f"Seed 004 Fig. 7: PRN {a['fault_prn']} fault mode, ramp "
                 f"{a['fault_ramp_mps']:g} m/s from {a['fault_onset_s']:g} s; detected at "
                 f"{a['t_detect_gps_s']:.1f} s (GPS) vs {a['t_detect_sop1_s']:.1f} s (+SOP 1)"
                 f"\nnoise-free (bias = minimum detectable bias): "
                 f"{a['t_detect_noise_free_gps_s']:.3f} s vs "
                 f"{a['t_detect_noise_free_sop1_s']:.3f} s", fontsize=8)
    a1.legend(fontsize=7)
    a2.plot(t, ds["fault_tau_gps"].values - ds["fault_tau_sop1"].values, color="k", lw=0.8)
    a2.set_ylabel("tau GPS - tau GPS+SOP 1")
    a2.set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(f"{out_dir}/fig7_detection_sensitivity.png", dpi=130)
    plt.close(fig)
    files.append("fig7_detection_sensitivity.png")
    # Fig. 8
    fig, ax = plt.subplots(figsize=(8, 3.8))
    cmap = plt.get_cmap("viridis")
    for i, n in enumerate(n_sops):
        if 1 <= n <= 8:
            ax.plot(t, hpl[0] - hpl[i], lw=0.9, color=cmap((n - 1) / 7), label=f"{n} SOPs")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("HPL reduction (m)")
    ax.set_title("Seed 004 Fig. 8: HPL(GPS) - HPL(GPS + n SOPs)", fontsize=9)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    fig.savefig(f"{out_dir}/fig8_hpl_reduction.png", dpi=130)
    plt.close(fig)
    files.append("fig8_hpl_reduction.png")
    # Fig. 9: horizontal Stanford diagrams (log axes, regions shaded and counted)
    sel = [i for i, n in enumerate(n_sops) if n in STANFORD_SOPS]
    counts = json.loads(a["stanford_counts"])
    hal = float(a["hal_m"])
    ncol = min(3, len(sel))
    nrow = -(-len(sel) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 5.0 * nrow + 0.3), squeeze=False,
                             layout="constrained")
    for ax, i in zip(axes.ravel(), sel, strict=False):
        lo, hi = ds["mi_ci_low"].values[i], ds["mi_ci_high"].values[i]
        draw_stanford(fig, ax, hpe[i], hpl[i], hal, counts[str(int(n_sops[i]))],
                      StanfordLabels("HPE (m)", "HPL (m)",
                                     f"GPS + {n_sops[i]} SOPs, HAL {hal:g} m: MI 95 % CI "
                                     f"{100 * lo:.2g}-{100 * hi:.2g} %"))
    for ax in axes.ravel()[len(sel):]:
        ax.axis("off")
    inj = float(a.get("inject_sop_bias_m", 0.0))
    extra = f"; injected {inj:g} m on SOP {a['inject_sop']}" if inj else ""
    fig.suptitle(f"Seed 004 Fig. 9: Stanford diagrams (MHSS all-in-view){extra}", fontsize=9)
    fig.savefig(f"{out_dir}/fig9_stanford.png", dpi=110)
    plt.close(fig)
    files.append("fig9_stanford.png")
    return [f"{out_dir}/{f}" for f in files]
