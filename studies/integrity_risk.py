"""Does the protection level bound the risk? Fault injection with importance sampling.

Seed 004's MHSS protection levels promise that, for every monitored fault mode and every fault
magnitude, the probability of hazardous misleading information (HMI: an error beyond the PL
with no alert) stays within the integrity budget (eqs. 14-16, Table I). This study measures it.
One geometry is the Orange County receiver of seed 004 section VI at a GPS epoch uniform over
the day (``studies.common.seed004``) with, in the cells that have SOPs, towers drawn by the BPP; the
same epochs in every cell (common random numbers), so "with" and "without SOPs" differ by the
towers only. For each geometry ``araim.integrity_risk`` injects every scenario (fault-free, a
bias on each satellite and tower, a constellation-wide fault, two simultaneous biases) at the
magnitudes ``x_grid`` x A_det, draws nominal errors from C_int with the worst-sign b_nom bias,
runs the full MHSS detection and exclusion, and estimates P(HMI) per direction by importance
sampling; the measured risk is the fault-free risk plus each monitored mode's prior times its
worst scenario and magnitude, against the allocation PHMI (1 - P_NM / (PHMI_V + PHMI_H)).

One realization is one (geometry, scenario slot, magnitude): ``geometries`` sets their number,
``--realizations`` is not used. SOPs: sigma_URA^S = 3 m and P_s^S = 1e-4, the values of seed
004's UAV experiment (section VII, "semi-urban" sigma from its ref. [17]); P_const^S = 1e-4
(Table I). The cross-check of importance sampling against crude Monte Carlo uses a
deliberately weak budget (PHMI 2e-3, P_FA 1e-3) on the first geometry, where crude Monte Carlo
resolves the risks (1e-3 and more), and times both to give the speed-up at equal relative error;
at Table I levels the speed-up is the ratio of the samples crude Monte Carlo would need,
p (1 - p) / (n se^2), to the samples drawn (cross-entropy rounds included).
"""

import time

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import araim, mc
from oaraim.araim import IntegrityBudget
from oaraim.araim import integrity_risk as ir
from oaraim.mc import Values
from oaraim.studies.base import (
    Param,
    StudyResult,
    SweepStudy,
    axis,
    count,
    in_range,
    parse_choice,
    positive,
    probability,
)
from oaraim.studies.common import seed004 as c

#: seed 004 section VII (UAV experiment): sigma_URA^S and P_s^S
SIGMA_URA_SOP_M = 3.0
P_S_SOP = 1e-4
#: the cross-check budget: weak enough that crude Monte Carlo resolves the risks
WEAK_BUDGET = IntegrityBudget(phmi_v=2e-3, phmi_h=2e-3, p_fa_v=1e-3, p_fa_h=1e-3,
                              p_thresh=6e-8)
N_CONSTELLATIONS = 2  # GPS 0, the SOP constellation 1 (empty without SOPs)
DIRS = ("h", "v")
#: per-scenario outputs per direction: name -> (Estimate / Injection field, dtype)
EST_FIELDS = ("p_md", "se_md", "hits_md", "upper_md", "p_we", "se_we", "mu_norm")


def n_slots(params):
    """GPS source slots L of the sky table (the most satellites in view over the day)."""
    table = c.gps_sky_table(params["nav"], params["mask_deg"], params["sky_step_s"])
    return table["az_rad"].shape[1]


def n_scenarios(params):
    """Scenario slots of the largest cell: 1 + L + 2 C (``ir.scenario_slots``)."""
    return 1 + n_slots(params) + max(params["n_sops"]) + 2 * N_CONSTELLATIONS


def outputs():
    """{name: dtype} of the kernel's outputs per realization: the geometry, scenario and
    magnitude indices, its PLs and status, and per direction (``_h``, ``_v``) the mode, prior,
    A_det / A_PL, magnitude and the importance-sampling estimate (``EST_FIELDS``)."""
    out = {"geometry": "int32", "epoch": "int32", "scenario": "int16", "kind": "int8",
           "source": "int16", "constellation": "int8", "x": "float64", "scale": "int8",
           "hpl_m": "float64",
           "vpl_m": "float64", "status": "int8", "p_not_monitored": "float64"}
    for d in DIRS:
        out.update({f"active_{d}": "bool", f"monitored_{d}": "bool", f"mode_{d}": "int16",
                    f"prior_{d}": "float64", f"a_det_{d}_m": "float64", f"a_pl_{d}_m": "float64",
                    f"magnitude_{d}_m": "float64"})
        out.update({f"{f}_{d}": ("int32" if f.startswith("hits") else "float64")
                    for f in EST_FIELDS})
    return out


