"""Tower placement: where should SOP towers stand so that a region's 99.5 % HPL is smallest?

An inverse question seed 004 leaves to its readers, answered with the exact
gradients of the MHSS protection levels (docs/gradients.md). The region is a square grid of
receivers (``region_half_m``, ``grid_n``, ``receiver_h_m`` up) around seed 004's Orange County
receiver; the GPS sky is the day's broadcast (or nominal) sky at ``sky_step_s`` (one sky for
the whole region: 3 km move a satellite's direction by < 0.01 deg); the towers are SOPs of one
operator (one SOP constellation) with Table I's budget and the study's sigma_URA^S and P_s^S.
``receivers`` may instead name a CSV of points (a drive's or a flight's path), and candidate
sites a CSV too, in the ENU frame of that receiver or in latitude, longitude and height (a
cell-tower database extract; ``read_points``). The objective is the 99.5 % HPL over receivers
x epochs (the order statistic ceil(0.995 n); an HPL that cannot be computed counts as
``HPL_CAP_M``), or with ``objective=availability`` the share of HPLs above ``hal_m``.

Three answers, compared on that objective:

- **random placement** (the baseline, one realization = one placement): the ``n_towers``
  towers uniform in the square of half-width ``box_half_m`` at ``tower_h_m``;
- **free placement by gradient descent**: projected Adam on the towers' east and north
  coordinates, from the ``starts`` best random placements, on a smooth surrogate, the
  log-sum-exp of the HPLs at temperature ``tau_m`` (``tau log mean exp(HPL / tau)``: a soft
  maximum, smooth wherever the active mode sets do not switch), or for availability the mean
  sigmoid((HPL - HAL) / tau);
- **selection among candidate sites** (``candidates``: a CSV of east_m,north_m,up_m or 'auto',
  ``n_candidates`` sites drawn like a random placement): greedy (add the site that lowers the
  objective most) then 1-swap local search, both on the exact objective, against exhaustive
  search over every subset of ``n_select`` sites; and a gradient refinement of the selection
  (each chosen tower may move ``refine_radius_m`` from its site).

Every PL comes from ``araim.protection_levels_kernel`` (seed 004 eqs. 14-16, ``grouped``
fault modes); one compiled evaluation program serves every placement, greedy step and map
(towers that a placement lacks are masked sources), one compiled gradient program the descent.
"""

import functools
import itertools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import geometry, mc
from oaraim.mc.checkpoint import counted_unit
from oaraim.studies.base import (
    Param,
    ResumableStudy,
    count,
    in_range,
    keyword_or_file,
    non_negative,
    parse_choice,
    positive,
    probability,
)
from oaraim.studies.common import seed004 as c

#: the objective's quantile (the 99.5 % HPL of the issue)
QUANTILE = 0.995
#: an HPL that cannot be computed (status not OK) counts as this in the objective (m)
HPL_CAP_M = 1000.0
#: placements per call of the evaluation program (its one compiled batch shape)
EVAL_BATCH = 32
#: receivers per row of the HPL maps of the figures (the map is computed in chunks of the
#: region's grid size, so it reuses the evaluation program)
MAP_N = 15
#: Adam's moment decay rates (Kingma and Ba 2015, their defaults)
ADAM_B1, ADAM_B2 = 0.9, 0.999


_POINTS_CSV = "CSV file of east_m,north_m,up_m or lat_deg,lon_deg,height_m rows"
#: parser of ``candidates``: 'auto' or a CSV file of points (``read_points``)
parse_candidates = keyword_or_file(("auto",), _POINTS_CSV)
#: parser of ``receivers``: 'grid' or a CSV file of points (e.g. a drive's or flight's path)
parse_receivers = keyword_or_file(("grid",), _POINTS_CSV)


