"""Does a filter's protection level bound the risk? The solution-separation filter bank against
seed 000's Xi-slope HPL and the snapshot MHSS on the same simulated drives
(docs/filter-integrity.md).

One realization is one run of the seed 000 drive (``sim.drive_seed000``, 5 towers of one
operator, LTE + IMU EKF; ``sim.simulate_filter_drive``) under one fault scenario:

- ``fault-free``;
- ``step``: a bias on one tower, the tower uniform over the five, the onset uniform in
  [0.1, 0.6] of the run, the size log-uniform in ``step_m`` (m);
- ``ramp``: a bias growing at a slope log-uniform in ``ramp_m_s`` (m/s), same tower and onset
  draws (a tower clock or a multipath bias drifting away: the case an innovation test misses).

Each run carries three monitors on the same measurements: the filter bank (main EKF + one
sub-filter per order-1 mode of ``fault_modes``: 5 towers and the operator), seed 000's EKF
with NIS detection and the Xi-slope HPL (the same estimate as the bank's main filter; no
exclusion), and the snapshot MHSS of each epoch's pseudoranges (its own estimate). An epoch is
*at risk* from the onset on (every epoch of a fault-free run); it is hazardously misleading
(HMI) for a monitor when HPE > HPL and the monitor raised no alert.

**What is compared with the budget.** The PL equation (seed 004 eq. 14) spends at most PHMI_H
on the sum over modes of P_f,i P(HMI | mode i), so a single-tower fault, whatever its size and
onset, may give P(HMI | fault) <= PHMI_H / P_s (here 9.9e-8 / 1e-5 ~ 1e-2 per epoch); the
fault-free epochs may give at most PHMI_H ~ 1e-7, which a Monte Carlo of this size cannot
resolve (reported as its upper confidence bound, 'not resolved'). The rate is per at-risk
epoch with a Clopper-Pearson 95 % interval; epochs of one run are correlated, so the runs with
at least one HMI epoch are reported too (the per-run share, an independent count). A check
fails where the interval's lower end lies above the allocation. ``sigma_scale`` < 1 makes
every filter believe its pseudoranges better than they are: the check must then fail (the
committed quick run and tests/test_filter_integrity.py show it does).

The seed 004 UAV flight (``uav=yes``, the default) runs the same three scenarios on the flight's
geometry (``studies/seed004_uav/filter_mc.py``: GPS + 11 SOPs of 3 operators, ``grouped`` modes
at the order the snapshot MHSS needs, a linear constant-velocity bank of 87 filters told the
truth: the vehicle's deviation from the flight path follows the bank's own model, white noise
of the model's variances); the fault hits a source in view the whole flight. Its allocation
for a fault is PHMI_H / P_s^SOP (1e-4: the stricter of GPS and SOP). The UAV has no IMU and no
Xi-slope HPL here: the bank alone.

Beside the crude counts, ``conditional=yes`` (the default) estimates each scenario's P(HMI)
bound by eq. (1) of ``araim.filter_risk`` (``studies/filter_integrity_conditional.py``):
the Gaussian factors computed, the fault magnitude by quadrature, the faulty source
importance sampled, with a crude check at 0.3 HPL on the study's own runs that flags a wrong
model (docs/filter-integrity.md, "The conditional risk estimate"; conditional.png).

Choices (the seeds give none): P_s = 1e-5 per tower and epoch, P_const = 1e-8 for the operator
(below P_THRES: the operator mode is left in P_NM, as a common operator bias goes into the
receiver clock), seed 004 Table I budget, HAL 30 m (seed 001), the clean world by default
(white noise, the filter told the truth: the filter bank's P_sub - P_main holds); ``world=
realistic`` adds the Gauss-Markov multipath and tower clocks of ``sim.ErrorModel`` and
``gm_overbound=yes`` inflates the filters' variance by the GM long-run overbound, while
``tower_states=yes`` augments the bank's filters with each tower's correlated-error states
(the world's GM multipath and clock deviation and the error of the clock line the receiver
fitted in the GNSS period, with their exact prior: ``sim.filter_drive.tower_error_states``).
Not done: exclusion (the banks here run without it).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr
from scipy import special

from oaraim import araim, errors, mc, sim
from oaraim.studies import filter_integrity_conditional as fic
from oaraim.studies.base import (
    Param,
    Study,
    StudyResult,
    in_range,
    parse_choice,
    positive,
    probability,
)
from oaraim.studies.common.seed004 import NAV, NAV_FILE

#: runs per call of the vmapped kernel: one compiled shape whatever the realization count
MC_BATCH = 16
SCENARIOS = ("fault-free", "step", "ramp")
MONITORS = sim.filter_drive.MONITORS
MONITOR_LABELS = {"filter_ss": "filter solution separation", "ekf_xi_slope": "EKF NIS + Xi-slope",
                  "snapshot_mhss": "snapshot MHSS"}
#: the onset window, as fractions of the run's duration
ONSET_WINDOW = (0.1, 0.6)
#: cells of the fault draws (mc.realization_keys): one per scenario, apart from the runs'
FAULT_CELL = 100
#: cells of the UAV flight's runs and of their fault draws
UAV_CELL, UAV_FAULT_CELL = 200, 300


def _range(name, v):
    """'lo,hi' with 0 < lo <= hi."""
    try:
        lo, hi = (float(x) for x in str(v).split(","))
    except ValueError:
        raise ValueError(f"{name} must be 'lo,hi' (two numbers), got {v!r}") from None
    if not 0 < lo <= hi:
        raise ValueError(f"{name} must satisfy 0 < lo <= hi, got {v!r}")
    return f"{lo:g},{hi:g}"


@functools.cache
def _kernel(cfg):
    """The jitted vmapped drive of one config (static)."""
    def f(keys, faults, setup, err, sigma_f):
        return jax.vmap(lambda k, fl: sim.simulate_filter_drive(
            k, setup, err, fl, cfg, filter_sigma_pr_m=sigma_f))(keys, faults)
    return jax.jit(f)


@functools.cache
def _uav_setup(n_epochs, nav):
    from oaraim.studies.seed004_uav import filter_mc
    return filter_mc.uav_setup(n_epochs, nav)


@functools.cache
def _uav_kernel(n_epochs, nav):
    """The jitted vmapped UAV run on the flight of ``_uav_setup`` (static)."""
    from oaraim.studies.seed004_uav import filter_mc
    st = _uav_setup(n_epochs, nav)
    return jax.jit(jax.vmap(lambda k, f: filter_mc.uav_run(k, st, f)))


@functools.cache
def _trace_kernel(cfg):
    def f(key, fault, setup, err, sigma_f):
        return sim.simulate_filter_drive(key, setup, err, fault, cfg, filter_sigma_pr_m=sigma_f,
                                         traces=True)[1]
    return jax.jit(f)


class FilterIntegrity(Study):
    """The ``filter-integrity`` study (module docstring)."""

    name = "filter-integrity"
    title = ("Measured integrity risk of a filter's PLs: solution-separation filter bank vs "
             "Xi-slope HPL vs snapshot MHSS, seed 000 drive and seed 004 UAV flight, steps "
             "and ramps")
    seed_file = "000_da291ac15380f45f.txt"
    realization = ("one run of the seed 000 drive and one of the seed 004 UAV flight per fault "
                   "scenario (fault-free, step, ramp)")
    nav_file = NAV_FILE
    default_realizations = 160
    quick_realizations = 16
    quick_sets = {"duration_s": 60.0}
    quick_cost_s = 190
    max_realizations = 100_000
    #: the generic tests of tests/test_studies.py cap realizations at this (a realization is a
    #: whole drive through a bank of 7 EKFs)
    test_realizations = 16
    params = {
        "duration_s": Param(0.0, in_range(0.0, 1e4),
                            "truncate the drive to this many seconds (0: whole drive, 145 s)",
                            "s"),
        "world": Param("clean", parse_choice("clean", "realistic"),
                       "error world: clean (white noise, filter told the truth) or realistic "
                       "(sim.ErrorModel: GM multipath, tower clocks, calibration; no NLOS)"),
        "gm_overbound": Param("no", parse_choice("no", "yes"),
                              "inflate the filters' variance by the GM multipath long-run "
                              "overbound (sim.filter_drive.gm_overbound_variance)"),
        "tower_states": Param("no", parse_choice("no", "yes"),
                              "augment the bank's filters with each tower's correlated-error "
                              "states (GM multipath and clock deviation, the calibration "
                              "line's error: sim.filter_drive.tower_error_states) instead of "
                              "treating them as white; exclusive with gm_overbound"),
        "sigma_pr_m": Param(2.0, positive, "white pseudorange noise of the truth", "m"),
        "sigma_scale": Param(1.0, in_range(1e-3, 100.0),
                             "the filters' pseudorange sigma = this x the truth's (< 1: an "
                             "injected model error, the check must fail)"),
        "step_m": Param("3,60", _range, "step size range, log-uniform", "m"),
        "ramp_m_s": Param("0.02,2", _range, "ramp slope range, log-uniform", "m/s"),
        "p_s": Param(1e-5, probability, "P_s per tower and epoch"),
        "p_const": Param(1e-8, probability, "P_const of the operator"),
        "fault_modes": Param("add-v4.2", parse_choice(*araim.FAULT_MODE_CONVENTIONS),
                             "fault-mode convention of the bank and the snapshot"),
        "hal_m": Param(30.0, positive, "horizontal alert limit (seed 001)", "m"),
        "uav": Param("yes", parse_choice("yes", "no"),
                     "also the seed 004 UAV flight (GPS + 11 SOPs, grouped modes, a linear "
                     "constant-velocity bank: studies/seed004_uav/filter_mc.py)"),
        "uav_epochs": Param(240, in_range(10, 100000), "epochs over the 220 s UAV flight "
                            "(240: 1.1 Hz)"),
        "nav": NAV,
        "conditional": Param("yes", parse_choice("yes", "no"),
                             "also the conditional estimate of the bank's risk (eq. 1 of "
                             "araim.filter_risk: Gaussian factors computed, the magnitude by "
                             "quadrature, the source importance sampled) with its crude check "
                             "at 0.3 HPL on the same runs (docs/filter-integrity.md)"),
        "linearisation": Param("main", parse_choice(*araim.filter_monitor.LINEARISATIONS),
                               "the EKF bank's sub-filters: error-state filters about the main "
                               "filter (main) or each a full EKF about its own estimate (own, "
                               "the earlier bank: false alerts, docs/filter-integrity.md)"),
    }

    def check(self, params):
        """Refuses the GM overbound together with the towers' error states (both model the
        same errors)."""
        if params["tower_states"] == "yes" and params["gm_overbound"] == "yes":
            raise ValueError("tower_states=yes models the Gauss-Markov errors the GM overbound "
                             "inflates for; set gm_overbound=no (or tower_states=no)")

    def run(self, params, realizations, seed, progress):
        """Every scenario's runs through ``sim.simulate_filter_drive``, then the rates."""
        p = params
        budget = araim.BUDGET_SEED004_TABLE_I
        cfg = sim.FilterDriveConfig(budget=budget, p_sat=p["p_s"], p_const=p["p_const"],
                                    fault_modes=p["fault_modes"], max_order=1,
                                    hal_m=p["hal_m"],
                                    gm_inflation=1.0 if p["gm_overbound"] == "yes" else 0.0,
                                    linearisation=p["linearisation"],
                                    tower_states=p["tower_states"] == "yes")
        setup = sim.drive_setup(sim.drive_seed000(),
                                duration_s=p["duration_s"] if p["duration_s"] > 0 else None)
        t_end = float(setup.t_s[-1])
        if p["world"] == "clean":
            err = errors.ErrorModel.clean(sigma_pr_m=p["sigma_pr_m"], fault_onset_s=np.inf,
                                       fault_bias_m=0.0)
        else:
            err = errors.ErrorModel(sigma_pr_m=p["sigma_pr_m"], nlos_rate_per_s=0.0,
                                 fault_onset_s=np.inf, fault_bias_m=0.0)
        sigma_f = p["sigma_scale"] * p["sigma_pr_m"] if (
            p["world"] == "clean" or p["sigma_scale"] != 1.0) else 0.0
        n_t = int(setup.towers.shape[0])
        onset = (ONSET_WINDOW[0] * t_end, ONSET_WINDOW[1] * t_end)
        fn = _kernel(cfg)
        fields = sim.FilterDriveSummary._fields
        out = {s: {k: [] for k in fields} for s in SCENARIOS}
        drawn = {s: [] for s in SCENARIOS}
        traces = {}
        cond = p["conditional"] == "yes"
        case = fic.DriveCase(setup, err, cfg, sigma_f)
        dval = {s: [] for s in SCENARIOS}
        for si, scen in enumerate(SCENARIOS):
            for start in range(0, realizations, MC_BATCH):
                m = min(MC_BATCH, realizations - start)
                keys = mc.realization_keys(seed, si, start, MC_BATCH)
                faults = self._faults(scen, seed, si, start, n_t, onset, p)
                s = fn(keys, faults, setup, err, sigma_f)
                if cond and start < fic.MAX_RUNS:
                    dval[scen].append([x[:m] for x in fic.drive_validation(case, keys, faults)])
                for k in fields:
                    out[scen][k].append(np.asarray(getattr(s, k))[:m])
                drawn[scen].append(np.stack([np.asarray(x, float)[:m] for x in faults], -1))
                if progress is not None:
                    progress.advance(m)
            fl0 = jax.tree.map(lambda x: x[0], self._faults(scen, seed, si, 0, n_t, onset, p))
            traces[scen] = _trace_kernel(cfg)(mc.realization_keys(seed, si, 0, 1)[0], fl0,
                                              setup, err, sigma_f)
        res = {s: {k: np.concatenate(v) for k, v in out[s].items()} for s in SCENARIOS}
        faults = {s: np.concatenate(drawn[s]) for s in SCENARIOS}
        ds = self._dataset(res, faults, traces, realizations, p, budget)
        rows, metrics = self._summary(res, faults, p, budget, realizations, t_end)
        if cond:
            c_rows, metrics["conditional"] = fic.drive_rows(
                case, dval, p, min(realizations, fic.MAX_RUNS), seed, onset, budget)
            rows[-1:-1] = c_rows
            ds = ds.assign(fic.dataset_vars(metrics["conditional"], "cond"))
        if p["uav"] == "yes":
            uav_vars, uav_rows, uav_metrics = self._uav(p, realizations, seed, budget, progress)
            ds = ds.assign(uav_vars)
            check = rows.pop()
            rows.extend(uav_rows)
            rows.append(check)
            metrics["uav"] = uav_metrics
            passed = metrics["integrity_check"]["passed"] and uav_metrics["passed"]
            metrics["integrity_check"]["passed"] = bool(passed)
            check["reproduced"] = float(passed)
        if cond:
            c_ok = metrics["conditional"]["passed"] and (
                p["uav"] != "yes" or metrics["uav"]["conditional"]["passed"])
            metrics["conditional"]["check_passed"] = bool(c_ok)
            rows.insert(len(rows) - 1, fic.check_row(c_ok))
        ds.attrs["check_passed"] = int(metrics["integrity_check"]["passed"])
        return StudyResult(ds, rows, metrics)

    @staticmethod
    def _uav(p, n, seed, budget, progress):
        """The three scenarios on the seed 004 UAV flight (``filter_mc.uav_run``): the fault on a
        source in view the whole flight (uniform), onset and size as the drive's. Returns
        (dataset variables, rows, metrics)."""
        n_ep = int(p["uav_epochs"])
        st = _uav_setup(n_ep, p["nav"])
        fn = _uav_kernel(n_ep, p["nav"])
        t = st.t_s
        onset = (ONSET_WINDOW[0] * t[-1], ONSET_WINDOW[1] * t[-1])
        cand = np.flatnonzero(st.faultable)
        hal = p["hal_m"]
        names = ("n_at_risk", "n_misleading", "n_exceed", "n_false_alerts", "n_free",
                 "n_available", "hpl_sum_m", "n_finite", "delay_s", "source")
        out = {s: {k: [] for k in names} for s in SCENARIOS}
        trace = {}
        cond = p["conditional"] == "yes"
        vfn = fic.uav_validation_kernel((n_ep, p["nav"])) if cond else None
        uval = {s: [] for s in SCENARIOS}
        for si, scen in enumerate(SCENARIOS):
            for start in range(0, n, MC_BATCH):
                m = min(MC_BATCH, n - start)
                keys = mc.realization_keys(seed, UAV_CELL + si, start, MC_BATCH)
                f = FilterIntegrity._faults(scen, seed, si, start, cand.size, onset, p,
                                            UAV_FAULT_CELL)
                f = f._replace(source=jnp.where(f.source >= 0, jnp.asarray(cand)[
                    jnp.clip(f.source, 0)], -1))
                hpe, hpl, alert, bias = (np.asarray(x)[:m] for x in fn(keys, f))
                if cond and start < fic.MAX_RUNS:
                    uval[scen].append([np.asarray(x)[:m] for x in vfn(keys, f)])
                src = np.asarray(f.source)[:m]
                on = np.asarray(f.onset_s)[:m]
                risk = t[None] >= np.where(src >= 0, on, -np.inf)[:, None]
                faulted = risk & (src >= 0)[:, None]
                exceed = hpe > hpl
                fin = np.isfinite(hpl)
                first = np.min(np.where(alert & risk, t[None], np.inf), axis=1)
                o = out[scen]
                o["n_at_risk"].append(risk.sum(1))
                o["n_misleading"].append((exceed & ~alert & risk).sum(1))
                o["n_exceed"].append((exceed & risk).sum(1))
                o["n_false_alerts"].append((alert & ~faulted).sum(1))
                o["n_free"].append((~faulted).sum(1))
                o["n_available"].append(((hpl <= hal) & risk).sum(1))
                o["hpl_sum_m"].append(np.where(fin & risk, hpl, 0.0).sum(1))
                o["n_finite"].append((fin & risk).sum(1))
                o["delay_s"].append(np.where(src >= 0, first - np.where(src >= 0, on, 0.0),
                                             np.inf))
                o["source"].append(src)
                if start == 0:
                    trace[scen] = (hpe[0], hpl[0], alert[0],
                                   bias[0, :, max(int(src[0]), 0)] if src[0] >= 0
                                   else np.zeros_like(t))
                if progress is not None:
                    progress.advance(0)
        res = {s: {k: np.concatenate(v) for k, v in out[s].items()} for s in SCENARIOS}
        rows, per, passed = [], {}, True
        p_s_max = float(np.max(st.p_s[cand]))
        for scen in SCENARIOS:
            r = res[scen]
            alloc = budget.phmi_h if scen == "fault-free" else budget.phmi_h / p_s_max
            k, nn = int(r["n_misleading"].sum()), int(r["n_at_risk"].sum())
            rate = mc.rate_with_interval(k, nn)
            fails = rate["ci_low"] > alloc
            passed = passed and not fails
            verdict = "exceeds the allocation" if fails else (
                "within the allocation" if rate["ci_high"] <= alloc else
                "not resolved (bound above the allocation)")
            fa = mc.rate_with_interval(int(r["n_false_alerts"].sum()), int(r["n_free"].sum()))
            mean_hpl = float(r["hpl_sum_m"].sum() / max(r["n_finite"].sum(), 1))
            avail = 100.0 * float(r["n_available"].sum()) / max(nn, 1)
            d = r["delay_s"]
            per[scen] = {"hmi_per_epoch": rate, "allocation": alloc, "verdict": verdict,
                         "hpe_gt_hpl": mc.rate_with_interval(int(r["n_exceed"].sum()), nn),
                         "false_alerts": fa, "mean_hpl_m": mean_hpl, "availability_pct": avail,
                         "detected_runs_pct": (100.0 * float(np.mean(np.isfinite(d)))
                                               if scen != "fault-free" else None),
                         "median_detection_delay_s": (float(np.median(d))
                                                      if scen != "fault-free" else None)}
            det = ("" if scen == "fault-free" else
                   f"; detected in {per[scen]['detected_runs_pct']:.3g} % of runs, median "
                   f"delay {per[scen]['median_detection_delay_s']:.3g} s")
            rows.append({
                "quantity": f"P(HMI) per at-risk epoch, {scen}, UAV flight (seed 004), filter "
                            "solution separation", "unit": "-", "published": None,
                "reproduced": rate["rate"],
                "note": f"{k} of {nn} epochs, 95 % CI [{rate['ci_low']:.2g}, "
                        f"{rate['ci_high']:.2g}], allocation {alloc:.2g}"
                        f"{'' if scen == 'fault-free' else ' (PHMI_H / P_s of a SOP)'}: "
                        f"{verdict}; mean HPL {mean_hpl:.3g} m, available at HAL {hal:g} m "
                        f"{avail:.3g} %; alerts without a fault {fa['count']} of "
                        f"{fa['trials']} epochs{det}"})
        v = {f"uav_{k}": (("scenario", "run"), np.stack([res[s][k] for s in SCENARIOS]))
             for k in names}
        for i, k in enumerate(("hpe_m", "hpl_m", "alert", "fault_m")):
            v[f"uav_trace_{k}"] = (("scenario", "uav_epoch"),
                                   np.stack([trace[s][i] for s in SCENARIOS]))
        v["uav_trace_t_s"] = ("uav_epoch", t)
        v["uav_source_id"] = ("uav_source", st.ids)
        metrics = {"scenarios": per, "passed": bool(passed), "epochs": n_ep,
                   "filters": int(araim.filter_monitor.n_bank_filters(
                       st.used.shape[1], st.sources.p_const.size, st.options.max_order,
                       st.options.fault_modes)),
                   "max_order": int(st.options.max_order), "faultable_sources": int(cand.size)}
        if cond:
            c_rows, metrics["conditional"] = fic.uav_rows(st, uval, p, min(n, fic.MAX_RUNS), seed,
                                                          onset, budget)
            rows.extend(c_rows)
            v.update(fic.dataset_vars(metrics["conditional"], "uav_cond"))
        return v, rows, metrics

    @staticmethod
    def _faults(scen, seed, si, start, n_t, onset, p, cell=FAULT_CELL):
        """MC_BATCH fault scenarios of runs start.., one key per run (cell ``cell`` + si)."""
        if scen == "fault-free":
            nf = sim.no_fault()
            return jax.tree.map(lambda x: jnp.broadcast_to(x, (MC_BATCH,)), nf)
        keys = mc.realization_keys(seed, cell + si, start, MC_BATCH)
        size = fic.fault_size_range(p, scen)
        draw = jax.vmap(lambda k: jax.tree.map(lambda x: x[0], sim.draw_faults(
            k, 1, n_t, scen, onset, size)))
        return draw(keys)

    @staticmethod
    def _dataset(res, faults, traces, n, p, budget):
        v = {}
        for k in res[SCENARIOS[0]]:
            arr = np.stack([res[s][k] for s in SCENARIOS])
            third = "sep_sigma" if k == "n_sep_over" else "monitor"
            v[k] = (("scenario", "run", third) if arr.ndim == 3 else ("scenario", "run"), arr)
        v["fault"] = (("scenario", "run", "fault_field"),
                      np.stack([faults[s] for s in SCENARIOS]))
        for k in ("hpe_m", "hpl_m", "alert"):
            v[f"trace_{k}"] = (("scenario", "epoch", "monitor"),
                               np.stack([np.asarray(getattr(traces[s], k)) for s in SCENARIOS]))
        v["trace_fault_m"] = (("scenario", "epoch"),
                              np.stack([np.asarray(traces[s].fault_m) for s in SCENARIOS]))
        v["trace_t_s"] = ("epoch", np.asarray(traces[SCENARIOS[0]].t_s))
        return xr.Dataset(v, coords={"scenario": list(SCENARIOS), "run": np.arange(n),
                                     "monitor": list(MONITORS),
                                     "sep_sigma": list(sim.filter_drive.SEPARATION_SIGMAS),
                                     "fault_field": list(sim.FaultScenario._fields)},
                          attrs={"phmi_h": budget.phmi_h, "p_s": p["p_s"], "hal_m": p["hal_m"],
                                 "realizations": n, "world": p["world"],
                                 "linearisation": p["linearisation"],
                                 "sigma_scale": p["sigma_scale"],
                                 "tower_states": p["tower_states"]})

    @staticmethod
    def _summary(res, faults, p, budget, n, t_end):
        rows, per = [], {}
        passed = True
        for scen in SCENARIOS:
            r = res[scen]
            allocation = budget.phmi_h if scen == "fault-free" else budget.phmi_h / p["p_s"]
            per[scen] = {}
            for mi, mon in enumerate(MONITORS):
                k, nn = int(r["n_misleading"][:, mi].sum()), int(r["n_at_risk"].sum())
                rate = mc.rate_with_interval(k, nn)
                runs_hmi = mc.rate_with_interval(int(np.sum(r["n_misleading"][:, mi] > 0)), n)
                exceed = mc.rate_with_interval(int(r["n_exceed"][:, mi].sum()), nn)
                resolved = rate["ci_high"] < 1.0 and (rate["ci_high"] <= allocation
                                                     or rate["ci_low"] > allocation)
                fails = rate["ci_low"] > allocation
                if mon == "filter_ss":
                    passed = passed and not fails
                fin = np.maximum(r["n_finite"][:, mi].sum(), 1)
                delay = r["detection_delay_s"][:, mi]
                per[scen][mon] = {
                    "hmi_per_epoch": rate, "runs_with_hmi": runs_hmi, "hpe_gt_hpl": exceed,
                    "allocation": allocation,
                    "verdict": "exceeds the allocation" if fails else (
                        "within the allocation" if resolved else "not resolved (bound above "
                        "the allocation)"),
                    "mean_hpl_m": float(r["hpl_sum_m"][:, mi].sum() / fin),
                    "availability_pct": 100.0 * float(r["n_available"][:, mi].sum()) / max(nn, 1),
                    "false_alerts": int(r["n_false_alerts"][:, mi].sum()),
                    "epochs_without_fault": int(r["n_epochs"].sum()) - (
                        int(r["n_at_risk"].sum()) if scen != "fault-free" else 0),
                    "detected_runs_pct": (100.0 * float(np.mean(np.isfinite(delay)))
                                          if scen != "fault-free" else None),
                    "median_detection_delay_s": (float(np.median(delay)) if scen != "fault-free"
                                                 else None),
                    "max_hpe_m": float(r["hpe_max_m"][:, mi].max()),
                }
                d = per[scen][mon]
                rows.append({
                    "quantity": f"P(HMI) per at-risk epoch, {scen}, {MONITOR_LABELS[mon]}",
                    "unit": "-", "published": None, "reproduced": rate["rate"],
                    "note": (f"{k} of {nn} epochs, 95 % CI [{rate['ci_low']:.2g}, "
                             f"{rate['ci_high']:.2g}], allocation {allocation:.2g}: "
                             f"{d['verdict']}; runs with HMI {runs_hmi['count']} of {n}; "
                             f"mean HPL {d['mean_hpl_m']:.3g} m, available at HAL "
                             f"{d['availability_pct']:.3g} %; alerts without a fault "
                             f"{d['false_alerts']} of {d['epochs_without_fault']} epochs")})
            if scen == "ramp":
                for mon in MONITORS:
                    d = per[scen][mon]
                    rows.append({"quantity": f"ramp detection delay (median), "
                                             f"{MONITOR_LABELS[mon]}", "unit": "s",
                                 "published": None,
                                 "reproduced": d["median_detection_delay_s"],
                                 "note": f"detected in {d['detected_runs_pct']:.3g} % of runs; "
                                         "the median over all runs, an undetected run counting "
                                         "as inf"})
        fa = sum(per[s]["filter_ss"]["false_alerts"] for s in SCENARIOS)
        n_free = sum(per[s]["filter_ss"]["epochs_without_fault"] for s in SCENARIOS)
        fa_rate = mc.rate_with_interval(fa, n_free)
        fa_alloc = (budget.p_fa_h + budget.p_fa_v) / budget.n_es_cont
        fa_ok = fa_rate["ci_low"] <= fa_alloc
        fa_verdict = ("exceeds the allocation" if not fa_ok else (
            "within the allocation" if fa_rate["ci_high"] <= fa_alloc else
            "consistent with the allocation (not resolved: bound above it)"))
        rows.append({"quantity": "alerts without a fault per epoch, filter solution separation",
                     "unit": "-", "published": None, "reproduced": fa_rate["rate"],
                     "note": f"{fa} of {n_free} fault-free epochs (all scenarios), 95 % CI "
                             f"[{fa_rate['ci_low']:.2g}, {fa_rate['ci_high']:.2g}] against the "
                             f"false-alert allocation P_FA_H + P_FA_V = {fa_alloc:.2g}: "
                             f"{fa_verdict} (sub-filters linearised: {p['linearisation']})"})
        n_tests = sum(int(res[s]["n_sep_tests"].sum()) for s in SCENARIOS)
        tails = {}
        for j, k_sig in enumerate(sim.filter_drive.SEPARATION_SIGMAS):
            cnt = sum(int(res[s]["n_sep_over"][:, j].sum()) for s in SCENARIOS)
            t = mc.rate_with_interval(cnt, n_tests)
            t["gaussian"] = float(2.0 * special.ndtr(-k_sig))
            tails[f"{k_sig:g}"] = t
            rows.append({"quantity": f"P(|separation| > {k_sig:g} sigma_ss), fault-free, filter "
                                     "solution separation", "unit": "-", "published": None,
                         "reproduced": t["rate"],
                         "note": f"{cnt} of {n_tests} monitored separation tests (mode x "
                                 f"direction x epoch), CI [{t['ci_low']:.2g}, "
                                 f"{t['ci_high']:.2g}] as if independent (they are not: "
                                 f"correlated in time and across modes); Gaussian with "
                                 f"covariance P_i - P_0: {t['gaussian']:.2g}"})
        rows.append({"quantity": "integrity check: the filter bank's P(HMI) not above the "
                                 "allocation in any scenario", "unit": "pass", "published": None,
                     "reproduced": float(passed),
                     "note": "1 pass, 0 fail; sigma_scale < 1 (an injected model error) must "
                             "fail it"})
        metrics = {"scenarios": per, "integrity_check": {"passed": bool(passed)},
                   "filter_ss_false_alerts": {**fa_rate, "allocation": fa_alloc,
                                              "verdict": fa_verdict},
                   "separation_tails": tails, "linearisation": p["linearisation"],
                   "runs_per_scenario": n, "drive_s": t_end, "world": p["world"],
                   "sigma_scale": p["sigma_scale"], "gm_overbound": p["gm_overbound"],
                   "tower_states": p["tower_states"],
                   "budget": {"phmi_h": budget.phmi_h, "p_fa_h": budget.p_fa_h,
                              "p_thresh": budget.p_thresh},
                   "fault_sizes": {s: {"median": float(np.median(
                       faults[s][:, 2] + faults[s][:, 3]))} for s in ("step", "ramp")}}
        return rows, metrics

    def plot(self, out_dir):
        """risk.png (measured P(HMI) with CIs vs the allocation), pl.png (HPL distributions),
        ramp_run.png (one ramp run's HPE, HPLs and alerts) and conditional.png (the conditional
        estimate beside the crude count)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from oaraim.mc import clopper_pearson

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
        phmi, p_s, hal = ds.attrs["phmi_h"], ds.attrs["p_s"], ds.attrs["hal_m"]
        files = []
        fig, ax = plt.subplots(figsize=(8.0, 4.2))
        floor = 1e-8
        for mi, mon in enumerate(MONITORS):
            for si in range(len(SCENARIOS)):
                k = int(ds["n_misleading"].values[si, :, mi].sum())
                n = int(ds["n_at_risk"].values[si].sum())
                lo, hi = clopper_pearson(k, n)
                x = si + (mi - 1) * 0.22
                rate = k / max(n, 1)
                ax.plot([x, x], [max(lo, floor), hi], color=f"C{mi}", lw=2)
                ax.plot(x, max(rate, floor), "o" if k else "v", color=f"C{mi}",
                        label=MONITOR_LABELS[mon] if si == 0 else None)
        for si, scen in enumerate(SCENARIOS):
            alloc = phmi if scen == "fault-free" else phmi / p_s
            ax.plot([si - 0.4, si + 0.4], [alloc, alloc], "k--", lw=1,
                    label="allocation (PHMI_H; PHMI_H / P_s under a fault)" if si == 0 else None)
        ax.set_yscale("log")
        ax.set_ylim(floor * 0.5, 1.5)
        ax.set_xticks(range(len(SCENARIOS)), SCENARIOS)
        ax.set_ylabel("P(HPE > HPL, no alert) per at-risk epoch")
        ax.set_title(f"Measured integrity risk, {ds.attrs['realizations']} runs per scenario "
                     f"(95 % CI; a triangle at {floor:g}: none seen)", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, loc="upper left")
        fig.tight_layout()
        files.append(f"{out_dir}/risk.png")
        fig.savefig(files[-1], dpi=120)
        plt.close(fig)

        fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.8))
        hpl = ds["trace_hpl_m"].values  # (scenario, epoch, monitor)
        for mi, mon in enumerate(MONITORS):
            h = hpl[0, :, mi]
            fin = np.sort(h[np.isfinite(h)])
            if fin.size:
                axes[0].plot(fin, np.arange(1, fin.size + 1) / h.size, color=f"C{mi}",
                             label=MONITOR_LABELS[mon])
        axes[0].axvline(hal, color="k", ls=":", label=f"HAL {hal:g} m")
        axes[0].set_xscale("log")
        axes[0].set_xlim(0.5, 1e4)
        axes[0].set_ylim(0, 1)
        axes[0].set_xlabel("HPL (m), fault-free run 0")
        axes[0].set_ylabel("share of epochs with HPL <= x (inf: never)")
        axes[0].legend(fontsize=7)
        axes[0].grid(alpha=0.3)
        mean = ds["hpl_sum_m"].values.sum(1) / np.maximum(ds["n_finite"].values.sum(1), 1)
        for mi, mon in enumerate(MONITORS):
            axes[1].bar(np.arange(len(SCENARIOS)) + (mi - 1) * 0.27, mean[:, mi], 0.25,
                        color=f"C{mi}", label=MONITOR_LABELS[mon])
        axes[1].set_yscale("log")
        axes[1].set_ylim(0.5, 1e4)
        axes[1].legend(fontsize=7)
        axes[1].set_xticks(range(len(SCENARIOS)), SCENARIOS)
        axes[1].set_ylabel("mean HPL over at-risk epochs (m)")
        axes[1].grid(alpha=0.3, axis="y")
        fig.tight_layout()
        files.append(f"{out_dir}/pl.png")
        fig.savefig(files[-1], dpi=120)
        plt.close(fig)

        t = ds["trace_t_s"].values
        si = SCENARIOS.index("ramp")
        fig, ax = plt.subplots(figsize=(8.0, 4.0))
        for mi, mon in enumerate(MONITORS):
            ax.plot(t, ds["trace_hpl_m"].values[si, :, mi], color=f"C{mi}",
                    label=f"HPL, {MONITOR_LABELS[mon]}")
            ax.plot(t, ds["trace_hpe_m"].values[si, :, mi], color=f"C{mi}", ls=":", lw=1,
                    label=f"HPE, {MONITOR_LABELS[mon]}")
            al = ds["trace_alert"].values[si, :, mi]
            if al.any():
                ax.plot(t[al], np.full(al.sum(), 0.6 * (1.4 ** mi)), "|", color=f"C{mi}",
                        ms=6)
        ax.plot(t, np.maximum(ds["trace_fault_m"].values[si], 1e-3), "k-", lw=0.8,
                label="injected ramp (m)")
        f = ds["fault"].values[si, 0]
        ax.set_yscale("log")
        ax.set_ylim(0.3, 3e3)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("m (ticks near the bottom: alerts)")
        same = ("the bank's main EKF models the towers' correlated errors: two HPEs"
                if ds.attrs.get("tower_states") == "yes"
                else "the bank's main EKF is the Xi-slope EKF: one HPE")
        ax.set_title(f"Ramp run 0: tower {int(f[0]) + 1}, onset {f[1]:.1f} s, "
                     f"{f[3]:.3g} m/s ({same})", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=6, ncol=2, loc="upper left")
        fig.tight_layout()
        files.append(f"{out_dir}/ramp_run.png")
        fig.savefig(files[-1], dpi=120)
        plt.close(fig)
        if "uav_trace_t_s" in ds:
            files.append(self._plot_uav(ds, out_dir, plt))
        if "cond_rate" in ds:
            files.append(fic.plot_conditional(ds, out_dir, plt))
        return files

    @staticmethod
    def _plot_uav(ds, out_dir, plt):
        """uav_runs.png: run 0 of the step and ramp scenarios on the UAV flight."""
        t = ds["uav_trace_t_s"].values
        fig, axes = plt.subplots(1, 2, figsize=(10.0, 3.8), sharey=True)
        for ax, scen in zip(axes, ("step", "ramp"), strict=True):
            si = SCENARIOS.index(scen)
            ax.plot(t, ds["uav_trace_hpl_m"].values[si], "C0", label="HPL, filter bank")
            ax.plot(t, ds["uav_trace_hpe_m"].values[si], "C0:", lw=1, label="HPE")
            ax.plot(t, np.maximum(ds["uav_trace_fault_m"].values[si], 1e-3), "k-", lw=0.8,
                    label="injected bias (m)")
            al = ds["uav_trace_alert"].values[si].astype(bool)
            if al.any():
                ax.plot(t[al], np.full(al.sum(), 0.15), "|", color="C3", ms=6, label="alert")
            src = str(ds["uav_source_id"].values[int(ds["uav_source"].values[si, 0])])
            ax.set_title(f"UAV flight, {scen} run 0 (fault on {src})", fontsize=9)
            ax.set_yscale("log")
            ax.set_ylim(0.1, 1e3)
            ax.set_xlabel("time (s)")
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7, loc="upper left")
        axes[0].set_ylabel("m")
        fig.tight_layout()
        path = f"{out_dir}/uav_runs.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        return path
