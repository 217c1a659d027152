"""``rinex-replay``: real GNSS data, snapshot RAIM and ARAIM epoch by epoch.

RINEX observation + navigation files -> per epoch: L1 code pseudoranges corrected with the
broadcast satellite clock (relativistic term and T_GD included), Klobuchar ionosphere and the
RTCA MOPS troposphere; satellite positions at the transmit time, rotated for the Earth's
rotation during the transit (Sagnac) -> WNLS -> chi-square slope RAIM and MHSS (ARAIM, seed 004)
protection levels, each with exclusion -> horizontal/vertical position errors against a truth
(``--set truth=X,Y,Z`` in ECEF metres, default the header's APPROX POSITION, which for the GSI
stations of the shared data is the surveyed position) -> HPE vs HPL over time and a Stanford
diagram. The pseudorange model is in ``geometry.pseudorange_model``; the per-epoch integrity in
``araim.snapshot`` (which the GNSS + SOP replays reuse).

One realization = one epoch of the file: ``--realizations N`` replays the first N epochs (all
of them when the file has fewer; default 2,880, a day at 30 s).

Choices (none of them tuned on the results):

* Integrity parameters of seed 004 section VII / Table I (its real-data experiment):
  sigma_URA = 1 m, b_nom = 0.75 m, P_s = 1e-5, P_const = 1e-8. The integrity budget is
  ``--set budget=``: ``lpv200`` (default, MAAST's LPV-200 allocation
  ``araim.BUDGET_LPV200_MAAST``, the availability map's), ``lpv200-add`` (the ADD table) or
  ``seed004-table-i`` (seed 004 Table I by its symbols, MAAST's H-ARAIM allocation); the
  default pairs the LPV-200 budget with the LPV-200 alert limits of the Stanford diagrams, as
  an aviation reader expects. ``hpl_median_m`` is this MHSS (ARAIM) HPL.
* Nominal error model of a single-frequency L1 user (variances add, seed 004 App. A):
  C_int = sigma_URA^2 + sigma_iono^2 + sigma_tropo^2 + sigma_user^2 with sigma_iono of RTCA
  DO-229 J.2.3 for the Klobuchar model (max(delay / 5, F_pp tau_vert)), sigma_tropo the MOPS
  0.12 m m(E) (``errors.sigma_tropo_m``), sigma_user the ADD's L1 noise and
  multipath curves without the dual-frequency factor; C_acc the same with sigma_URE = 2/3
  sigma_URA. WNLS and slope RAIM weight with C_int^-1.
* Chi-square slope RAIM: P_FA = 1e-5, P_MD = 1e-3 (as our seed 001 studies).
* Elevation mask 5 deg (ARAIM practice, ADD; the error models above are defined down to it);
  seed 004's UAV experiment used 15 deg: ``--set mask_deg=15``.
* HAL 40 m and VAL 35 m (LPV-200; ``--set hal_m=``, ``val_m=``) for the horizontal and
  vertical Stanford diagrams (log axes, the regions of the WAAS / EGNOS reports shaded and
  counted: ``studies.common.stanford``) and the availability shares.
* ``--set signals=auto`` (default): where the observation file has ionosphere-free code pairs
  (RINEX 3: GPS L1/L5 or L1/L2, Galileo E1/E5a) the dual-frequency GPS + Galileo ARAIM user of
  ``studies.common.dual_replay`` replaces the L1 user above (one clock per constellation, ISM
  per constellation; docs/replay.md); ``dual`` insists, ``gps-l1`` keeps the L1 user.
* A navigation header without Klobuchar coefficients: no ionospheric correction is applied (a
  warning; ``iono_model`` in the summary says so) and sigma_iono bounds the whole delay
  (F_pp tau_vert); ``--set iono=none`` does the same on purpose.
"""

import json
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

from oaraim import araim, data, errors, geometry
from oaraim.araim import required_order, snapshot
from oaraim.constants import C_M_S
from oaraim.errors import sigma_multipath_m, sigma_noise_m
from oaraim.geometry import pseudorange_model as prm
from oaraim.readers import gpstime, navigation_extras, rinex_obs, tgd_at
from oaraim.studies.base import (
    Param,
    Study,
    StudyResult,
    count,
    fault_modes_param,
    in_range,
    parse_choice,
    positive,
    probability,
)
from oaraim.studies.common import dual_replay
from oaraim.studies.common.injected_faults import fault_bias_m, parse_faults, unmonitored
from oaraim.studies.common.rinex_files import (
    as_paths,
    file_names,
    navigation_beside,
    parse_paths,
)
from oaraim.studies.common.seed004 import B_NOM_GPS, P_CONST_GPS_PARAM, P_SAT_GPS
from oaraim.studies.common.stanford import StanfordLabels, draw_stanford, stanford_counts

DEFAULT_OBS = "obs/07590920.05o"
DEFAULT_NAV = "obs/07590920.05n"
#: epochs per kernel call: every replay call sees (BLOCK_EPOCHS, L) arrays whatever the file
#: length or ``chunk``, so results are bit-identical and the kernels compile once per L
BLOCK_EPOCHS = 60
#: static source counts (visible GPS above 5 deg never exceed ~14 at any latitude)
SLOTS = (12, 16, 24, 32)
#: WNLS passes that refresh the receiver-dependent terms (Sagnac, elevation, atmosphere); the
#: first starts from the Earth's centre without them (tens of metres), the second is then
#: exact to millimetres, the third confirms
N_PASSES = 3


#: ``budget``: the integrity budgets of the MHSS by name
REPLAY_BUDGETS = {"lpv200": araim.BUDGET_LPV200_MAAST, "lpv200-add": araim.BUDGET_LPV200,
                  "seed004-table-i": araim.BUDGET_SEED004_TABLE_I}
