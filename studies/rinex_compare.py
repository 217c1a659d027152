"""``rinex-compare``: one real station day replayed by three users, side by side.

The same observation and navigation files through ``rinex-replay`` three times:

* **GPS + Galileo dual-frequency** ARAIM (the ADD's user: ionosphere-free GPS L1/L5, else
  L1/L2, and Galileo E1/E5a; one clock per constellation, the ISM of each),
* **GPS dual-frequency** (the same user with Galileo left out: what the second constellation
  buys),
* **GPS L1** single frequency with the Klobuchar correction (today's civil aviation user, seed
  004's real-data setup).

The default is the NIST day of the shared data (``obs3/NIST00USA_R_20230010000_01D_30S_MO``,
Boulder, 2023-01-01, 2,880 epochs at 30 s, with the IGS merged navigation file of the day); the
truth is the header's APPROX POSITION XYZ (``--set truth=`` otherwise). Each configuration keeps
every ``rinex-replay`` default (mask 5 deg, MAAST's LPV-200 budget, ADD v4.2 fault modes,
ED-259A airborne model, seed 004 Table I GPS ISM); the ones given here apply to all three.
Per configuration: LPV-200 availability (MAAST's criterion: VPL <= 35 m, HPL <= 40 m,
EMT <= 15 m, sigma_acc <= 1.87 m), PL and error percentiles, misleading epochs, detections and
exclusions. Each configuration is one checkpointed unit: an interrupted run resumes.
"""

import numpy as np
import xarray as xr

from oaraim.studies.base import (
    Param,
    ResumableStudy,
    StudyResult,
    keyword_or_file,
    parse_choice,
)
from oaraim.studies.common.injected_faults import parse_faults
from oaraim.studies.rinex_replay import RinexReplay, parse_truth

#: the shared day replayed by default (``oaraim data list``)
DEFAULT_OBS = "obs3/NIST00USA_R_20230010000_01D_30S_MO.crx.gz"
DEFAULT_NAV = "obs3/BRDC00IGS_R_20230010000_01D_MN.rnx.gz"
#: (key, label, rinex-replay settings) of the three users
CONFIGS = (
    ("gps_galileo_dual", "GPS + Galileo dual-frequency", {"signals": "dual",
                                                           "constellations": "auto"}),
    ("gps_dual", "GPS dual-frequency", {"signals": "dual", "constellations": "gps"}),
    ("gps_l1", "GPS L1 (Klobuchar)", {"signals": "gps-l1", "constellations": "auto"}),
)
#: per-epoch arrays kept for the figures
EPOCH_KEYS = ("hpl_mhss_m", "vpl_mhss_m", "hpe_mhss_m", "vpe_mhss_m", "emt_mhss_m", "n_used")
#: summary numbers per configuration (``rinex-replay`` summary names)
SUMMARY_KEYS = ("lpv200_available_pct", "hpl_median_m", "vpl_median_m", "hpe_median_m",
                "hpe_95_m", "hpe_max_m", "vpe_median_m", "vpe_max_m",
                "misleading_information_epochs", "detections_mhss", "exclusions_mhss",
                "exclusion_failures_mhss", "epochs_too_few_sources", "satellites_used_median")
#: the figures' colours per configuration
COLORS = {"gps_galileo_dual": "tab:blue", "gps_dual": "tab:green", "gps_l1": "tab:red"}

parse_path = keyword_or_file(("auto",), "RINEX file")


def _pct(x, q):
    x = np.asarray(x, np.float64)
    x = x[np.isfinite(x)]
    return float(np.percentile(x, q)) if x.size else float("inf")


