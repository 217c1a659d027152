"""The seed004-uav study itself (the package docstring describes it)."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import araim, errors, mc, sim
from oaraim.araim import BUDGET_SEED004_TABLE_I, required_order, snapshot, solution_separation
from oaraim.batching import TILE
from oaraim.errors import gnss_variances, sop_variances
from oaraim.geometry import epoch_geometry
from oaraim.readers import gpstime, load_recording
from oaraim.studies.base import (
    NO_RECORDING,
    Param,
    Study,
    StudyResult,
    count,
    fault_modes_param,
    in_range,
    non_negative,
    parse_choice,
    parse_recording,
    positive,
    probability,
)
from oaraim.studies.common.seed004 import (
    B_NOM_GPS,
    NAV,
    NAV_FILE,
    P_CONST_GPS_PARAM,
    P_SAT_GPS,
    resolve_sky,
)
from oaraim.studies.common.stanford import stanford_counts
from oaraim.studies.seed004_uav import filter_ss
from oaraim.studies.seed004_uav.plots import plot_uav
from oaraim.studies.seed004_uav.towers import tower_operators, towers_enu_m

PUBLISHED_EPOCHS = 2880
FLIGHT_S = 220.0
#: epochs per MHSS kernel call (fixed: results do not depend on N or the chunk)
BLOCK = 480
#: epochs per detect_and_exclude call: one kernel tile (``oaraim.batching.TILE``), the shape
#: its program runs anyway (96 was padded to 128: a third of the exclusion work was padding)
BLOCK_FDE = TILE
#: the slope-RAIM-only replay of the flight (the solution and the sources used)
SLOPE_ONLY = snapshot.ReplayConfig(monitors=("slope",))
#: the realistic world's GNSS period before take-off (t = 0) over which the receiver fits the
#: tower clocks (seed 000 II-D; ``sim.ErrorModel.calib_window_s`` of it are used): 300 epochs
#: at 1 Hz, as seed001-vehicle and the drives
GNSS_PERIOD_EPOCHS = 300


def parse_prn(name, v):
    """Parser of ``fault_prn``: 'auto' or a GPS PRN 1..32 (an int)."""
    v = str(v).strip()
    if v == "auto":
        return v
    try:
        n = int(v)
    except ValueError:
        raise ValueError(f"{name} must be 'auto' or a GPS PRN 1..32, got {v!r}") from None
    if not 1 <= n <= 32:
        raise ValueError(f"{name} must be 'auto' or a GPS PRN 1..32, got {v!r}")
    return n


def parse_bool(name, v):
    """Parser of a yes/no parameter: a bool, or true/false, yes/no, on/off, 1/0."""
    if isinstance(v, bool):
        return v
    s = str(v).strip().lower()
    if s in ("1", "true", "yes", "on"):
        return True
    if s in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"{name} must be true or false, got {v!r}")


def synthesize(params, seed, scenario=None):
    """(EpochGeometry, pseudorange_m, correction_m, description) for the study's inputs."""
    if params["recording"] != NO_RECORDING:
        m = epoch_geometry.from_recording(load_recording(params["recording"]), params["mask_deg"])
        return m.geom, m.pseudorange_m, m.correction_m, f"recording {params['recording']}"
    # the flight of sim.uav_seed004 with the study's tower table (towers.py), in SOP order,
    # one clock group per operator
    scenario = scenario or sim.uav_seed004()._replace(towers_enu_m=towers_enu_m())
    carrier = tower_operators()
    source, desc, real = resolve_sky(params["nav"])
    if real:
        from oaraim.studies.common.seed004 import day_start
        day = day_start(source, True)
    else:
        day = float(gpstime.gps_seconds(2022, 1, 1))
    t0 = day + 3600.0 * params["start_h"]
    t = sim.epoch_times(FLIGHT_S, params["n_epochs"])
    geom = sim.scenario_geometry(scenario, t, t0, source, desc, real, params["mask_deg"],
                                 carrier)
    if params["world"] == "clean":
        noise = draw_noise(geom, seed, params["sigma_ura_gps_m"], params["sigma_lte_noise_m"])
    else:
        noise, _ = world_errors(geom, params, seed)
    pr = sim.pseudoranges(geom, noise)
    return geom, pr, np.where(geom.valid, geom.tx_clock_m, 0.0), desc


def inject_bias(geom, pr, params):
    """pr with ``inject_sop_bias_m`` added to SOP ``inject_sop`` (1-based, SOP order) at
    every epoch: an error outside the PL's model, for the MI check."""
    if params["inject_sop_bias_m"] == 0.0:
        return pr
    tw = np.flatnonzero(~geom.is_gps)
    tw = tw[np.argsort(labels(geom)[0][tw], kind="stable")]  # SOP numbering, as run() does
    if not 1 <= params["inject_sop"] <= tw.size:
        raise ValueError(f"inject_sop must be an SOP number 1..{tw.size}, got "
                         f"{params['inject_sop']!r}")
    out = np.array(pr, copy=True)
    j = tw[params["inject_sop"] - 1]
    out[:, j] = np.where(geom.valid[:, j], out[:, j] + params["inject_sop_bias_m"], out[:, j])
    return out


def draw_noise(geom, seed, sigma_ura_gps_m, sigma_lte_m):
    """Noise (T, L): GPS N(0, C_acc(el)), towers N(0, sigma_lte^2); epoch k from
    fold_in(key(seed), k)."""
    keys = jax.vmap(lambda k: jax.random.fold_in(jax.random.key(int(seed)), k))(
        jnp.arange(geom.t_s.size, dtype=jnp.uint32))
    n = np.asarray(jax.vmap(lambda k: jax.random.normal(k, (geom.valid.shape[1],)))(keys))
    _, var_acc = gnss_variances(geom.el_rad, sigma_ura_gps_m)
    sig = np.where(geom.is_gps, np.sqrt(np.asarray(var_acc)), sigma_lte_m)
    return np.where(geom.valid, sig * n, 0.0)