BUDGET_NAMES = {"lpv200": "LPV-200 (MAAST)", "lpv200-add": "LPV-200 (ADD table)",
                "seed004-table-i": "seed 004 Table I"}
#: ``constellations``: the RINEX system letters of the dual-frequency and single users
SYSTEMS_OF = {"auto": "GE", "gps": "G", "galileo": "E"}
#: the Stanford diagrams: (name, error, PL, alert limit key) per axis
STANFORD_AXES = (("horizontal", "hpe", "hpl", "hal_m"), ("vertical", "vpe", "vpl", "val_m"))



def parse_truth(name, v):
    """'header' (APPROX POSITION XYZ) or 'X,Y,Z' ECEF metres."""
    if isinstance(v, str) and v.strip() == "header":
        return "header"
    parts = v.split(",") if isinstance(v, str) else list(v)
    try:
        xyz = tuple(float(x) for x in parts)
    except (TypeError, ValueError):
        xyz = ()
    if len(xyz) != 3 or not all(np.isfinite(xyz)):
        raise ValueError(f"{name} must be 'header' or X_M,Y_M,Z_M (ECEF metres, e.g. "
                         f"-3976219.5,3382372.6,3652513.0), got {v!r}")
    r = float(np.linalg.norm(xyz))
    if not (6.2e6 <= r <= 6.5e6):
        raise ValueError(f"{name} must be a point near the Earth's surface (|X| between 6,200 "
                         f"and 6,500 km), got {v!r} (|X| = {r / 1e3:.1f} km)")
    return xyz



def data_files(obs, nav):
    """Registry names (``oaraim.data``) the parameters ask for."""
    if obs != "auto":
        return ()
    return (DEFAULT_OBS, DEFAULT_NAV) if nav == "auto" else (DEFAULT_OBS,)


def resolve_files(obs, nav):
    """(obs, nav) from the parameters (each a path, or a list of paths where several were
    given); 'auto' files come from ``oaraim.data`` (the data folder, else fetched into the
    cache); 'auto' navigation beside a given observation file: ``navigation_beside``; one
    line with the fix when one is missing."""
    hint = "pass --set obs=PATH --set nav=PATH (RINEX observation and navigation files)"
    if obs == "auto":
        try:
            obs = str(data.path(DEFAULT_OBS))
            if nav == "auto":
                nav = str(data.path(DEFAULT_NAV))
        except data.DataUnavailable as e:
            raise data.DataUnavailable(f"{e}; or {hint}") from None
    obs = as_paths(obs)
    for one in ([obs] if isinstance(obs, str) else obs):
        rinex_obs.check_observation_file(one)  # an obs/nav mix-up is named before nav lookup
    if nav == "auto":
        nav = navigation_beside(obs if isinstance(obs, str) else obs[0], hint)
    nav = as_paths(nav)
    for one in ([nav] if isinstance(nav, str) else nav):
        if not Path(one).is_file():
            raise ValueError(f"navigation file {one} not found; {hint}")
    return obs, nav


def user_sigma_l1_m(el_rad):
    """Single-frequency L1 code noise and multipath, metres: the ADD's airborne L1 curves
    (``araim.error_models``) without the dual-frequency amplification factor."""
    return np.sqrt(np.asarray(sigma_multipath_m(el_rad)) ** 2
                   + np.asarray(sigma_noise_m(el_rad)) ** 2)


