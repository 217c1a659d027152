"""SOP requirements: how good must an SOP be before adding it lowers the HPL?

Seed 004's Fig. 4 answers on a grid (26 sigma_URA^S x 13 P_s^S cells x 5,000 draws per panel);
Theorem 2 says one SOP never helps. This study finds, for n SOPs and each P_s^S, the largest
sigma_URA^S at which the n SOPs still lower the mean HPL: the largest root of

    f(sigma) = mean over draws of [HPL(GPS) - HPL(GPS + n SOPs; sigma, P_s^S)] - TOL_M = 0

(TOL_M = 2 mm, Fig. 4's "reduces" threshold), by Newton's method in log sigma with the exact
derivative of the mean HPL (``jax.jvp`` through ``araim.protection_levels_kernel``, the PL roots
differentiated by the implicit function theorem, docs/gradients.md), safeguarded by a bracket
from ``PROBES_M``. The draws are Fig. 4's (``studies.common.seed004``: GPS epochs uniform over
the day, BPP towers; the same keys, ``mc.realization_keys(seed, 0, ...)``, as the grid study's
common random numbers), so the root must lie between Fig. 4's grid boundary and the next grid
value: the study checks this at ``check_p_s`` against a grid it evaluates on the same draws,
and counts the evaluations each way. Beside it, the sensitivity maps d mean HPL / d sigma_URA^S
and d mean HPL / d log10 P_s^S on a subgrid (``map_sigma_ura_sop_m``), one forward-mode
derivative per cell.

A root is "none" (NaN) when the SOPs do not reduce the HPL even at the smallest probe and ">
the largest probe" (inf) when they still do at the largest. The derivative is that of the
active fault-mode set (the order rule switches with P_s^S, not sigma).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim.batching import jit_kernel
from oaraim.mc import realization_keys
from oaraim.mc.checkpoint import counted_unit
from oaraim.studies.base import Param, ResumableStudy, axis, count, positive, probability
from oaraim.studies.common import seed004 as c
from oaraim.studies.common.seed004 import TOL_M
from oaraim.studies.seed004_fig4 import largest_reducing_sigma

#: sigma_URA^S probes that bracket the largest root before Newton (m)
PROBES_M = (0.5, 2.0, 8.0, 25.0)
#: Newton stops when the log-sigma step is below this (relative sigma change 1e-4)
LOG_TOL = 1e-4
#: most Newton (or bisection) steps per root
MAX_STEPS = 30


def mean_sop_hpl(hpl_gps_m, gps, sops, sigma_ura_sop_m, log10_p_s, p_const_sop, max_order,
                 fault_modes):
    """(mean HPL reduction - TOL_M, mean GPS + SOP HPL) over the draws where both HPLs are
    finite: differentiable in sigma_ura_sop_m and log10_p_s (``jax.jvp``). ``gps`` is the
    draws' (az, el, valid) (R, S), ``sops`` their towers' (az, el, valid) (R, N) padded to a
    common N (``padded_towers``: absent towers are invalid sources, which change no PL)."""
    (az, el, v), (az_s, el_s, valid_s) = gps, sops
    sources = c.gps_sources(az, el, v).concat(
        c.sop_sources(az_s, el_s, sigma_ura_sop_m, 10.0 ** log10_p_s, 1, valid_s))
    hs, _, _, _, _ = c.mhss(sources, jnp.stack([jnp.float64(c.P_CONST_GPS), p_const_sop]),
                            max_order, fault_modes)
    both = jnp.isfinite(hs) & jnp.isfinite(hpl_gps_m)
    hs0 = jnp.where(both, hs, 0.0)
    n = jnp.maximum(jnp.sum(both), 1)
    red = jnp.sum(jnp.where(both, hpl_gps_m - hs0, 0.0)) / n
    return red - TOL_M, jnp.sum(hs0) / n


@functools.partial(jit_kernel, static_argnames=("max_order", "fault_modes"))
def cell_derivatives(hpl_gps_m, gps, sops, sigma_ura_sop_m, log10_p_s, p_const_sop, max_order,
                     fault_modes):
    """``mean_sop_hpl`` and its derivatives by forward mode, in one compiled program per
    max_order (every SOP count shares it: the towers are padded to one count): (f, mean HPL,
    df/dsigma, d HPL/dsigma, d HPL/dlog10 P_s). Every evaluation of the study (probes, Newton
    steps, the check grid, the maps) uses it: a second, value-only program would cost a
    compilation (20-45 s) for a 3x cheaper call."""
    def f(s, lp):
        return jnp.stack(mean_sop_hpl(hpl_gps_m, gps, sops, s, lp, p_const_sop, max_order,
                                      fault_modes))

    x = (sigma_ura_sop_m, log10_p_s)
    val, d_s = jax.jvp(f, x, (jnp.ones_like(sigma_ura_sop_m), jnp.zeros_like(log10_p_s)))
    _, d_p = jax.jvp(f, x, (jnp.zeros_like(sigma_ura_sop_m), jnp.ones_like(log10_p_s)))
    return val[0], val[1], d_s[0], d_s[1], d_p[1]


@functools.partial(jax.jit, static_argnames=("n_sops", "n_pad"))
def padded_towers(keys, n_sops, n_pad, d_min_m, d_max_m, h_min_m, h_max_m):
    """Fig. 4's BPP draw of ``n_sops`` towers per key (``c.draw_sops``, the grid study's
    draws), padded with invalid towers to ``n_pad``: (az, el, valid) (R, n_pad)."""
    tw = jax.vmap(lambda k: c.draw_sops(k, n_sops, d_min_m, d_max_m, h_min_m, h_max_m))(keys)
    pad = ((0, 0), (0, n_pad - n_sops))
    valid = jnp.broadcast_to(jnp.arange(n_pad) < n_sops, (keys.shape[0], n_pad))
    return jnp.pad(tw.az_rad, pad), jnp.pad(tw.el_rad, pad), valid


class Cell:
    """f and its derivatives for one (n SOPs, P_s^S) on the run's draws. Evaluations are
    memoized by sigma (a probe, a grid value and a map value often coincide); ``evaluations``
    counts every request (the cost of a method), memoized or not."""

    def __init__(self, draws, params, n_sops, p_s):
        self.d, self.n, self.lp = draws, int(n_sops), float(np.log10(p_s))
        self.p_const = params["p_const_sop"]
        self.order = c.order_for(draws["slots"], self.n, float(p_s), params["p_const_sop"],
                                 params["fault_modes"])
        self.fm = params["fault_modes"]
        self.evaluations = 0
        self.memo = {}

    def _eval(self, sigma):
        d = self.d
        self.evaluations += 1
        sigma = float(sigma)
        if sigma not in self.memo:
            out = cell_derivatives(d["hpl_gps"], d["gps"], d["towers"](self.n),
                                   jnp.float64(sigma), jnp.float64(self.lp),
                                   jnp.float64(self.p_const), self.order, self.fm)
            self.memo[sigma] = tuple(float(x) for x in out)
        return self.memo[sigma]

    def value(self, sigma):
        """f(sigma) (m)."""
        return self._eval(sigma)[0]

    def value_and_slope(self, sigma):
        """f(sigma) and df/dsigma."""
        f, _, df, _, _ = self._eval(sigma)
        return f, df

    def sensitivities(self, sigma):
        """(mean GPS + SOP HPL, d/d sigma_URA^S, d/d log10 P_s^S) at sigma."""
        _, h, _, dh_ds, dh_dp = self._eval(sigma)
        return h, dh_ds, dh_dp


def largest_root(cell, probes=PROBES_M):
    """The largest sigma with f(sigma) = 0 (module docstring): bracket between the largest
    probe where f > 0 and the next probe, then Newton in u = log sigma, falling back to
    bisection whenever a step leaves the bracket. Returns (root, steps); NaN when f <= 0 at
    every probe, inf when f > 0 at the largest."""
    vals = [cell.value(s) for s in probes]
    pos = [i for i, v in enumerate(vals) if v > 0]
    if not pos:
        return float("nan"), 0
    i = pos[-1]
    if i == len(probes) - 1:
        return float("inf"), 0
    lo, hi = np.log(probes[i]), np.log(probes[i + 1])  # f(lo) > 0 >= f(hi)
    u = 0.5 * (lo + hi)
    for step in range(1, MAX_STEPS + 1):
        f, df = cell.value_and_slope(np.exp(u))
        if f == 0.0:
            return float(np.exp(u)), step
        if f > 0:
            lo = u
        else:
            hi = u
        slope = df * np.exp(u)  # df/du
        new = u - f / slope if slope < 0 and np.isfinite(slope) else np.nan
        if not (lo <= new <= hi):
            new = 0.5 * (lo + hi)
        if abs(new - u) < LOG_TOL:
            return float(np.exp(new)), step
        u = new
    return float(np.exp(u)), MAX_STEPS


class SopRequirements(ResumableStudy):
    """SOP requirements (module docstring): the largest sigma_URA^S at which n SOPs still lower
    the mean HPL, per P_s^S, by Newton on exact derivatives, against Fig. 4's grid."""

    name = "sop-requirements"
    title = "SOP requirements: the largest sigma_URA^S that still lowers the HPL, by Newton"
    seed_file = "004_55e51818ceb3e5a9.txt"
    realization = "one GPS epoch and one BPP draw of the towers (Fig. 4's draws)"
    default_realizations = 1024
    quick_realizations = 512
    quick_cost_s = 36
    max_realizations = 20_000
    #: --quick: 2 SOPs at two P_s^S of one fault-mode order (one compiled program), the grid
    #: check at 1e-4 and a 2 x 2 map: every comparison of the study, ~1 min
    test_realizations = 256
    quick_sets = {"n_sops": "2", "p_s_sop": "1e-6,1e-4", "check_p_s": "1e-4",
                  "map_n_sops": "2", "map_sigma_ura_sop_m": "2,10", "map_p_s_sop": "1e-6,1e-4"}
    nav_file = c.NAV_FILE
    params = {
        "n_sops": Param((2, 3, 4, 5, 6, 8), axis(count(1, 16)), "SOP counts (Fig. 4's panels)"),
        "p_s_sop": Param(c.P_S_GRID, axis(probability), "P_s^S values (Fig. 4's 13)"),
        "check_p_s": Param((1e-6, 1e-4), axis(probability),
                           "P_s^S values where Fig. 4's grid boundary is computed too"),
        "map_n_sops": Param((2, 8), axis(count(1, 16)), "panels of the sensitivity maps"),
        "map_sigma_ura_sop_m": Param((0.5, 1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 25.0),
                                     axis(positive), "sigma_URA^S of the sensitivity maps",
                                     "m"),
        "map_p_s_sop": Param((1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1), axis(probability),
                             "P_s^S of the sensitivity maps"),
        **{k: v for k, v in c.common_params().items() if k != "chunk"},
    }

    def check(self, p):
        """The BPP annulus: d_min_m < d_max_m, h_min_m <= h_max_m."""
        c.check_geometry_params(p)

    def draws(self, params, realizations, seed):
        """Fig. 4's draws: keys, GPS-only HPLs, each key's GPS sky (az, el, valid), the sky
        table, and ``towers(n)``: the n-tower BPP draw padded to the run's largest SOP count
        (memoized; device arrays)."""
        table = c.gps_sky_table(params["nav"], params["mask_deg"], params["sky_step_s"])
        jt = c.gps_sky_arrays(params["nav"], params["mask_deg"], params["sky_step_s"])
        keys = realization_keys(int(seed), 0, 0, int(realizations))
        gps = c.gps_kernel(keys, jt["az_rad"], jt["el_rad"], jt["valid"], params["fault_modes"])
        _, az, el, v = jax.vmap(lambda k: c.draw_gps(k, jt["az_rad"], jt["el_rad"],
                                                     jt["valid"]))(keys)
        n_pad = max((*params["n_sops"], *params["map_n_sops"]))
        geo = tuple(params[k] for k in ("d_min_m", "d_max_m", "h_min_m", "h_max_m"))
        towers = functools.lru_cache(maxsize=None)(
            lambda n: padded_towers(keys, n, n_pad, *geo))
        return {"keys": keys, "hpl_gps": gps["hpl_gps_m"], "gps": (az, el, v),
                "towers": towers, "n_pad": n_pad, "slots": table["az_rad"].shape[1],
                "table": table}

    def run_units(self, params, realizations, seed, progress, checkpoint):
        """Newton roots per (n, P_s^S), Fig. 4's grid boundary at ``check_p_s``, the
        sensitivity maps. Units (``checkpoint``): each root, each grid boundary, each map row
        (one n and P_s^S), every one a value with the evaluations it cost."""
        from oaraim.studies.sop_requirements_report import RequirementsOutcome, finish

        d = self.draws(params, realizations, seed)
        cells = {}

        def cell(n, p):
            if (n, p) not in cells:
                cells[(n, p)] = Cell(d, params, n, p)
            return cells[(n, p)]

        def counted(name, n, p, compute):
            cl = cell(n, p)
            e0 = cl.evaluations
            value = counted_unit(checkpoint, cl, f"{name}-n{n}-p{p!r}", lambda: compute(cl))
            return value, cl.evaluations - e0

        ns, ps = params["n_sops"], params["p_s_sop"]
        roots = np.full((len(ns), len(ps)), np.nan)
        steps = np.zeros((len(ns), len(ps)), int)
        evals_newton = 0
        for i, n in enumerate(ns):
            for j, p in enumerate(ps):
                (roots[i, j], steps[i, j]), e = counted("root", n, p, largest_root)
                evals_newton += e
            _advance(progress, realizations * (i + 1) // (2 * len(ns))
                     - realizations * i // (2 * len(ns)))
        grid = np.asarray(c.SIGMA_GRID_M)
        cps = params["check_p_s"]
        bound = np.full((len(ns), len(cps)), np.nan)
        evals_grid = 0
        for i, n in enumerate(ns):
            for j, p in enumerate(cps):
                f, e = counted("grid", n, p, lambda cl: np.array([cl.value(s) for s in grid]))
                bound[i, j] = largest_reducing_sigma((f + TOL_M)[None], grid)[0]
                evals_grid += e
        mn, ms, mp = params["map_n_sops"], params["map_sigma_ura_sop_m"], params["map_p_s_sop"]
        sens = np.full((3, len(mn), len(mp), len(ms)), np.nan)
        for i, n in enumerate(mn):
            for j, p in enumerate(mp):
                sens[:, i, j], _ = counted("map", n, p, lambda cl: np.array(
                    [cl.sensitivities(s) for s in ms]).T)
        _advance(progress, realizations - realizations // 2)
        return finish(params, d, realizations, RequirementsOutcome(
            roots, steps, evals_newton, bound, evals_grid, sens))

    def plot(self, out_dir):
        """sop_requirements.png (the roots against P_s^S beside Fig. 4's grid boundary) and
        sop_requirements_sensitivity.png (the derivative maps)."""
        from oaraim.studies.sop_requirements_report import plot

        return plot(xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False), out_dir)


def _advance(progress, n):
    if progress is not None and n > 0:
        progress.advance(n)
