"""What the seed 004 sweep studies share: the Orange County receiver, its GPS sky, Table I.

Seed 004 section VI: "a stationary receiver located in Orange County, California ... fixed at
r_r = 1e6 x [-2.482345, -4.700049, 3.513616] (ECEF)" (33.64 N, 117.84 W, ~ 27 m), "the
geometric distribution of GPS satellites is varied by randomizing the time ... uniformly span
time of a day"; SOPs by BPP (section III-D); Table I integrity constants.

GPS sky (DESIGN.md, default sky): the broadcast file ``nav/brdc0010.22n`` (IGS merged GPS
navigation of 2022-01-01, 31 satellites) through ``oaraim.data`` (fetched if missing; a file
that cannot be had stops the run), or on ``--set nav=nominal`` only the built-in SPS
24-slot constellation; ``sky_source`` in the summary and provenance says which.
The sky is tabulated once per run at ``sky_step_s`` (10 s) over the file's day and a
realization draws its epoch uniformly from that table: a GPS satellite moves at most ~0.02 deg
in 10 s as seen from the ground, so a 10 s grid over 86,400 s is as good as continuous time
here, and the table is shared by every cell.

Choices the seed leaves open (DESIGN.md "silent"; stated, exposed as parameters, with one
sensitivity run in results/):
  * GPS elevation mask 5 deg: ARAIM practice (WG-C ADD); the UAV experiment used 15 deg.
  * BPP annulus d in [5 m, 3 km]: seed 001's values for the same authors' BPP (far field of
    an LTE antenna; reliable LTE tracking range); tower heights above the receiver uniform in
    [0, 50] m (macro-cell antennas 15-50 m above a receiver on the ground; 0 m gives seed 001's
    0 deg elevation).
  * sigma_URE = 2/3 sigma_URA for GPS (ADD), sigma_URE^S = sigma_URA^S, SOP b_nom = 0, GPS
    user term: the ADD dual-frequency airborne model, SOP user term 0 (araim.error_models).
  * Realizations use common random numbers (no axis is a key axis): realization i draws the
    same GPS epoch in every cell and the same towers in every cell with the same number of
    SOPs, so neighbouring cells differ by their parameters only, not by sampling noise.
"""

import collections
import functools
import hashlib
import threading
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import geometry, mc
from oaraim.araim import (
    BUDGET_SEED004_TABLE_I,
    MHSSOptions,
    Sources,
    fault_mode_rule,
    protection_levels_kernel,
    protection_levels_priors_kernel,
    required_order,
)
from oaraim.batching import jit_kernel
from oaraim.errors import gnss_variances, sop_variances
from oaraim.readers import gpstime
from oaraim.studies.base import (
    Param,
    check_bpp_annulus,
    count,
    fault_modes_param,
    in_range,
    non_negative,
    positive,
    probability,
)
from oaraim.studies.common import sky

#: seed 004 section VI, ECEF metres
ORANGE_COUNTY_ECEF_M = (-2482345.0, -4700049.0, 3513616.0)
NAV_FILE = "nav/brdc0010.22n"
#: the day of the nominal sky: that of NAV_FILE
DEFAULT_DAY = (2022, 1, 1)
#: Table I, GPS
SIGMA_URA_GPS_M = 1.0
B_NOM_GPS_M = 0.75
P_S_GPS = 1e-5
P_CONST_GPS = 1e-8
#: Table I, SOP constellation
P_CONST_SOP = 1e-4
BUDGET = BUDGET_SEED004_TABLE_I
#: seed 004's own rule (eq. 8 with grouped multiple faults): P_s^S reaches 0.1 on the Fig. 4
#: grid, where the ADD's enumeration of every pair, triple, ... of SOPs explodes
FAULT_MODES = "grouped"
#: DESIGN.md: seed 004 Fig. 4 grid
SIGMA_GRID_M = (0.5, *[float(s) for s in range(1, 26)])
P_S_GRID = tuple(float(f"{m}e{e}") for e in range(-7, -1) for m in (1, 3)) + (0.1,)