def gnss_replay_inputs(obs, ephemeris, extras, *, mask_deg=5.0, sigma_ura_m=1.0,
                       iono="klobuchar", tropo="mops", n_passes=N_PASSES):
    """Per-epoch inputs of ``araim.snapshot.replay`` from real GNSS observations.

    Args:
      obs: ``readers.Observations``.
      ephemeris: ``geometry.load_navigation(nav, systems=("G",))``.
      extras: ``readers.navigation_extras(nav)`` (Klobuchar, T_GD).
      mask_deg: elevation mask at the receiver estimate.
      sigma_ura_m: URA of the integrity model (seed 004 Table I: 1 m).
      iono: "klobuchar" or "none"; tropo: "mops" or "none".
      n_passes: WNLS passes refreshing the receiver-dependent terms (>= 2).

    Returns:
      dict of NumPy arrays over (T, S) epochs x satellites of the file: ``pseudorange_m``,
      ``correction_m`` (+ c (dt_sv - T_GD) - iono - tropo), ``tx_pos_m`` (reception-time frame),
      ``var_int_m2``, ``var_acc_m2``, ``valid`` (observed, ephemeris, above the mask),
      ``az_rad``, ``el_rad``, ``iono_m``, ``tropo_m``, ``sat_clock_m``, ``tgd_m``,
      ``ephemeris_age_s``, ``x_ecef_m`` (T, 3) last WNLS position, ``iono_model``.
    """
    t = obs.t_gps_s
    tgd = tgd_at(extras, obs.sv, t)
    sat = prm.satellites_at_transmit(ephemeris, t, obs.pseudorange_m, obs.valid, obs.sv,
                                           tgd)
    use_iono = iono == "klobuchar" and extras.alpha is not None
    if iono == "klobuchar" and extras.alpha is None:
        warnings.warn("the navigation header has no Klobuchar coefficients (ION ALPHA/BETA); "
                      "no ionospheric correction is applied", stacklevel=2)
    iono_model = ("klobuchar (IS-GPS-200 20.3.3.5.2.5)" if use_iono else
                  "none (header lacks ION ALPHA/BETA)" if iono == "klobuchar" else
                  "none (requested)")
    clock_m = C_M_S * sat.clock_s
    tgd_m = C_M_S * sat.tgd_s
    pr = obs.pseudorange_m
    valid = sat.valid
    n_t, n_s = pr.shape
    # pass 0: Earth's centre, satellite clocks only, Sagnac with the travel time from the centre
    rot, _ = prm.sagnac_rotate(np.zeros((n_t, 3)), sat.ecef_tx_m)
    sol = araim.wnls(np.where(valid, pr + clock_m - tgd_m, 0.0), np.asarray(rot), 1.0,
                     valid=valid)
    x = np.asarray(sol.position_m)
    mask = np.deg2rad(mask_deg)
    for _ in range(max(2, n_passes) - 1):
        rt = prm.receiver_terms(x, sat.ecef_tx_m, t, extras.alpha if use_iono else None,
                                      extras.beta if use_iono else None)
        el = np.asarray(rt.el_rad)
        iono_m = np.asarray(rt.iono_m)
        tropo_m = np.asarray(rt.tropo_m) if tropo == "mops" else np.zeros_like(el)
        v = valid & (el >= mask)
        var_int, var_acc = errors.gnss_variances(
            el, sigma_ura_m, sigma_iono_m=rt.sigma_iono_m, user_model=user_sigma_l1_m)
        var_int, var_acc = np.asarray(var_int), np.asarray(var_acc)
        corr = clock_m - tgd_m - iono_m - tropo_m
        sol = araim.wnls(np.where(v, pr + corr, 0.0), np.asarray(rt.sat_ecef_m),
                         np.sqrt(np.where(v, var_int, 1.0)), x0_m=x, valid=v)
        x = np.asarray(sol.position_m)
    rt = prm.receiver_terms(x, sat.ecef_tx_m, t, extras.alpha if use_iono else None,
                                  extras.beta if use_iono else None)
    el = np.asarray(rt.el_rad)
    iono_m = np.asarray(rt.iono_m)
    tropo_m = np.asarray(rt.tropo_m) if tropo == "mops" else np.zeros_like(el)
    v = valid & (el >= mask)
    var_int, var_acc = errors.gnss_variances(
        el, sigma_ura_m, sigma_iono_m=rt.sigma_iono_m, user_model=user_sigma_l1_m)
    z = lambda a: np.where(valid, np.asarray(a), 0.0)  # noqa: E731
    return {
        "pseudorange_m": pr, "correction_m": z(clock_m - tgd_m - iono_m - tropo_m),
        "tx_pos_m": np.where(valid[..., None], np.asarray(rt.sat_ecef_m), 0.0),
        "var_int_m2": np.where(v, np.asarray(var_int), 1.0),
        "var_acc_m2": np.where(v, np.asarray(var_acc), 1.0), "valid": v,
        "az_rad": z(rt.az_rad), "el_rad": z(el), "iono_m": z(iono_m), "tropo_m": z(tropo_m),
        "sat_clock_m": z(clock_m), "tgd_m": z(tgd_m), "ephemeris_age_s": z(sat.age_s),
        "observed": obs.valid, "ephemeris_valid": sat.valid, "x_ecef_m": x,
        "iono_model": iono_model,
    }


def compact(valid, n_slots):
    """Per epoch, the order that moves valid sources to the front, cut to ``n_slots``."""
    order = np.argsort(~valid, axis=-1, kind="stable")[..., :n_slots]
    return order, np.take_along_axis(valid, order, -1)