def world_errors(geom, params, seed):
    """Errors (T, L) m of the realistic world (docs/error-world.md) along the flight, and the
    empirical LTE sigma of its GNSS period (m; the PL does not use it: sigma_URA^S is the
    seed's 3 m), by ``sim.gnss_sop_errors``. GPS columns: ``sim.gnss_errors`` with
    ``sim.GnssErrorModel()`` at the study's sigma_URA; tower columns: ``sim.sop_errors`` in
    ``sim.ErrorModel()`` with thermal noise ``sigma_pr_m`` and no fault of its own, each
    tower's operator its common clock term (seed 004 eq. 3), the clocks fitted over a GNSS
    period of ``GNSS_PERIOD_EPOCHS`` s at 1 Hz before take-off (seed 000 II-D). The flight is
    draw 0: key fold_in(key(seed), 0)."""
    key = jax.random.fold_in(jax.random.key(int(seed)), 0)
    tw = np.flatnonzero(~geom.is_gps)
    operator = labels(geom)[0][tw] - 1  # 0 = the first operator (labels: GPS is 0)
    world = errors.ErrorModel(sigma_pr_m=params["sigma_pr_m"], fault_onset_s=np.inf,
                           fault_bias_m=0.0, nlos_rate_per_s=params["nlos_rate_per_s"],
                           calib_window_s=params["calib_window_s"])
    t_s = jnp.asarray(geom.t_s)
    t_cal_s = -jnp.arange(GNSS_PERIOD_EPOCHS, dtype=t_s.dtype)[::-1]
    err, sigma_emp_m = sim.gnss_sop_errors(
        key, t_s, jnp.asarray(geom.el_rad), geom.is_gps, params["sigma_ura_gps_m"],
        sim.SnapshotWorld(world, t_cal_s, jnp.asarray(operator)))
    return np.where(geom.valid, np.asarray(err), 0.0), float(sigma_emp_m)


def error_rms(geom, pr, n_t, recorded):
    """RMS (m) of the synthesized pseudorange errors of the first ``n_t`` epochs, GPS and
    towers, before any injected bias: what the world put in, against the sigmas the PL
    assumes (nan for a recording, whose truth errors are unknown)."""
    if recorded:
        return {"gps": float("nan"), "sop": float("nan")}
    e = (pr - sim.pseudoranges(geom, 0.0))[:n_t]
    v = geom.valid[:n_t]
    return {k: float(np.sqrt(np.mean(e[v & m[None]] ** 2)))
            for k, m in (("gps", geom.is_gps), ("sop", ~geom.is_gps))}


def model_variances(geom, params):
    """C_int, C_acc (T, L): GPS ADD model at the elevation, SOP sigma_URA^S (URE = URA)."""
    vi_g, va_g = (np.asarray(a) for a in gnss_variances(geom.el_rad, params["sigma_ura_gps_m"]))
    vi_s, va_s = (float(a) for a in sop_variances(params["sigma_ura_sop_m"]))
    var_int = np.where(geom.is_gps, vi_g, vi_s)
    var_acc = np.where(geom.is_gps, va_g, va_s)
    return np.where(geom.valid, var_int, 1.0), np.where(geom.valid, var_acc, 1.0)


def labels(geom):
    """Clock groups: GPS 0, then each carrier in order of first appearance."""
    names = [g for g in dict.fromkeys(geom.group.tolist()) if g != "GPS"]
    lab = np.asarray([0 if g == "GPS" else 1 + names.index(g) for g in geom.group], np.int32)
    return lab, ["GPS"] + names


def _crossing_time(t_s, f, after):
    """First time at which f (sampled at t_s) reaches 0 from below where ``after``, linearly
    interpolated between the two epochs around the crossing (inf if it never does)."""
    hit = np.flatnonzero((f >= 0) & after)
    if hit.size == 0:
        return float("inf")
    i = int(hit[0])
    if i == 0 or not np.isfinite(f[i - 1]):
        return float(t_s[i])
    return float(t_s[i - 1] + (t_s[i] - t_s[i - 1]) * (-f[i - 1]) / (f[i] - f[i - 1]))


def _blocks(n_t, size):
    for start in range(0, n_t, size):
        yield start, np.minimum(np.arange(start, start + size), n_t - 1), min(size, n_t - start)