#: 'auto' (NAV_FILE, fetched if missing), 'nominal', or a navigation file
parse_nav = sky.parse_nav


#: the ``nav`` parameter of the studies that fly or drive under the 2022-01-01 sky
NAV = Param("auto", parse_nav, "GPS sky: 'auto' (nav/brdc0010.22n, fetched if missing: "
                     "`oaraim data list`), 'nominal' (built-in 24 slots), or a RINEX "
                     "navigation file")
#: Table I GPS parameters of the studies that expose them one by one (UAV, RINEX replay)
B_NOM_GPS = Param(B_NOM_GPS_M, non_negative, "GPS nominal bias (seed 004 Table I)", "m")
P_SAT_GPS = Param(P_S_GPS, probability, "GPS P_s (seed 004 Table I)")
P_CONST_GPS_PARAM = Param(P_CONST_GPS, probability, "GPS P_const (seed 004 Table I)")


def common_params():
    """Parameters every seed 004 sweep study exposes (defaults above)."""
    return {
        "nav": NAV,
        "mask_deg": Param(5.0, in_range(0.0, 89.0),
                          "GPS elevation mask (seed 004 silent; ARAIM practice 5 deg)", "deg"),
        "sky_step_s": Param(10.0, in_range(1.0, 600.0),
                            "time grid of the GPS sky table (epochs uniform over a day)", "s"),
        "d_min_m": Param(5.0, non_negative, "BPP inner radius (seed 004 silent; seed 001)", "m"),
        "d_max_m": Param(3000.0, positive, "BPP outer radius (seed 004 silent; seed 001)", "m"),
        "h_min_m": Param(0.0, in_range(-1000.0, 1000.0),
                         "tower height above the receiver, min (silent)", "m"),
        "h_max_m": Param(50.0, in_range(-1000.0, 1000.0),
                         "tower height above the receiver, max (silent)", "m"),
        "p_const_sop": Param(P_CONST_SOP, probability, "SOP constellation fault (Table I)"),
        "fault_modes": fault_modes_param(FAULT_MODES, "seed 004 eq. 8, P_s^S up to 0.1 on the "
                                         "Fig. 4 grid (max_order 2 for the ADD rules)"),
        "chunk": Param(5120, count(1024), "realizations per task and chunk file (not a result)"),
    }


check_geometry_params = check_bpp_annulus


def resolve_sky(nav):
    """(source for geometry.sky, description, is a real file): ``common.sky.resolve_sky``
    with ``NAV_FILE`` (no silent nominal fallback)."""
    return sky.resolve_sky(nav, NAV_FILE)


def day_start(source, real):
    """00:00 GPS time of the sky's day: the file's day for a real file (``resolve_sky``'s
    third value), else ``DEFAULT_DAY``."""
    if real:
        return sky.file_day_start(geometry.load_navigation(source, systems=("G",)))
    return float(gpstime.gps_seconds(*DEFAULT_DAY))


@functools.lru_cache(maxsize=4)
def gps_sky_table(nav, mask_deg, step_s):
    """The GPS sky over one day at the receiver: dict of az/el/valid ``(E, S)`` with the
    visible satellites moved to the front and S the most ever visible, plus a description."""
    source, desc, real = resolve_sky(nav)
    t0 = day_start(source, real)
    n_t = int(round(86400.0 / step_s))
    t = t0 + step_s * np.arange(n_t)
    s = geometry.sky(np.array(ORANGE_COUNTY_ECEF_M), t, source=source, mask_deg=mask_deg,
                     constellations=("gps",))
    az, el, valid = (np.asarray(x) for x in (s.az_rad, s.el_rad, s.valid))
    order = np.argsort(~valid, axis=-1, kind="stable")
    n_slots = int(valid.sum(-1).max())
    take = lambda x: np.take_along_axis(x, order, -1)[:, :n_slots]  # noqa: E731
    az, el, valid = take(az), take(el), take(valid)
    el = np.where(valid, el, np.pi / 2)  # padding rows: harmless finite values
    az = np.where(valid, az, 0.0)
    n_vis = valid.sum(-1)
    if real:
        desc = f"broadcast ephemeris {Path(source).name} ({s.sv.size} GPS)"
    return {"az_rad": az, "el_rad": el, "valid": valid, "t0_gps_s": t0, "step_s": step_s,
            "description": desc, "real_file": real, "n_visible_min": int(n_vis.min()),
            "n_visible_max": int(n_vis.max()), "n_visible_mean": float(n_vis.mean())}