def replay_blocks(inp, truth, params, max_order, progress=None):
    """``araim.snapshot.replay`` over fixed blocks of ``BLOCK_EPOCHS`` epochs (padded with the
    last epoch), sources compacted to a static slot count. Returns per-epoch arrays, with
    per-source arrays scattered back onto the file's satellite axis."""
    valid = inp["valid"]
    n_t, n_s = valid.shape
    n_vis = int(valid.sum(-1).max()) if n_t else 0
    n_slots = next((k for k in SLOTS if k >= n_vis), max(n_vis, 1))
    order, v_c = compact(valid, n_slots)
    if n_slots > n_s:  # fewer satellites in the file than slots: pad with invalid columns
        pad = n_slots - n_s
        order = np.concatenate([order, np.zeros((n_t, pad), order.dtype)], -1)
        v_c = np.concatenate([v_c, np.zeros((n_t, pad), bool)], -1)
    take = lambda a: np.take_along_axis(  # noqa: E731
        a, order.reshape(order.shape + (1,) * (a.ndim - 2)), 1)
    c = {k: take(inp[k]) for k in ("pseudorange_m", "correction_m", "tx_pos_m", "var_int_m2",
                                   "var_acc_m2")}
    for k, default in (("constellation", 0), ("p_sat", params["p_sat"]),
                       ("b_nom_m", params["b_nom_m"])):
        c[k] = take(inp[k] if k in inp else np.full(valid.shape, default))
    p_const = inp.get("p_const", (params["p_const"],))
    c["var_int_m2"] = np.where(v_c, c["var_int_m2"], 1.0)
    c["var_acc_m2"] = np.where(v_c, c["var_acc_m2"], 1.0)
    x0 = inp["x_ecef_m"]
    out = {}
    per_epoch = ("hpe_m", "vpe_m", "hpl_slope_m", "vpl_slope_m", "hpl_slope_aiv_m",
                 "vpl_slope_aiv_m", "hpe_slope_m", "vpe_slope_m", "hpl_mhss_m", "vpl_mhss_m",
                 "hpl_mhss_aiv_m", "vpl_mhss_aiv_m", "hpe_mhss_m", "vpe_mhss_m",
                 "slope_statistic", "mhss_max_tau", "emt_mhss_m", "sigma_acc_mhss_m")
    ints = ("wnls_status", "slope_status", "mhss_status", "slope_detected", "mhss_detected",
            "n_used")
    for k in per_epoch:
        out[k] = np.zeros(n_t)
    for k in ints:
        out[k] = np.zeros(n_t, np.int8 if "status" in k else np.int16)
    out["error_enu_m"] = np.zeros((n_t, 3))
    out["residual_m"] = np.zeros((n_t, n_s))
    out["slope_excluded"] = np.zeros((n_t, n_s), bool)
    out["mhss_excluded"] = np.zeros((n_t, n_s), bool)
    out["position_m"] = np.zeros((n_t, 3))
    for start in range(0, n_t, BLOCK_EPOCHS):
        idx = np.minimum(np.arange(start, start + BLOCK_EPOCHS), n_t - 1)
        n = min(BLOCK_EPOCHS, n_t - start)
        r = snapshot.replay(
            c["pseudorange_m"][idx], c["tx_pos_m"][idx], snapshot.ReplaySources(
                c["var_int_m2"][idx], c["var_acc_m2"][idx], v_c[idx],
                constellation=c["constellation"][idx], p_sat=c["p_sat"][idx],
                b_nom_m=c["b_nom_m"][idx]), truth, p_const=p_const,
            correction_m=c["correction_m"][idx], x0_m=x0[idx], config=snapshot.ReplayConfig(
                budget=REPLAY_BUDGETS[params["budget"]], p_fa=params["p_fa"], p_md=params["p_md"],
                max_order=max_order, fault_modes=params["fault_modes"]))
        sl = slice(start, start + n)
        f = lambda a, n=n: np.asarray(a)[:n]  # noqa: E731
        vals = {
            "hpe_m": r.hpe_m, "vpe_m": r.vpe_m, "hpl_slope_m": r.slope.hpl_m,
            "vpl_slope_m": r.slope.vpl_m, "hpl_slope_aiv_m": r.slope.hpl_all_in_view_m,
            "vpl_slope_aiv_m": r.slope.vpl_all_in_view_m, "hpe_slope_m": r.slope.hpe_m,
            "vpe_slope_m": r.slope.vpe_m, "hpl_mhss_m": r.mhss.hpl_m, "vpl_mhss_m": r.mhss.vpl_m,
            "hpl_mhss_aiv_m": r.mhss.hpl_all_in_view_m,
            "vpl_mhss_aiv_m": r.mhss.vpl_all_in_view_m, "hpe_mhss_m": r.mhss.hpe_m,
            "vpe_mhss_m": r.mhss.vpe_m, "slope_statistic": r.slope.statistic,
            "mhss_max_tau": r.mhss.statistic, "wnls_status": r.wnls.status,
            "emt_mhss_m": r.mhss.emt_m, "sigma_acc_mhss_m": r.mhss.sigma_acc_u_m,
            "slope_status": r.slope.status, "mhss_status": r.mhss.status,
            "slope_detected": r.slope.detected, "mhss_detected": r.mhss.detected,
            "n_used": np.sum(np.asarray(r.used), -1), "error_enu_m": r.error_enu_m,
            "position_m": r.wnls.position_m}
        for k, a in vals.items():
            out[k][sl] = f(a)
        # per-source results back onto the satellite axis of the file
        ri, sj = np.nonzero(v_c[sl])
        for k, a in (("residual_m", r.wnls.residual_m), ("slope_excluded", r.slope.excluded),
                     ("mhss_excluded", r.mhss.excluded)):
            out[k][start + ri, order[sl][ri, sj]] = f(a)[ri, sj]
        if progress is not None:
            progress.advance(n)
    return out