class Seed004Uav(Study):
    """Seed 004 section VII (module docstring): the UAV flight, snapshot OARAIM per epoch with
    GPS + the first n of 11 LTE towers, n = 0..11 (Figs. 6-9)."""

    name = "seed004-uav"
    title = "Seed 004 section VII: UAV, GPS + up to 11 LTE towers, OARAIM HPE/HPL (Figs. 6-9)"
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = ("one epoch of the flight (n_epochs epochs uniform over 220 s; "
                   "--realizations N: the first N)")
    default_realizations = PUBLISHED_EPOCHS
    quick_realizations = PUBLISHED_EPOCHS
    quick_cost_s = 88
    #: --quick: the whole flight (the Fig. 7 ramp included) at a twelfth of the epoch rate
    #: (240 epochs, ~1.1 Hz: the quarter rate took 49 s of a warm `reproduce --quick`)
    quick_sets = {"n_epochs": PUBLISHED_EPOCHS // 12}
    test_realizations = 400
    nav_file = NAV_FILE
    params = {
        "nav": NAV,
        "start_h": Param(20.5, in_range(0.0, 23.9), "GPS time of the take-off, hours of the "
                         "file's day (our choice: 12:30 local, the first daylight half hour "
                         "with PRN 8 above 15 deg all flight, seed 004 Fig. 7)", "h"),
        "n_epochs": Param(PUBLISHED_EPOCHS, count(10, 100000),
                          "epochs over the 220 s flight (seed 004: 2880)"),
        "mask_deg": Param(15.0, in_range(0.0, 89.0), "GPS elevation mask (seed 004 VII-B)",
                          "deg"),
        "sigma_ura_gps_m": Param(1.0, positive, "GPS sigma_URA (Table I)", "m"),
        "b_nom_m": B_NOM_GPS,
        "p_sat": P_SAT_GPS,
        "p_const": P_CONST_GPS_PARAM,
        "sigma_ura_sop_m": Param(3.0, positive, "SOP sigma_URA^S (seed 004 VII-D: 3 m)", "m"),
        "p_s_sop": Param(1e-4, probability, "SOP P_s^S (seed 004 VII-A: 1e-4)"),
        "p_const_sop": Param(1e-4, probability, "SOP P_const^S per carrier (Table I)"),
        "world": Param("realistic", parse_choice("realistic", "clean"), "error world of the "
                       "synthesis: 'realistic' (sim.GnssErrorModel for GPS, sim.ErrorModel for "
                       "the towers, one common clock term per operator; docs/error-world.md) or "
                       "'clean' (white noise from the PL's own model: GPS N(0, C_acc), LTE "
                       "N(0, sigma_lte_noise_m^2))"),
        "sigma_pr_m": Param(errors.ErrorModel().sigma_pr_m, positive, "LTE thermal (white) "
                            "noise of the realistic world (sim.ErrorModel default)", "m"),
        "nlos_rate_per_s": Param(0.0, non_negative, "NLOS episode onsets per second on each "
                                 "tower in the realistic world (the world's default is 1/250 s "
                                 "for a car in a street; 0 here: an aircraft above the roofs "
                                 "sees the towers in line of sight, seed 004 refs. [52]-[53])",
                                 "1/s"),
        "calib_window_s": Param(float(GNSS_PERIOD_EPOCHS), in_range(2.0, GNSS_PERIOD_EPOCHS),
                                "realistic world: the last seconds of the pre-flight GNSS "
                                "period over which the tower clocks are fitted (the world's "
                                "default is 120 s; here the whole period: the UAV waits on "
                                "the ground with GPS)", "s"),
        "sigma_lte_noise_m": Param(2.0, positive, "LTE pseudorange noise of the clean world "
                                   "(scenario: meter-level LTE ranging)", "m"),
        "fault_prn": Param("auto", parse_prn, "GPS PRN of the Fig. 7 ramp ('auto': 8 if in "
                           "view the whole flight, else the lowest such PRN)"),
        "fault_onset_s": Param(100.0, in_range(0.0, 1e4), "onset of the Fig. 7 ramp", "s"),
        "fault_ramp_mps": Param(0.5, positive, "slope of the Fig. 7 bias ramp", "m/s"),
        "fault_modes": fault_modes_param("grouped", "seed 004's rule (eq. 8), as the other seed "
                                         "004 studies; P_s^S = 1e-4 (VII)"),
        "inject_sop_bias_m": Param(0.0, in_range(-1e4, 1e4), "constant bias added to SOP "
                                   "inject_sop's pseudoranges, outside the PL's model (MI "
                                   "check; 0 = off)", "m"),
        "inject_sop": Param(1, count(1, 11), "SOP number (towers.py) that inject_sop_bias_m "
                            "biases"),
        "exclusion": Param(True, parse_bool, "GPS + all SOPs also with detect_and_exclude "
                           "(~2 min per 2880 epochs on 2 CPU cores)"),
        "hal_m": Param(40.0, positive, "horizontal alert limit of the Stanford diagrams "
                       "(LPV-200)", "m"),
        "monitor": Param("mhss", parse_choice("mhss", "filter-ss"), "integrity monitor: the "
                         "snapshot MHSS of the paper, or also the solution-separation filter "
                         "bank on GPS + all SOPs (docs/filter-integrity.md; its rows added)"),
        "recording": Param(NO_RECORDING, parse_recording, "replay a recorded flight (folder in the "
                           "geometry.recording format) instead of synthesizing"),
        "chunk": Param(BLOCK, count(1), "accepted for the common interface and ignored "
                       f"(fixed blocks of {BLOCK} epochs)"),
    }

    def run(self, params, realizations, seed, progress):
        """The first ``realizations`` epochs: WNLS and MHSS HPL per SOP configuration, GPS +
        all SOPs with exclusion (Fig. 6), the Fig. 7 ramp and the detectable bias."""
        self.fault_modes = params["fault_modes"]
        geom, pr, corr, desc = synthesize(params, seed)
        n_t = min(int(realizations), geom.t_s.size)
        err_rms = error_rms(geom, pr, n_t, params["recording"] != NO_RECORDING)
        pr = inject_bias(geom, pr, params)
        sl = slice(0, n_t)
        geom = geom._replace(**{k: getattr(geom, k)[sl] for k in (
            "t_s", "t_gps_s", "truth_m", "tx_pos_m", "range_m", "valid", "el_rad", "tx_clock_m",
            "rx_clock_m")})
        pr, corr = pr[sl], corr[sl]
        var_int, var_acc = model_variances(geom, params)
        cons, group_names = labels(geom)
        n_c = len(group_names)
        p_const = np.array([params["p_const"]] + [params["p_const_sop"]] * (n_c - 1))
        p_sat = np.where(geom.is_gps, params["p_sat"], params["p_s_sop"])
        b_nom = np.where(geom.is_gps, params["b_nom_m"], 0.0)
        is_tw = ~geom.is_gps
        tw_idx = np.flatnonzero(is_tw)
        # SOP numbering: by clock group (operator, in order of first appearance), then tower
        # order; for a synthesized flight this is the table's (towers.py); a recording is
        # numbered the same way by its groups
        order = np.argsort(cons[tw_idx], kind="stable")
        n_sop_max = tw_idx.size
        configs = list(range(n_sop_max + 1))
        x0 = np.broadcast_to(geom.origin_ecef_m, (n_t, 3))
        res = {"hpl": np.full((len(configs), n_t), np.inf), "hpe": np.full((len(configs), n_t),
                                                                           np.inf),
               "vpl": np.full((len(configs), n_t), np.inf)}
        res["error_rms_m"] = err_rms
        orders = []
        for ci, n in enumerate(configs):
            use = geom.valid & (geom.is_gps | np.isin(np.arange(geom.valid.shape[1]),
                                                      tw_idx[order[:n]]))[None]
            hpl, vpl, hpe, mo = self._config(geom, pr, corr, var_int, var_acc, use, cons,
                                             p_sat, b_nom, p_const, x0)
            res["hpl"][ci], res["vpl"][ci], res["hpe"][ci] = hpl, vpl, hpe
            orders.append(mo)
            if progress is not None:
                progress.advance(0)
        excl = self._exclusion(geom, pr, corr, var_int, var_acc, cons, p_sat, b_nom, p_const,
                               x0, params) if params["exclusion"] else None
        fault = self._fault(geom, pr, corr, var_int, var_acc, cons, p_sat, b_nom, p_const, x0,
                            tw_idx[order[:1]], params)
        if progress is not None:
            progress.advance(int(realizations))
        out = self._result(params, geom, desc, configs, res, orders, excl, fault,
                           [str(geom.ids[tw_idx[j]]) for j in order], group_names, cons)
        if params["monitor"] == "filter-ss":
            use = geom.valid & (geom.is_gps | np.isin(np.arange(geom.valid.shape[1]), tw_idx))
            fm = araim.filter_monitor
            *_, fs = filter_ss.filter_monitor(
                geom, filter_ss.FlightPseudoranges(pr, corr, var_int, use),
                fm.BankSources(cons, p_sat, p_const), x0,
                fm.BankOptions(araim.BUDGET_SEED004_TABLE_I, orders[-1], self.fault_modes),
                params["hal_m"])
            out.rows.extend(filter_ss.filter_rows(fs, res["hpl"][-1], params["hal_m"]))
            out.metrics["filter_ss"] = fs
        return out

    # ----------------------------------------------------------------- pieces
    def _config(self, geom, pr, corr, var_int, var_acc, use, cons, p_sat, b_nom, p_const, x0):
        n_t = use.shape[0]
        r = snapshot.replay(pr, geom.tx_pos_m, snapshot.ReplaySources(
                                var_int, var_acc, use, constellation=cons), geom.truth_m,
                            p_const=p_const, correction_m=corr, x0_m=x0, config=SLOPE_ONLY)
        used = np.asarray(r.used)
        g = np.asarray(r.g_enu)
        mo = int(required_order(jnp.asarray(used), jnp.asarray(np.broadcast_to(cons, used.shape)),
                                jnp.asarray(np.broadcast_to(p_sat, used.shape)),
                                jnp.asarray(np.broadcast_to(p_const, (n_t, p_const.size))),
                                BUDGET_SEED004_TABLE_I, fault_modes=self.fault_modes))
        hpl = np.full(n_t, np.inf)
        vpl = np.full(n_t, np.inf)
        for start, idx, n in _blocks(n_t, BLOCK):
            pl = araim.protection_levels(
                araim.Sources(g[idx], np.broadcast_to(cons, (idx.size, cons.size)), var_int[idx],
                              var_acc[idx], np.broadcast_to(b_nom, (idx.size, b_nom.size)),
                              np.broadcast_to(p_sat, (idx.size, p_sat.size)), used[idx]),
                np.broadcast_to(p_const, (idx.size, p_const.size)), BUDGET_SEED004_TABLE_I,
                araim.MHSSOptions(mo, fault_modes=self.fault_modes))
            hpl[start:start + n] = np.asarray(pl.hpl_m)[:n]
            vpl[start:start + n] = np.asarray(pl.vpl_m)[:n]
        ok = np.asarray(r.wnls.status) == 0
        return (np.where(ok, hpl, np.inf), np.where(ok, vpl, np.inf), np.asarray(r.hpe_m), mo)

    def _exclusion(self, geom, pr, corr, var_int, var_acc, cons, p_sat, b_nom, p_const, x0,
                   params):
        n_t = pr.shape[0]
        use = geom.valid
        mo = int(required_order(jnp.asarray(use), jnp.asarray(np.broadcast_to(cons, use.shape)),
                                jnp.asarray(np.broadcast_to(p_sat, use.shape)),
                                jnp.asarray(np.broadcast_to(p_const, (n_t, p_const.size))),
                                BUDGET_SEED004_TABLE_I, fault_modes=self.fault_modes))
        out = {k: np.zeros(n_t) for k in ("hpl", "hpe", "hpl_aiv", "tau")}
        out["detected"] = np.zeros(n_t, bool)
        out["n_excluded"] = np.zeros(n_t, np.int16)
        for start, idx, n in _blocks(n_t, BLOCK_FDE):
            r = snapshot.replay(pr[idx], geom.tx_pos_m[idx], snapshot.ReplaySources(
                                    var_int[idx], var_acc[idx], use[idx],
                                    constellation=np.broadcast_to(cons, (idx.size, cons.size)),
                                    p_sat=p_sat, b_nom_m=b_nom),
                                geom.truth_m[idx], p_const=p_const, correction_m=corr[idx],
                                x0_m=x0[idx],
                                config=snapshot.ReplayConfig(monitors=("mhss",), max_order=mo,
                                                             fault_modes=self.fault_modes))
            s = slice(start, start + n)
            out["hpl"][s] = np.asarray(r.mhss.hpl_m)[:n]
            out["hpe"][s] = np.asarray(r.mhss.hpe_m)[:n]
            out["hpl_aiv"][s] = np.asarray(r.mhss.hpl_all_in_view_m)[:n]
            out["tau"][s] = np.asarray(r.mhss.statistic)[:n]
            out["detected"][s] = np.asarray(r.mhss.detected)[:n]
            out["n_excluded"][s] = np.asarray(r.mhss.excluded)[:n].sum(-1)
        out["max_order"] = mo
        return out

    def _fault(self, geom, pr, corr, var_int, var_acc, cons, p_sat, b_nom, p_const, x0,
               sop1, params):
        """Fig. 7: the fault mode of one GPS satellite under a bias ramp, GPS only vs + SOP 1."""
        n_t = pr.shape[0]
        gps = np.flatnonzero(geom.is_gps)
        always = [j for j in gps if geom.valid[:, j].all()]
        prn = {j: int(str(geom.ids[j])[1:]) for j in always}
        if params["fault_prn"] == "auto":
            j = next((k for k in always if prn[k] == 8), always[0] if always else None)
        else:
            j = next((k for k in always if prn[k] == params["fault_prn"]), None)
            if j is None:
                raise ValueError(f"fault_prn={params['fault_prn']} is not in view above the mask "
                                 "for the whole flight; choose one of "
                                 f"{sorted(prn.values())}")
        if j is None:
            raise ValueError("no GPS satellite is in view for the whole flight")
        bias = np.where(geom.t_s >= params["fault_onset_s"],
                        params["fault_ramp_mps"] * (geom.t_s - params["fault_onset_s"]), 0.0)
        prf = pr.copy()
        prf[:, j] += bias
        out = {"prn": prn[j], "bias_m": bias}
        for tag, extra in (("gps", []), ("sop1", list(sop1))):
            use = geom.valid & (geom.is_gps | np.isin(np.arange(pr.shape[1]), extra))[None]
            r = snapshot.replay(prf, geom.tx_pos_m, snapshot.ReplaySources(
                                    var_int, var_acc, use, constellation=cons), geom.truth_m,
                                p_const=p_const, correction_m=corr, x0_m=x0, config=SLOPE_ONLY)
            used = np.asarray(r.used)
            mo = int(required_order(jnp.asarray(used),
                                    jnp.asarray(np.broadcast_to(cons, used.shape)),
                                    jnp.asarray(np.broadcast_to(p_sat, used.shape)),
                                    jnp.asarray(np.broadcast_to(p_const, (n_t, p_const.size))),
                                    BUDGET_SEED004_TABLE_I, fault_modes=self.fault_modes))
            sep = np.zeros((n_t, 3))
            thr = np.zeros((n_t, 3))
            tau_mode = np.zeros(n_t)
            tau_max = np.zeros(n_t)
            det = np.zeros(n_t, bool)
            mdb = np.full(n_t, np.inf)
            g = np.asarray(r.g_enu)
            y = np.asarray(r.wnls.residual_m)
            unit = np.zeros_like(y)
            unit[:, j] = 1.0  # a 1 m bias on the faulty satellite alone, no noise
            for start, idx, n in _blocks(n_t, BLOCK):
                # s: the measured residuals; s1: a 1 m bias on satellite j alone. The
                # separations are linear in the residual, so the noise-free bias at which the
                # first tau reaches 1 (the minimum detectable bias) is the min over monitored
                # modes and axes of T / |separation per metre of bias|
                s, s1 = [solution_separation(
                    araim.Sources(g[idx], np.broadcast_to(cons, (idx.size, cons.size)),
                                  var_int[idx], var_acc[idx],
                                  np.broadcast_to(b_nom, (idx.size, b_nom.size)),
                                  np.broadcast_to(p_sat, (idx.size, p_sat.size)), used[idx]),
                    np.broadcast_to(p_const, (idx.size, p_const.size)), BUDGET_SEED004_TABLE_I,
                    resid[idx], araim.MHSSOptions(mo, fault_modes=self.fault_modes))
                    for resid in (y, unit)]
                per_m = np.abs(np.asarray(s1.separation_m)[:n])
                thr_all = np.asarray(s1.threshold_m)[:n]
                live = (per_m > 0) & (thr_all > 0) & np.asarray(s1.monitored)[:n][..., None]
                mdb[start:start + n] = np.min(np.where(live, thr_all / np.where(live, per_m, 1.0),
                                                       np.inf), axis=(-2, -1))
                ex = np.asarray(s.excluded)[:n]  # (n, K, L)
                target = np.zeros(ex.shape[-1], bool)
                target[j] = True
                k = np.argmax(np.all(ex == target, -1) & np.asarray(s.monitored)[:n], -1)
                rows = np.arange(n)
                sl = slice(start, start + n)
                sep[sl] = np.abs(np.asarray(s.separation_m)[:n][rows, k])
                thr[sl] = np.asarray(s.threshold_m)[:n][rows, k]
                tau = np.asarray(s.tau)[:n]
                tau_mode[sl] = np.max(tau[rows, k], -1)
                tau_max[sl] = np.max(np.where(np.isfinite(tau), tau, 0.0), axis=(-2, -1))
                det[sl] = np.asarray(s.detected)[:n]
            after = geom.t_s >= params["fault_onset_s"]
            first = np.flatnonzero(det & after)
            first_mode = np.flatnonzero((tau_mode > 1) & after)
            t_nf = _crossing_time(geom.t_s, bias - mdb, after)
            out[tag] = {"sep": sep, "thr": thr, "tau_mode": tau_mode, "tau_max": tau_max,
                        "detected": det, "max_order": mo, "mdb": mdb,
                        "t_detect_noise_free": t_nf,
                        "t_detect": float(geom.t_s[first[0]]) if first.size else float("inf"),
                        "t_detect_mode": (float(geom.t_s[first_mode[0]]) if first_mode.size
                                          else float("inf")),
                        "false_alarms_before": int(np.sum(det & ~after))}
        return out

    # ----------------------------------------------------------------- result
    def _result(self, params, geom, desc, configs, res, orders, excl, fault, sop_ids,
                group_names, cons):
        n_t = geom.t_s.size
        hpl, hpe = res["hpl"], res["hpe"]
        fin = np.all(np.isfinite(hpl), 0)
        share_fin = float(np.mean(fin))
        mean = lambda a: float(np.mean(a[fin])) if fin.any() else float("inf")  # noqa: E731
        mean_hpl = {n: mean(hpl[i]) for i, n in enumerate(configs)}
        red = {n: mean(hpl[0] - hpl[i]) for i, n in enumerate(configs)}
        raise1 = float(np.mean((hpl[1] > hpl[0])[fin])) if fin.any() and len(configs) > 1 \
            else float("nan")
        n_all = configs[-1]
        mi = {n: int(np.sum(np.isfinite(hpl[i]) & (hpe[i] > hpl[i]))) for i, n in
              enumerate(configs)}
        # MI rate with its Clopper-Pearson interval: epochs with a finite HPL are the trials;
        # the clean world's noise is drawn independently per epoch, so given the flight's
        # geometry the trials are independent; the realistic world's errors (multipath, NLOS
        # episodes, clocks) and a recording's are correlated from epoch to epoch, and the
        # interval, which assumes independence, is then too narrow
        n_fin = {n: int(np.sum(np.isfinite(hpl[i]))) for i, n in enumerate(configs)}
        mi_rate = {n: mc.rate_with_interval(mi[n], n_fin[n]) for n in configs}
        reduced = {n: float(np.mean((hpl[i] < hpl[0])[fin])) if fin.any() else float("nan")
                   for i, n in enumerate(configs)}
        n_red = [n for n in configs if 2 <= n <= 8]
        med_hpe = {n: float(np.median(hpe[i])) for i, n in enumerate(configs)}
        hal = params["hal_m"]
        normal_all = float(np.mean((hpe[-1] <= hpl[-1]) & (hpl[-1] <= hal)))
        stanford = {str(n): stanford_counts(hpe[i], hpl[i], hal) for i, n in enumerate(configs)}
        f_gps, f_sop = fault["gps"], fault["sop1"]
        sep_diff = float(np.max(np.abs(f_gps["sep"] - f_sop["sep"])))
        thr_ratio = float(np.median(f_sop["thr"][:, :2] / f_gps["thr"][:, :2]))
        mdb_gps = float(np.median(f_gps["mdb"]))
        mdb_sop = float(np.median(f_sop["mdb"]))
        world = "recorded" if params["recording"] != NO_RECORDING else params["world"]
        indep = "independent" if world == "clean" else "correlated: the interval is too narrow"
        # axis 0 east, 1 north, 2 up (integers: a string coordinate has no Zarr v3 encoding)
        coords = {"epoch": np.arange(n_t), "n_sops": np.asarray(configs), "axis": np.arange(3)}
        data = {"t_s": ("epoch", geom.t_s), "hpl_m": (("n_sops", "epoch"), hpl),
                "vpl_m": (("n_sops", "epoch"), res["vpl"]), "hpe_m": (("n_sops", "epoch"), hpe),
                "fault_bias_m": ("epoch", fault["bias_m"]),
                "n_gps": ("epoch", np.sum(geom.valid & geom.is_gps, -1)),
                "mi_count": ("n_sops", np.asarray([mi[n] for n in configs])),
                "mi_ci_low": ("n_sops", np.asarray([mi_rate[n]["ci_low"] for n in configs])),
                "mi_ci_high": ("n_sops", np.asarray([mi_rate[n]["ci_high"] for n in configs]))}
        for tag in ("gps", "sop1"):
            f = fault[tag]
            data[f"fault_sep_{tag}_m"] = (("epoch", "axis"), f["sep"])
            data[f"fault_thr_{tag}_m"] = (("epoch", "axis"), f["thr"])
            data[f"fault_tau_{tag}"] = ("epoch", f["tau_mode"])
            data[f"fault_tau_max_{tag}"] = ("epoch", f["tau_max"])
            data[f"fault_detected_{tag}"] = ("epoch", f["detected"])
            data[f"fault_mdb_{tag}_m"] = ("epoch", f["mdb"])
        if excl is not None:
            data.update({"hpl_excl_m": ("epoch", excl["hpl"]), "hpe_excl_m": ("epoch", excl["hpe"]),
                         "hpl_excl_aiv_m": ("epoch", excl["hpl_aiv"]),
                         "mhss_max_tau": ("epoch", excl["tau"]),
                         "mhss_detected": ("epoch", excl["detected"]),
                         "n_excluded": ("epoch", excl["n_excluded"])})
        ds = xr.Dataset(data, coords=coords, attrs={
            "sky_source": desc, "real_ephemeris": int(geom.real_ephemeris), "hal_m": hal,
            "fault_prn": fault["prn"], "fault_onset_s": params["fault_onset_s"],
            "fault_ramp_mps": params["fault_ramp_mps"], "sop_order": ",".join(sop_ids),
            "t_detect_gps_s": f_gps["t_detect"], "t_detect_sop1_s": f_sop["t_detect"],
            "t_detect_noise_free_gps_s": f_gps["t_detect_noise_free"],
            "t_detect_noise_free_sop1_s": f_sop["t_detect_noise_free"],
            "exclusion": int(excl is not None),
            "inject_sop_bias_m": params["inject_sop_bias_m"], "inject_sop": params["inject_sop"],
            "world": world, "stanford_counts": json.dumps(stanford)})
        hpl_fig6 = excl["hpl"] if excl is not None else hpl[-1]
        hpe_fig6 = excl["hpe"] if excl is not None else hpe[-1]
        mi6 = int(np.sum(np.isfinite(hpl_fig6) & (hpe_fig6 > hpl_fig6)))
        mi6_rate = mc.rate_with_interval(mi6, int(np.sum(np.isfinite(hpl_fig6))))
        note = (f"{n_t} epochs, sky: {desc}; sigma_URA^S = {params['sigma_ura_sop_m']:g} m, "
                f"P_s^S = {params['p_s_sop']:g}; synthetic flight ({world} error world), not "
                "tuned")
        rows = [
            {"quantity": "epochs of the flight", "unit": "count", "published": PUBLISHED_EPOCHS,
             "reproduced": n_t, "note": "2880 epochs uniform over 220 s (13.09 Hz, our reading)"},
            {"quantity": f"misleading-information epochs (HPE > HPL), GPS + {n_all} SOPs (Fig. 6)",
             "unit": "count", "published": 0, "reproduced": mi6,
             "note": ("MHSS with detect_and_exclude, solution kept" if excl is not None
                      else "all-in-view MHSS") + "; " + note},
            {"quantity": f"epochs in normal operation (HPE <= HPL <= HAL {hal:g} m), GPS + "
                         f"{n_all} SOPs (Fig. 9)", "unit": "%", "published": 100.0,
             "reproduced": 100.0 * normal_all, "note": "all-in-view MHSS"},
            {"quantity": f"MI rate (HPE > HPL), GPS + {n_all} SOPs (Fig. 6)", "unit": "%",
             "published": 0.0, "reproduced": 100.0 * mi6_rate["rate"],
             "note": (f"95 % Clopper-Pearson [{100 * mi6_rate['ci_low']:.3g}, "
                      f"{100 * mi6_rate['ci_high']:.3g}] % over {mi6_rate['trials']} epochs "
                      f"({indep}); "
                      "the seed's text gives no HPE or HPL level, only 'HPE can always be "
                      "bounded' (Fig. 6)")},
            {"quantity": "+1 SOP raises the HPL (Fig. 8, Theorem 2): share of epochs",
             "unit": "%", "published": 100.0, "reproduced": 100.0 * raise1,
             "note": "seed: 'adding one SOP slightly increases the HPL' (our reading: at every "
                     "epoch; the size is in Fig. 8 only)"},
            {"quantity": "+n SOPs (n = 2..8) reduce the HPL (Fig. 8): smallest share of epochs",
             "unit": "%", "published": 100.0,
             "reproduced": 100.0 * min((reduced[n] for n in n_red), default=float("nan")),
             "note": "seed: 'for two or more SOPs, the results show HPL reduction over the "
                     "experiment trajectory'"},
            {"quantity": "+n SOPs (n = 2..8) reduce the HPE (Fig. 9): largest median HPE "
                         "relative to GPS only", "unit": "-", "published": None,
             "reproduced": max((med_hpe[n] / med_hpe[0] for n in n_red), default=float("nan")),
             "note": "seed: 'adding two or more SOPs reduces both the HPL and HPE' (< 1); "
                     "the realistic world's LTE errors (error_rms_sop_m) can raise it"},
        ] + [
            {"quantity": f"mean HPL reduction, +{n} SOP{'s' if n > 1 else ''} (Fig. 8)",
             "unit": "m", "published": None, "reproduced": red[n],
             "note": ("the seed states no reduction in numbers (Fig. 8's curves only); "
                      "negative = HPL raised") if n == 1 else ""}
            for n in configs if 1 <= n <= 8
        ] + [
            {"quantity": f"+1 SOP changes the fault-mode statistic of PRN {fault['prn']} "
                         "(Fig. 7a, Theorem 1): max |difference|", "unit": "m", "published": 0.0,
             "reproduced": sep_diff, "note": "seed: 'does not change the test statistics'"},
            {"quantity": "+1 SOP: threshold ratio (E, N; median) (Fig. 7a)", "unit": "-",
             "published": None, "reproduced": thr_ratio,
             "note": "seed: 'increases the test threshold' (> 1)"},
            {"quantity": f"detection time of the PRN {fault['prn']} ramp, GPS only", "unit": "s",
             "published": None, "reproduced": f_gps["t_detect"],
             "note": (f"ramp {params['fault_ramp_mps']:g} m/s from "
                      f"{params['fault_onset_s']:g} s; any tau > 1")},
            {"quantity": f"detection time of the PRN {fault['prn']} ramp, GPS + SOP 1",
             "unit": "s", "published": None, "reproduced": f_sop["t_detect"],
             "note": "Theorem 1: later (less sensitive) with one SOP"},
            {"quantity": f"minimum detectable bias on PRN {fault['prn']}, GPS only (median "
                         "over the flight)", "unit": "m", "published": None,
             "reproduced": mdb_gps,
             "note": ("noise-free bias at which the first tau reaches 1: min over modes and "
                      "axes of T / |separation per metre of bias|")},
            {"quantity": f"minimum detectable bias on PRN {fault['prn']}, GPS + SOP 1 (Fig. 7, "
                         "Theorem 1)", "unit": "m", "published": None, "reproduced": mdb_sop,
             "note": "Theorem 1: larger with one SOP (same separations, larger thresholds)"},
            {"quantity": f"noise-free detection time of the PRN {fault['prn']} ramp, GPS only",
             "unit": "s", "published": None, "reproduced": f_gps["t_detect_noise_free"],
             "note": "ramp = minimum detectable bias, interpolated between epochs"},
            {"quantity": f"noise-free detection time of the PRN {fault['prn']} ramp, GPS + "
                         "SOP 1", "unit": "s", "published": None,
             "reproduced": f_sop["t_detect_noise_free"],
             "note": ("the delay one SOP causes; the noisy detection times above are quantised "
                      "to the epoch spacing and cannot show it")},
        ]
        metrics = {
            "sky_source": desc, "real_ephemeris": bool(geom.real_ephemeris), "epochs": n_t,
            "gps_visible_min": int(data["n_gps"][1].min()),
            "gps_visible_max": int(data["n_gps"][1].max()),
            "sop_order": sop_ids, "carriers": group_names[1:],  # = operators
            "share_epochs_all_hpl_finite": share_fin,
            "mean_hpl_m": {str(n): v for n, v in mean_hpl.items()},
            "mean_hpl_reduction_m": {str(n): v for n, v in red.items()},
            "share_epochs_hpl_reduced": {str(n): v for n, v in reduced.items()},
            "misleading_information_epochs": {str(n): v for n, v in mi.items()},
            "stanford_counts": stanford,
            "misleading_information_rate": {str(n): v for n, v in mi_rate.items()},
            "inject_sop_bias_m": params["inject_sop_bias_m"], "inject_sop": params["inject_sop"],
            "world": world, "error_rms_gps_m": res["error_rms_m"]["gps"],
            "error_rms_sop_m": res["error_rms_m"]["sop"],
            "misleading_information_epochs_note": f"epochs {indep}",
            "mhss_max_order": {str(n): v for n, v in zip(configs, orders, strict=True)},
            "median_hpe_m": {str(n): v for n, v in med_hpe.items()},
            "max_hpe_m": {str(n): float(np.max(hpe[i])) for i, n in enumerate(configs)},
            "fault_prn": fault["prn"], "fault_onset_s": params["fault_onset_s"],
            "fault_ramp_mps": params["fault_ramp_mps"],
            "detection_time_gps_s": f_gps["t_detect"],
            "detection_time_sop1_s": f_sop["t_detect"],
            "detection_time_mode_gps_s": f_gps["t_detect_mode"],
            "detection_time_mode_sop1_s": f_sop["t_detect_mode"],
            "false_alarms_before_onset_gps": f_gps["false_alarms_before"],
            "false_alarms_before_onset_sop1": f_sop["false_alarms_before"],
            "fault_statistic_max_abs_difference_m": sep_diff,
            "fault_threshold_ratio_median": thr_ratio,
            "fault_tau_reduction_median": float(np.median(f_gps["tau_mode"] - f_sop["tau_mode"])),
            "fault_mdb_median_gps_m": mdb_gps, "fault_mdb_median_sop1_m": mdb_sop,
            "fault_mdb_ratio_median": float(np.median(f_sop["mdb"] / f_gps["mdb"])),
            "detection_time_noise_free_gps_s": f_gps["t_detect_noise_free"],
            "detection_time_noise_free_sop1_s": f_sop["t_detect_noise_free"],
            "detection_delay_noise_free_s": (f_sop["t_detect_noise_free"]
                                             - f_gps["t_detect_noise_free"]),
        }
        if excl is not None:
            metrics.update({
                "exclusion_max_order": excl["max_order"],
                "exclusion_detections": int(excl["detected"].sum()),
                "exclusion_epochs_with_exclusion": int(np.sum(excl["n_excluded"] > 0)),
                "exclusion_mean_hpl_m": float(np.mean(excl["hpl"][np.isfinite(excl["hpl"])]))
                if np.isfinite(excl["hpl"]).any() else float("inf"),
                "exclusion_misleading_information_epochs": mi6})
        metrics["fig6_misleading_information_rate"] = mi6_rate
        return StudyResult(ds, rows, metrics, extra_provenance={
            "sky_source": desc, "real_ephemeris": bool(geom.real_ephemeris),
            "recording": params["recording"]})

    # ----------------------------------------------------------------- plots
    def plot(self, out_dir):
        """fig6_hpe_hpl.png, fig7_detection_sensitivity.png, fig8_hpl_reduction.png and
        fig9_stanford.png (Figs. 6-9) in out_dir; returns their paths."""
        return plot_uav(out_dir)