@functools.lru_cache(maxsize=4)
def gps_sky_arrays(nav, mask_deg, step_s):
    """``gps_sky_table``'s az/el/valid as JAX arrays, made once per process (a sweep builds a
    kernel per cell, and warms one ahead: ~0.3 ms of host transfer each)."""
    table = gps_sky_table(nav, mask_deg, step_s)
    return {k: jnp.asarray(table[k]) for k in ("az_rad", "el_rad", "valid")}


def draw_gps(key, table_az, table_el, table_valid):
    """One realization's GPS sky: an epoch uniform over the day's table. Returns the epoch
    index and (az, el, valid) of shape (S,)."""
    e = jax.random.randint(mc.stream(key, "gps_epoch"), (), 0, table_az.shape[0])
    return e, table_az[e], table_el[e], table_valid[e]


def draw_sops(key, n_sops, d_min_m, d_max_m, h_min_m, h_max_m):
    """One realization's BPP towers (seed 004 section III-D), independent of the GPS draw."""
    return geometry.bpp_towers(mc.stream(key, "bpp_towers"), n_sops, d_min_m, d_max_m, h_min_m,
                               h_max_m)


def gps_sources(az, el, valid):
    """Table I GPS sources of a (..., S) sky (``araim.Sources``): the rows, labels 0, the
    variances of the ADD models, b_nom and P_s."""
    vi, va = gnss_variances(el, SIGMA_URA_GPS_M)
    return Sources(geometry.geometry_rows(az, el), jnp.zeros(el.shape, jnp.int32), vi, va,
                   jnp.full(el.shape, B_NOM_GPS_M), jnp.full(el.shape, P_S_GPS), valid)


def sop_sources(az, el, sigma_ura_sop_m, p_s_sop, label, valid=None):
    """SOP sources of a (..., N) draw (``araim.Sources``): one constellation ``label``,
    sigma_URE^S = sigma_URA^S, b_nom 0 (DESIGN.md); every tower valid unless ``valid``."""
    vi, va = sop_variances(jnp.full(az.shape, sigma_ura_sop_m))
    return Sources(geometry.geometry_rows(az, el), jnp.full(az.shape, label, jnp.int32), vi, va,
                   jnp.zeros(az.shape), jnp.full(az.shape, p_s_sop),
                   jnp.ones(az.shape, bool) if valid is None else valid)


def mhss(sources, p_const, max_order, fault_modes=FAULT_MODES):
    """HPL, VPL, status, order and mode count of a batch of ``Sources`` (B, L) through the
    jit-safe kernel (we are inside jit)."""
    r = protection_levels_kernel(sources, p_const, BUDGET,
                                 MHSSOptions(max_order, fault_modes=fault_mode_rule(fault_modes)))
    return r.hpl_m, r.vpl_m, r.status, r.order, r.n_modes