class RinexReplay(Study):
    """The ``rinex-replay`` study (module docstring): one realization per epoch of a real
    observation file."""

    name = "rinex-replay"
    requires_data = True  # real observation files only (generic tests skip without them)
    title = "Real GNSS data: snapshot slope RAIM and ARAIM (MHSS), HPE vs HPL, Stanford diagram"
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = "one epoch of the observation file (--realizations N: the first N epochs)"
    default_realizations = 2880
    quick_realizations = 2880
    quick_cost_s = 40

    def data_files(self, params):
        """The default observation and navigation files when ``obs``/``nav`` are 'auto'."""
        return data_files(params["obs"], params["nav"])

    def too_many_realizations(self, n, limit):
        """A realization is an epoch of the file (the seed draws nothing): replay parts."""
        return (f"--realizations {n:,} is more epochs than {self.name} replays in one run (at "
                f"most {limit:,}, it keeps them in memory); one realization is one epoch of the "
                "observation file: split a longer file into parts (e.g. with gfzrnx or teqc) "
                "and replay each")

    params = {
        "obs": Param("auto", parse_paths, "RINEX 2/3 observation file, or several of one "
                     f"receiver joined by ',' ('auto': {DEFAULT_OBS}, fetched if missing: "
                     "`oaraim data list`)"),
        "nav": Param("auto", parse_paths, "RINEX 2/3 navigation file, or several joined by ',' "
                     f"(GN,EN) ('auto': {DEFAULT_NAV} with the default obs, else the day's "
                     "file beside the obs file: .yyn, BRDC00IGS_R_..._MN, *_MN or *_GN + *_EN)"),
        "truth": Param("header", parse_truth, "true receiver position X,Y,Z (ECEF m) or "
                       "'header' (APPROX POSITION XYZ)", "m"),
        "mask_deg": Param(5.0, in_range(0.0, 60.0), "elevation mask (ARAIM practice 5 deg; "
                          "seed 004 VII: 15 deg)", "deg"),
        "p_fa": Param(snapshot.DEFAULT_P_FA, probability, "slope RAIM false-alarm probability"),
        "p_md": Param(snapshot.DEFAULT_P_MD, probability,
                      "slope RAIM missed-detection probability"),
        "sigma_ura_m": Param(1.0, positive, "GPS sigma_URA (seed 004 Table I)", "m"),
        "b_nom_m": B_NOM_GPS,
        "p_sat": P_SAT_GPS,
        "p_const": P_CONST_GPS_PARAM,
        "signals": Param("auto", parse_choice("auto", "dual", "gps-l1", "single"), "auto: "
                         "dual-frequency GPS + Galileo (ionosphere-free) where the observation "
                         "file has it, else GPS L1; dual; gps-l1; single: GPS L1 + Galileo E1 "
                         "(T_GD, BGD, Klobuchar on both)"),
        "gps_pair": Param("l1l5", parse_choice(*dual_replay.dfq.GPS_PAIRS), "dual: l1l5, "
                          "GPS L1/L5 where observed (referred to L1/L2 by the per-satellite "
                          "median L1/L5 - L1/L2 offset of the file: a RINEX 3 navigation "
                          "file has no CNAV ISCs), else L1/L2 (C1C/C2W); l1l5-raw: L1/L5 "
                          "uncorrected; l1l2: GPS L1/L2 only"),
        "constellations": Param("auto", parse_choice("auto", "gps", "galileo"), "dual and "
                                "single: auto, GPS + Galileo where the files have them; gps or "
                                "galileo alone"),
        "fault": Param("none", parse_faults, "faults injected into the pseudoranges: 'none' "
                       "or SV,step,BIAS_M,ONSET_S / SV,ramp,RATE_M_PER_S,ONSET_S (onset in "
                       "seconds after the first epoch), several joined by ';'"),
        "fde": Param("on", parse_choice("on", "off"), "on: the monitors detect and exclude; "
                     "off: the unmonitored user, all-in-view position and PLs whatever the "
                     "tests say (to count the misleading epochs a monitor prevents)"),
        "airborne_model": Param("ed259a", parse_choice("ed259a", "add"), "dual: airborne "
                                "noise and multipath, EUROCAE ED-259A's dual-frequency curve "
                                "(the availability map's and the epoch API's default) or the "
                                "ADD's L1 curves times the iono-free factor"),
        "galileo_ism": Param(dual_replay.ISM_GALILEO_TEXT, dual_replay.parse_ism, "dual: "
                             "Galileo ISM sigma_URA,b_nom,P_sat,P_const (ADD defaults)"),
        "iono": Param("klobuchar", parse_choice("klobuchar", "none"), "ionospheric correction"),
        "tropo": Param("mops", parse_choice("mops", "none"),
                       "tropospheric correction (RTCA DO-229 A.4.2.4)"),
        "budget": Param("lpv200", parse_choice(*REPLAY_BUDGETS), "MHSS integrity budget: "
                        "lpv200 (MAAST's LPV-200 allocation), lpv200-add (the ADD table) or "
                        "seed004-table-i (seed 004 Table I, MAAST's H-ARAIM allocation)"),
        "hal_m": Param(40.0, positive, "horizontal alert limit of the Stanford diagram and "
                       "the availability share (LPV-200: 40 m; H-ARAIM: 185 m)", "m"),
        "val_m": Param(35.0, positive, "vertical alert limit of the Stanford diagram and the "
                       "availability share (LPV-200: 35 m)", "m"),
        "fault_modes": fault_modes_param("add-v4.2", "a GNSS receiver follows the current ADD"),
        "allow_gaps": Param("no", parse_choice("no", "yes"), "yes: replay the epochs the "
                            "navigation file does not cover (no usable orbits there) instead "
                            "of refusing it"),
        "bad_epochs": Param("error", parse_choice("error", "skip"),
                            "a malformed, truncated or duplicated epoch of the observation file: "
                            "'error' stops with its file and line, 'skip' leaves it out and "
                            "lists it (one warning each; skipped_epochs in the summary)"),
        "chunk": Param(BLOCK_EPOCHS, count(1), "accepted for the common study interface and "
                       f"ignored: the replay always runs in blocks of {BLOCK_EPOCHS} epochs "
                       "(one compilation, results independent of any chunking)"),
    }

    def run(self, params, realizations, seed, progress):
        """Replay the first ``realizations`` epochs: pseudoranges corrected, WNLS, slope RAIM
        and MHSS with exclusion, errors against the truth (``seed`` is not used)."""
        obs_path, nav_path = resolve_files(params["obs"], params["nav"])
        obs = rinex_obs.read_observations(obs_path, max_epochs=int(realizations),
                                          lenient=params["bad_epochs"] == "skip")
        eph = geometry.load_navigation(nav_path, systems=("G",))
        check_coverage(eph, obs.t_gps_s, nav_path, params["allow_gaps"] == "yes")
        extras = navigation_extras(nav_path)
        if params["truth"] == "header":
            if obs.approx_position_m is None:
                raise ValueError(f"{obs_path}: the header has no usable APPROX POSITION XYZ; "
                                 "give the true position with --set truth=X,Y,Z (ECEF m)")
            truth = np.asarray(obs.approx_position_m, np.float64)
            truth_src = "header APPROX POSITION XYZ"
        else:
            truth = np.asarray(params["truth"], np.float64)
            truth_src = "--set truth"
        table = dual_replay.dual_table(obs_path, obs, params["signals"],
                                       params["bad_epochs"] == "skip")
        if table is not None:
            gps = araim.Ism(params["sigma_ura_m"], None, params["b_nom_m"], params["p_sat"],
                            params["p_const"])
            inp = dual_replay.dual_inputs(table, nav_path, dual_replay.DualUser(
                mask_deg=params["mask_deg"],
                isms=(gps, dual_replay.parse_ism("galileo_ism", params["galileo_ism"])),
                airborne_model=params["airborne_model"], gps_pair=params["gps_pair"],
                tropo=params["tropo"], single=params["signals"] == "single",
                systems=SYSTEMS_OF[params["constellations"]]))
            obs = obs._replace(sv=inp["sv"])
            raw = [s for s in inp["sv"][np.isnan(inp["l5_offset_m"])
                                        & (inp["combination"] == 1).any(0)]]
            if raw and params["gps_pair"] == "l1l5":
                warnings.warn(f"{len(raw)} GPS satellites ({', '.join(raw[:4])}) have L5 but "
                              "no L2 code (C2W, C2L, C2X, C2S) in the file: their L1/L5 cannot be "
                              "referred to L1/L2 and "
                              "keeps metres of inter-signal bias (gps_l5_uncorrected in the "
                              "summary); --set gps_pair=l1l2 avoids it", stacklevel=2)
        elif params["constellations"] == "galileo":
            raise ValueError(f"{obs_path}: constellations=galileo needs a RINEX 3 file with "
                             "Galileo codes and signals=auto, dual or single")
        else:
            inp = gnss_replay_inputs(obs, eph, extras, mask_deg=params["mask_deg"],
                                     sigma_ura_m=params["sigma_ura_m"], iono=params["iono"],
                                     tropo=params["tropo"])
        bias = fault_bias_m(params["fault"], obs.t_gps_s, obs.sv)
        hit = (bias != 0) & inp["valid"]
        for j in np.flatnonzero((bias != 0).any(0) & ~hit.any(0)):
            warnings.warn(f"fault on {obs.sv[j]}: the satellite is never used after its onset "
                          "(below the mask, unhealthy or not observed); nothing injected",
                          stacklevel=2)
        inp["pseudorange_m"] = inp["pseudorange_m"] + np.where(inp["valid"], bias, 0.0)
        inp["fault_epochs"] = int(hit.any(-1).sum())
        n_t = obs.t_gps_s.size
        p_sat = inp.get("p_sat", np.full(inp["valid"].shape, params["p_sat"]))
        cons = inp.get("constellation", np.zeros(inp["valid"].shape, np.int32))
        p_const = np.asarray(inp.get("p_const", (params["p_const"],)), np.float64)
        order, v_c = compact(inp["valid"], max(int(inp["valid"].sum(-1).max()), 1))
        cons, p_sat = (np.take_along_axis(a, order, -1) for a in (cons, p_sat))
        max_order = required_order(v_c, cons, p_sat,
                                   np.broadcast_to(p_const, (n_t, p_const.size)),
                                   REPLAY_BUDGETS[params["budget"]],
                                   fault_modes=params["fault_modes"])
        out = replay_blocks(inp, truth, params, max_order, progress)
        if params["fde"] == "off":
            out = unmonitored(out)
        few = np.flatnonzero(out["mhss_status"] == araim.Status.TOO_FEW_SOURCES)
        if few.size:
            when = ", ".join(str(gpstime.to_datetime64(obs.t_gps_s[i]))[11:19] for i in few[:3])
            warnings.warn(f"{few.size} of {n_t} epochs had too few satellites for the MHSS "
                          f"solution (3 + one clock + 1), e.g. at {when} GPS time; no PL there "
                          "(epochs_too_few_sources in the summary)", stacklevel=2)
        return self._result(params, obs, nav_path, truth, truth_src, inp, out, max_order)

    def _result(self, params, obs, nav_path, truth, truth_src, inp, out, max_order):
        t = obs.t_gps_s
        n_t = t.size
        hours = (t - t[0]) / 3600.0 if n_t else t
        lat_r, lon_r, h_m = (float(a) for a in geometry.ecef_to_geodetic(truth))
        lat, lon, h = float(np.rad2deg(lat_r)), float(np.rad2deg(lon_r)), h_m
        ep = ("epoch",)
        es = ("epoch", "sv")
        m = metrics(out, params)
        m.update(dual_replay.summary_extras(inp, out, obs.sv))
        ds = xr.Dataset(
            {k: (ep, out[k]) for k in out if out[k].ndim == 1}
            | {"error_e_m": (ep, out["error_enu_m"][:, 0]),
               "error_n_m": (ep, out["error_enu_m"][:, 1]),
               "error_u_m": (ep, out["error_enu_m"][:, 2]),
               "position_x_m": (ep, out["position_m"][:, 0]),
               "position_y_m": (ep, out["position_m"][:, 1]),
               "position_z_m": (ep, out["position_m"][:, 2]),
               "residual_m": (es, out["residual_m"]),
               "slope_excluded": (es, out["slope_excluded"]),
               "mhss_excluded": (es, out["mhss_excluded"]),
               "used": (es, inp["valid"]), "observed": (es, inp["observed"]),
               "el_deg": (es, np.rad2deg(inp["el_rad"])), "az_deg": (es, np.rad2deg(inp["az_rad"])),
               "iono_m": (es, inp["iono_m"]), "tropo_m": (es, inp["tropo_m"]),
               "sat_clock_m": (es, inp["sat_clock_m"]), "tgd_m": (es, inp["tgd_m"]),
               "ephemeris_age_s": (es, inp["ephemeris_age_s"]),
               "sigma_int_m": (es, np.sqrt(inp["var_int_m2"])),
               "t_gps_s": (ep, t), "hours": (ep, hours)}
            | dual_replay.dataset_extras(inp, out),
            # GPS PRN numbers (a string coordinate has no stable Zarr v3 encoding)
            coords={"epoch": np.arange(n_t), "sv": dual_replay.sv_numbers(obs.sv)},
            attrs={"obs_file": file_names(obs.path), "nav_file": file_names(nav_path),
                   "code": obs.code, "marker": obs.marker, "truth_ecef_m": list(truth),
                   "truth_source": truth_src, "truth_lat_lon_h": [lat, lon, h],
                   "start_gps": str(gpstime.to_datetime64(t[0]))[:19] if n_t else "",
                   "iono_model": inp["iono_model"], "hal_m": params["hal_m"],
                   "budget": BUDGET_NAMES[params["budget"]],
                   "stanford_counts": json.dumps(m["stanford"]),
                   "val_m": params["val_m"], "mask_deg": params["mask_deg"],
                   "mhss_max_order": int(max_order), "sv_names": ",".join(obs.sv),
                   "combination": m["combination"],
                   "constellations": ",".join(m["constellations"])})
        m.update({"obs_file": file_names(obs.path), "nav_file": file_names(nav_path),
                  "code": obs.code, "truth_source": truth_src, "truth_ecef_m": list(truth),
                  "iono_model": inp["iono_model"], "mhss_max_order": int(max_order),
                  "gps_in_file": int(obs.sv.size), "skipped_epochs": len(obs.skipped),
                  "ephemeris_age_max_s": float(np.abs(inp["ephemeris_age_s"]).max())
                  if n_t else 0.0,
                  "wnls_start_to_truth_median_m": float(np.median(np.linalg.norm(
                      inp["x_ecef_m"] - truth, axis=-1))) if n_t else float("inf")})
        note = (f"no published number (real-data replay, seed 004 VII setup on GPS L1); "
                f"truth: {truth_src}; {obs.code}, mask {params['mask_deg']:g} deg"
                + (f"; {len(obs.skipped)} bad epochs skipped" if obs.skipped else ""))
        rows = [
            {"quantity": f"median HPE, {file_names(obs.path)}", "unit": "m", "published": None,
             "reproduced": m["hpe_median_m"], "note": note},
            {"quantity": f"median HPL, ARAIM / MHSS ({BUDGET_NAMES[params['budget']]} "
             "budget)", "unit": "m", "published": None,
             "reproduced": m["hpl_mhss_median_m"],
             "note": f"hpl_median_m; fault modes {params['fault_modes']}"},
            {"quantity": "median HPL, slope RAIM", "unit": "m", "published": None,
             "reproduced": m["hpl_slope_median_m"],
             "note": f"P_FA {params['p_fa']:g}, P_MD {params['p_md']:g}"},
            {"quantity": "misleading-information epochs (HPE > HPL), MHSS / slope", "unit": "count",
             "published": None, "reproduced": m["misleading_information_epochs_mhss"]
             + m["misleading_information_epochs_slope"],
             "note": f"MHSS {m['misleading_information_epochs_mhss']}, slope "
                     f"{m['misleading_information_epochs_slope']} of {m['epochs']} epochs"},
        ]
        return StudyResult(ds, rows, m, extra_provenance={
            "obs_file": obs.path, "truth_source": truth_src,
            "nav_file": nav_path if isinstance(nav_path, str) else ",".join(nav_path),
            "skipped_epochs": list(obs.skipped),
            "fault_modes": params["fault_modes"], "budget": params["budget"]})

    def plot(self, out_dir):
        """hpe_hpl_time.png (errors and protection levels over the day),
        stanford_diagram.png (horizontal and vertical, MHSS and slope RAIM: log axes, the
        regions shaded and labelled with the counts the run stored) and satellites_used.png
        (per constellation)."""
        import matplotlib.pyplot as plt

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False)
        a = ds.attrs
        h = ds["hours"].values
        hal, val = a["hal_m"], a["val_m"]
        paths = []
        top = 10 ** np.ceil(np.log10(max(hal, 1.0) * 5))
        clip = lambda x: np.minimum(np.where(np.isfinite(x), x, top), top)  # noqa: E731

        fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        ax.semilogy(h, clip(ds["hpl_mhss_m"].values), color="tab:red", lw=1,
                    label=f"HPL ARAIM / MHSS ({a['budget']})")
        ax.semilogy(h, clip(ds["hpl_slope_m"].values), color="tab:orange", lw=1,
                    label="HPL slope RAIM")
        ax.semilogy(h, np.maximum(clip(ds["hpe_m"].values), 1e-3), color="k", lw=1, label="HPE")
        ax.axhline(hal, color="gray", ls="--", lw=0.8, label=f"HAL {hal:g} m")
        ax.set_ylabel("horizontal (m)")
        ax.set_title(f"{a['obs_file']} + {a['nav_file']} ({a['code']}; truth: "
                     f"{a['truth_source']}); mask {a['mask_deg']:g} deg", fontsize=9)
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3, which="both")
        ax2.semilogy(h, clip(ds["vpl_mhss_m"].values), color="tab:red", lw=1, label="VPL MHSS")
        ax2.semilogy(h, clip(ds["vpl_slope_m"].values), color="tab:orange", lw=1,
                     label="VPL slope")
        ax2.semilogy(h, np.maximum(clip(ds["vpe_m"].values), 1e-3), color="k", lw=1,
                     label="VPE")
        ax2.axhline(val, color="gray", ls="--", lw=0.8, label=f"VAL {val:g} m")
        ax2.set_ylabel("vertical (m)")
        ax2.set_xlabel(f"hours from {a['start_gps']} (GPS time)")
        ax2.legend(fontsize=7, loc="upper right")
        ax2.grid(alpha=0.3, which="both")
        fig.tight_layout()
        p = f"{out_dir}/hpe_hpl_time.png"
        fig.savefig(p, dpi=120)
        plt.close(fig)
        paths.append(p)

        counts = json.loads(a["stanford_counts"])
        fig, axes = plt.subplots(2, 2, figsize=(11, 10), layout="constrained")
        for row, (name, err, pl, lim) in zip(axes, STANFORD_AXES, strict=True):
            al = float(a[lim])
            for axx, (kind, label) in zip(row, (("mhss", f"ARAIM / MHSS, {a['budget']} budget"),
                                                ("slope", "slope RAIM")), strict=True):
                draw_stanford(fig, axx, ds[f"{err}_{kind}_m"].values,
                              ds[f"{pl}_{kind}_m"].values, al, counts[f"{kind}_{name}"],
                              StanfordLabels(f"{err.upper()} (m)", f"{pl.upper()} (m)",
                                             f"{name}, {label}; "
                                             f"{'HAL' if lim == 'hal_m' else 'VAL'} {al:g} m"))
        fig.suptitle(f"Stanford diagrams, {a['obs_file']} ({a['code']}, {len(ds['epoch'])} "
                     f"epochs; truth: {a['truth_source']})", fontsize=9)
        p = f"{out_dir}/stanford_diagram.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
        paths.append(dual_replay.draw_satellites_used(ds, out_dir))
        return paths