def read_points(path, origin_ecef_m=c.ORANGE_COUNTY_ECEF_M, at_least=1):
    """(K, 3) east, north, up (m) about ``origin_ecef_m`` from a CSV file: rows of
    east_m,north_m,up_m, or, under a header whose first column names a latitude (``lat``...),
    rows of lat_deg,lon_deg,height_m (WGS-84 ellipsoidal height; e.g. a cell-tower database
    extract), converted to the origin's ENU frame. Messages name the file and the line."""
    text = Path(path).read_text().splitlines()
    geodetic = bool(text) and text[0].split(",")[0].strip().lower().startswith("lat")
    want = "lat_deg,lon_deg,height_m" if geodetic else "east_m,north_m,up_m"
    rows = []
    for i, line in enumerate(text, 1):
        parts = [s.strip() for s in line.split(",")]
        if not line.strip() or (i == 1 and not _is_number(parts[0])):
            continue
        try:
            a, b, h = (float(x) for x in parts[:3])
        except ValueError:
            raise ValueError(f"{path}:{i}: expected {want}, got {line!r}") from None
        rows.append((a, b, h))
    if len(rows) < at_least:
        raise ValueError(f"{path}: needs at least {at_least} rows of {want}, found {len(rows)}")
    pts = np.array(rows, float)
    if geodetic:
        ecef = np.asarray(geometry.geodetic_to_ecef(np.deg2rad(pts[:, 0]),
                                                    np.deg2rad(pts[:, 1]), pts[:, 2]))
        pts = np.asarray(geometry.ecef_to_enu(ecef, np.asarray(origin_ecef_m)))
    return pts


def read_candidates(path):
    """Candidate sites (K >= 2, 3) ENU from a CSV file (``read_points``)."""
    return read_points(path, at_least=2)


def _is_number(s):
    try:
        float(s)
    except ValueError:
        return False
    return True


def receiver_grid(half_m, n, up_m):
    """(n * n, 3) ENU receivers on a square grid of half-width ``half_m`` at height ``up_m``."""
    x = np.linspace(-half_m, half_m, n)
    e, nn = np.meshgrid(x, x)
    return np.stack([e.ravel(), nn.ravel(), np.full(e.size, float(up_m))], -1)


def tower_rows(towers, receivers):
    """Azimuth and elevation (rad) of towers (..., T, 3) seen from receivers (..., R, 3), ENU:
    (..., R, T) each. The horizontal distance carries 1e-6 m^2 so a tower straight above a
    receiver has a finite derivative."""
    d = towers[..., None, :, :] - receivers[..., :, None, :]
    hor = jnp.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + 1e-6)
    return jnp.arctan2(d[..., 0], d[..., 1]), jnp.arctan2(d[..., 2], hor)


def region_hpls(towers, tower_valid, receivers, sky, sop):
    """HPL (m) of each receiver at each sky epoch with the towers: towers (P, T, 3),
    tower_valid (P, T), receivers (P, R, 3) -> (P, R * E), inf where no PL. ``sky`` holds the
    GPS table (E, S) arrays; ``sop`` = (sigma_ura_sop_m, p_s_sop, p_const_sop)."""
    az, el = tower_rows(towers, receivers)  # (P, R, T)
    n_p, n_r, n_t = az.shape
    n_e, n_s = sky["az_rad"].shape
    b = (n_p, n_r, n_e)
    az_t = jnp.broadcast_to(az[:, :, None], (*b, n_t)).reshape(-1, n_t)
    el_t = jnp.broadcast_to(el[:, :, None], (*b, n_t)).reshape(-1, n_t)
    valid_t = jnp.broadcast_to(tower_valid[:, None, None], (*b, n_t)).reshape(-1, n_t)
    gaz, gel, gvalid = (jnp.broadcast_to(jnp.asarray(sky[k]), (*b, n_s)).reshape(-1, n_s)
                        for k in ("az_rad", "el_rad", "valid"))
    sigma, p_s, p_const = sop
    sources = c.gps_sources(gaz, gel, gvalid).concat(
        c.sop_sources(az_t, el_t, sigma, p_s, 1, valid_t))
    hpl, _, _, _, _ = c.mhss(sources, jnp.array([c.P_CONST_GPS, p_const]), 1)
    return hpl.reshape(n_p, n_r * n_e)


def quantile_hpl(hpl, q=QUANTILE):
    """The objective: the ceil(q n)-th smallest HPL along the last axis, inf as ``HPL_CAP_M``."""
    h = np.sort(np.where(np.isfinite(hpl), hpl, HPL_CAP_M), axis=-1)
    k = int(np.ceil(q * h.shape[-1] - 1e-9)) - 1
    return h[..., min(max(k, 0), h.shape[-1] - 1)]


