"""What the EKF-RAIM drive studies share (seed 000's 1.35 km drive, seed 002's 1.4 km drive):
``EkfDriveStudy``, its parameters, the single replayed drive and the Monte Carlo of runs.

Written for seed 000 (ION GNSS 2018: EKF-based RAIM of an LTE + IMU ground vehicle); seed 002
runs the same machinery on its own drive (``studies.seed002_outlier``).

The two parts (one synthesized drive written, loaded and replayed for the figures; a Monte
Carlo of whole-drive runs with a multipath sensitivity) and the choices the seeds leave open
are described once, in the seed 000 study's docstring (``studies.seed000_ekf_raim``).
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import jax
import numpy as np
import xarray as xr

from oaraim import errors, mc, readers, sim
from oaraim.araim import ekf_raim, ekf_replay
from oaraim.studies.base import (
    NO_RECORDING,
    Param,
    Study,
    StudyResult,
    count,
    in_range,
    non_negative,
    parse_choice,
    parse_recording,
    positive,
    probability,
)
from oaraim.studies.common import params as shared

#: runs per call of the vmapped drive kernel: one compiled shape, whatever the chunk
MC_BATCH = 16
FILTERS = ("without_exclusion", "with_exclusion")
VARIANTS = ("nominal", "multipath")
SUMMARY_FIELDS = sim.DriveSummary._fields
#: towers of both drives (sim.drive_seed000 / drive_seed002)
N_TOWERS = 5


def parse_dof(name, v):
    """The NIS degrees of freedom: 'n_s' (d = N_s, seed 002) or 'n_s-4' (seed 000's text)."""
    s = str(v).strip().lower().replace(" ", "")
    if s in ("n_s", "ns"):
        return "n_s"
    if s in ("n_s-4", "ns-4"):
        return "n_s-4"
    raise ValueError(f"{name} must be 'n_s' (d = N_s, seed 002) or 'n_s-4' (d = N_s - 4, seed "
                     f"000's text), got {v!r}")


def world_of(p, mp_sigma_m=None, mp_tau_s=None):
    """The ``sim.ErrorModel`` of the study parameters ``p`` (multipath replaced where given:
    the sensitivity runs)."""
    mps = p["mp_sigma_m"] if mp_sigma_m is None else mp_sigma_m
    mpt = p["mp_tau_s"] if mp_tau_s is None else mp_tau_s
    fault = dict(fault_tower=p["fault_tower"] - 1, fault_onset_s=p["fault_onset_s"],
                 fault_bias_m=p["fault_bias_m"])
    if p["world"] == "clean":
        return errors.ErrorModel.clean(sigma_pr_m=p["sigma_pr_m"], mp_sigma_m=mps, mp_tau_s=mpt,
                                    **fault)
    return errors.ErrorModel(
        sigma_pr_m=p["sigma_pr_m"], mp_sigma_m=mps, mp_tau_s=mpt,
        nlos_rate_per_s=p["nlos_rate_per_s"], nlos_duration_s=p["nlos_duration_s"],
        nlos_bias_m=p["nlos_bias_m"], clk_eps_sigma_m=p["clk_eps_sigma_m"],
        clk_eps_tau_s=p["clk_eps_tau_s"], calib_window_s=p["calib_window_s"], **fault)


def parse_path(name, v):
    """A folder path, kept as given (created when used)."""
    return str(v).strip()


def _pct_reduction(a, b):
    return 100.0 * (a - b) / a


class EkfDriveStudy(Study):
    """Shared by seed000-ekf-raim and seed002-outlier: a scenario, its published numbers, the
    single replayed drive and the Monte Carlo."""

    scenario_fn = staticmethod(sim.drive_seed000)
    fig_prefix = "seed000"
    published_rows: tuple = ()
    published_detection_s: float = 25.0
    published_length_km: float = 1.35
    default_dof = "n_s"
    #: the generic tests of tests/test_studies.py cap realizations at this (a realization is a
    #: whole drive, ~0.1 s; their 3000 would take minutes)
    test_realizations = 4

    #: parameter -> default fitted by ``oaraim calibrate`` (replaces the table's default)
    calibrated: dict = {}
    #: what the ``calibrated`` parameters were fitted to (the summary rows' note)
    calibrated_to: str = "the published RMSEs"
    #: parameter -> (default, why): a world parameter the study sets apart from the error
    #: world's default on its own evidence, not by a fit (replaces the table's default)
    chosen: dict = {}

    def __init__(self):
        # defaults = the scenario's values (sim.trajectory._scenario; tested), written
        # here so that importing the registry does not build the trajectory
        self._scenario = None
        w = errors.ErrorModel()
        self.params = {
            "world": Param("realistic", shared.parse_world, "error world: 'realistic' "
                           "(sim.ErrorModel defaults, docs/error-world.md) or 'clean' (white "
                           "noise, no multipath/NLOS/clock residual, filter told the truth's "
                           "sigma)"),
            "sigma_pr_m": Param(w.sigma_pr_m, positive, "LTE thermal (white) pseudorange "
                                "noise of the truth (seed 000: 'meter-level'; open)", "m"),
            "filter_sigma_pr_m": Param(0.0, non_negative, "pseudorange sigma of the filter "
                                       "(0: estimated from the GNSS period's fault-free data, "
                                       "seed 000 'determined empirically')", "m"),
            "fault_bias_m": Param(30.0, non_negative, "bias on the faulty tower (seed silent)",
                                  "m"),
            "fault_tower": Param(1, count(1, N_TOWERS), "faulty tower, 1-based (seed: tower 1)"),
            "fault_onset_s": Param(self.published_detection_s, in_range(0.0, 1e4),
                                   "fault onset (the seed's detection time)", "s"),
            "duration_s": Param(0.0, in_range(0.0, 1e4),
                                "truncate the drive to this many seconds (0: whole drive)", "s"),
            "mp_sigma_m": Param(w.mp_sigma_m, non_negative,
                                "GM short-delay multipath sigma per tower (0: off)", "m"),
            "mp_tau_s": Param(w.mp_tau_s, positive, "GM multipath correlation time", "s"),
            "nlos_rate_per_s": Param(w.nlos_rate_per_s, non_negative,
                                     "NLOS episode onsets per tower and second", "1/s"),
            "nlos_duration_s": Param(w.nlos_duration_s, positive, "mean NLOS episode duration",
                                     "s"),
            "nlos_bias_m": Param(w.nlos_bias_m, non_negative, "mean NLOS excess delay", "m"),
            "clk_eps_sigma_m": Param(w.clk_eps_sigma_m, non_negative, "sigma of each tower's "
                                     "own clock deviation epsilon_n (seed 004 eq. 3)", "m"),
            "clk_eps_tau_s": Param(w.clk_eps_tau_s, positive, "correlation time of epsilon_n",
                                   "s"),
            "calib_window_s": Param(w.calib_window_s, in_range(0.0, 300.0), "GNSS period of "
                                    "the tower-clock fit and the sigma estimate (seed 000 "
                                    "II-D; open)", "s"),
            "sens_mp_sigma_m": Param(3.0, non_negative, "sensitivity runs: GM multipath sigma "
                                     "per tower replacing mp_sigma_m (0: no sensitivity runs)",
                                     "m"),
            "sens_mp_tau_s": Param(30.0, positive, "sensitivity runs: multipath correlation "
                                   "time (~330 m of travel at 25 mph)", "s"),
            "p_fa": Param(1e-5, probability, "false-alarm probability per epoch (seed silent)"),
            "p_md": shared.P_MD_SILENT,
            "hal_m": Param(30.0, positive, "horizontal alert limit (seed silent; seed 001)", "m"),
            "dof": Param(self.default_dof, parse_dof,
                         "NIS degrees of freedom: n_s (seed 002) or n_s-4 (seed 000)"),
            "recording": Param(NO_RECORDING, parse_recording,
                               "replay this recorded drive folder for the single-drive figures "
                               "(Monte Carlo skipped); 'none': synthesize"),
            "drive_dir": Param("", parse_path, "keep the synthesized drive recording in this "
                               "folder (default: temporary)"),
            "chunk": Param(64, count(1), "runs per progress step (never changes a result)"),
            "monitor": Param("ekf-raim", parse_choice("ekf-raim", "filter-ss",
                                                      "filter-ss-overbound",
                                                      "filter-ss-states"),
                             "integrity monitor: 'ekf-raim' (the seeds' NIS + Xi-slope HPL) or "
                             "'filter-ss' (also the solution-separation filter bank of "
                             "docs/filter-integrity.md on the same Monte Carlo runs, beside the "
                             "Xi-slope HPL and the snapshot MHSS; the seeds' rows unchanged); "
                             "'filter-ss-overbound': the filters' variance inflated by the GM "
                             "multipath overbound; 'filter-ss-states': the filters augmented "
                             "with each tower's correlated-error states"),
        }
        for key, value in self.calibrated.items():
            self.params[key] = dataclasses.replace(
                self.params[key], default=value,
                doc=f"{self.params[key].doc}; calibrated: `oaraim calibrate {self.name}`")
        for key, (value, why) in self.chosen.items():
            self.params[key] = dataclasses.replace(
                self.params[key], default=value, doc=f"{self.params[key].doc}; here {why}")

    # ------------------------------------------------------------------ helpers
    def scenario(self):
        """The study's synthesized drive (``scenario_fn()``), built once per study object."""
        if self._scenario is None:
            self._scenario = self.scenario_fn()
        return self._scenario

    def _cfg(self, p):
        return ekf_raim.RaimConfig(p_fa=p["p_fa"], p_md=p["p_md"], hal_m=p["hal_m"],
                                   dof_offset=4 if p["dof"] == "n_s-4" else 0)

    def _duration(self, p):
        return p["duration_s"] if p["duration_s"] > 0 else None

    def _monte_carlo(self, p, setup, n, seed, mp_sigma, mp_tau, progress, part):
        """Per-run DriveSummary arrays of runs 0..n-1; ``part`` = (index, count) of this
        variant for the progress bar (total n over all variants)."""
        fn = _mc_fn()
        out = {k: [] for k in SUMMARY_FIELDS}
        vi, nv = part
        advanced = n * vi // nv
        for start in range(0, n, MC_BATCH):
            m = min(MC_BATCH, n - start)
            # always MC_BATCH keys (one compiled shape); runs beyond n are padding, trimmed
            keys = mc.realization_keys(seed, 0, start, MC_BATCH)
            s = fn(keys, setup, world_of(p, mp_sigma, mp_tau), p["filter_sigma_pr_m"],
                   p["hal_m"], 4 if p["dof"] == "n_s-4" else 0)
            for k in SUMMARY_FIELDS:
                out[k].append(np.asarray(getattr(s, k))[:m])
            if progress is not None:
                target = (vi * n + start + m) // nv
                progress.advance(target - advanced)
                advanced = target
        return {k: np.concatenate(v) for k, v in out.items()}

    def _filter_ss(self, p, setup, n, seed):
        """The filter bank, the Xi-slope HPL and the snapshot MHSS on the nominal Monte Carlo
        runs (the same keys, so the same worlds; ``sim.simulate_filter_drive``, its defaults:
        P_s 1e-5 per tower, seed 004 Table I budget), the study's fault as a step. Returns
        per monitor the misleading epochs after the onset, mean HPL, availability at HAL,
        false alerts and the median detection delay (JSON values)."""
        cfg = sim.FilterDriveConfig(
            hal_m=p["hal_m"], gm_inflation=float(p["monitor"] == "filter-ss-overbound"),
            tower_states=p["monitor"] == "filter-ss-states")
        err = world_of(p)._replace(fault_onset_s=np.inf)
        fault = sim.FaultScenario(np.asarray(p["fault_tower"] - 1), np.asarray(
            p["fault_onset_s"]), np.asarray(p["fault_bias_m"]), np.asarray(0.0))
        fn = _filter_ss_fn(cfg)
        parts = []
        for start in range(0, n, MC_BATCH):
            keys = mc.realization_keys(seed, 0, start, MC_BATCH)
            s = fn(keys, setup, err, fault, p["filter_sigma_pr_m"])
            m = min(MC_BATCH, n - start)
            parts.append(jax.tree.map(lambda x, m=m: np.asarray(x)[:m], s))
        r = {k: np.concatenate([getattr(x, k) for x in parts]) for k in parts[0]._fields}
        out = {}
        for i, mon in enumerate(sim.filter_drive.MONITORS):
            nn = int(r["n_at_risk"].sum())
            fin = max(int(r["n_finite"][:, i].sum()), 1)
            delay = r["detection_delay_s"][:, i]
            out[mon] = {
                "misleading_epochs": mc.rate_with_interval(int(r["n_misleading"][:, i].sum()),
                                                           nn),
                "mean_hpl_m": float(r["hpl_sum_m"][:, i].sum() / fin),
                "availability_pct": 100.0 * float(r["n_available"][:, i].sum()) / max(nn, 1),
                "false_alerts": int(r["n_false_alerts"][:, i].sum()),
                "detected_runs_pct": 100.0 * float(np.mean(np.isfinite(delay))),
                "median_detection_delay_s": float(np.median(delay))}
        return out

    # ------------------------------------------------------------------ run
    def run(self, params, realizations, seed, progress):
        """The single replayed drive (figures) and the Monte Carlo of ``realizations`` runs."""
        p = params
        cfg = self._cfg(p)
        sc = self.scenario()
        onset, tower = p["fault_onset_s"], p["fault_tower"] - 1
        prov = {}
        if p["recording"] != NO_RECORDING:
            rec = readers.load_recording(p["recording"])
            tr = ekf_replay.replay_ekf_raim(rec, sigma_pr_m=p["filter_sigma_pr_m"] or
                                            p["sigma_pr_m"], cfg=cfg)
            single_src = f"recording {p['recording']} ({rec.meta.get('name', '')})"
            onset_s, tower_i = None, None
            prov["recording"] = {"path": p["recording"], "meta": rec.meta}
        else:
            key0 = mc.realization_keys(seed, 0, 0, 1)[0]
            rec = sim.synthesize_recording(
                sc, key0, err=world_of(p), filter_sigma_pr_m=p["filter_sigma_pr_m"],
                duration_s=self._duration(p))
            with tempfile.TemporaryDirectory(prefix="oaraim-drive-") as tmp:
                folder = Path(p["drive_dir"]) if p["drive_dir"] else Path(tmp) / "drive"
                readers.write_recording(folder, rec, overwrite=True)
                loaded = readers.load_recording(folder)
                tr = ekf_replay.replay_ekf_raim(loaded, sigma_pr_m=p["sigma_pr_m"], cfg=cfg)
            single_src = ("synthesized run 0 written with geometry.write_recording, loaded with "
                          "geometry.load_recording, replayed by araim.ekf_replay")
            if p["drive_dir"]:
                single_src += f" (kept in {p['drive_dir']})"
            onset_s, tower_i = onset, tower
            prov["drive_meta"] = {k: v for k, v in rec.meta.items() if k != "source"}
        single = ekf_replay.trace_summary(tr, onset_s, tower_i)

        ds = self._trace_dataset(tr, p)
        mcres = {}
        if p["recording"] == NO_RECORDING:
            setup = sim.drive_setup(sc, cfg=cfg, duration_s=self._duration(p))
            variants = [("nominal", p["mp_sigma_m"], p["mp_tau_s"])]
            if p["sens_mp_sigma_m"] > 0:
                variants.append(("multipath", p["sens_mp_sigma_m"], p["sens_mp_tau_s"]))
            for vi, (name, mps, mpt) in enumerate(variants):
                mcres[name] = self._monte_carlo(p, setup, realizations, seed, mps, mpt, progress,
                                                (vi, len(variants)))
            n_ep = int(setup.t_s.shape[0]) // 10 * 10
            ds = ds.merge(self._mc_dataset(mcres, realizations))
            ds.attrs["mc_epochs_per_run"] = n_ep
            ds.attrs["mc_pre_onset_epochs"] = int(np.sum(np.asarray(setup.t_s[:n_ep]) < onset))
            if p["monitor"] != "ekf-raim":
                filter_ss = self._filter_ss(p, setup, realizations, seed)
        elif progress is not None:
            progress.advance(realizations)
        ds.attrs.update({"single_drive_source": single_src, "hal_m": p["hal_m"],
                         "fault_onset_s": -1.0 if onset_s is None else onset_s,
                         "fault_tower": -1 if tower_i is None else tower_i + 1,
                         "published_detection_s": self.published_detection_s,
                         "init_source": tr.init_source, "dof": p["dof"],
                         "p_fa": p["p_fa"], "p_md": p["p_md"]})
        rows, metrics = self._rows_metrics(p, tr, single, mcres, ds, realizations)
        metrics["single_drive_source"] = single_src
        if p["monitor"] != "ekf-raim" and mcres:
            rows += filter_ss_rows(filter_ss, realizations)
            metrics["filter_ss"] = filter_ss
        return StudyResult(ds, rows, metrics, extra_provenance=prov)

    def _trace_dataset(self, tr, p):
        def f(x):
            return ("filter", "epoch") + (("axis",) if np.ndim(x) == 3 else ()), np.asarray(x)

        v = {"t_s": ("epoch", tr.t_s), "nis": f(tr.nis), "dof": f(tr.dof),
             "threshold": f(tr.threshold), "detected": f(tr.detected),
             "excluded": f(tr.excluded), "n_used": f(tr.n_used), "hpl_m": f(tr.hpl_m),
             "alarm": f(tr.alarm), "status": f(tr.status), "n_valid": ("epoch", tr.n_valid),
             "position_enu_m": f(tr.position_enu_m), "sigma_enu_m": f(tr.sigma_enu_m)}
        if tr.err_enu_m is not None:
            v["err_enu_m"] = f(tr.err_enu_m)
            v["err_2d_m"] = f(tr.err_2d_m)
            v["truth_enu_m"] = (("epoch", "axis"), tr.truth_enu_m)
        return xr.Dataset(v, coords={"filter": list(FILTERS), "epoch": np.arange(len(tr.t_s)),
                                     "axis": ["east", "north", "up"],
                                     "tower": [str(i) for i in tr.tx_ids]},
                          attrs={"has_truth": int(tr.err_enu_m is not None)})

    def _mc_dataset(self, mcres, n):
        names = list(mcres)
        v = {}
        for k in SUMMARY_FIELDS:
            v[f"mc_{k}"] = (("variant", "run", "filter"), np.stack([mcres[x][k] for x in names]))
        rm = v["mc_rmse_2d_m"][1]
        v["mc_rmse_reduction_pct"] = (("variant", "run"), _pct_reduction(rm[..., 0], rm[..., 1]))
        return xr.Dataset(v, coords={"variant": names, "run": np.arange(n),
                                     "filter": list(FILTERS)})

    # ------------------------------------------------------------------ summary
    def _rows_metrics(self, p, tr, single, mcres, ds, n):
        s0, s1 = single["without_exclusion"], single["with_exclusion"]
        rows = []
        nan = float("nan")
        r0 = s0.get("rmse_2d_m") or nan
        r1 = s1.get("rmse_2d_m") or nan
        m0 = s0.get("max_2d_m") or nan
        m1 = s1.get("max_2d_m") or nan
        single_vals = {"rmse_without": r0, "rmse_with": r1, "reduction": _pct_reduction(r0, r1),
                       "max_without": m0, "max_with": m1,
                       "max_reduction": _pct_reduction(m0, m1)}
        mc_vals, runs = {}, {}
        if "nominal" in mcres:
            rm, mx = mcres["nominal"]["rmse_2d_m"], mcres["nominal"]["max_2d_m"]
            red = _pct_reduction(rm[:, 0], rm[:, 1])
            mred = _pct_reduction(mx[:, 0], mx[:, 1])
            runs = {"rmse_without": rm[:, 0], "rmse_with": rm[:, 1], "reduction": red,
                    "max_without": mx[:, 0], "max_with": mx[:, 1], "max_reduction": mred}
            mc_vals = {"mean": {k: v.mean() for k, v in runs.items()},
                       "median": {k: np.median(v) for k, v in runs.items()}}
        src = ("replayed recording" if p["recording"] != NO_RECORDING
               else "single drive (run 0, via recording)")
        why = self.difference_note(p)
        for key, quantity, unit, published in self.published_rows:
            spread = "" if key not in runs else "; " + published_among_runs(published, runs[key])
            rows.append({"quantity": f"{quantity}, {src}", "unit": unit, "published": published,
                         "reproduced": float(single_vals[key]),
                         "note": why + ("" if not spread else
                                        "; one draw of the Monte Carlo runs" + spread)})
            for stat, vals in mc_vals.items():
                rows.append({"quantity": f"{quantity}, Monte Carlo {stat} of {n} runs",
                             "unit": unit, "published": published,
                             "reproduced": float(vals[key]),
                             "note": "same scenario, independent noise per run" + spread})
        det = s1["first_detection_s"]
        rows.append({"quantity": "first detection (threshold exceeded), single drive",
                     "unit": "s", "published": self.published_detection_s,
                     "reproduced": nan if det is None else det,
                     "note": "our fault onset is set at the published detection time, so this "
                             "checks detection delay, not timing"})
        excl = s1["exclusions_by_tower"]
        top = max(excl, key=excl.get) if any(excl.values()) else None
        rows.append({"quantity": "excluded tower (most often), single drive", "unit": "index",
                     "published": 1,
                     "reproduced": float(list(excl).index(top) + 1) if top else nan,
                     "note": f"exclusions per tower: {excl}"})
        if self.published_length_km:
            rows.append({"quantity": "drive length", "unit": "km",
                         "published": self.published_length_km,
                         "reproduced": float(self.scenario().traj.length_m) / 1e3
                         if p["recording"] == NO_RECORDING else nan,
                         "note": "route sized to the published length"})
        metrics = {"single_drive": single, "epochs": int(len(tr.t_s)),
                   "init_source": tr.init_source, "dof": p["dof"],
                   "choices": {k: p[k] for k in (
                       "world", "sigma_pr_m", "filter_sigma_pr_m", "fault_bias_m",
                       "fault_tower", "fault_onset_s", "p_fa", "p_md", "hal_m", "mp_sigma_m",
                       "mp_tau_s", "nlos_rate_per_s", "nlos_duration_s", "nlos_bias_m",
                       "clk_eps_sigma_m", "clk_eps_tau_s", "calib_window_s",
                       "sens_mp_sigma_m", "sens_mp_tau_s")}}
        if tr.err_2d_m is not None:
            mi = np.asarray(tr.err_2d_m) > np.asarray(tr.hpl_m)
            metrics["single_drive_misleading_epochs"] = {
                f: mc.rate_with_interval(mi[i].sum(), mi.shape[1]) for i, f in enumerate(FILTERS)}
        if mcres:
            pre = int(ds.attrs["mc_pre_onset_epochs"])
            metrics["monte_carlo"] = {"runs": n, "epochs_per_run": int(
                ds.attrs["mc_epochs_per_run"]), "pre_onset_epochs_per_run": pre,
                **{v: self._mc_metrics(mcres[v], pre, p, int(ds.attrs["mc_epochs_per_run"]))
                   for v in mcres}}
        else:
            metrics["monte_carlo"] = ("skipped: --set recording replays a recorded drive; the "
                                      "Monte Carlo needs the synthetic scenario")
        return rows, metrics

    def difference_note(self, p):
        """Why our numbers differ from the published ones (the note of the summary rows)."""
        if p["world"] == "clean":
            return ("clean synthetic world: white noise, no multipath/NLOS besides the injected "
                    f"{p['fault_bias_m']:g} m fault, filter model = truth model: the "
                    "with-exclusion error is far smaller than the real drive's")
        how = (f"{', '.join(sorted(self.calibrated))} calibrated to {self.calibrated_to} "
               "(oaraim calibrate)" if self.calibrated else "not calibrated")
        if self.chosen:
            how += "; " + "; ".join(f"{k} = {v:g}: {why}" for k, (v, why) in self.chosen.items())
        return ("simulated error world (docs/error-world.md: multipath, NLOS episodes, tower-clock "
                "residual after the GNSS-period fit, empirical filter sigma) at literature / "
                f"stated defaults, {how}; the {p['fault_bias_m']:g} m fault sets the "
                "without-exclusion error")

    @staticmethod
    def _mc_metrics(r, pre, p, n_ep):
        onset = p["fault_onset_s"]
        rm, mx = r["rmse_2d_m"], r["max_2d_m"]
        red = _pct_reduction(rm[:, 0], rm[:, 1])
        det = r["detection_time_s"][:, 1]
        hit = np.isfinite(det)
        n = rm.shape[0]
        fa = r["n_false_alarms"][:, 1]
        pct = (5, 25, 50, 75, 95)

        def stats(x):
            x = np.asarray(x, float)
            return {"mean": float(x.mean()), "min": float(x.min()), "max": float(x.max())}

        out = {
            "rmse_2d_m": {f: stats(rm[:, i]) for i, f in enumerate(FILTERS)},
            "max_2d_m": {f: stats(mx[:, i]) for i, f in enumerate(FILTERS)},
            "rmse_reduction_pct": {"mean": float(red.mean()),
                                   **{f"p{q:02d}": float(np.percentile(red, q)) for q in pct}},
            "detection_rate": float(hit.mean()),
            "detection_delay_s": ({"mean": float(np.mean(det[hit] - onset)),
                                   "max": float(np.max(det[hit] - onset))} if hit.any()
                                  else None),
            "false_alarms_per_run": {"mean": float(fa.mean()), "max": int(fa.max()),
                                     "runs_with_any": float(np.mean(fa > 0))},
            "false_alarm_rate_per_epoch": float(fa.sum() / max(n * pre, 1)),
            "p_fa": p["p_fa"],
            "correct_exclusion_share_after_onset": float(
                r["n_correct_exclusions"][:, 1].sum()
                / max(r["n_detections_after_onset"][:, 1].sum(), 1)),
            "wrong_exclusions_per_run": float(r["n_wrong_exclusions"][:, 1].mean()),
            "nees_mean": {f: float(r["nees_mean"][:, i].mean()) for i, f in enumerate(FILTERS)},
            "nees_dof": 17,
            "nis_mean": {f: float(r["nis_mean"][:, i].mean()) for i, f in enumerate(FILTERS)},
            "nis_dof_mean": float(r["nis_dof_mean"][:, 1].mean()),
            "hpl_max_m": {f: float(r["hpl_max_m"][:, i].max()) for i, f in enumerate(FILTERS)},
            "hal_alarms_per_run": {f: float(r["n_alarms"][:, i].mean())
                                   for i, f in enumerate(FILTERS)},
            "misleading_epochs_per_run": {f: float(r["n_misleading"][:, i].mean())
                                          for i, f in enumerate(FILTERS)},
            # MI = 2D error > HPL. Runs are independent: the run rate's Clopper-Pearson
            # interval is exact; epochs of one run are correlated, so the epoch rate's
            # interval (computed as if independent) is too narrow
            "misleading_information": {f: {
                "runs_with_any": mc.rate_with_interval(np.sum(r["n_misleading"][:, i] > 0), n),
                "epochs": mc.rate_with_interval(np.sum(r["n_misleading"][:, i]), n * n_ep),
                "note": "epoch interval assumes independent epochs (they are not)"}
                for i, f in enumerate(FILTERS)},
            "filter_sigma_m": stats(r["filter_sigma_m"][:, 0]),
        }
        return out

    # ------------------------------------------------------------------ plots
    def plot(self, out_dir):
        """Figures of the single drive and the Monte Carlo, from the stored results."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
        a = ds.attrs
        t = ds["t_s"].values
        pre = self.fig_prefix
        paths = []
        src = a["single_drive_source"]
        src_short = "replayed recording" if src.startswith("recording") else \
            "synthesized drive via the recording format"

        # Fig. 3a: NIS vs threshold (the RAIM filter, i.e. with exclusion)
        fig, ax = plt.subplots(figsize=(7.5, 3.6))
        nis = ds["nis"].sel(filter="with_exclusion").values
        th = ds["threshold"].sel(filter="with_exclusion").values
        ax.semilogy(t, np.maximum(nis, 1e-3), lw=0.8, color="tab:blue",
                    label="test statistic phi (NIS, all towers, before exclusion)")
        ax.semilogy(t, th, lw=1.2, color="k", ls="--",
                    label=f"threshold T_h (P_FA = {a['p_fa']:g}, d = {a['dof']})")
        det = ds["detected"].sel(filter="with_exclusion").values.astype(bool)
        if det.any():
            i = int(np.argmax(det))
            ax.plot(t[i], nis[i], "o", mfc="none", mec="r", ms=12, mew=1.5,
                    label=f"first detection t = {t[i]:.1f} s (published "
                          f"{a['published_detection_s']:g} s)")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("phi")
        ax.set_title(f"{self.title}: Fig. 3a, fault detection test ({src_short})", fontsize=9)
        ax.legend(fontsize=7, loc="center right")
        ax.grid(alpha=0.3)
        fig.tight_layout()
        paths.append(f"{out_dir}/{pre}_fig3a_nis.png")
        fig.savefig(paths[-1], dpi=120)
        plt.close(fig)

        # Figs. 3b-c: east / north errors without and with exclusion, +-3 sigma
        fig, axes = plt.subplots(2, 2, figsize=(9, 5.5), sharex=True)
        for j, f in enumerate(FILTERS):
            for i, comp in enumerate(("east", "north")):
                ax = axes[i, j]
                sd = ds["sigma_enu_m"].sel(filter=f, axis=comp).values
                ax.fill_between(t, -3 * sd, 3 * sd, color="0.85", label="+-3 sigma")
                if a["has_truth"]:
                    e = ds["err_enu_m"].sel(filter=f, axis=comp).values
                    ax.plot(t, e, lw=0.8, color="tab:red" if j == 0 else "tab:green",
                            label=f"{comp} error")
                else:
                    ax.text(0.5, 0.5, "no truth in the recording", transform=ax.transAxes,
                            ha="center")
                if a["fault_onset_s"] >= 0:
                    ax.axvline(a["fault_onset_s"], color="k", lw=0.6, ls=":")
                ax.set_ylabel(f"{comp} error (m)")
                ax.grid(alpha=0.3)
                ax.legend(fontsize=7, loc="upper left")
            axes[0, j].set_title(f.replace("_", " "), fontsize=9)
            axes[1, j].set_xlabel("time (s)")
        fig.suptitle(f"{self.title}: Figs. 3b-c, position errors ({src_short})", fontsize=9)
        fig.tight_layout()
        paths.append(f"{out_dir}/{pre}_fig3bc_errors.png")
        fig.savefig(paths[-1], dpi=120)
        plt.close(fig)

        # Fig. 4: HPL vs HAL, with the 2D error
        fig, ax = plt.subplots(figsize=(7.5, 3.6))
        for f, c in zip(FILTERS, ("tab:red", "tab:blue"), strict=True):
            h = ds["hpl_m"].sel(filter=f).values
            ax.plot(t, np.where(np.isfinite(h), h, np.nan), lw=1.0, color=c,
                    label=f"HPL, {f.replace('_', ' ')}")
            if a["has_truth"]:
                ax.plot(t, ds["err_2d_m"].sel(filter=f).values, lw=0.7, color=c, ls=":",
                        label=f"2D error, {f.replace('_', ' ')}")
        ax.axhline(a["hal_m"], color="k", ls="--", lw=1.2, label=f"HAL = {a['hal_m']:g} m")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("m")
        ax.set_title(f"{self.title}: Fig. 4, HPL and HAL ({src_short})", fontsize=9)
        ax.set_ylim(0, 1.7 * a["hal_m"])
        ax.legend(fontsize=7, loc="upper left", ncol=3)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        paths.append(f"{out_dir}/{pre}_fig4_hpl_hal.png")
        fig.savefig(paths[-1], dpi=120)
        plt.close(fig)

        if "mc_rmse_reduction_pct" in ds:
            fig, ax = plt.subplots(figsize=(7.5, 3.6))
            red = ds["mc_rmse_reduction_pct"]
            allv = red.values[np.isfinite(red.values)]
            bins = np.linspace(min(allv.min(), 0.0), 100.0, 51)
            for v, c in zip(ds["variant"].values, ("tab:blue", "tab:orange"), strict=False):
                x = red.sel(variant=v).values
                ax.hist(x, bins=bins, alpha=0.6, color=c,
                        label=f"{v}: median {np.median(x):.1f} % ({x.size} runs)")
            for q, pub in self.published_reduction_lines():
                ax.axvline(pub, color="k", ls="--", lw=1.2, label=f"published {q}: {pub:g} %")
            ax.set_xlabel("2D RMSE reduction by exclusion (%)")
            ax.set_ylabel("runs")
            ax.set_title(f"{self.title}: RMSE reduction over Monte Carlo runs", fontsize=9)
            ax.legend(fontsize=7, loc="upper left")
            ax.grid(alpha=0.3)
            fig.tight_layout()
            paths.append(f"{out_dir}/{pre}_mc_rmse_reduction.png")
            fig.savefig(paths[-1], dpi=120)
            plt.close(fig)
        return paths

    def published_reduction_lines(self):
        """(label, published %) lines drawn on the reduction figure."""
        return [("RMSE reduction", 49.0)]


_MC_FN = None


FILTER_SS_LABELS = {"filter_ss": "filter solution separation",
                    "ekf_xi_slope": "EKF NIS + Xi-slope", "snapshot_mhss": "snapshot MHSS"}


def filter_ss_rows(fs, n):
    """The summary rows of ``--set monitor=filter-ss`` (``EkfDriveStudy._filter_ss``)."""
    rows = []
    for mon, d in fs.items():
        m = d["misleading_epochs"]
        rows.append({
            "quantity": f"HPE > HPL without alert after the onset, {FILTER_SS_LABELS[mon]}, "
                        f"Monte Carlo {n} runs", "unit": "-", "published": None,
            "reproduced": m["rate"],
            "note": f"{m['count']} of {m['trials']} epochs, 95 % CI [{m['ci_low']:.2g}, "
                    f"{m['ci_high']:.2g}]; mean HPL {d['mean_hpl_m']:.3g} m, available at HAL "
                    f"{d['availability_pct']:.3g} %, alerts before the onset "
                    f"{d['false_alerts']}, detected in {d['detected_runs_pct']:.3g} % of runs, "
                    f"median delay {d['median_detection_delay_s']:.3g} s "
                    "(docs/filter-integrity.md)"})
    return rows


_FILTER_SS_FNS = {}


def _filter_ss_fn(cfg):
    """The jitted vmapped ``sim.simulate_filter_drive`` of one (static) config."""
    if cfg not in _FILTER_SS_FNS:
        def f(keys, setup, err, fault, filter_sigma):
            return jax.vmap(lambda k: sim.simulate_filter_drive(
                k, setup, err, fault, cfg, filter_sigma_pr_m=filter_sigma))(keys)

        _FILTER_SS_FNS[cfg] = jax.jit(f)
    return _FILTER_SS_FNS[cfg]


def _mc_fn():
    """One jitted vmapped drive kernel (compiled once per setup shape)."""
    global _MC_FN
    if _MC_FN is None:
        def f(keys, setup, err, filter_sigma, hal, dof_off):
            return sim.monte_carlo_drive(keys, setup, err=err, filter_sigma_pr_m=filter_sigma,
                                         hal_m=hal, dof_offset=dof_off)

        _MC_FN = jax.jit(f)
    return _MC_FN


def published_among_runs(published, values):
    """Where a published single-drive number falls among the Monte Carlo runs' values: their
    5-95 % range and the published value's percentile (the paper drove once: a number outside
    the range is a difference of the world, one inside it may be the luck of one drive)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "no finite run"
    lo, hi = np.percentile(v, [5, 95])
    rank = 100.0 * float(np.mean(v <= published))
    return f"runs' 5-95 % range {lo:.3g}-{hi:.3g}, published at percentile {rank:.0f}"