@functools.lru_cache(maxsize=1024)
def order_for(n_gps_slots, n_sops, p_s_sop, p_const_sop, fault_modes=FAULT_MODES):
    """Static max_order for a cell: the order the P_thresh rule needs with every GPS slot in
    view (the most GPS faults, so the worst case); the kernel still picks each geometry's own
    order up to it. Memoized: it depends on neither sigma_URA^S nor the draws, so Fig. 4's
    2,028 cells ask it 78 distinct questions (each a compiled call, ~9 ms with its host
    round trip: 18 s of the full run before)."""
    L = n_gps_slots + n_sops
    valid = np.ones((1, L), bool)
    const = np.array([[0] * n_gps_slots + [1] * n_sops])
    p_sat = np.array([[P_S_GPS] * n_gps_slots + [p_s_sop] * n_sops])
    p_const = np.array([[P_CONST_GPS, p_const_sop]])
    return int(required_order(jnp.asarray(valid), jnp.asarray(const), jnp.asarray(p_sat),
                              jnp.asarray(p_const), BUDGET, cap=2, fault_modes=fault_modes))


# ----------------------------------------------------------------------------------------------
# the cell of seed 004 Figs. 3 and 4: HPL/VPL of GPS alone and of GPS + SOPs per realization

#: a reduction is "positive"/"negative" beyond twice the 1e-3 m PL solver tolerance
TOL_M = 2e-3


class SopCell(NamedTuple):
    """The traced parameters of ``sop_kernel``'s cell: the SOPs' ISM and the BPP annulus."""

    sigma_ura_sop_m: object
    """sigma_URA^S (m)."""
    p_s_sop: jax.Array
    """(P,) the P_s^S values computed at once."""
    p_const_sop: object
    """P_const^S."""
    d_min_m: object
    """Inner radius of the annulus (m)."""
    d_max_m: object
    """Outer radius (m)."""
    h_min_m: object
    """Lowest tower height (m)."""
    h_max_m: object
    """Highest tower height (m)."""


@functools.partial(jit_kernel, static_argnames=("n_sops", "options"))
def sop_kernel(keys, table, cell: SopCell, n_sops, options):
    """HPL/VPL of GPS + n_sops SOPs per realization key (chunk,) under each P_s^S of
    ``cell.p_s_sop`` (P,): outputs (P, chunk). ``table``: the day's (az, el, valid) GPS sky
    table; ``options`` the ``araim.MHSSOptions`` (static). The geometry's fault-tolerant
    solutions are shared by the P values (``araim.protection_levels_priors_kernel``)."""
    t_az, t_el, t_valid = table

    def draw(k):
        _, az, el, v = draw_gps(k, t_az, t_el, t_valid)
        tw = draw_sops(k, n_sops, cell.d_min_m, cell.d_max_m, cell.h_min_m, cell.h_max_m)
        return az, el, v, tw.az_rad, tw.el_rad

    az, el, v, az_s, el_s = jax.vmap(draw)(keys)
    gps = gps_sources(az, el, v)
    sources = gps.concat(sop_sources(az_s, el_s, cell.sigma_ura_sop_m, 0.0, 1))
    n_sets = cell.p_s_sop.shape[0]
    p_sat = jnp.concatenate([
        jnp.broadcast_to(gps.p_sat, (n_sets,) + el.shape),
        jnp.broadcast_to(cell.p_s_sop[:, None, None], (n_sets,) + az_s.shape)], -1)
    p_const_sop = cell.p_const_sop
    p_const = jnp.broadcast_to(jnp.stack([jnp.full_like(p_const_sop, P_CONST_GPS),
                                          p_const_sop]), (n_sets, keys.shape[0], 2))
    r = protection_levels_priors_kernel(sources._replace(p_sat=p_sat), p_const, BUDGET, options)
    return {"hpl_sop_m": r.hpl_m, "vpl_sop_m": r.vpl_m, "status_sop": r.status,
            "order_sop": r.order}


