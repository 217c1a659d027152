"""Seed 001 section 4.2: the ground-vehicle experiment, GPS + 5 LTE towers, mean slope HPL
GPS-only vs GPS-SOP (published 15.01 m vs 8.29 m, a 44.77 % reduction).

Setup (stated choices; seed 001 gives neither route, date, rates nor sigmas):
  * Drive: ``sim.drive_seed000()`` (the 1.35 km downtown Riverside, CA drive with 5 LTE
    towers of the same group's seed 000; seed 001's vehicle experiment is by the same group, in
    the same area, with 5 LTE towers), or ``drive=seed002-drive``. Epochs at the scenario's
    10 Hz pseudorange rate over the drive (``duration_s`` shortens it).
  * GPS sky: broadcast ephemeris ``nav/brdc0010.22n`` (2022-01-01; ``oaraim.data``, fetched
    if missing) at ``start_h`` = 18.0 h GPS time (10:00 local), or the nominal 24-slot
    constellation on ``--set nav=nominal`` (provenance says which); mask 15 deg (seed 001
    section 3.2: "typically around 15").
  * Measurements: ``sim.gnss`` (module docstring). Noise: GPS N(0, C_acc(el))
    (ADD accuracy model, sigma_URE = 2/3 sigma_URA = 0.67 m plus troposphere and user terms),
    LTE N(0, 2^2 m^2) (the scenario's "meter-level" LTE ranging).
  * Slope RAIM of seed 001 section 3.1 on the WNLS solution (``araim.snapshot.replay`` with
    ``ReplayConfig(monitors=("slope",))``; with one clock group it is ``araim.slope_hpl``): one
    receiver clock (seed 001's state [r, c dt]; tower clocks known), R = diag(sigma^2) with GPS
    sigma = sqrt(C_int(el)) (ADD integrity model) and the LTE sigma estimated from the
    simulated data, P_FA = 1e-5, P_MD = 1e-3 (the repo's seed 001 studies; seed 001 silent).
    The GPS sigma_URA and the LTE truth's thermal noise are calibrated (``oaraim calibrate
    seed001-vehicle``) to the two published mean HPLs: 1.891 m and 2.64 m (20 draws;
    defaults 1.9 and 2.6 m); elasticities: the GPS-only mean 0.91 to sigma_URA, the GPS + LTE
    mean 0.20 to sigma_URA and 0.51 to the LTE noise.
  * One realization = one noise draw of the whole drive (draw i from fold_in(key(seed), i));
    ``--realizations N`` draws (default 100). The HPL depends on the geometry only (to ~1e-3 m
    through the linearisation point), so the mean HPLs barely move between draws; the draws
    give the HPE and the false-alarm rate of the chi-square test.
"""

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import errors, geometry, mc, sim
from oaraim.araim import snapshot
from oaraim.errors import gnss_variances
from oaraim.geometry import epoch_geometry
from oaraim.readers import gpstime, load_recording
from oaraim.studies.base import (
    NO_RECORDING,
    Calibration,
    Free,
    Param,
    Study,
    StudyResult,
    Target,
    count,
    in_range,
    non_negative,
    parse_recording,
    positive,
    probability,
)
from oaraim.studies.common.params import parse_world
from oaraim.studies.common.seed004 import NAV, NAV_FILE, resolve_sky

PUBLISHED_HPL_GPS_M = 15.01
PUBLISHED_HPL_SOP_M = 8.29
PUBLISHED_REDUCTION_PCT = 44.77
#: epoch rows per replay call: draws are stacked along the epoch axis in fixed blocks
BLOCK_ROWS = 4096
DRIVES = {"seed000-drive": "drive_seed000", "seed002-drive": "drive_seed002"}


def world_noise_fn(geom, params, seed):
    """A jitted function of draw indices (k,) -> (errors (k, T, L) m, LTE sigma (k,) m) of the
    realistic world (``sim.gnss_sop_errors``: GNSS period of 300 s at 1 Hz before t = 0), from
    the draw's key fold_in(key(seed), i)."""
    seed_key = jax.random.key(int(seed))
    t = jnp.asarray(geom.t_s)
    el = jnp.asarray(geom.el_rad)
    is_gps = np.asarray(geom.is_gps)
    err = errors.ErrorModel(sigma_pr_m=params["sigma_lte_noise_m"], fault_onset_s=np.inf,
                         fault_bias_m=0.0)
    t_cal = -jnp.arange(300)[::-1] * 1.0

    def one(i):
        return sim.gnss_sop_errors(jax.random.fold_in(seed_key, i), t, el, is_gps,
                                   params["sigma_ura_gps_m"], sim.SnapshotWorld(err, t_cal))

    return jax.jit(jax.vmap(one))