def check_coverage(ephemeris, t_gps_s, nav_path, allow_gaps=False):
    """Refuse, in one line, a navigation file that does not cover the observation epochs
    (``geometry.ephemeris_gaps``: a file of another day, or cut short), unless
    ``allow_gaps``."""
    if not np.size(t_gps_s):
        return
    _, usable, _, cons, _, _ = geometry.satellites(ephemeris, t_gps_s, ("gps",))
    gaps = geometry.ephemeris_gaps(usable, cons)
    if gaps.any() and not allow_gaps:
        bad = np.flatnonzero(gaps)
        first = str(gpstime.to_datetime64(np.asarray(t_gps_s)[bad[0]]))[:19]
        raise ValueError(f"{file_names(nav_path)}: no usable GPS orbits for most satellites at "
                         f"{bad.size} of {np.size(t_gps_s)} observation epochs (from {first} "
                         "GPS time); the navigation file is of another day or cut short: give "
                         "the day's file with --set nav=FILE, or --set allow_gaps=yes to "
                         "replay what it covers")


def metrics(out, params):
    """Summary numbers (``araim.snapshot.replay_metrics`` definitions) from the stored arrays:
    medians/maxima over finite values, MI = HPE > HPL with both finite."""
    def med(x):
        x = x[np.isfinite(x)]
        return float(np.median(x)) if x.size else float("inf")

    def mx(x):
        x = x[np.isfinite(x)]
        return float(np.max(x)) if x.size else float("inf")

    n = int(out["hpe_m"].size)
    hpe = out["hpe_m"]
    m = {"epochs": n, "epochs_solved": int(np.sum(np.isfinite(hpe))),
         "satellites_used_median": float(np.median(out["n_used"])) if n else 0.0,
         "satellites_used_min": int(out["n_used"].min()) if n else 0,
         "hpe_median_m": med(hpe), "hpe_max_m": mx(hpe),
         "hpe_95_m": float(np.percentile(hpe[np.isfinite(hpe)], 95))
         if np.isfinite(hpe).any() else float("inf"),
         "vpe_median_m": med(out["vpe_m"]), "vpe_max_m": mx(out["vpe_m"]),
         "epochs_too_few_sources": int(np.sum(out["mhss_status"]
                                              == araim.Status.TOO_FEW_SOURCES))}
    for kind in ("mhss", "slope"):
        hpl, vpl = out[f"hpl_{kind}_m"], out[f"vpl_{kind}_m"]
        he, ve = out[f"hpe_{kind}_m"], out[f"vpe_{kind}_m"]
        m[f"hpl_{kind}_median_m"] = med(hpl)
        m[f"hpl_{kind}_max_m"] = mx(hpl)
        m[f"vpl_{kind}_median_m"] = med(vpl)
        m[f"vpl_{kind}_max_m"] = mx(vpl)
        m[f"hpl_{kind}_finite_share"] = float(np.mean(np.isfinite(hpl))) if n else 0.0
        m[f"hpe_{kind}_median_m"] = med(he)
        m[f"hpe_{kind}_max_m"] = mx(he)
        m[f"misleading_information_epochs_{kind}"] = int(np.sum(
            np.isfinite(hpl) & np.isfinite(he) & (he > hpl)))
        m[f"vertical_misleading_information_epochs_{kind}"] = int(np.sum(
            np.isfinite(vpl) & np.isfinite(ve) & (ve > vpl)))
        m[f"availability_hal_{kind}"] = float(np.mean(hpl <= params["hal_m"])) if n else 0.0
        m[f"availability_val_{kind}"] = float(np.mean(vpl <= params["val_m"])) if n else 0.0
        m[f"detections_{kind}"] = int(np.sum(out[f"{kind}_detected"]))
        m[f"exclusions_{kind}"] = int(np.sum(np.any(out[f"{kind}_excluded"], -1)))
        m[f"exclusion_failures_{kind}"] = int(np.sum(out[f"{kind}_status"]
                                                     == araim.Status.EXCLUSION_FAILED))
    m["stanford"] = {f"{kind}_{name}": stanford_counts(out[f"{err}_{kind}_m"],
                                                       out[f"{pl}_{kind}_m"], params[lim])
                     for kind in ("mhss", "slope") for name, err, pl, lim in STANFORD_AXES}
    m["hpl_median_m"] = m["hpl_mhss_median_m"]
    m["vpl_median_m"] = m["vpl_mhss_median_m"]
    m["misleading_information_epochs"] = m["misleading_information_epochs_mhss"]
    m["vertical_misleading_information_epochs"] = m["vertical_misleading_information_epochs_mhss"]
    return m