@functools.partial(jit_kernel, static_argnames=("fault_modes",))
def gps_kernel(keys, t_az, t_el, t_valid, fault_modes=FAULT_MODES):
    """HPL/VPL of GPS alone per realization key (chunk,): the same in every cell."""
    epoch, az, el, v = jax.vmap(lambda k: draw_gps(k, t_az, t_el, t_valid))(keys)
    hpl, vpl, status, _, _ = mhss(gps_sources(az, el, v), jnp.array([P_CONST_GPS]), 1,
                                  fault_modes)
    return {"hpl_gps_m": hpl, "vpl_gps_m": vpl, "status_gps": status, "epoch": epoch,
            "n_gps": jnp.sum(v, -1)}


class _Memo:
    """A bounded, least-recently-used memo of NumPy results shared by a process's sweep threads
    (the lock guards the dict only: two threads may compute one entry, with the same bits)."""

    def __init__(self, size):
        self.size = size
        self.entries = collections.OrderedDict()
        self.lock = threading.Lock()

    def get(self, key, compute):
        """The entry of ``key``, from ``compute()`` (a dict of arrays) when absent."""
        with self.lock:
            hit = self.entries.get(key)
            if hit is not None:
                self.entries.move_to_end(key)
                return hit
        out = {name: np.asarray(v) for name, v in compute().items()}
        with self.lock:
            self.entries[key] = out
            while len(self.entries) > self.size:
                self.entries.popitem(last=False)
        return out


def keys_digest(keys):
    """A short hash of a chunk of realization keys: the memos' key for "the same draws"."""
    return hashlib.blake2b(np.asarray(jax.random.key_data(keys)).tobytes(),
                           digest_size=16).hexdigest()


#: GPS-only results by (sky table, keys): common random numbers make them identical in every
#: cell, so a process computes them once per chunk of keys (a pure function, memoized)
_GPS_CACHE = _Memo(64)


def _gps_args(keys, table, fault_modes):
    return keys, table["az_rad"], table["el_rad"], table["valid"], fault_modes


def gps_only(keys, table, table_id, fault_modes=FAULT_MODES):
    """``gps_kernel`` of a chunk of keys, memoized per process: with common random numbers
    every cell of a run shares it."""
    return _GPS_CACHE.get((table_id, keys_digest(keys), fault_modes),
                          lambda: gps_kernel(*_gps_args(keys, table, fault_modes)))


#: the programs ``Fig4Cell.warm`` compiled in this process
_WARMED: set = set()
_WARMED_LOCK = threading.Lock()


def compare(gps, sop):
    """Per-realization outputs of one cell from the GPS-only and GPS + SOP PLs."""
    hg, hs = gps["hpl_gps_m"], np.asarray(sop["hpl_sop_m"])
    vg, vs = gps["vpl_gps_m"], np.asarray(sop["vpl_sop_m"])
    both = np.isfinite(hg) & np.isfinite(hs)
    both_v = np.isfinite(vg) & np.isfinite(vs)
    red = np.where(both, hg - np.where(both, hs, 0.0), 0.0)
    red_v = np.where(both_v, vg - np.where(both_v, vs, 0.0), 0.0)
    return {
        "hpl_reduction_m": red, "vpl_reduction_m": red_v,
        "hpl_gps_m": np.where(both, hg, 0.0), "hpl_sop_m": np.where(both, hs, 0.0),
        "both_finite": both, "vpl_both_finite": both_v,
        "hpl_reduced": both & (red > 0.0),
        "hpl_increase_m": -red, "vpl_increase_m": -red_v,
        "hpl_raised": both & (red <= TOL_M), "vpl_raised": both_v & (red_v <= TOL_M),
        "order_2": np.asarray(sop["order_sop"]) >= 2,
        "n_gps": gps["n_gps"].astype(np.float64),
    }


#: GPS + SOP results by (cell parameters but P_s^S, its group of P_s^S values, keys): the cells
#: of one group share the group's kernel call (``Fig4Cell``)
_SOP_CACHE = _Memo(256)