def parse_drive(name, v):
    """Parser of the ``drive`` parameter: a name of ``DRIVES``."""
    v = str(v).strip()
    if v not in DRIVES:
        raise ValueError(f"{name} must be one of {', '.join(DRIVES)}, got {v!r}")
    return v


class Seed001Vehicle(Study):
    """Seed 001 section 4.2 (module docstring): mean slope HPL along a drive, GPS only and
    GPS + 5 LTE towers."""

    name = "seed001-vehicle"
    title = "Seed 001 section 4.2: vehicle drive, GPS + 5 LTE towers, mean slope HPL"
    seed_file = "001_c7da69deb44e932b.txt"
    realization = "one noise draw of the whole drive (all epochs at 10 Hz)"
    default_realizations = 100
    quick_realizations = 20
    quick_cost_s = 13
    #: ``oaraim calibrate``: the GPS URA of the PL's model and the LTE truth's noise (the
    #: filter's LTE sigma is estimated from it), from the two published mean HPLs
    calibration = Calibration(
        free=(Free("sigma_ura_gps_m", 0.5, 4.0), Free("sigma_lte_noise_m", 0.2, 10.0)),
        targets=(Target(r"^mean GPS-only HPL over the drive"),
                 Target(r"^mean GPS \+ \d+ LTE HPL over the drive")),
        realizations=20)
    test_realizations = 64
    nav_file = NAV_FILE
    params = {
        "drive": Param("seed000-drive", parse_drive, "scenario of sim.trajectory"),
        "duration_s": Param(0.0, in_range(0.0, 1e4), "replay the first duration_s of the drive "
                            "(0: all of it)", "s"),
        "rate_hz": Param(10.0, in_range(0.1, 100.0), "epoch rate (scenario: 10 Hz)", "Hz"),
        "nav": NAV,
        "start_h": Param(18.0, in_range(0.0, 23.9), "GPS time of the start, hours of the file's "
                         "day (our choice: 10:00 local)", "h"),
        "mask_deg": Param(15.0, in_range(0.0, 89.0), "GPS elevation mask (seed 001: ~15 deg)",
                          "deg"),
        "sigma_ura_gps_m": Param(1.9, positive, "GPS sigma_URA of the ADD model (seed "
                                 "silent; `oaraim calibrate`: 1.891 m)", "m"),
        "world": Param("realistic", parse_world, "error world of the synthesis: 'realistic' "
                       "(sim.GnssErrorModel for GPS, sim.ErrorModel for the towers; "
                       "docs/error-world.md) or 'clean' (white N(0, C_acc) GPS and "
                       "sigma_lte_noise_m LTE noise)"),
        "sigma_lte_m": Param(0.0, non_negative, "LTE sigma in R (seed silent; 0: the realistic "
                             "world's empirical estimate from the GNSS period, the clean "
                             "world's sigma_lte_noise_m)", "m"),
        "sigma_lte_noise_m": Param(2.6, positive, "LTE thermal (white) noise of the "
                                   "synthesis (seed silent; `oaraim calibrate`: 2.64 m)", "m"),
        "inject_lte_bias_m": Param(0.0, in_range(-1e3, 1e3), "an error outside the PL's model "
                                   "(tests of the MI check): this bias on LTE tower 1 at "
                                   "every epoch", "m"),
        "p_fa": Param(snapshot.DEFAULT_P_FA, probability, "false-alarm probability (seed silent)"),
        "p_md": Param(snapshot.DEFAULT_P_MD, probability,
                      "missed-detection probability (seed silent)"),
        "recording": Param(NO_RECORDING, parse_recording, "replay a recorded drive (folder in the "
                           "geometry.recording format; then one realization = the drive)"),
        "chunk": Param(BLOCK_ROWS, count(1), "accepted for the common interface and ignored "
                       f"(fixed blocks of {BLOCK_ROWS} epoch rows)"),
    }

    def inputs(self, params):
        """(EpochGeometry, noise-free pseudoranges or the recorded ones, corrections, desc,
        recorded?)."""
        if params["recording"] != NO_RECORDING:
            m = epoch_geometry.from_recording(load_recording(params["recording"]),
                                              params["mask_deg"])
            return m.geom, m.pseudorange_m, m.correction_m, f"recording {params['recording']}", \
                True
        scen = getattr(sim, DRIVES[params["drive"]])()
        dur = float(scen.traj.t_s[-1])
        if params["duration_s"] > 0:
            dur = min(dur, params["duration_s"])
        n_t = max(2, int(np.floor(dur * params["rate_hz"])) + 1)
        t = np.arange(n_t) / params["rate_hz"]
        source, desc, real = resolve_sky(params["nav"])
        if real:
            from oaraim.studies.common.seed004 import day_start
            day = day_start(source, True)
        else:
            day = float(gpstime.gps_seconds(2022, 1, 1))
        geom = sim.scenario_geometry(scen, t, day + 3600.0 * params["start_h"], source, desc,
                                     real, params["mask_deg"])
        pr0 = sim.pseudoranges(geom, 0.0)
        return geom, pr0, np.where(geom.valid, geom.tx_clock_m, 0.0), desc, False

    def run(self, params, realizations, seed, progress):
        """Replay each noise draw of the drive (a recording: once) with slope RAIM, GPS only
        and GPS + LTE: mean and max HPL and HPE, alarms; draw 0 kept as the trace."""
        geom, pr0, corr, desc, recorded = self.inputs(params)
        n_t, n_l = geom.valid.shape
        n_draws = 1 if recorded else int(realizations)
        vi, va = (np.asarray(a) for a in gnss_variances(geom.el_rad, params["sigma_ura_gps_m"]))
        realistic = params["world"] == "realistic" and not recorded
        sig_lte = params["sigma_lte_m"] or params["sigma_lte_noise_m"]
        sig_noise = np.where(geom.is_gps, np.sqrt(va), params["sigma_lte_noise_m"])
        per_block = max(1, BLOCK_ROWS // n_t)
        seed_key = jax.random.key(int(seed))
        noise_fn = jax.jit(jax.vmap(lambda i: jax.random.normal(
            jax.random.fold_in(seed_key, i), (n_t, n_l))))
        world_fn = world_noise_fn(geom, params, seed) if realistic else None
        out = {k: np.zeros((2, n_draws)) for k in ("mean_hpl", "mean_hpe", "max_hpl", "max_hpe",
                                                   "alarms", "finite", "mi", "mi_undetected",
                                                   "sigma_lte")}
        trace = None
        x0 = np.broadcast_to(geom.origin_ecef_m, (per_block * n_t, 3))
        for start in range(0, n_draws, per_block):
            ids = np.minimum(np.arange(start, start + per_block), n_draws - 1)
            nb = min(per_block, n_draws - start)
            sl_lte = np.full(ids.size, sig_lte)
            if recorded:
                pr = pr0[None]
            elif realistic:
                e, s_emp = (np.asarray(a) for a in world_fn(jnp.asarray(ids, jnp.uint32)))
                pr = pr0[None] + np.where(geom.valid, e, 0.0)
                if not params["sigma_lte_m"]:
                    sl_lte = s_emp
            else:
                pr = pr0[None] + np.where(geom.valid, sig_noise, 0.0)[None] * np.asarray(
                    noise_fn(jnp.asarray(ids, jnp.uint32)))
            tower1 = np.arange(n_l) == np.argmin(geom.is_gps)
            pr = pr + np.where(geom.valid & tower1, params["inject_lte_bias_m"], 0.0)
            # the PL's sigmas per draw: ADD C_int for GPS, the LTE sigma (empirical per draw)
            sig_model = np.where(geom.is_gps[None, None], np.sqrt(vi)[None],
                                 sl_lte[:, None, None])
            var_int = np.where(geom.valid[None], sig_model**2, 1.0).reshape(-1, n_l)
            sig_model = sig_model.reshape(-1, n_l)
            rows = lambda a, k=ids.size: np.broadcast_to(a, (k,) + a.shape).reshape(  # noqa: E731
                (k * n_t,) + a.shape[1:])
            for ci, sop in enumerate((False, True)):
                use = geom.valid & (geom.is_gps | sop)[None]
                r = snapshot.replay(
                    pr.reshape(-1, n_l), rows(geom.tx_pos_m), snapshot.ReplaySources(
                        var_int, var_int, rows(use), slope_sigma_m=sig_model),
                    rows(geom.truth_m), correction_m=rows(corr), x0_m=x0,
                    config=snapshot.ReplayConfig(monitors=("slope",), p_fa=params["p_fa"],
                                                 p_md=params["p_md"]))
                hpl = np.asarray(r.slope.hpl_all_in_view_m).reshape(ids.size, n_t)[:nb]
                hpe = np.asarray(r.hpe_m).reshape(ids.size, n_t)[:nb]
                det = np.asarray(r.slope.detected).reshape(ids.size, n_t)[:nb]
                fin = np.isfinite(hpl)
                sl = slice(start, start + nb)
                out["finite"][ci, sl] = fin.mean(-1)
                out["mean_hpl"][ci, sl] = np.where(fin, hpl, 0).sum(-1) / np.maximum(
                    fin.sum(-1), 1)
                out["max_hpl"][ci, sl] = np.max(hpl, -1)
                out["mean_hpe"][ci, sl] = np.mean(hpe, -1)
                out["max_hpe"][ci, sl] = np.max(hpe, -1)
                out["alarms"][ci, sl] = det.sum(-1)
                mi = fin & (hpe > hpl)
                out["mi"][ci, sl] = mi.sum(-1)
                out["mi_undetected"][ci, sl] = (mi & ~det).sum(-1)
                out["sigma_lte"][ci, sl] = sl_lte[:nb]
                if start == 0:
                    trace = {} if trace is None else trace
                    trace[ci] = (hpl[0], hpe[0])
            if progress is not None:
                progress.advance(nb)
        return self._result(params, geom, desc, out, trace, n_draws)

    def _result(self, params, geom, desc, out, trace, n_draws):
        hpl_g, hpl_s = trace[0][0], trace[1][0]
        both = np.isfinite(hpl_g) & np.isfinite(hpl_s)
        # per-epoch means over the epochs where both are finite (draw 0), then over draws
        m_g = float(np.mean(out["mean_hpl"][0]))
        m_s = float(np.mean(out["mean_hpl"][1]))
        red = 100.0 * (m_g - m_s) / m_g if m_g > 0 else float("nan")
        enu = np.asarray(geometry.frames.ecef_to_enu(geom.truth_m, geom.origin_ecef_m))
        tw = np.asarray(geometry.frames.ecef_to_enu(geom.tx_pos_m[0, ~geom.is_gps],
                                                    geom.origin_ecef_m))
        n_gps = np.sum(geom.valid & geom.is_gps, -1)
        ds = xr.Dataset(
            {"t_s": ("epoch", geom.t_s), "hpl_gps_m": ("epoch", hpl_g),
             "hpl_sop_m": ("epoch", hpl_s), "hpe_gps_m": ("epoch", trace[0][1]),
             "hpe_sop_m": ("epoch", trace[1][1]), "n_gps": ("epoch", n_gps),
             "east_m": ("epoch", enu[:, 0]), "north_m": ("epoch", enu[:, 1]),
             "tower_east_m": ("tower", tw[:, 0]), "tower_north_m": ("tower", tw[:, 1]),
             "draw_mean_hpl_gps_m": ("draw", out["mean_hpl"][0]),
             "draw_mean_hpl_sop_m": ("draw", out["mean_hpl"][1]),
             "draw_mean_hpe_gps_m": ("draw", out["mean_hpe"][0]),
             "draw_mean_hpe_sop_m": ("draw", out["mean_hpe"][1]),
             "draw_alarms_gps": ("draw", out["alarms"][0]),
             "draw_alarms_sop": ("draw", out["alarms"][1])},
            coords={"epoch": np.arange(geom.t_s.size), "draw": np.arange(n_draws),
                    "tower": np.arange(tw.shape[0])},
            attrs={"sky_source": desc, "real_ephemeris": int(geom.real_ephemeris),
                   "mean_hpl_gps_m": m_g, "mean_hpl_sop_m": m_s, "reduction_pct": red})
        note = (f"slope HPL, P_FA={params['p_fa']:g}, P_MD={params['p_md']:g}; GPS sigma "
                f"sqrt(C_int(el)) (URA {params['sigma_ura_gps_m']:g} m), LTE "
                f"{np.median(out['sigma_lte'][1]):.2f} m; {params['drive']}, "
                f"{geom.t_s.size} epochs x "
                f"{n_draws} draws; sky: {desc}; synthetic ({params['world']} error world), "
                "sigmas calibrated (oaraim calibrate)")
        rows = [
            {"quantity": "mean GPS-only HPL over the drive", "unit": "m",
             "published": PUBLISHED_HPL_GPS_M, "reproduced": m_g, "note": note},
            {"quantity": f"mean GPS + {int((~geom.is_gps).sum())} LTE HPL over the drive",
             "unit": "m", "published": PUBLISHED_HPL_SOP_M, "reproduced": m_s, "note": ""},
            {"quantity": "HPL reduction by the SOPs", "unit": "%",
             "published": PUBLISHED_REDUCTION_PCT, "reproduced": red,
             "note": "100 (mean GPS - mean GPS-SOP) / mean GPS"},
        ]
        n_ep = geom.t_s.size
        metrics = {
            "sky_source": desc, "real_ephemeris": bool(geom.real_ephemeris),
            "epochs": int(n_ep), "draws": int(n_draws), "drive": params["drive"],
            "gps_visible_min": int(n_gps.min()), "gps_visible_max": int(n_gps.max()),
            "gps_sv": [str(s) for s in geom.ids[geom.is_gps]],
            "share_epochs_both_finite_draw0": float(np.mean(both)),
            "share_epochs_finite_gps": float(np.mean(out["finite"][0])),
            "share_epochs_finite_sop": float(np.mean(out["finite"][1])),
            "sd_over_draws_mean_hpl_gps_m": float(np.std(out["mean_hpl"][0])),
            "sd_over_draws_mean_hpl_sop_m": float(np.std(out["mean_hpl"][1])),
            "max_hpl_gps_m": float(np.max(out["max_hpl"][0])),
            "max_hpl_sop_m": float(np.max(out["max_hpl"][1])),
            "mean_hpe_gps_m": float(np.mean(out["mean_hpe"][0])),
            "mean_hpe_sop_m": float(np.mean(out["mean_hpe"][1])),
            "max_hpe_gps_m": float(np.max(out["max_hpe"][0])),
            "max_hpe_sop_m": float(np.max(out["max_hpe"][1])),
            "false_alarm_rate_gps": float(np.sum(out["alarms"][0]) / (n_ep * n_draws)),
            "false_alarm_rate_sop": float(np.sum(out["alarms"][1]) / (n_ep * n_draws)),
            "ratio_sop_over_gps": m_s / m_g if m_g > 0 else float("nan"),
            "world": params["world"],
            "sigma_lte_in_pl_m_median": float(np.median(out["sigma_lte"][1])),
            # MI = HPE > HPL (finite HPL); draws are independent: the run share's
            # Clopper-Pearson interval is exact, the epoch one assumes independent epochs
            "misleading_information": {cfg: {
                "draws_with_any": mc.rate_with_interval(np.sum(out["mi"][ci] > 0), n_draws),
                "epochs": mc.rate_with_interval(np.sum(out["mi"][ci]), n_ep * n_draws),
                "epochs_without_alarm": mc.rate_with_interval(np.sum(out["mi_undetected"][ci]),
                                                              n_ep * n_draws),
                "note": "epoch intervals assume independent epochs (they are not)"}
                for ci, cfg in enumerate(("gps", "sop"))},
        }
        return StudyResult(ds, rows, metrics, extra_provenance={
            "sky_source": desc, "real_ephemeris": bool(geom.real_ephemeris),
            "recording": params["recording"]})

    def plot(self, out_dir):
        """vehicle_hpl.png: both HPLs and HPEs of draw 0 over time, and the drive with its
        towers, in out_dir; returns its path."""
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
        a = ds.attrs
        fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 3.8),
                                      gridspec_kw={"width_ratios": [1.6, 1]})
        t = ds["t_s"].values
        ax.plot(t, ds["hpl_gps_m"].values, color="tab:blue", lw=1,
                label=f"GPS only (mean {a['mean_hpl_gps_m']:.2f} m; published 15.01 m)")
        ax.plot(t, ds["hpl_sop_m"].values, color="tab:red", lw=1,
                label=f"GPS + LTE (mean {a['mean_hpl_sop_m']:.2f} m; published 8.29 m)")
        ax.plot(t, ds["hpe_gps_m"].values, color="tab:blue", lw=0.5, alpha=0.5, label="HPE")
        ax.plot(t, ds["hpe_sop_m"].values, color="tab:red", lw=0.5, alpha=0.5)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("m")
        ax.set_ylim(bottom=0)
        ax.set_title(f"Seed 001 vehicle: slope HPL (draw 0), reduction {a['reduction_pct']:.1f} % "
                     "(published 44.77 %)", fontsize=8)
        ax.legend(fontsize=7)
        ax2.plot(ds["east_m"].values, ds["north_m"].values, "k-", lw=1.2, label="drive")
        ax2.plot(ds["tower_east_m"].values, ds["tower_north_m"].values, "^", color="tab:red",
                 label="LTE towers")
        ax2.set_aspect("equal")
        ax2.set_xlabel("east (m)")
        ax2.set_ylabel("north (m)")
        ax2.legend(fontsize=7)
        ax2.set_title(a["sky_source"], fontsize=7)
        fig.tight_layout()
        fig.savefig(f"{out_dir}/vehicle_hpl.png", dpi=130)
        plt.close(fig)
        return [f"{out_dir}/vehicle_hpl.png"]