class RinexCompare(ResumableStudy):
    """The ``rinex-compare`` study (module docstring)."""

    name = "rinex-compare"
    requires_data = True
    title = ("Real station day, three users side by side: GPS + Galileo dual-frequency vs GPS "
             "dual-frequency vs GPS L1 ARAIM")
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = "one epoch of the observation file, replayed by each of the three users"
    default_realizations = 2880
    quick_realizations = 120
    quick_cost_s = 90
    max_realizations = 2880
    #: the generic study tests replay this many epochs (three users, one compilation each)
    test_realizations = 60

    params = {
        "obs": Param("auto", parse_path, "RINEX 3 observation file with GPS and Galileo codes "
                     f"('auto': {DEFAULT_OBS}, fetched if missing)"),
        "nav": Param("auto", parse_path, "RINEX 3 mixed navigation file of the day ('auto': "
                     f"{DEFAULT_NAV} with the default obs)"),
        "truth": Param("header", parse_truth, "true receiver position X,Y,Z (ECEF m) or "
                       "'header' (APPROX POSITION XYZ)", "m"),
        "fault": Param("none", parse_faults, "faults injected in all three replays "
                       "(rinex-replay's fault: SV,step,BIAS_M,ONSET_S or "
                       "SV,ramp,RATE_M_PER_S,ONSET_S)"),
        "fde": Param("on", parse_choice("on", "off"), "on: detection and exclusion; off: the "
                     "unmonitored user (rinex-replay's fde)"),
        "allow_gaps": Param("no", parse_choice("no", "yes"), "yes: replay epochs the "
                            "navigation file does not cover"),
    }

    def data_files(self, params):
        """The shared day when ``obs`` is 'auto' (and its navigation file with ``nav`` auto)."""
        if params["obs"] != "auto":
            return ()
        return (DEFAULT_OBS, DEFAULT_NAV) if params["nav"] == "auto" else (DEFAULT_OBS,)

    def too_many_realizations(self, n, limit):
        """Realizations are epochs of the file (a day at 30 s: 2,880)."""
        return (f"--realizations {n:,} is more epochs than {self.name} replays (at most "
                f"{limit:,}, a day at 30 s); one realization is one epoch of the file")

    def _files(self, params):
        from oaraim import data

        obs, nav = params["obs"], params["nav"]
        if obs == "auto":
            obs = str(data.path(DEFAULT_OBS))
            if nav == "auto":
                nav = str(data.path(DEFAULT_NAV))
        if nav == "auto":
            raise ValueError(f"no navigation file given for {obs}: pass --set nav=PATH (the "
                             "RINEX 3 mixed navigation file of the day)")
        return obs, nav

    def run_units(self, params, realizations, seed, progress, checkpoint):
        """Each user replayed as one checkpointed unit; ``seed`` is not used."""
        obs, nav = self._files(params)
        replay = RinexReplay()
        done = 0
        per = {}
        for key, _, sets in CONFIGS:
            def compute(sets=sets):
                p = replay.validate({"obs": obs, "nav": nav, "truth": params["truth"],
                                     "fault": params["fault"], "fde": params["fde"],
                                     "allow_gaps": params["allow_gaps"]} | sets)
                r = replay.run(p, realizations, 0, None)
                ds, m = r.dataset, r.metrics
                return {"epochs": {k: np.asarray(ds[k].values) for k in EPOCH_KEYS},
                        "hours": np.asarray(ds["hours"].values),
                        "t_gps_s": np.asarray(ds["t_gps_s"].values),
                        "start_gps": ds.attrs["start_gps"], "obs_file": ds.attrs["obs_file"],
                        "nav_file": ds.attrs["nav_file"],
                        "combination": m["combination"],
                        "constellations": list(m["constellations"]),
                        "summary": {k: m[k] for k in SUMMARY_KEYS}
                        | {"hpl_95_m": _pct(ds["hpl_mhss_m"].values, 95),
                           "vpl_95_m": _pct(ds["vpl_mhss_m"].values, 95),
                           "vpe_95_m": _pct(ds["vpe_mhss_m"].values, 95)}}

            per[key] = checkpoint.unit(key, compute)
            if progress is not None:
                step = realizations * (len(per)) // len(CONFIGS) - done
                progress.advance(step)
                done += step
        return self._result(params, per)

    def _result(self, params, per):
        keys = [k for k, _, _ in CONFIGS]
        first = per[keys[0]]
        n = {k: per[k]["hours"].size for k in keys}
        if len(set(n.values())) != 1:
            raise ValueError(f"the three replays kept different epochs {n}; a bad epoch the "
                             "users read differently? replay each with rinex-replay")
        ds = xr.Dataset(
            {f"{name}_{k}": (("epoch",), per[k]["epochs"][name]) for k in keys
             for name in EPOCH_KEYS}
            | {"hours": (("epoch",), first["hours"]), "t_gps_s": (("epoch",), first["t_gps_s"])},
            coords={"epoch": np.arange(first["hours"].size)},
            attrs={"obs_file": first["obs_file"], "nav_file": first["nav_file"],
                   "start_gps": first["start_gps"], "configs": ",".join(keys),
                   "labels": "|".join(lbl for _, lbl, _ in CONFIGS)})
        metrics = {k: per[k]["summary"] | {"combination": per[k]["combination"],
                                           "constellations": per[k]["constellations"]}
                   for k in keys}
        metrics["epochs"] = int(first["hours"].size)
        metrics["obs_file"], metrics["nav_file"] = first["obs_file"], first["nav_file"]
        rows = []
        note = (f"{first['obs_file']}, {metrics['epochs']:,} epochs; no published number "
                "(real-data replay)")
        for k, label, _ in CONFIGS:
            s = per[k]["summary"]
            rows += [
                {"quantity": f"LPV-200 availability, {label}", "unit": "%", "published": None,
                 "reproduced": s["lpv200_available_pct"],
                 "note": f"{per[k]['combination']}; {note}"},
                {"quantity": f"median / 95 % VPL, {label}", "unit": "m", "published": None,
                 "reproduced": s["vpl_median_m"], "note": f"95 %: {s['vpl_95_m']:.2f} m"},
                {"quantity": f"median / 95 % HPL, {label}", "unit": "m", "published": None,
                 "reproduced": s["hpl_median_m"], "note": f"95 %: {s['hpl_95_m']:.2f} m"},
                {"quantity": f"95 % / max VPE, {label}", "unit": "m", "published": None,
                 "reproduced": s["vpe_95_m"], "note": f"max {s['vpe_max_m']:.2f} m; HPE 95 % "
                 f"{s['hpe_95_m']:.2f} m, max {s['hpe_max_m']:.2f} m"},
                {"quantity": f"misleading epochs (HPE > HPL or VPE > VPL), {label}",
                 "unit": "count", "published": None,
                 "reproduced": s["misleading_information_epochs"],
                 "note": f"detections {s['detections_mhss']}, exclusions "
                         f"{s['exclusions_mhss']}, failed exclusions "
                         f"{s['exclusion_failures_mhss']}"},
            ]
        return StudyResult(ds, rows, metrics)

    def plot(self, out_dir):
        """``pl_over_day.png`` (VPL and HPL of the three users over the day, log axes, alert
        limits) and ``pl_cdf.png`` (their distributions, the LPV-200 limits marked)."""
        import matplotlib.pyplot as plt

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
        a = ds.attrs
        keys = a["configs"].split(",")
        labels = dict(zip(keys, a["labels"].split("|"), strict=True))
        h = ds["hours"].values
        top = 1e3
        clip = lambda x: np.minimum(np.where(np.isfinite(x), x, top), top)  # noqa: E731
        paths = []
        fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
        for ax, pl, err, lim, name in ((axes[0], "vpl", "vpe", 35.0, "vertical"),
                                       (axes[1], "hpl", "hpe", 40.0, "horizontal")):
            for k in keys:
                ax.semilogy(h, clip(ds[f"{pl}_mhss_m_{k}"].values), lw=0.9, color=COLORS[k],
                            label=f"{pl.upper()}, {labels[k]}")
            ax.semilogy(h, np.maximum(clip(ds[f"{err}_mhss_m_{keys[0]}"].values), 1e-2),
                        lw=0.6, color="k", label=f"{err.upper()}, {labels[keys[0]]}")
            ax.axhline(lim, color="gray", ls="--", lw=0.8,
                       label=f"LPV-200 {'VAL' if pl == 'vpl' else 'HAL'} {lim:g} m")
            ax.set_ylim(1e-2, top)
            ax.set_ylabel(f"{name} (m)")
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7, loc="upper right", ncol=2)
        axes[1].set_xlabel(f"hours from {a['start_gps']} (GPS time); PLs above {top:g} m or not "
                           "computable drawn at the top")
        axes[0].set_title(f"ARAIM (MHSS) protection levels of three users\n{a['obs_file']} + "
                          f"{a['nav_file']}", fontsize=9)
        fig.tight_layout()
        p = f"{out_dir}/pl_over_day.png"
        fig.savefig(p, dpi=120)
        plt.close(fig)
        paths.append(p)

        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        for ax, pl, lim in ((axes[0], "vpl", 35.0), (axes[1], "hpl", 40.0)):
            for k in keys:
                x = np.sort(ds[f"{pl}_mhss_m_{k}"].values)
                y = np.arange(1, x.size + 1) / max(x.size, 1)
                fin = np.isfinite(x)
                ax.step(np.minimum(x[fin], top), y[fin], where="post", color=COLORS[k],
                        label=f"{labels[k]} ({100 * np.mean(x <= lim):.1f} % <= {lim:g} m)")
            ax.axvline(lim, color="gray", ls="--", lw=0.8)
            ax.set_xscale("log")
            ax.set_xlim(1, top)
            ax.set_ylim(0, 1)
            ax.set_xlabel(f"{pl.upper()} (m), log scale; not computable: the curve ends below 1")
            ax.set_ylabel("share of epochs")
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7, loc="lower right")
        fig.suptitle(f"{a['obs_file']}: distribution of the ARAIM protection levels over "
                     f"{len(ds['epoch']):,} epochs", fontsize=9)
        fig.tight_layout()
        p = f"{out_dir}/pl_cdf.png"
        fig.savefig(p, dpi=120)
        plt.close(fig)
        paths.append(p)
        return paths
