"""LEO sensitivity: how bad may LEO ranging be and still lower the protection levels?

Seed 004's Fig. 4 question (the mean HPL change over a sigma_URA^S x P_s^S grid, per number
of SOPs) asked of LEO constellations: GPS + Galileo (ADD error models, sigma_URA 1 m,
b_nom 0.75 m, P_sat 1e-5, P_const 1e-8 / 1e-4, mask 5 deg) plus the n LEO satellites of highest
elevation above ``leo_mask_deg`` of one constellation (``errors.leo``: its downlink's
ionosphere, MOPS troposphere, airborne multipath, code noise; one clock; P_const^LEO), under
the LPV-200 budget and seed 004's fault-mode convention (``grouped``, as Fig. 4: P_s up to
0.1 assigned to monitored modes). ``fault_modes=add-v4.2`` is an option, but a costly one:
from P_s^LEO = 1e-5 on, 30-odd sources need the ADD's order 2 (pairs of satellites: ~400
modes at 40 sources), where the MHSS runs at ~40 PL/s (``oaraim bench --only leo``).

One realization: a user uniform in area between +-``lat_max_deg`` and an epoch uniform over a
day (300 s grid) of the nominal GPS 24-slot + Galileo Walker skies and of the LEO Walker
shell placed at the same epoch 0. A realization counts for n where at least n LEO satellites
are in view (the "n used" question; the summary gives the share). Change = PL(GNSS + LEO) -
PL(GNSS), VPL and HPL, averaged where both are finite (negative: LEO helps).

The boundary: for each constellation, n and P_s^LEO the largest sigma_URA^LEO at which the n
LEO satellites still lower the mean VPL by more than ``TOL_M`` (2 mm, Fig. 4's threshold), by
Newton's method in log sigma on the exact derivative (``jax.jvp`` through
``araim.protection_levels_kernel``, the PL roots differentiated by the implicit function
theorem), bracketed by the probes ``PROBES_M``; NaN where the LEO satellites do not help even
at the smallest probe, inf where they still help at the largest.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import araim, errors, geometry, mc, readers
from oaraim.studies.base import (
    Param,
    ResumableStudy,
    StudyResult,
    axis,
    count,
    fault_modes_param,
    in_range,
    parse_choice,
    positive,
    probability,
)

#: a mean change counts as a reduction beyond twice the 1e-3 m PL solver tolerance
TOL_M = 2e-3
#: sigma_URA^LEO probes that bracket the boundary before Newton (m)
PROBES_M = (0.25, 2.0, 16.0, 128.0)
#: Newton stops when the log-sigma step is below this; at most MAX_STEPS steps
LOG_TOL = 1e-3
MAX_STEPS = 20
#: GNSS ISM (MAAST / ADD defaults, as ``availability-map``): sigma_URA, b_nom, P_sat,
#: P_const GPS and Galileo
GNSS_ISM = (araim.ISM_GPS, araim.ISM_GALILEO)
#: the day of the skies (its nominal constellations are representative, not a date's)
SKY_DAY_T_GPS_S = float(readers.gpstime.gps_seconds(2025, 1, 1))
STEP_S = 300.0


def draws(params, realizations, seed, name):
    """The realizations of one constellation: GNSS rows and inputs (R, Ng) compacted to the
    most in view, and the LEO satellites in view by decreasing elevation (R, K), K the
    largest n; numpy arrays."""
    keys = mc.realization_keys(int(seed), 0, 0, int(realizations))
    u = np.asarray(jax.vmap(lambda k: jax.random.uniform(k, (3,)))(keys))
    s_max = np.sin(np.deg2rad(params["lat_max_deg"]))
    lat = np.arcsin(s_max * (2.0 * u[:, 0] - 1.0))  # uniform in area
    lon = np.pi * (2.0 * u[:, 1] - 1.0)
    t = SKY_DAY_T_GPS_S + STEP_S * np.floor(u[:, 2] * 86400.0 / STEP_S)
    rx = np.asarray(geometry.geodetic_to_ecef(lat, lon, 0.0))  # (R, 3)
    ecef, ok, _, cons, _, _ = geometry.satellites("nominal", t)  # (R, S, 3) at each own t
    ecef_l, _, _ = geometry.leo_constellation(name, SKY_DAY_T_GPS_S).sat_position_ecef(t)
    az, el, _, vis = (np.asarray(x) for x in jax.vmap(
        lambda r, e, o: geometry.look_angles(r, e[None], o[None], np.deg2rad(
            params["mask_deg"])))(jnp.asarray(rx), jnp.asarray(ecef), jnp.asarray(ok)))
    az, el, vis = az[:, 0], el[:, 0], vis[:, 0]
    az_l, el_l, _, vis_l = (np.asarray(x) for x in jax.vmap(
        lambda r, e: geometry.look_angles(r, e[None], jnp.ones(e.shape[:1], bool)[None],
                                          np.deg2rad(params["leo_mask_deg"])))(
        jnp.asarray(rx), jnp.asarray(ecef_l)))
    az_l, el_l, vis_l = az_l[:, 0], el_l[:, 0], vis_l[:, 0]
    ng = int(vis.sum(-1).max())
    order = np.argsort(~vis, axis=-1, kind="stable")[:, :ng]
    take = lambda x, o: np.take_along_axis(x, o, -1)  # noqa: E731
    az, el, vis = take(az, order), take(el, order), take(vis, order)
    code = np.asarray(cons)[order]
    k = max(params["n_leo"])
    o_l = np.argsort(np.where(vis_l, -el_l, np.inf), axis=-1, kind="stable")[:, :k]
    az_l, el_l, vis_l = take(az_l, o_l), take(el_l, o_l), take(vis_l, o_l)
    return {"az": az, "el": np.where(vis, el, 0.0), "valid": vis, "code": code,
            "az_l": az_l, "el_l": np.where(vis_l, el_l, 0.0), "valid_l": vis_l,
            "n_in_view": vis_l.sum(-1) if k else np.zeros(realizations, int)}


def _rule(name):
    return araim.FaultModeRule(name)


def _sources(d, n, sigma, log10_p_s, p_const_leo, signal):
    """``araim.Sources`` and P_const (R, 3) of GNSS + the first n LEO slots (traced sigma and
    P_s: differentiable)."""
    el = jnp.where(d["valid"], d["el"], jnp.pi / 2)
    is_gps = d["code"] == 0
    vi_g, va_g = errors.gnss_variances(el, 1.0)
    k = d["az_l"].shape[-1]
    use = d["valid_l"] & (jnp.arange(k) < n)
    ism = araim.Ism(sigma, 2.0 / 3.0 * sigma, 0.0, 0.0, 0.0)
    vi_l, va_l = errors.leo_variances(jnp.where(use, d["el_l"], jnp.pi / 2), ism, signal)
    p_s = 10.0 ** log10_p_s
    cat = lambda a, b: jnp.concatenate([a, b], -1)  # noqa: E731
    g = jnp.concatenate([geometry.geometry_rows(d["az"], d["el"]),
                         geometry.geometry_rows(d["az_l"], d["el_l"])], -2)
    src = araim.Sources(
        g, cat(d["code"].astype(jnp.int32), jnp.full(use.shape, 2, jnp.int32)),
        cat(vi_g, vi_l), cat(va_g, va_l),
        cat(jnp.where(is_gps, GNSS_ISM[0].b_nom_m, GNSS_ISM[1].b_nom_m), jnp.zeros(use.shape)),
        cat(jnp.where(is_gps, GNSS_ISM[0].p_sat, GNSS_ISM[1].p_sat),
            jnp.broadcast_to(p_s, use.shape)),
        cat(d["valid"], use))
    p_const = jnp.broadcast_to(jnp.stack([jnp.float64(GNSS_ISM[0].p_const),
                                          jnp.float64(GNSS_ISM[1].p_const),
                                          jnp.asarray(p_const_leo, jnp.float64)]),
                               (use.shape[0], 3))
    return src, p_const


@functools.partial(jax.jit, static_argnames=("setup",))
def cell(d, keep, n, sigma, priors, baseline, *, setup):
    """(mean VPL change, mean HPL change, share finite) over the realizations ``keep`` and
    their derivatives in sigma (forward mode): one compiled program per order and signal.
    ``priors``: (log10 P_s, P_const) of the LEO slots; ``baseline``: the GNSS-only (VPL, HPL)
    (R,); ``setup``: the static (max_order, signal, fault_modes)."""
    log10_p_s, p_const_leo = priors
    vpl0, hpl0 = baseline
    max_order, signal, fault_modes = setup
    budget = araim.BUDGET_LPV200
    rule = _rule(fault_modes)

    def f(s):
        src, pc = _sources(d, n, s, log10_p_s, p_const_leo, signal)
        r = araim.protection_levels_kernel(src, pc, budget,
                                           araim.MHSSOptions(max_order, fault_modes=rule))
        both = keep & jnp.isfinite(r.vpl_m) & jnp.isfinite(r.hpl_m) & jnp.isfinite(vpl0) \
            & jnp.isfinite(hpl0)
        m = jnp.where(jnp.sum(both) > 0, jnp.sum(both), jnp.nan)  # no user: NaN, not 0
        dv = jnp.sum(jnp.where(both, jnp.where(both, r.vpl_m, 0.0) - jnp.where(both, vpl0, 0.0),
                               0.0)) / m
        dh = jnp.sum(jnp.where(both, jnp.where(both, r.hpl_m, 0.0) - jnp.where(both, hpl0, 0.0),
                               0.0)) / m
        return jnp.stack([dv, dh, jnp.sum(both) / jnp.maximum(jnp.sum(keep), 1)])

    val, dval = jax.jvp(f, (sigma,), (jnp.ones_like(sigma),))
    return val, dval


@functools.partial(jax.jit, static_argnames=("signal", "fault_modes"))
def gnss_only(d, p_const_leo, *, signal, fault_modes):
    """VPL and HPL (R,) of GNSS alone (every LEO slot unused)."""
    src, pc = _sources(d, 0, jnp.float64(1.0), jnp.float64(-5.0), p_const_leo, signal)
    r = araim.protection_levels_kernel(src, pc, araim.BUDGET_LPV200,
                                       araim.MHSSOptions(1, fault_modes=_rule(fault_modes)))
    return r.vpl_m, r.hpl_m


def order_for(ng, n, p_s, p_const_leo, fault_modes):
    """The static order of a cell: the P_thresh rule with every slot in view."""
    labels = np.array([[0] * ((ng + 1) // 2) + [1] * (ng // 2) + [2] * n])
    p_sat = np.array([[1e-5] * ng + [p_s] * n])
    pc = np.array([[GNSS_ISM[0].p_const, GNSS_ISM[1].p_const, p_const_leo]])
    return int(araim.required_order(jnp.ones(labels.shape, bool), jnp.asarray(labels),
                                    jnp.asarray(p_sat), jnp.asarray(pc), araim.BUDGET_LPV200,
                                    cap=2, fault_modes=fault_modes))


def boundary(evaluate):
    """The largest sigma with mean VPL change + TOL_M = 0 (module docstring); ``evaluate``
    maps sigma to (mean VPL change, its derivative). Returns (sigma, evaluations)."""
    n_eval = 0

    def g(s):
        nonlocal n_eval
        n_eval += 1
        v, dv = evaluate(s)
        return -v - TOL_M, -dv  # > 0 where LEO lowers the mean VPL

    vals = [g(s)[0] for s in PROBES_M]
    pos = [i for i, v in enumerate(vals) if v > 0]
    if not pos:
        return float("nan"), n_eval
    i = pos[-1]
    if i == len(PROBES_M) - 1:
        return float("inf"), n_eval
    lo, hi = np.log(PROBES_M[i]), np.log(PROBES_M[i + 1])
    u = 0.5 * (lo + hi)
    for _ in range(MAX_STEPS):
        f, df = g(np.exp(u))
        lo, hi = (u, hi) if f > 0 else (lo, u)
        slope = df * np.exp(u)
        new = u - f / slope if slope < 0 and np.isfinite(slope) else np.nan
        if not (lo <= new <= hi):
            new = 0.5 * (lo + hi)
        if abs(new - u) < LOG_TOL:
            return float(np.exp(new)), n_eval
        u = new
    return float(np.exp(u)), n_eval


def grid_and_boundary(ctx, ng, params):
    """One checkpoint unit: the (P_s, sigma) grid of mean VPL/HPL changes and, per P_s, the
    boundary, for the draws and n of ``ctx``."""
    d, keep, n, vpl0, hpl0, pcl, signal = ctx
    ps, sig = params["p_s_leo"], params["sigma_ura_leo_m"]
    out = {k: np.full((len(ps), len(sig)), np.nan) for k in ("dv", "dh", "share")}
    out["root"], out["evals"] = np.full(len(ps), np.nan), np.zeros(len(ps))
    for a, p in enumerate(ps):
        order = order_for(ng, n, p, params["p_const_leo"], params["fault_modes"])

        def ev(s, p=p, order=order):
            v, dvl = cell(d, keep, n, jnp.float64(s), (jnp.float64(np.log10(p)), pcl),
                          (vpl0, hpl0), setup=(order, signal, params["fault_modes"]))
            return np.asarray(v), np.asarray(dvl)

        for b, s in enumerate(sig):
            out["dv"][a, b], out["dh"][a, b], out["share"][a, b] = ev(s)[0]

        def vpl_slope(s, ev=ev):
            v, dvl = ev(s)
            return v[0], dvl[0]

        out["root"][a], out["evals"][a] = boundary(vpl_slope)
    return out


class LeoSensitivity(ResumableStudy):
    """LEO sensitivity (module docstring): mean VPL/HPL change over sigma_URA^LEO x P_s^LEO
    per constellation and number of LEO satellites used, and the boundary by Newton."""

    name = "leo-sensitivity"
    title = "LEO sensitivity: mean VPL/HPL change over sigma_URA^LEO x P_s^LEO, and where LEO " \
            "stops helping"
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = ("one user (uniform in area within +-lat_max_deg) at one epoch of a day of "
                   "nominal GPS + Galileo and the LEO shell")
    default_realizations = 500
    quick_realizations = 128
    #: the generic study tests: a handful of draws (one is a sky, its LEO and the PL grid)
    test_realizations = 16
    quick_cost_s = 60
    max_realizations = 20_000
    quick_sets = {"constellations": "starlink", "n_leo": "4", "sigma_ura_leo_m": "1,10",
                  "p_s_leo": "1e-5"}
    params = {
        "constellations": Param(("starlink", "oneweb", "iridium", "globalstar"),
                                axis(parse_choice(*geometry.LEO_PRESETS)),
                                "LEO constellations (Walker presets, docs/leo.md); ORBCOMM's "
                                "VHF ionosphere (~600 m) leaves it nothing to add"),
        "n_leo": Param((2, 4, 8, 12), axis(count(1, 20)), "LEO satellites used (highest "
                       "elevation first)"),
        "sigma_ura_leo_m": Param((0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0), axis(positive),
                                 "sigma_URA^LEO grid (sigma_URE 2/3 of it)", "m"),
        "p_s_leo": Param((1e-7, 1e-5, 1e-4, 1e-3), axis(probability), "P_s^LEO grid"),
        "p_const_leo": Param(1e-4, probability, "P_const^LEO"),
        "mask_deg": Param(5.0, in_range(0.0, 60.0), "GNSS elevation mask (ADD)", "deg"),
        "leo_mask_deg": Param(10.0, in_range(0.0, 80.0), "LEO elevation mask (10 deg: "
                              "Iridium's 66 and Globalstar's 48 satellites rarely give 4 above "
                              "Starlink's 25 deg)", "deg"),
        "lat_max_deg": Param(60.0, in_range(1.0, 90.0), "users within +- this latitude",
                             "deg"),
        "fault_modes": fault_modes_param("grouped", "seed 004's Fig. 4 convention (P_s up to "
                                         "0.1); add-v4.2 needs order 2 from P_s^LEO 1e-5"),
    }

    def run_units(self, params, realizations, seed, progress, checkpoint):
        """Per constellation: the draws, GNSS-only PLs, the grid and the boundaries (one
        checkpoint unit per constellation and n)."""
        from oaraim.studies.leo_sensitivity_report import finish

        cs, ns = params["constellations"], params["n_leo"]
        sig, ps = params["sigma_ura_leo_m"], params["p_s_leo"]
        dv = np.full((len(cs), len(ns), len(ps), len(sig)), np.nan)
        dh, share = dv.copy(), dv.copy()
        root = np.full((len(cs), len(ns), len(ps)), np.nan)
        n_eval = np.zeros(root.shape, int)
        used = np.zeros((len(cs), len(ns)))
        pcl = jnp.float64(params["p_const_leo"])
        for i, name in enumerate(cs):
            d = {k: jnp.asarray(v) for k, v in draws(params, realizations, seed, name).items()}
            signal = errors.LEO_SIGNALS[name]
            vpl0, hpl0 = gnss_only(d, pcl, signal=signal, fault_modes=params["fault_modes"])
            ng = d["az"].shape[-1]
            for j, n in enumerate(ns):
                keep = d["n_in_view"] >= n

                ctx = (d, keep, n, vpl0, hpl0, pcl, signal)
                u = checkpoint.unit(f"{name}-n{n}",
                                    functools.partial(grid_and_boundary, ctx, ng, params))
                dv[i, j], dh[i, j], share[i, j] = u["dv"], u["dh"], u["share"]
                root[i, j], n_eval[i, j] = u["root"], u["evals"]
                used[i, j] = float(np.mean(np.asarray(keep)))
                if progress is not None:
                    progress.advance(realizations // (len(cs) * len(ns)))
        ds = xr.Dataset(
            {"vpl_change_m": (("constellation", "n_leo", "p_s_leo", "sigma_ura_leo_m"), dv),
             "hpl_change_m": (("constellation", "n_leo", "p_s_leo", "sigma_ura_leo_m"), dh),
             "share_finite": (("constellation", "n_leo", "p_s_leo", "sigma_ura_leo_m"), share),
             "sigma_boundary_m": (("constellation", "n_leo", "p_s_leo"), root),
             "boundary_evaluations": (("constellation", "n_leo", "p_s_leo"), n_eval),
             "share_n_in_view": (("constellation", "n_leo"), used)},
            coords={"constellation": list(cs), "n_leo": list(ns), "p_s_leo": list(ps),
                    "sigma_ura_leo_m": list(sig)})
        return finish(params, ds, realizations)

    def plot(self, out_dir):
        """leo_sensitivity.png: mean VPL change maps with the boundary, per constellation
        (rows) and n (columns)."""
        from oaraim.studies.leo_sensitivity_report import plot

        return plot(xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False), out_dir)


__all__ = ["LeoSensitivity", "StudyResult"]