def unavailability_pct(hpl, hal_m):
    """The availability objective: % of HPLs above ``hal_m`` (or not computable) along the last
    axis (lower is better)."""
    return 100.0 * np.mean(~(np.asarray(hpl) <= hal_m), axis=-1)


def soft_unavailability_pct(hpl, hal_m, tau_m):
    """Its surrogate: 100 mean sigmoid((HPL - HAL) / tau) (inf as HPL_CAP_M)."""
    h = jnp.where(jnp.isfinite(hpl), hpl, HPL_CAP_M)
    return 100.0 * jnp.mean(jax.nn.sigmoid((h - hal_m) / tau_m), axis=-1)


#: ``objective``: what the placement minimises
OBJECTIVES = ("hpl", "availability")


def soft_max_hpl(hpl, tau_m):
    """The surrogate: tau log mean exp(HPL / tau) along the last axis (inf as HPL_CAP_M; no
    derivative flows through a capped element)."""
    h = jnp.where(jnp.isfinite(hpl), hpl, HPL_CAP_M)
    return tau_m * (jax.scipy.special.logsumexp(h / tau_m, axis=-1) - jnp.log(h.shape[-1]))


class Problem:
    """One run's compiled programs and fixed inputs (sky, receivers, SOP parameters)."""

    def __init__(self, params, sky):
        self.sky = {k: jnp.asarray(sky[k]) for k in ("az_rad", "el_rad", "valid")}
        self.sop = (params["sigma_ura_sop_m"], params["p_s_sop"], params["p_const_sop"])
        if params["receivers"] == "grid":
            self.receivers = receiver_grid(params["region_half_m"], params["grid_n"],
                                           params["receiver_h_m"])
        else:
            self.receivers = read_points(params["receivers"])
        self.tau = params["tau_m"]
        self.hal = params["hal_m"]
        self.kind = params["objective"]
        #: what the objective is, for the summary rows and figures, and its unit
        self.label, self.unit = (("99.5 % HPL", "m") if self.kind == "hpl" else
                                 (f"unavailability at HAL {self.hal:g} m", "%"))
        self.evaluations = 0
        self._eval = jax.jit(functools.partial(region_hpls, sky=self.sky, sop=self.sop))
        self._grad = jax.jit(jax.value_and_grad(self._surrogate))

    def _surrogate(self, towers, valid):
        r = jnp.asarray(self.receivers)[None]
        h = region_hpls(towers[None], valid[None], r, self.sky, self.sop)
        if self.kind == "hpl":
            return soft_max_hpl(h, self.tau)[0]
        return soft_unavailability_pct(h, self.hal, self.tau)[0]

    def score(self, hpl):
        """The exact objective of HPLs (..., R * E): the 99.5 % HPL or the unavailability."""
        if self.kind == "hpl":
            return quantile_hpl(hpl)
        return unavailability_pct(hpl, self.hal)

    def hpls(self, towers, valid, receivers=None):
        """HPLs (P, R * E) of P placements (P, T, 3) in calls of ``EVAL_BATCH`` placements."""
        towers, valid = np.asarray(towers, float), np.asarray(valid, bool)
        rec = self.receivers if receivers is None else receivers
        rec = np.broadcast_to(rec, (towers.shape[0], *rec.shape[-2:]))
        out = []
        for s in range(0, towers.shape[0], EVAL_BATCH):
            n = min(EVAL_BATCH, towers.shape[0] - s)
            pad = lambda x, s=s, n=n: np.concatenate(  # noqa: E731
                [x[s:s + n], np.repeat(x[s:s + 1], EVAL_BATCH - n, 0)], 0)
            h = self._eval(jnp.asarray(pad(towers)), jnp.asarray(pad(valid)),
                           jnp.asarray(pad(rec)))
            out.append(np.asarray(h)[:n])
        self.evaluations += towers.shape[0]
        return np.concatenate(out, 0)

    def objective(self, towers, valid=None):
        """The exact objective (``score``) of each placement (P, T, 3) (all towers valid
        unless ``valid``)."""
        towers = np.asarray(towers, float)
        valid = np.ones(towers.shape[:2], bool) if valid is None else valid
        return self.score(self.hpls(towers, valid))

    def value_and_grad(self, towers):
        """Surrogate and its gradient with respect to one placement's towers (T, 3)."""
        v, g = self._grad(jnp.asarray(towers, float), jnp.ones(towers.shape[0], bool))
        return float(v), np.asarray(g)

    def hpl_map(self, towers, valid, half_m, n=MAP_N):
        """(n, n) 99.5 % HPL over the epochs of receivers on an n x n grid of half-width
        ``half_m``, with one placement (T, 3)."""
        rec = receiver_grid(half_m, n, self.receivers[0, 2])
        r = self.receivers.shape[0]
        chunks = -(-rec.shape[0] // r)
        rec = np.concatenate([rec, np.repeat(rec[-1:], chunks * r - rec.shape[0], 0)])
        h = self.hpls(np.repeat(np.asarray(towers, float)[None], chunks, 0),
                      np.repeat(np.asarray(valid, bool)[None], chunks, 0),
                      rec.reshape(chunks, r, 3))
        e = self.sky["az_rad"].shape[0]
        per_rx = h.reshape(chunks * r, e)[:n * n]
        return quantile_hpl(per_rx).reshape(n, n)


def descend(problem, start, iterations, step_m, lower, upper):
    """Projected Adam on the towers' east and north (heights fixed) from ``start`` (T, 3),
    the step decaying linearly from ``step_m`` to step_m / 10, each coordinate kept in
    [lower, upper] (T, 2) arrays. Returns the best placement by the exact objective and the
    history (surrogate, 99.5 % HPL) per iteration."""
    x = np.array(start, float)
    m = np.zeros_like(x[:, :2])
    v = np.zeros_like(m)
    hist_s, hist_q, placements = [], [], []
    for k in range(iterations):
        s, g = problem.value_and_grad(x)
        hist_s.append(s)
        placements.append(x.copy())
        g = g[:, :2]
        m = ADAM_B1 * m + (1 - ADAM_B1) * g
        v = ADAM_B2 * v + (1 - ADAM_B2) * g * g
        mh = m / (1 - ADAM_B1 ** (k + 1))
        vh = v / (1 - ADAM_B2 ** (k + 1))
        lr = step_m * (1.0 - 0.9 * k / max(iterations - 1, 1))
        x[:, :2] = np.clip(x[:, :2] - lr * mh / (np.sqrt(vh) + 1e-12), lower, upper)
    placements.append(x.copy())
    q = problem.objective(np.stack(placements))
    hist_q = q[:-1]
    best = int(np.argmin(q))
    return placements[best], float(q[best]), np.array(hist_s), np.array(hist_q)


def greedy_swap(problem, sites, n_select):
    """Greedy selection of ``n_select`` of the K ``sites`` (K, 3) on the exact objective, then
    1-swap local search to a local optimum. Returns (chosen indices, objective, history)."""
    k_sites = sites.shape[0]
    chosen = []
    for _ in range(n_select):
        rest = [j for j in range(k_sites) if j not in chosen]
        towers = np.zeros((len(rest), n_select, 3))
        valid = np.zeros((len(rest), n_select), bool)
        for i, j in enumerate(rest):
            idx = [*chosen, j]
            towers[i, :len(idx)] = sites[idx]
            valid[i, :len(idx)] = True
        q = problem.score(problem.hpls(towers, valid))
        chosen.append(rest[int(np.argmin(q))])
    best = float(problem.objective(sites[chosen][None])[0])
    history = [best]
    while True:
        swaps = [(a, b) for a in range(n_select) for b in range(k_sites) if b not in chosen]
        if not swaps:
            break
        cand = np.stack([sites[[b if i == a else chosen[i] for i in range(n_select)]]
                         for a, b in swaps])
        q = problem.objective(cand)
        i = int(np.argmin(q))
        if q[i] >= best - 1e-9:
            break
        a, b = swaps[i]
        chosen[a] = b
        best = float(q[i])
        history.append(best)
    return sorted(chosen), best, history


def exhaustive(problem, sites, n_select, limit):
    """Every subset of ``n_select`` sites: (best indices, best objective, all objectives), or
    None when there are more than ``limit`` subsets."""
    combos = list(itertools.combinations(range(sites.shape[0]), n_select))
    if len(combos) > limit:
        return None
    q = problem.objective(np.stack([sites[list(cb)] for cb in combos]))
    i = int(np.argmin(q))
    return list(combos[i]), float(q[i]), q


class TowerPlacement(ResumableStudy):
    """Tower placement (module docstring): the 99.5 % HPL of a region with random, gradient-
    optimised and selected SOP towers."""

    name = "tower-placement"
    title = "Tower placement: SOP towers that minimise a region's 99.5 % HPL (gradients)"
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = "one random placement of the towers (the baseline the optimiser is compared with)"
    default_realizations = 256
    quick_realizations = 32
    quick_cost_s = 24
    #: the generic study tests' cap (a realization evaluates a whole placement over the region)
    test_realizations = 16
    #: --quick: a coarser region and sky and fewer iterations, the same three comparisons
    quick_sets = {"grid_n": "3", "sky_step_s": "7200", "iterations": "12", "starts": "2",
                  "n_candidates": "8"}
    nav_file = c.NAV_FILE
    params = {
        "nav": c.NAV,
        "mask_deg": Param(5.0, in_range(0.0, 89.0), "GPS elevation mask (seed 004 Table I "
                          "setting: ARAIM practice)", "deg"),
        "sky_step_s": Param(3600.0, in_range(60.0, 86400.0),
                            "epochs of the day's GPS sky (one per step)", "s"),
        "region_half_m": Param(1500.0, positive, "half-width of the receivers' square", "m"),
        "grid_n": Param(5, count(1, 41), "receivers per side of the square"),
        "receiver_h_m": Param(0.0, in_range(-100.0, 10000.0), "receiver height (ENU up)", "m"),
        "receivers": Param("grid", parse_receivers, "'grid' (the square above) or a CSV of "
                           "points (e.g. a drive's or flight's path), ENU or lat/lon"),
        "n_towers": Param(3, count(1, 12), "free towers (random and gradient placement)"),
        "tower_h_m": Param(30.0, in_range(-100.0, 1000.0), "tower height (ENU up)", "m"),
        "box_half_m": Param(3000.0, positive, "towers stay within this half-width", "m"),
        "sigma_ura_sop_m": Param(2.0, positive, "SOP sigma_URA (seed 004: 'regular' <= 2 m)",
                                 "m"),
        "p_s_sop": Param(1e-5, probability, "SOP P_s (seed 004 finding (i): <= 1e-5)"),
        "p_const_sop": Param(c.P_CONST_SOP, probability, "SOP constellation fault (Table I)"),
        "objective": Param("hpl", parse_choice(*OBJECTIVES), "minimise the 99.5 % HPL ('hpl') or "
                           "the share of HPLs above hal_m ('availability')"),
        "hal_m": Param(40.0, positive, "horizontal alert limit of objective=availability", "m"),
        "tau_m": Param(1.0, positive, "temperature of the surrogate (log-sum-exp; sigmoid "
                       "width for availability)", "m"),
        "iterations": Param(40, count(1, 10000), "gradient steps per start"),
        "starts": Param(3, count(1, 64), "starts: the best random placements"),
        "step_m": Param(150.0, positive, "first Adam step (decays to a tenth)", "m"),
        "candidates": Param("auto", parse_candidates, "candidate sites: 'auto' (random, like a "
                            "placement) or a CSV of east_m,north_m,up_m or lat_deg,lon_deg,"
                            "height_m (e.g. a cell-tower database extract)"),
        "n_candidates": Param(10, count(2, 200), "'auto' candidate sites"),
        "n_select": Param(3, count(1, 12), "sites to select"),
        "exhaustive_limit": Param(5000, count(1), "largest subset count searched exhaustively"),
        "refine_radius_m": Param(200.0, non_negative,
                                 "how far a selected tower may move in the refinement", "m"),
    }

    def check(self, p):
        """Candidates and selection sizes agree; the box holds the region."""
        if p["candidates"] == "auto" and p["n_select"] > p["n_candidates"]:
            raise ValueError(f"n_select ({p['n_select']}) must not exceed n_candidates "
                             f"({p['n_candidates']})")

    def data_files(self, params):
        """The broadcast file of nav='auto'."""
        return (c.NAV_FILE,) if params["nav"] == "auto" else ()

    def run_units(self, params, realizations, seed, progress, checkpoint):
        """Random placements, gradient descent from the best of them, greedy + swap and
        exhaustive selection among the candidates, refinement; maps for the figures. Units
        (``checkpoint``): the random baseline, each start, greedy, exhaustive, refinement,
        maps."""
        from oaraim.studies.tower_placement_report import PlacementOutcome, finish, median_index

        sky = c.gps_sky_table(params["nav"], params["mask_deg"], params["sky_step_s"])
        prob = Problem(params, sky)
        unit = functools.partial(counted_unit, checkpoint, prob)
        key = jax.random.key(int(seed))
        box, h_t, n_t = params["box_half_m"], params["tower_h_m"], params["n_towers"]
        xy = np.asarray(jax.random.uniform(mc.stream(key, "placement_random"),
                                           (realizations, n_t, 2), minval=-box, maxval=box))
        rand = np.concatenate([xy, np.full((realizations, n_t, 1), h_t)], -1)
        q_rand = unit("random", lambda: prob.objective(rand))
        _advance(progress, realizations // 2)
        runs = []
        for k, i in enumerate(np.argsort(q_rand, kind="stable")[:params["starts"]]):
            runs.append(unit(f"start{k:02d}", lambda i=i: descend(
                prob, rand[i], params["iterations"], params["step_m"], -box, box)))
        free = min(runs, key=lambda r: r[1])
        sites = self.sites(params, key)
        greedy, q_greedy, swaps = unit("greedy", lambda: greedy_swap(prob, sites,
                                                                     params["n_select"]))
        exh = unit("exhaustive", lambda: exhaustive(prob, sites, params["n_select"],
                                                    params["exhaustive_limit"]))
        lo = sites[greedy][:, :2] - params["refine_radius_m"]
        hi = sites[greedy][:, :2] + params["refine_radius_m"]
        refined = unit("refine", lambda: descend(
            prob, sites[greedy], params["iterations"],
            min(params["step_m"], max(params["refine_radius_m"], 1e-3)) / 2,
            np.maximum(lo, -box), np.minimum(hi, box)))
        _advance(progress, realizations - realizations // 2)
        none = np.zeros((n_t, 3)), np.zeros(n_t, bool)
        every = np.ones(n_t, bool)
        maps, q_gps = unit("maps", lambda: (
            {"gps_only": prob.hpl_map(*none, box),
             "random_median": prob.hpl_map(rand[median_index(q_rand)], every, box),
             "optimised": prob.hpl_map(free[0], every, box)},
            float(prob.score(prob.hpls(none[0][None], none[1][None]))[0])))
        return finish(params, sky, prob, PlacementOutcome(
            rand, q_rand, runs, free, sites, greedy, q_greedy, swaps, exh, refined, maps, q_gps))

    @staticmethod
    def sites(params, key):
        """(K, 3) candidate sites: the CSV's, or 'auto': uniform in the box at tower_h_m."""
        if params["candidates"] != "auto":
            return read_candidates(params["candidates"])
        box = params["box_half_m"]
        xy = np.asarray(jax.random.uniform(mc.stream(key, "placement_candidates"),
                                           (params["n_candidates"], 2), minval=-box,
                                           maxval=box))
        return np.concatenate([xy, np.full((xy.shape[0], 1), params["tower_h_m"])], -1)

    def plot(self, out_dir):
        """tower_placement_maps.png (99.5 % HPL maps: GPS only, random median, optimised) and
        tower_placement_convergence.png (surrogate and objective per step, selection)."""
        from oaraim.studies.tower_placement_report import plot

        return plot(xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False), out_dir)


def _advance(progress, n):
    if progress is not None:
        progress.advance(n)