def geometry_inputs(key, jtable, n_sops, params):
    """One geometry: (its GPS epoch, its ``araim.Sources``: GPS at an epoch of the day table,
    then n_sops BPP towers, P_const)."""
    epoch, az, el, v = c.draw_gps(key, jtable["az_rad"], jtable["el_rad"], jtable["valid"])
    sources = c.gps_sources(az, el, v)
    if n_sops:
        tw = c.draw_sops(key, n_sops, params["d_min_m"], params["d_max_m"], params["h_min_m"],
                         params["h_max_m"])
        sources = sources.concat(c.sop_sources(tw.az_rad, tw.el_rad, params["sigma_ura_sop_m"],
                                               params["p_s_sop"], 1))
    p_const = jnp.array([c.P_CONST_GPS, params["p_const_sop"]])
    return epoch, sources, p_const


class RiskCell:
    """The index kernel of one cell (``mc.sweep``): realization i = (geometry, scenario slot,
    magnitude); a geometry's whole table is computed once and kept for the next indices."""

    index_kernel = True

    def __init__(self, params, n_sops):
        self.p = params
        self.n_sops = int(n_sops)
        self.jtable = c.gps_sky_arrays(params["nav"], params["mask_deg"], params["sky_step_s"])
        self.S = n_scenarios(params)
        self.x = np.asarray(params["x_grid"], float)
        self.X = 2 * self.x.size  # x A_det, then x A_PL (ir.risk_table)
        self.G = int(params["geometries"])
        self.max_order = c.order_for(self.jtable["az_rad"].shape[1], self.n_sops, params["p_s_sop"],
                                     params["p_const_sop"], params["fault_modes"])
        self.cache = {}

    def table(self, g, key):
        """Every output of geometry ``g`` as (scenario slots, 2 len(x_grid)) arrays: its MHSS
        maps and ``ir.risk_table``, computed once (the last 4 geometries are cached)."""
        if g in self.cache:
            return self.cache[g]
        kg = mc.stream(key, "risk_geometry", g)
        epoch, sources, p_const = geometry_inputs(kg, self.jtable, self.n_sops, self.p)
        maps = ir.monitor_maps(sources, p_const, c.BUDGET,
                               araim.MHSSOptions(self.max_order, fault_modes=self.p["fault_modes"]))
        t = ir.risk_table(maps, mc.stream(kg, "risk_table"), self.x, sampling(self.p))
        S, X = t.kind.size, self.X
        out = {k: np.zeros((self.S, X), np.dtype(v)) for k, v in outputs().items()}
        out["geometry"][:] = g
        out["epoch"][:] = int(epoch)
        out["scenario"][:] = np.arange(self.S)[:, None]
        out["kind"][:] = -1
        out["kind"][:S] = t.kind[:, None]
        out["source"][:S] = t.source[:, None]
        out["constellation"][:S] = t.constellation[:, None]
        out["x"][:] = np.concatenate([self.x, self.x])[None]
        out["scale"][:] = (np.arange(X) >= self.x.size)[None]
        for k in ("hpl_m", "vpl_m", "status", "p_not_monitored"):
            out[k][:] = np.asarray(getattr(maps, k))
        for j, d in enumerate(DIRS):
            out[f"active_{d}"][:S] = np.asarray(t.active)[:, j, None]
            out[f"monitored_{d}"][:S] = np.asarray(t.monitored)[:, j, None]
            out[f"mode_{d}"][:S] = np.asarray(t.mode)[:, j, None]
            out[f"prior_{d}"][:S] = np.asarray(t.prior)[:, j, None]
            out[f"a_det_{d}_m"][:S] = np.asarray(t.a_det_m)[:, j, None]
            out[f"a_pl_{d}_m"][:S] = np.asarray(t.a_pl_m)[:, j, None]
            out[f"magnitude_{d}_m"][:S] = np.asarray(t.magnitude_m)[:, :, j]
            for f in EST_FIELDS:
                out[f"{f}_{d}"][:S] = np.asarray(getattr(t.estimate, f))[:, :, j]
        if len(self.cache) >= 4:
            self.cache.pop(next(iter(self.cache)))
        self.cache[g] = out
        return out

    def __call__(self, idx, key):
        idx = np.asarray(idx)
        X = self.X
        per_g = self.S * X
        res = {k: np.zeros(idx.shape, np.dtype(v)) for k, v in outputs().items()}
        g_of = idx // per_g
        for g in np.unique(g_of[(idx >= 0) & (g_of < self.G)]):
            sel = g_of == g
            t = self.table(int(g), key)
            s = (idx[sel] // X) % self.S
            xi = idx[sel] % X
            for k in res:
                res[k][sel] = t[k][s, xi]
        return res


def _reshape(ds, name, G, S, X):
    return ds[name].values.reshape(ds[name].shape[:-1] + (G, S, X))


def per_geometry_risk(ds, G, S, X):
    """(cells, G, 2) measured risk and its upper bound, and the allocation."""
    n_cells = ds.sizes["n_sops"]
    risk = np.zeros((n_cells, G, 2))
    upper = np.zeros((n_cells, G, 2))
    get = lambda n: _reshape(ds, n, G, S, X)  # noqa: E731
    kind = get("kind")[..., 0]
    fields = {n: get(n) for n in ("active_h", "active_v", "monitored_h", "monitored_v",
                                  "mode_h", "mode_v", "prior_h", "prior_v", "p_md_h",
                                  "p_md_v", "upper_md_h", "upper_md_v")}
    for ci in range(n_cells):
        for g in range(G):
            two = lambda n, ci=ci, g=g: np.stack(  # noqa: E731
                [fields[f"{n}_h"][ci, g], fields[f"{n}_v"][ci, g]], axis=-1)
            r, u, _, _ = ir.risk_sum(kind[ci, g], two("active")[:, 0], two("monitored")[:, 0],
                                     two("mode")[:, 0], two("prior")[:, 0], two("p_md"),
                                     two("upper_md"))
            risk[ci, g], upper[ci, g] = r, u
    return risk, upper


def geometry_zero_maps(params, key, n_sops, budget, max_order):
    """Geometry 0 of a cell (as ``RiskCell.table`` draws it): (its key, inputs, MonitorMaps,
    the GPS epoch) under ``budget``."""
    jt = c.gps_sky_arrays(params["nav"], params["mask_deg"], params["sky_step_s"])
    kg = mc.stream(key, "risk_geometry", 0)
    epoch, sources, p_const = geometry_inputs(kg, jt, n_sops, params)
    m = ir.monitor_maps(sources, p_const, budget,
                        araim.MHSSOptions(max_order, fault_modes=params["fault_modes"]))
    return kg, sources, m, epoch


def sampling(params):
    """The ``ir.Sampling`` of the study's parameters (importance sampling)."""
    return ir.Sampling(params["samples"], params["ce_samples"], params["ce_rounds"],
                       nominal_bias=params["nominal_bias"])


def cross_check(params, key, crude_samples):
    """Weak budget, first geometry of the largest cell: IS against crude Monte Carlo on the
    fault-free and the worst single-satellite scenarios, with wall times (compiled first)."""
    _, x, m, _ = geometry_zero_maps(params, key, max(params["n_sops"]), WEAK_BUDGET, 1)
    worst = int(np.argmax(np.abs(np.asarray(m.s0[2])) * np.asarray(x.valid)))
    opts = sampling(params)
    out = []
    for name, kind, src, d, xm in (("fault-free, vertical", ir.FAULT_FREE, -1, ir.VERTICAL, 0.0),
                                   ("largest-slope satellite at A_det, vertical", ir.SINGLE,
                                    worst, ir.VERTICAL, 1.0),
                                   ("largest-slope satellite at A_det, horizontal", ir.SINGLE,
                                    worst, ir.HORIZONTAL, 1.0)):
        k = mc.stream(key, "risk_cross_check", len(out))
        runs = {}
        scenario = ir.Scenario(kind, d, xm, source=src)
        for mode, kw in (("is", opts), ("crude", ir.Sampling(
                n_samples=crude_samples, crude=True, nominal_bias=params["nominal_bias"]))):
            jax.block_until_ready(ir.scenario_estimate(m, scenario, k, kw))
            t0 = time.perf_counter()
            e = jax.block_until_ready(ir.scenario_estimate(
                m, scenario, mc.stream(k, "risk_rerun"), kw))[2]
            runs[mode] = (float(e.p_md), float(e.se_md), int(e.hits_md),
                          time.perf_counter() - t0)
        (pi, si, _, ti), (pc, sc, hc, tc) = runs["is"], runs["crude"]
        z = (pi - pc) / max(np.hypot(si, sc), 1e-300)
        speedup = (tc * sc**2) / (ti * si**2) if si > 0 and sc > 0 else None
        out.append({"scenario": name, "p_is": pi, "se_is": si, "p_crude": pc, "se_crude": sc,
                    "hits_crude": hc, "z": z, "time_is_s": ti, "time_crude_s": tc,
                    "speedup_equal_rel_error": speedup})
    return out


def sop_ramps(params, key, n_sops):
    """Ramps on every tower of the first geometry of a cell with SOPs: (n_sops, 2, epochs)
    per-epoch P(missed-detection HMI), the union bound per tower and direction, the epochs."""
    first = n_slots(params)
    order = c.order_for(first, n_sops, params["p_s_sop"], params["p_const_sop"],
                        params["fault_modes"])
    kg, _, m, _ = geometry_zero_maps(params, key, n_sops, c.BUDGET, order)
    p, union, t, prior = [], [], None, []
    for j in range(n_sops):
        pj, uj = [], []
        for d in (ir.HORIZONTAL, ir.VERTICAL):
            r = ir.ramp_risk(m, ir.Ramp(first + j, d, params["ramp_rate_mps"],
                                        params["ramp_duration_s"], params["ramp_epoch_s"]),
                             mc.stream(kg, "risk_ramp", 2 * j + d), sampling(params))
            pj.append(r.p_md)
            uj.append(r.union_p_md)
            t = r.time_s
        p.append(pj)
        union.append(uj)
        inj = ir.injection(m, ir.SINGLE, first + j, -1, ir.HORIZONTAL)
        prior.append(float(inj.prior))
    return np.array(p), np.array(union), t, np.array(prior), m


def _save(fig, path):
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


class IntegrityRisk(SweepStudy):
    """The ``integrity-risk`` study (module docstring): one sweep cell per SOP count, every
    (geometry, scenario slot, magnitude) a realization."""

    name = "integrity-risk"
    title = ("Measured integrity risk of the MHSS PLs by fault injection and importance "
             "sampling, seed 004 Table I with and without SOPs")
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = ("one (geometry, fault scenario, magnitude): a GPS epoch uniform over the "
                   "day (+ BPP towers), a scenario slot and x A_det; set by 'geometries'")
    default_realizations = 1
    quick_realizations = 1
    quick_cost_s = 77
    #: --quick: 4 geometries per cell instead of 32, 5 magnitudes around A_det instead of 11,
    #: half the importance samples (relative errors ~1.4x), a tenth of the crude cross-check,
    #: ramp snapshots every 6 s instead of 2 s
    quick_sets = {"geometries": 4, "x_grid": "0,0.5,1,1.25,2", "samples": 1000,
                  "ce_samples": 500, "crude_samples": 20_000, "ramp_epoch_s": 6.0}
    nav_file = c.NAV_FILE
    axis_names = ("n_sops",)
    key_axes = ()  # the same GPS epochs in every cell (common random numbers)
    params = {
        "n_sops": Param((0, 4), axis(count(0, 16)),
                        "SOPs (one constellation) per cell: without and with SOPs"),
        "geometries": Param(32, count(1, 100_000), "geometries (GPS epoch + towers) per cell"),
        "x_grid": Param(ir.DEFAULT_X_GRID, axis(in_range(0.0, 100.0)),
                        "fault magnitudes in units of A_det (the mode's mean separation reaches "
                        "its threshold) and, as many again, of A_PL (the mean error reaches the "
                        "PL)"),
        "samples": Param(2000, count(100), "importance samples per estimate"),
        "ce_samples": Param(1000, count(100), "samples per cross-entropy round"),
        "ce_rounds": Param(2, count(0, 10), "cross-entropy rounds"),
        "nominal_bias": Param("worst", parse_choice("worst", "zero"),
                              "nominal bias: b_nom with the slope's sign, or none"),
        "crude_samples": Param(200_000, count(0),
                               "crude Monte Carlo samples of the weak-budget cross-check "
                               "(0 skips it)"),
        "ramp_rate_mps": Param(0.5, in_range(0.0, 1000.0),
                               "SOP tower ramp: growth rate (a tower clock drifting away)",
                               "m/s"),
        "ramp_duration_s": Param(120.0, in_range(1e-3, 1e5), "SOP tower ramp: duration", "s"),
        "ramp_epoch_s": Param(2.0, in_range(1e-3, 1e5), "SOP tower ramp: snapshot interval",
                              "s"),
        "sigma_ura_sop_m": Param(SIGMA_URA_SOP_M, positive,
                                 "sigma_URA^S (seed 004 VII: 3 m, semi-urban)", "m"),
        "p_s_sop": Param(P_S_SOP, probability, "P_s^S (seed 004 VII: 1e-4)"),
        **c.common_params(),
        "chunk": Param(2048, count(1024), "realizations per task and chunk file (not a "
                       "result)"),
    }

    def check(self, p):
        """The BPP annulus: d_min_m < d_max_m, h_min_m <= h_max_m."""
        c.check_geometry_params(p)

    def fixed_realizations(self, params):
        """geometries x scenario slots x magnitudes (x_grid in units of A_det, then A_PL)."""
        return params["geometries"] * n_scenarios(params) * 2 * len(params["x_grid"])

    def kernel(self, params, coords):
        """The index kernel of the cell with ``coords["n_sops"]`` SOPs (``RiskCell``)."""
        return RiskCell(params, coords["n_sops"])

    def reducers(self, params):
        """``Values`` of every output: each realization kept."""
        n = self.fixed_realizations(params)
        return tuple(Values(k, n, dtype) for k, dtype in outputs().items())

    def finish(self, params, ds, realizations, seed):
        """Measured risk per geometry against the allocation (with and without the
        unmonitored modes), the crude Monte Carlo cross-check and the SOP tower ramps."""
        from oaraim.mc import cell_key

        G, S, X = params["geometries"], n_scenarios(params), 2 * len(params["x_grid"])
        n_sops = list(params["n_sops"])
        risk, upper = per_geometry_risk(ds, G, S, X)
        get = lambda n: _reshape(ds, n, G, S, X)  # noqa: E731
        p_nm = get("p_not_monitored")[..., 0, 0]
        status = get("status")[..., 0, 0]
        ok = status == 0
        alloc = np.stack(ir.allocated_budget(c.BUDGET, p_nm), axis=-1)  # (cells, G, 2)
        ratio = np.where(ok[..., None], risk / alloc, np.nan)
        ratio_up = np.where(ok[..., None], upper / alloc, np.nan)
        # every unmonitored mode counted as HMI with certainty: its prior joins the risk, in
        # each direction in the share the PL equations give it (P_NM PHMI_d / (PHMI_V +
        # PHMI_H)), against the whole PHMI_d; <= 1 exactly when measured <= allocated
        total, phmi = ir.total_risk(risk, p_nm, c.BUDGET)
        total_up, _ = ir.total_risk(upper, p_nm, c.BUDGET)
        ratio_total = np.where(ok[..., None], total / phmi, np.nan)
        ratio_total_up = np.where(ok[..., None], total_up / phmi, np.nan)
        rows, metrics = [], {}
        for ci, n in enumerate(n_sops):
            tag = "without SOPs" if n == 0 else f"with {n} SOPs"
            for j, (d, word) in enumerate((("h", "horizontal"), ("v", "vertical"))):
                r = ratio[ci, :, j][ok[ci]]
                ru = ratio_up[ci, :, j][ok[ci]]
                if not r.size:
                    continue
                rows.append({"quantity": f"measured / allocated integrity risk, {word}, {tag}: "
                             "largest over geometries", "unit": "", "published": 1.0,
                             "reproduced": float(np.max(r)),
                             "note": f"median {np.median(r):.3g}; 95 % upper bound at most "
                             f"{np.max(ru):.3g}; the PL promises <= 1 (seed 004 eqs. 14-16, "
                             "Table I)"})
                metrics[f"risk_ratio_{d}_n{n}"] = {
                    "median": float(np.median(r)), "max": float(np.max(r)),
                    "max_upper95": float(np.max(ru)),
                    "share_upper95_within_budget": float(np.mean(ru <= 1.0))}
                metrics[f"measured_risk_{d}_n{n}_median"] = float(np.median(
                    risk[ci, :, j][ok[ci]]))
                t, tu = ratio_total[ci, :, j][ok[ci]], ratio_total_up[ci, :, j][ok[ci]]
                rows.append({"quantity": f"(measured + unmonitored) / PHMI, {word}, {tag}: "
                             "largest over geometries", "unit": "", "published": 1.0,
                             "reproduced": float(np.max(t)),
                             "note": f"every unmonitored mode's prior counted as HMI "
                             f"(P_NM median {np.median(p_nm[ci][ok[ci]]):.3g}, its share "
                             f"PHMI_d / (PHMI_V + PHMI_H)); median {np.median(t):.3g}, 95 % "
                             f"upper bound at most {np.max(tu):.3g}; fault modes "
                             f"{params['fault_modes']}"})
                metrics[f"total_risk_ratio_{d}_n{n}"] = {
                    "median": float(np.median(t)), "max": float(np.max(t)),
                    "max_upper95": float(np.max(tu))}
            metrics[f"available_share_n{n}"] = float(np.mean(ok[ci]))
            if ok[ci].any():
                metrics[f"p_not_monitored_n{n}"] = {
                    "median": float(np.median(p_nm[ci][ok[ci]])),
                    "max": float(np.max(p_nm[ci][ok[ci]]))}
        metrics["fault_modes"] = params["fault_modes"]
        metrics["allocated_h"] = float(np.median(alloc[..., 0]))
        metrics["allocated_v"] = float(np.median(alloc[..., 1]))
        # importance-sampling efficiency at the Table I levels: crude samples for the same
        # relative error over samples drawn, over every estimate with hits
        drawn = params["samples"] + params["ce_rounds"] * params["ce_samples"]
        gains, probs = [], []
        for d in DIRS:
            p, se = get(f"p_md_{d}"), get(f"se_md_{d}")
            act = get(f"active_{d}") & (get(f"hits_md_{d}") >= 10) & (p > 0) & (p < 0.5) & \
                (se > 0)
            p, se = p[act], se[act]
            gains.append(p * (1 - p) / (params["samples"] * se**2) * params["samples"] / drawn)
            probs.append(p)
        gains, probs = np.concatenate(gains), np.concatenate(probs)
        if gains.size:
            near = gains[probs >= 1e-10]
            metrics["is_sample_speedup_equal_rel_error"] = {
                "median": float(np.median(gains)), "p10": float(np.percentile(gains, 10)),
                "min": float(np.min(gains)), "estimates": int(gains.size),
                "median_where_p_ge_1e-10": float(np.median(near)) if near.size else None}
            rows.append({"quantity": "IS speed-up over crude Monte Carlo at equal relative "
                         "error, Table I estimates with P >= 1e-10 (samples, median)",
                         "unit": "x", "published": None,
                         "reproduced": float(np.median(near)) if near.size else None,
                         "note": f"all {gains.size} estimates with >= 10 hits: median "
                         f"{np.median(gains):.3g}, 10th percentile "
                         f"{np.percentile(gains, 10):.3g}; crude needs p(1-p)/se^2 samples for "
                         "the same standard error, IS drew samples + CE rounds"})
        cross, timing = [], []
        if params["crude_samples"]:
            cross = cross_check(params, cell_key(seed, 0), params["crude_samples"])
            for row in cross:
                # wall times vary from run to run: provenance, not results
                timing.append({k: row.pop(k) for k in ("time_is_s", "time_crude_s",
                                                       "speedup_equal_rel_error")})
                row["speedup"] = timing[-1]["speedup_equal_rel_error"]
                rows.append({"quantity": f"weak-budget check, {row['scenario']}: IS vs crude "
                             "Monte Carlo", "unit": "z", "published": 0.0,
                             "reproduced": row["z"],
                             "note": f"IS {row['p_is']:.4g} +- {row['se_is']:.2g}, crude "
                             f"{row['p_crude']:.4g} +- {row['se_crude']:.2g} "
                             f"({row['hits_crude']} hits); wall-time speed-up at equal "
                             f"relative error {row.pop('speedup') or 0:.3g}"})
        metrics["weak_budget_cross_check"] = cross
        n_max = max(n_sops)
        n_ep = int(np.floor(params["ramp_duration_s"] / params["ramp_epoch_s"] + 1e-9))
        ramp = np.zeros((len(n_sops), max(n_max, 1), 2, max(n_ep, 1)))
        ramp_t = params["ramp_epoch_s"] * np.arange(1, ramp.shape[-1] + 1)
        for ci, n in enumerate(n_sops):
            if n == 0 or not ok[ci, 0]:
                continue
            p, union, ramp_t, prior, m = sop_ramps(params, cell_key(seed, 0), n)
            ramp[ci, :n] = p
            alloc0 = np.array(ir.allocated_budget(c.BUDGET, float(m.p_not_monitored)))
            worst = union.max(axis=0)  # (2,) over towers
            metrics[f"sop_ramp_n{n}"] = {
                "union_p_hmi_h": union[:, 0].tolist(), "union_p_hmi_v": union[:, 1].tolist(),
                "prior": prior.tolist(),
                "prior_x_union_over_allocated": (prior.max() * worst / alloc0).tolist()}
            rows.append({"quantity": f"SOP tower ramp ({params['ramp_rate_mps']:g} m/s over "
                         f"{params['ramp_duration_s']:g} s), {n} SOPs, geometry 0: worst "
                         "tower's P(HMI at some epoch), horizontal", "unit": "",
                         "published": None, "reproduced": float(worst[0]),
                         "note": f"vertical {worst[1]:.3g}; union bound over "
                         f"{ramp_t.size} snapshots; x the tower's prior {prior.max():.2g} = "
                         f"{prior.max() * worst[0] / alloc0[0]:.3g} of the horizontal "
                         "allocation"})
        table = c.gps_sky_table(params["nav"], params["mask_deg"], params["sky_step_s"])
        metrics["sky_source"] = table["description"]
        metrics["geometries"] = G
        metrics["scenario_slots"] = S
        out = xr.Dataset(
            {k: (("n_sops", "geometry", "scenario", "x_index"), get(k)) for k in outputs()},
            coords={"n_sops": n_sops, "x_index": np.arange(X)})
        out["risk"] = (("n_sops", "geometry", "direction"), risk)
        out["risk_upper95"] = (("n_sops", "geometry", "direction"), upper)
        out["allocated"] = (("n_sops", "geometry", "direction"), alloc)
        out["ramp_p_md"] = (("n_sops", "ramp_source", "direction", "ramp_time_s"), ramp)
        out = out.assign_coords(ramp_time_s=ramp_t)
        out = out.assign_coords(direction=["horizontal", "vertical"])
        out = out.assign_attrs(sky_source=table["description"], gps_slots=n_slots(params),
                               phmi_h=c.BUDGET.phmi_h,
                               phmi_v=c.BUDGET.phmi_v)
        return StudyResult(out, rows, metrics, {"sky_source": table["description"],
                                                 "weak_budget_cross_check_timing": timing})

    def plot(self, out_dir):
        """risk_vs_magnitude.png (P(HMI) per scenario against |f|), risk_ratio_cdf.png
        (measured / allocated over geometries) and, with SOPs, sop_ramp_risk.png."""
        import matplotlib.pyplot as plt

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False).load()
        cells = ds["n_sops"].values
        paths = []
        colors = {ir.FAULT_FREE: "k", ir.SINGLE: "tab:blue", ir.CONSTELLATION: "tab:red",
                  ir.PAIR: "tab:purple"}
        g0 = int(np.argmax(ds["status"].values[-1, :, 0, 0] == 0))
        fig, axes = plt.subplots(2, len(cells), figsize=(5.2 * len(cells), 7.6), squeeze=False,
                                 layout="constrained")
        for ci, n in enumerate(cells):
            for j, (d, word) in enumerate((("h", "horizontal"), ("v", "vertical"))):
                ax = axes[j, ci]
                sub = ds.isel(n_sops=ci, geometry=g0)
                shown = False  # anything above the axis floor (1e-30)?
                for s in range(ds.sizes["scenario"]):
                    kind = int(sub["kind"].values[s, 0])
                    if kind < 0 or not bool(sub[f"active_{d}"].values[s, 0]):
                        continue
                    order = np.argsort(sub[f"magnitude_{d}_m"].values[s], kind="stable")
                    p = sub[f"p_md_{d}"].values[s][order]
                    a = sub[f"magnitude_{d}_m"].values[s][order]
                    sop = kind == ir.SINGLE and int(sub["source"].values[s, 0]) >= int(
                        ds.attrs["gps_slots"])
                    col = "tab:green" if sop else colors[kind]
                    mon = bool(sub[f"monitored_{d}"].values[s, 0])
                    if kind == ir.FAULT_FREE:
                        ax.axhline(max(float(p[0]), 1e-300), color="k", lw=1.2, ls=":")
                        shown |= float(p[0]) >= 1e-30
                        continue
                    ax.plot(a, np.where(p > 0, p, np.nan), "-" if mon else "--", color=col,
                            lw=0.9, alpha=0.8)
                    shown |= bool(np.any(p >= 1e-30))
                ax.axhline(float(ds["allocated"].values[ci, g0, j]), color="0.3", ls="-.",
                           lw=1)
                if not shown:  # nothing above the axis floor: say so, not an empty panel
                    pl = float(sub[f"{d}pl_m"].values[0, 0])
                    ax.text(0.5, 0.5, f"{word[0].upper()}PL {pl:,.0f} m: P(HMI | fault) below "
                            "1e-30 (the axis floor)\nfor every scenario and magnitude",
                            ha="center", transform=ax.transAxes, fontsize=8)
                    ax.set_xticks([])  # no curve: a magnitude scale would mean nothing
                ax.set_yscale("log")
                ax.set_ylim(1e-30, 2.0)
                ax.set_xlabel("fault magnitude |f| (m)")
                ax.set_ylabel(f"P(HMI {word} | fault)")
                ratio = float(ds["risk"].values[ci, g0, j] / ds["allocated"].values[ci, g0, j])
                ax.set_title(f"{'no SOPs' if n == 0 else f'{n} SOPs'}, {word}: measured / "
                             f"allocated {ratio:.2g}", fontsize=9)
                ax.grid(alpha=0.3)
        from matplotlib.lines import Line2D
        handles = [Line2D([], [], color=col, label=lab) for col, lab in (
            ("tab:blue", "one GPS satellite"), ("tab:green", "one SOP tower"),
            ("tab:red", "constellation"), ("tab:purple", "two sources"),
            ("k", "fault-free (dotted)"), ("0.3", "allocated PHMI (dash-dot)"))]
        handles.append(Line2D([], [], color="0.5", ls="--", label="not monitored (P_NM)"))
        axes[0, -1].legend(handles=handles, fontsize=7, loc="lower right")
        fig.suptitle(f"Risk vs fault magnitude per mode, geometry {g0} (missed detection, "
                     "importance sampling)", fontsize=10)
        paths.append(_save(fig, f"{out_dir}/risk_vs_magnitude.png"))

        fig, ax = plt.subplots(figsize=(6.4, 4.2), layout="constrained")
        for ci, n in enumerate(cells):
            for j, ls in ((0, "-"), (1, "--")):
                r = (ds["risk"].values[ci, :, j] / ds["allocated"].values[ci, :, j])
                r = np.sort(r[np.isfinite(r) & (ds["status"].values[ci, :, 0, 0] == 0)])
                if not r.size:
                    continue
                label = f"{'no SOPs' if n == 0 else f'{n} SOPs'}, {'HPL' if j == 0 else 'VPL'}"
                if not np.any(r > 0):  # off the log axis
                    ax.plot([], [], ls, label=label + ": 0 for every geometry")
                    continue
                ax.step(r, np.arange(1, r.size + 1) / r.size, ls, where="post", label=label)
        ax.axvline(1.0, color="k", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel("measured / allocated integrity risk (Table I)")
        ax.set_ylabel("share of geometries")
        ax.set_title("Does the PL bound the risk? (<= 1: yes)", fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        paths.append(_save(fig, f"{out_dir}/risk_ratio_cdf.png"))

        if "ramp_p_md" in ds and float(ds["ramp_p_md"].max()) > 0:
            ci = int(np.argmax(cells))
            fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
            t = ds["ramp_time_s"].values
            for j, ax in enumerate(axes):
                for k in range(int(cells[ci])):
                    p = ds["ramp_p_md"].values[ci, k, j]
                    ax.plot(t, np.where(p > 0, p, np.nan), label=f"tower {k}")
                if not np.any(ds["ramp_p_md"].values[ci, :, j] > 0):
                    ax.text(0.5, 0.5, "P(HMI) below 1e-300 at every epoch\n(the PL of geometry 0 "
                            "is far above any error)", ha="center", transform=ax.transAxes,
                            fontsize=8)
                ax.set_yscale("log")
                if not np.any(ds["ramp_p_md"].values[ci, :, j] > 0):
                    ax.set_xlim(float(t.min()), float(t.max()))
                    ax.set_ylim(1e-300, 1.0)  # no curve: the scale only frames the note
                ax.set_xlabel("time since the ramp started (s)")
                ax.set_ylabel(f"P(HMI {'horizontal' if j == 0 else 'vertical'}) per epoch")
                ax.grid(alpha=0.3)
            axes[0].legend(fontsize=8)
            fig.suptitle(f"SOP tower ramps, {int(cells[ci])} SOPs, geometry 0 (snapshot MHSS "
                         "with exclusion, importance sampling)", fontsize=10)
            paths.append(_save(fig, f"{out_dir}/sop_ramp_risk.png"))
        return paths