def p_s_group(p_s_values, p_s, order, n_gps_slots, n_sops, p_const_sop, fault_modes):
    """The P_s^S values of a run (``p_s_values``, the grid) that share cell ``p_s``'s static
    order (``order_for``): one kernel call computes them all on the same geometries. Always
    holds ``p_s``."""
    group = tuple(float(v) for v in np.atleast_1d(p_s_values)
                  if order_for(n_gps_slots, n_sops, float(v), p_const_sop, fault_modes) == order)
    return group if p_s in group else (p_s,)


class Fig4Cell:
    """The kernel of one cell: keys (chunk,) -> per-realization outputs (NumPy). ``coords``
    gives n_sops, sigma_ura_sop_m and p_s_sop (axes, or fixed parameters).

    The GPS + SOP PLs of a chunk of keys are computed for every P_s^S of the run's grid with
    the cell's order (``p_s_group``) at once and kept for the group's other cells (common
    random numbers: they draw the same geometries), so the fault-tolerant solutions of a
    geometry are computed once per order instead of once per P_s^S value. Each value's
    results come from the same loop body of one program whatever the group
    (``araim.protection_levels_priors_kernel``): a narrowed grid gives the same bits (tested).
    """

    def __init__(self, params, coords):
        self.table = gps_sky_table(params["nav"], params["mask_deg"], params["sky_step_s"])
        self.table_id = (params["nav"], params["mask_deg"], params["sky_step_s"])
        self.jtable = gps_sky_arrays(params["nav"], params["mask_deg"], params["sky_step_s"])
        n_slots = self.table["az_rad"].shape[1]
        self.n_sops = int(coords["n_sops"])
        self.p_s = float(coords["p_s_sop"])
        self.args = (float(coords["sigma_ura_sop_m"]), params["p_const_sop"],
                     params["d_min_m"], params["d_max_m"], params["h_min_m"], params["h_max_m"])
        self.fault_modes = params["fault_modes"]
        self.max_order = order_for(n_slots, self.n_sops, self.p_s, params["p_const_sop"],
                                     self.fault_modes)
        self.group = p_s_group(params.get("p_s_sop", self.p_s), self.p_s, self.max_order,
                               n_slots, self.n_sops, params["p_const_sop"], self.fault_modes)

    def _sop_args(self, keys):
        sigma, p_const_sop, *annulus = self.args
        return (keys, (self.jtable["az_rad"], self.jtable["el_rad"], self.jtable["valid"]),
                SopCell(sigma, np.asarray(self.group), p_const_sop, *annulus), self.n_sops,
                MHSSOptions(self.max_order, fault_modes=fault_mode_rule(self.fault_modes)))

    def sop(self, keys):
        """The GPS + SOP outputs of this cell's group for ``keys``: {name: (P, chunk)}."""
        k = (self.table_id, self.n_sops, self.args, self.group, self.max_order,
             self.fault_modes, keys_digest(keys))
        return _SOP_CACHE.get(k, lambda: sop_kernel(*self._sop_args(keys)))

    def warm(self, batch_size):
        """Compile, without running, the programs of a call with ``batch_size`` keys (the
        GPS-only and this cell's GPS + SOP kernels; ``mc.sweep`` warms the cells to come
        while the chunks run). Each program once per process."""
        keys = mc.realization_keys(0, 0, 0, batch_size)
        shape = (self.table["az_rad"].shape, self.fault_modes, batch_size)
        for kernel, args, program in (
                (gps_kernel, _gps_args(keys, self.jtable, self.fault_modes), ("gps", *shape)),
                (sop_kernel, self._sop_args(keys),
                 ("sop", *shape, len(self.group), self.n_sops, self.max_order))):
            with _WARMED_LOCK:
                if program in _WARMED:
                    continue
                _WARMED.add(program)
            kernel.jitted.lower(*args).compile()

    def __call__(self, keys):
        gps = gps_only(keys, self.jtable, self.table_id, self.fault_modes)
        j = self.group.index(self.p_s)
        return compare(gps, {name: v[j] for name, v in self.sop(keys).items()})
