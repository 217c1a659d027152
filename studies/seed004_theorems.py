"""Seed 004 Theorems 1 and 2 over many random geometries: adding ONE SOP as a new constellation.

Theorem 1 (section V, App. C): with the order-1 fault modes, adding one pseudorange from an
additional constellation makes the algorithm less sensitive to faults of the original
measurements, and it cannot detect a fault of the new measurement. Theorem 2 (App. D): it
raises the VPL and the HPL.

One realization (the hypotheses of the theorems, as in ``tests/test_theorems.py``): ``n_gps``
GPS satellites from the random sky (azimuth uniform, elevation uniform above a mask drawn from
5, 10, 15 deg), Table I GPS values and ADD error models, plus one BPP tower (d 200 m-3 km,
height -200..50 m relative to the receiver: a UAV above the tower is covered) in its own
constellation with sigma_URA^S drawn from the Fig. 4 grid, P_s^S log-uniform in 1e-7..1e-5 and
P_const^S log-uniform in 1e-8..1e-4, so that the P_thresh rule gives order 1 ("the maximum
number of simultaneous faults to be monitored is 1"). Residuals: GPS noise from C_acc, a 30 m
bias on one satellite in a third of the realizations (so detection happens), and a SOP residual
of 1e4 m in half of them (its fault must stay invisible).

Checks per realization, old system (GPS) vs new (GPS + SOP), same compiled shape:
  hypotheses: order 1 and status OK in both, one more monitored mode in the new one;
  Theorem 1: every old mode keeps its separation (within 1e-5 relative + 1 mm: different
  factorizations of the same position block, see SEP_RTOL), its threshold does not fall, tau
  does not grow; the new mode (the SOP excluded) never detects (tau < 1; in exact arithmetic
  its separation and threshold are both 0 and tau = 0, DESIGN.md; rounding leaves both at
  ~1e-7 m and their ratio is reported as the largest SOP-mode tau); the new system detects only
  where the old one does;
  Theorem 2: HPL and VPL do not decrease beyond 2 x the 1e-3 m solver tolerance (DESIGN.md).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import geometry
from oaraim.araim import MHSSOptions, Sources, Status, fault_mode_rule, separation_kernel
from oaraim.batching import jit_kernel
from oaraim.errors import gnss_variances, sop_variances
from oaraim.mc import Count, Max, Mean, Min
from oaraim.studies.base import Param, StudyResult, SweepStudy, axis, count, fault_modes_param
from oaraim.studies.common import seed004 as c

RAISE_TOL_M = 2e-3
#: "unchanged" separations: both sides are S y from different factorizations of the same
#: position block; with 5 satellites a fault-tolerant subset of 4 can be nearly singular
#: (separations of 50 km, condition numbers ~1e10), where float64 rounding alone reaches
#: kappa x eps ~ 2e-6 relative (seen: 1.2e-6); 1e-5 relative + 1 mm bounds that
SEP_RTOL = 1e-5
SEP_ATOL_M = 1e-3
GPS_SLOTS = 12
SIGMA_GRID = jnp.asarray(c.SIGMA_GRID_M)
MASKS_RAD = jnp.deg2rad(jnp.array([5.0, 10.0, 15.0]))


def draw(key, n_gps):
    """Old and new system of one realization: dict of (L,) arrays, L = 13, plus residuals."""
    ks = jax.random.split(key, 10)
    mask = MASKS_RAD[jax.random.randint(ks[0], (), 0, 3)]
    az, el = geometry.random_sky(ks[1], GPS_SLOTS, mask)
    tw = geometry.bpp_towers(ks[2], 1, 200.0, 3000.0, -200.0, 50.0)
    az = jnp.concatenate([az, tw.az_rad])
    el = jnp.concatenate([el, tw.el_rad])
    idx = jnp.arange(GPS_SLOTS + 1)
    sop = idx == GPS_SLOTS
    valid_new = (idx < n_gps) | sop
    valid_old = valid_new & ~sop
    sigma_s = SIGMA_GRID[jax.random.randint(ks[3], (), 0, SIGMA_GRID.size)]
    vi, va = gnss_variances(el, c.SIGMA_URA_GPS_M)
    vsi, vsa = sop_variances(sigma_s)
    vi, va = jnp.where(sop, vsi, vi), jnp.where(sop, vsa, va)
    p_s_sop = 10.0 ** jax.random.uniform(ks[4], (), minval=-7.0, maxval=-5.0)
    p_const_sop = 10.0 ** jax.random.uniform(ks[5], (), minval=-8.0, maxval=-4.0)
    y = jax.random.normal(ks[6], (GPS_SLOTS + 1,)) * jnp.sqrt(va)
    bias_sat = jax.random.randint(ks[7], (), 0, n_gps)
    biased = jax.random.uniform(ks[8]) < 1.0 / 3.0
    y = y + jnp.where(biased & (idx == bias_sat), 30.0, 0.0)
    big = jax.random.uniform(ks[9]) < 0.5
    y = jnp.where(sop, jnp.where(big, 1e4, y), y)
    g = jnp.where(valid_new[:, None], geometry.geometry_rows(az, el), 0.0)
    common = dict(g=g, constellation=sop.astype(jnp.int32), var_int=vi, var_acc=va,
                  b_nom=jnp.where(sop, 0.0, c.B_NOM_GPS_M),
                  p_sat=jnp.where(sop, p_s_sop, c.P_S_GPS),
                  p_const=jnp.stack([jnp.asarray(c.P_CONST_GPS), p_const_sop]), y=y)
    return common, valid_old, valid_new, big


def _sep(x, valid, fault_modes):
    return separation_kernel(Sources(x["g"], x["constellation"], x["var_int"], x["var_acc"],
                                     x["b_nom"], x["p_sat"], valid), x["p_const"], c.BUDGET,
                             x["y"], MHSSOptions(1, fault_modes=fault_mode_rule(fault_modes)))


@functools.partial(jit_kernel, static_argnames=("fault_modes",))
def theorem_kernel(keys, n_gps, fault_modes=c.FAULT_MODES):
    """Per realization flags and magnitudes; ``n_gps`` is traced (one compilation)."""
    x, v_old, v_new, big = jax.vmap(lambda k: draw(k, n_gps))(keys)
    so, sn = _sep(x, v_old, fault_modes), _sep(x, v_new, fault_modes)
    ok_status = ((so.pl.status == Status.OK) & (sn.pl.status == Status.OK)
                 & (so.pl.order == 1) & (sn.pl.order == 1)
                 & (sn.pl.n_modes == so.pl.n_modes + 1))
    old_m = so.monitored  # (B, K)
    new_mode = sn.monitored & ~so.monitored
    one_new = jnp.sum(new_mode, -1) == 1
    kept = jnp.all(~old_m | sn.monitored, -1)
    d_sep = jnp.abs(sn.separation_m - so.separation_m)
    lim = SEP_RTOL * jnp.abs(so.separation_m) + SEP_ATOL_M
    rel = jnp.where(old_m[..., None], d_sep / (jnp.abs(so.separation_m) + SEP_ATOL_M), 0.0)
    sep_same = jnp.all(~old_m[..., None] | (d_sep <= lim), (-2, -1))
    thr_up = jnp.all(~old_m[..., None] | (sn.threshold_m >= so.threshold_m), (-2, -1))
    tau_down = jnp.all(~old_m[..., None] | (sn.tau <= so.tau * (1.0 + 1e-12)), (-2, -1))
    tau_new = jnp.max(jnp.where(new_mode[..., None], sn.tau, 0.0), (-2, -1))
    thr_ratio = jnp.where(old_m[..., None] & (so.threshold_m > 0),
                          sn.threshold_m / jnp.where(so.threshold_m > 0, so.threshold_m, 1.0),
                          jnp.inf)
    detect_implied = ~sn.detected | so.detected
    d_h = sn.pl.hpl_m - so.pl.hpl_m
    d_v = sn.pl.vpl_m - so.pl.vpl_m
    fin = jnp.isfinite(d_h) & jnp.isfinite(d_v)
    hyp = ok_status & one_new & kept & fin
    thm1 = hyp & sep_same & thr_up & tau_down & (tau_new < 1.0) & detect_implied
    thm2 = hyp & (d_h >= -RAISE_TOL_M) & (d_v >= -RAISE_TOL_M)
    return {
        "hypotheses": hyp, "theorem_1": thm1, "theorem_2": thm2,
        "sep_unchanged": hyp & sep_same, "thresholds_raised": hyp & thr_up,
        "tau_not_increased": hyp & tau_down, "sop_undetectable": hyp & (tau_new < 1.0),
        "detection_implied": hyp & detect_implied,
        "sop_fault_big": hyp & big, "sop_fault_big_detected_by_own_mode": hyp & big
        & (tau_new > 1.0),
        "old_detected": hyp & so.detected,
        "sep_rel_change": jnp.where(hyp, jnp.max(rel, (-2, -1)), 0.0),
        "threshold_ratio_min": jnp.where(hyp, jnp.min(thr_ratio, (-2, -1)), jnp.inf),
        "sop_tau": jnp.where(hyp, tau_new, 0.0),
        "hpl_increase_m": jnp.where(hyp, d_h, 0.0), "vpl_increase_m": jnp.where(hyp, d_v, 0.0),
    }


class TheoremCell:
    """The kernel of one cell: keys -> ``theorem_kernel``'s flags for ``coords["n_gps"]``
    GPS satellites (picklable for Dask)."""

    def __init__(self, params, coords):
        self.n_gps = int(coords["n_gps"])
        self.fault_modes = params["fault_modes"]

    def __call__(self, keys):
        return theorem_kernel(keys, self.n_gps, self.fault_modes)


class Theorems(SweepStudy):
    """Seed 004 Theorems 1 and 2 (module docstring) checked per realization, one sweep cell
    per GPS satellite count."""

    name = "seed004-theorems"
    title = "Seed 004 Theorems 1-2: one SOP in its own constellation, random geometries"
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = ("one random GPS sky with n_gps satellites plus one BPP SOP, random Table-I "
                   "compatible SOP parameters and residuals")
    default_realizations = 12_500  # x 8 values of n_gps = 10^5 (issue: >= 10^5)
    quick_realizations = 1024
    quick_cost_s = 15
    axis_names = ("n_gps",)
    key_axes = ("n_gps",)
    params = {
        "n_gps": Param(tuple(range(5, 13)), axis(count(5, GPS_SLOTS)),
                       "GPS satellites of the old system (M_s >= 3 + M_const = 4)"),
        "fault_modes": fault_modes_param(c.FAULT_MODES, "the theorems are statements about "
                                         "seed 004's rule (eq. 8), order 1"),
        "chunk": Param(4096, count(1024), "realizations per task and chunk file (not a result)"),
    }

    def kernel(self, params, coords):
        """``TheoremCell`` of ``coords["n_gps"]``."""
        return TheoremCell(params, coords)

    def reducers(self, params):
        """Counts of each flag (hypotheses met, each theorem and its parts) and the extreme
        and mean magnitudes where the hypotheses hold."""
        flags = ("hypotheses", "theorem_1", "theorem_2", "sep_unchanged", "thresholds_raised",
                 "tau_not_increased", "sop_undetectable", "detection_implied", "sop_fault_big",
                 "sop_fault_big_detected_by_own_mode", "old_detected")
        return (*(Count(f) for f in flags),
                Max("sep_rel_change", where="hypotheses"),
                Min("threshold_ratio_min", where="hypotheses"),
                Max("sop_tau", where="hypotheses"),
                Min("hpl_increase_m", where="hypotheses"),
                Min("vpl_increase_m", where="hypotheses"),
                Mean("hpl_increase_m", where="hypotheses"),
                Mean("vpl_increase_m", where="hypotheses"))

    def finish(self, params, ds, realizations, seed):
        """Share of realizations meeting the hypotheses, and where they do, the share where
        each theorem holds and its largest violations."""
        tot = lambda v: int(ds[v].sum())  # noqa: E731
        n_all = realizations * ds.sizes["n_gps"]
        hyp = tot("hypotheses_count")
        share = lambda v: 100.0 * tot(v) / max(hyp, 1)  # noqa: E731
        rows = [
            {"quantity": "realizations meeting the theorems' hypotheses (order 1, status OK)",
             "unit": "%", "published": None, "reproduced": 100.0 * hyp / n_all,
             "note": f"{hyp:,} of {n_all:,}"},
            {"quantity": "Theorem 1 holds (old statistics unchanged, thresholds raised, lone "
             "SOP undetectable, detection only where GNSS-only detects)", "unit": "%",
             "published": 100.0, "reproduced": share("theorem_1_count"),
             "note": f"{hyp - tot('theorem_1_count')} of {hyp:,} violate it; largest "
                     f"relative separation change "
                     f"{float(ds['sep_rel_change_max'].max()):.2e}; largest SOP-mode tau "
                     f"{float(ds['sop_tau_max'].max()):g}"},
            {"quantity": "Theorem 2 holds (HPL and VPL raised)", "unit": "%",
             "published": 100.0, "reproduced": share("theorem_2_count"),
             "note": f"{hyp - tot('theorem_2_count')} of {hyp:,} violate it; smallest HPL "
                     f"change {float(ds['hpl_increase_m_min'].min()):.2e} m, "
                     f"VPL {float(ds['vpl_increase_m_min'].min()):.2e} m (tolerance "
                     f"-{RAISE_TOL_M:g} m)"},
        ]
        metrics = {
            "realizations_total": n_all, "hypotheses_met": hyp,
            **{f"share_{k}_pct": share(f"{k}_count") for k in (
                "theorem_1", "theorem_2", "sep_unchanged", "thresholds_raised",
                "tau_not_increased", "sop_undetectable", "detection_implied")},
            "largest_violation_hpl_m": max(0.0, -float(ds["hpl_increase_m_min"].min())),
            "largest_violation_vpl_m": max(0.0, -float(ds["vpl_increase_m_min"].min())),
            "largest_relative_separation_change": float(ds["sep_rel_change_max"].max()),
            "smallest_threshold_ratio": float(ds["threshold_ratio_min_min"].min()),
            "largest_sop_mode_tau": float(ds["sop_tau_max"].max()),
            "mean_hpl_increase_m": float((ds["hpl_increase_m_mean"]
                                          * ds["hypotheses_count"]).sum() / max(hyp, 1)),
            "mean_vpl_increase_m": float((ds["vpl_increase_m_mean"]
                                          * ds["hypotheses_count"]).sum() / max(hyp, 1)),
            "sop_faults_1e4_m": tot("sop_fault_big_count"),
            "sop_faults_detected_by_own_mode": tot("sop_fault_big_detected_by_own_mode_count"),
            "old_system_detections": tot("old_detected_count"),
        }
        ds = ds.assign_attrs(realizations=int(realizations))
        return StudyResult(ds, rows, metrics)

    def plot(self, out_dir):
        """theorems.png: share where each theorem holds, and the PL increases, against the GPS
        satellite count."""
        import matplotlib.pyplot as plt

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
        n = ds["n_gps"].values
        hyp = np.maximum(ds["hypotheses_count"].values, 1)
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(9.0, 3.6))
        for k, lab in (("theorem_1", "Theorem 1"), ("theorem_2", "Theorem 2")):
            a1.plot(n, 100.0 * ds[f"{k}_count"].values / hyp, "o-", label=lab)
        a1.set_ylim(0, 105)
        a1.set_xlabel("GPS satellites")
        a1.set_ylabel("realizations where it holds (%)")
        a1.legend(fontsize=8)
        a1.grid(alpha=0.3)
        a2.plot(n, ds["hpl_increase_m_mean"].values, "o-", label="mean HPL increase")
        a2.plot(n, ds["vpl_increase_m_mean"].values, "s-", label="mean VPL increase")
        a2.plot(n, ds["hpl_increase_m_min"].values, "v:", label="smallest HPL increase")
        a2.plot(n, ds["vpl_increase_m_min"].values, "^:", label="smallest VPL increase")
        a2.axhline(0.0, color="k", lw=0.8)
        a2.set_xlabel("GPS satellites")
        a2.set_ylabel("PL with SOP - PL without (m)")
        a2.legend(fontsize=7)
        a2.grid(alpha=0.3)
        fig.suptitle(f"Seed 004 Theorems 1-2 ({ds.attrs.get('realizations', '?')} realizations "
                     "per point)", fontsize=9)
        fig.tight_layout()
        path = f"{out_dir}/theorems.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        return [path]
