"""Snapshot replay: per-epoch WNLS with chi-square slope RAIM and with ARAIM / OARAIM
solution separation, each with fault exclusion, and the position errors against a truth.

Source-agnostic: an epoch is a set of L ranging sources (GNSS satellites, terrestrial SOP
transmitters) with measured pseudoranges, transmitter positions, known corrections, nominal
error variances, a validity mask and a clock group (GPS 0, Galileo 1, SOP constellations after
them). GNSS specifics (transmit time, Sagnac rotation, satellite clocks, atmosphere) are the
caller's: it passes transmitter positions already in the frame of the reception time and the
corrections it knows (``correction_m`` is *added* to the pseudorange). SOP towers are simply
transmitters with fixed positions and their own clock group.

Per epoch (all batched over the T epochs, fixed shapes, no NaN; a failure is ``inf`` plus a
``Status``):

1. ``araim.wnls``: z = pseudorange + correction = |x - r_l| + c dt_k(l), weights C_int^-1 (the
   ADD weights every projector with C_int^-1), one clock per group.
2. Geometry rows in the local ENU frame of the solution (``geometry.geometry_rows``
   convention, -line of sight), residuals y = z - h(x_hat).
3. Slope RAIM (seed 001 section 3.1, generalised to clock groups): test statistic WSSE against
   the chi-square threshold T(P_FA, dof), dof = n - 3 - C_used; HPL = max_i slope_i
   sqrt(lambda_det(P_FA, P_MD, dof)) with slope_i = sqrt(B_Ei^2 + B_Ni^2) sigma_i / sqrt(S_ii);
   VPL likewise with |B_Ui|. With one clock group this is exactly ``araim.slope_hpl`` (tested).
   Exclusion: on detection, every single-source exclusion is re-solved by one weighted
   least-squares step from the all-in-view solution on the kept rows (``_subset_fits``; the
   linearisation error |dx|^2 / 2r is ~1e-6 m for satellites, decimetres only for a tower
   closer than ~50 m when the exclusion moves the solution by metres; ``detect_and_exclude``
   linearises the same way). Candidates whose own test passes are acceptable and the one with the
   smallest WSSE is kept (ties: lowest index), its slope HPL/VPL reported; none acceptable ->
   ``Status.EXCLUSION_FAILED`` and inf PLs.
4. MHSS (seed 004): ``araim.protection_levels`` (all-in-view PLs) and ``araim.detect_and_exclude``
   with the residuals y (detection by solution separation, exclusion over the monitored fault
   modes, PLs of the solution kept).
5. Errors in the ENU frame at the truth: HPE = |(e, n)|, VPE = |u|, for the all-in-view
   solution and for each monitor's kept solution. Misleading information = HPE > HPL (inf
   never counts).

Monitors are objects in a table (``MONITORS``): each has a ``name``, says whether it needs
the MHSS fault-mode order (``needs_order``), and has one method, ``run(inputs, config) ->
MonitorReplay``, where ``inputs`` is the ``ReplayInputs`` every monitor sees (the all-in-view
solution, its rows and the epoch's data) and ``config`` the checked ``ReplayConfig`` (its
``max_order`` resolved). Slope RAIM (``SlopeMonitor``) and the MHSS (``MhssMonitor``) are the
first two; ``register_monitor`` adds another, which ``ReplayConfig(monitors=(..., name))``
then runs (docs/contributing.md, "A new monitor").

Frames: ``frame="ecef"`` (default): positions in WGS-84 ECEF, ENU axes at the solution (rows)
and at the truth (errors). ``frame="enu"``: positions already in one local ENU frame (a
simulation), the axes are the frame's own.
"""

from collections.abc import Sequence
from functools import partial
from typing import NamedTuple, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Real

from oaraim.araim import linalg
from oaraim.araim.budget import BUDGET_SEED004_TABLE_I, IntegrityBudget
from oaraim.araim.chi2 import detection_threshold, lambda_det_table
from oaraim.araim.fde import detect_and_exclude
from oaraim.araim.mhss import MHSSOptions, Sources, protection_levels, required_order
from oaraim.araim.status import Status
from oaraim.araim.validate import check_probability
from oaraim.araim.wnls import WNLSOptions, WNLSResult, wnls

#: chi-square slope RAIM defaults (seed 001 is silent; the values of our seed 001 studies)
DEFAULT_P_FA = 1e-5
DEFAULT_P_MD = 1e-3


class MonitorReplay(NamedTuple):
    """One integrity monitor over the epochs (slope RAIM or MHSS)."""

    hpl_all_in_view_m: jax.Array
    """(T,) HPL of the all-in-view solution, before any exclusion (m)."""
    vpl_all_in_view_m: jax.Array
    """(T,) VPL of the all-in-view solution (m)."""
    detected: jax.Array
    """(T,) bool: the all-in-view test failed."""
    statistic: jax.Array
    """(T,) the test statistic: slope, WSSE / T(P_FA, dof); MHSS, the largest tau (detected
    if > 1)."""
    excluded: jax.Array
    """(T, L) bool: the sources excluded."""
    hpl_m: jax.Array
    """(T,) HPL of the solution kept (the all-in-view one when nothing was detected), m."""
    vpl_m: jax.Array
    """(T,) VPL of the solution kept, m."""
    position_m: jax.Array
    """(T, 3) the solution kept, in the frame of the inputs (inf where exclusion failed)."""
    error_enu_m: jax.Array
    """(T, 3) its error in the ENU frame at the truth, m."""
    hpe_m: jax.Array
    """(T,) its horizontal position error |(e, n)|, m (inf where it failed)."""
    vpe_m: jax.Array
    """(T,) its vertical position error |u|, m (inf where it failed)."""
    status: jax.Array
    """(T,) int8 ``Status`` of the kept PLs."""
    emt_m: jax.Array | None = None
    """(T,) MHSS only: effective monitor threshold of the kept solution, m (inf where none)."""
    sigma_acc_u_m: jax.Array | None = None
    """(T,) MHSS only: vertical accuracy sigma of the kept solution, m (inf where none)."""


class ReplayResult(NamedTuple):
    """What ``replay`` returns: the all-in-view solution of every epoch, its errors against
    the truth and each integrity monitor asked for."""

    wnls: WNLSResult
    """The all-in-view WNLS solution (``position_m`` in the frame of the inputs)."""
    g_enu: jax.Array
    """(T, L, 3) geometry rows in the ENU frame at the solution (0 for unused sources)."""
    used: jax.Array
    """(T, L) bool: the sources used (valid, and the epoch solvable)."""
    error_enu_m: jax.Array
    """(T, 3) all-in-view position error in the ENU frame at the truth, m."""
    hpe_m: jax.Array
    """(T,) all-in-view horizontal position error, m (inf where the WNLS failed)."""
    vpe_m: jax.Array
    """(T,) all-in-view vertical position error, m (inf where the WNLS failed)."""
    slope: MonitorReplay | None
    """Chi-square slope RAIM (step 3 of the module docstring); None if not in ``monitors``."""
    mhss: MonitorReplay | None
    """MHSS solution separation (step 4); None if not in ``monitors``."""
    max_order: int
    """The MHSS fault-mode order used (0 without the MHSS)."""
    monitors: dict | None = None
    """Every monitor run, by name (``MONITORS``): slope and mhss (also the fields above) and
    any registered one asked for."""


# --------------------------------------------------------------------------- kernels


def _enu_axes(x, frame_ecef):
    """(..., 3, 3) ENU rotation at ECEF points x, or the identity in an ENU frame."""
    if not frame_ecef:
        return jnp.broadcast_to(jnp.eye(3), x.shape[:-1] + (3, 3))
    from oaraim.geometry import ecef_to_geodetic, enu_rotation

    lat, lon, _ = ecef_to_geodetic(x)
    return enu_rotation(lat, lon)


def _rows(x, tx, used, frame_ecef):
    """Geometry rows R (x - r_l) / |x - r_l| (= -line of sight in ENU), 0 where not used."""
    r = _enu_axes(x, frame_ecef)
    d = x[..., None, :] - jnp.where(used[..., None], tx, 0.0)
    rng = jnp.linalg.norm(d, axis=-1)
    u = d / jnp.where(rng > 0, rng, 1.0)[..., None]
    g = jnp.einsum("...ij,...lj->...li", r, u)
    return jnp.where(used[..., None], g, 0.0)


def _errors(x, truth, frame_ecef, ok):
    r = _enu_axes(truth, frame_ecef)
    e = jnp.einsum("...ij,...j->...i", r, x - truth)
    e = jnp.where(ok[..., None] & jnp.all(jnp.isfinite(x), -1, keepdims=True), e, jnp.inf)
    hpe = jnp.where(ok, jnp.hypot(e[..., 0], e[..., 1]), jnp.inf)
    vpe = jnp.where(ok, jnp.abs(e[..., 2]), jnp.inf)
    return e, hpe, vpe


def group_slopes(g, sigma_m, valid, clock_index, n_clocks):
    """Horizontal and vertical RAIM slopes with one clock column per group (seed 001 section
    3.1 generalised): (slope_h (..., L), slope_v (..., L), dof (...), status (...)).

    With ``n_clocks == 1`` the horizontal slopes are those of ``araim.slopes``. A group without
    a valid source loses its clock column (unit diagonal), as in ``araim.wnls``.
    """
    from oaraim.araim.slopes import REDUNDANCY_TOLERANCE, masked_geometry

    g, w = masked_geometry(g, sigma_m, valid)
    member = valid[..., :, None] & (clock_index[..., :, None] == jnp.arange(n_clocks))
    present = jnp.any(member, axis=-2)  # (..., C)
    cols = [g[..., 0], g[..., 1], g[..., 2]] + [member[..., c].astype(g.dtype)
                                                for c in range(n_clocks)]
    n = linalg.normal_entries(cols, w)
    for c in range(n_clocks):
        n[3 + c][3 + c] = n[3 + c][3 + c] + jnp.where(present[..., c], 0.0, 1.0)
    lower, nonsingular = linalg.cholesky(n)
    x = linalg.cholesky_solve(linalg.expand_last(lower), cols)  # (P h_l)_k, each (..., L)
    s_ii = 1.0 - w * sum(cols[k] * x[k] for k in range(len(cols)))
    redundant = s_ii > REDUNDANCY_TOLERANCE
    s_safe = jnp.where(redundant, s_ii, 1.0)
    slope_h = jnp.sqrt(w * (x[0] ** 2 + x[1] ** 2) / s_safe)
    slope_v = jnp.sqrt(w * x[2] ** 2 / s_safe)
    dof = jnp.sum(valid, axis=-1) - 3 - jnp.sum(present, axis=-1)
    status = jnp.where(
        dof < 1, Status.TOO_FEW_SOURCES,
        jnp.where(~nonsingular, Status.SINGULAR_GEOMETRY,
                  jnp.where(jnp.any(valid & ~redundant, axis=-1), Status.UNDETECTABLE_FAULT,
                            Status.OK))).astype(jnp.int8)
    fail = (status != Status.OK)[..., None]
    slope_h = jnp.where(valid, jnp.where(fail | ~redundant, jnp.inf, slope_h), 0.0)
    slope_v = jnp.where(valid, jnp.where(fail | ~redundant, jnp.inf, slope_v), 0.0)
    return slope_h, slope_v, dof, status


def _slope_pls(g, sigma, valid, clock_index, n_clocks, lam_table):
    sh, sv, dof, status = group_slopes(g, sigma, valid, clock_index, n_clocks)
    ok = status == Status.OK
    lam = lam_table[jnp.clip(dof, 0, lam_table.shape[0] - 1)]
    k = jnp.sqrt(jnp.where(ok, lam, 1.0))
    hpl = jnp.where(ok, jnp.max(sh, axis=-1) * k, jnp.inf)
    vpl = jnp.where(ok, jnp.max(sv, axis=-1) * k, jnp.inf)
    return hpl, vpl, dof, status


def _subset_fits(g, y, sigma, keep, clock_index, n_clocks):
    """Linearised weighted fits of the residuals y on the kept rows: (ENU + clock correction
    list, WSSE, nonsingular). One Gauss-Newton step from the converged all-in-view solution:
    removing a source moves the solution by metres, where the range nonlinearity at GNSS
    distances (|dx|^2 / 2 r ~ 1e-6 m) is negligible, so this is the subset's WNLS solution."""
    from oaraim.araim.slopes import masked_geometry

    g, w = masked_geometry(g, sigma, keep)
    member = keep[..., :, None] & (clock_index[..., :, None] == jnp.arange(n_clocks))
    present = jnp.any(member, axis=-2)
    cols = [g[..., 0], g[..., 1], g[..., 2]] + [member[..., c].astype(g.dtype)
                                                for c in range(n_clocks)]
    n = linalg.normal_entries(cols, w)
    for c in range(n_clocks):
        n[3 + c][3 + c] = n[3 + c][3 + c] + jnp.where(present[..., c], 0.0, 1.0)
    lower, ok = linalg.cholesky(n)
    yk = jnp.where(keep, y, 0.0)
    dx = linalg.cholesky_solve(lower, [jnp.sum(w * c * yk, axis=-1) for c in cols])
    r = yk - sum(dx[a][..., None] * cols[a] for a in range(len(cols)))
    return dx, jnp.where(ok, jnp.sum(w * r**2, axis=-1), jnp.inf), ok


@partial(jax.jit, static_argnames=("n_clocks", "frame_ecef"))
def _slope_raim(g, y, sigma, valid, clock_index, sol_x, wsse, used_epoch, truth, lam_table,
                thr_table, n_clocks, frame_ecef):
    """Chi-square slope RAIM with single-source exclusion, batched over epochs (T, L)."""
    n_l = y.shape[-1]
    hpl0, vpl0, dof0, st0 = _slope_pls(g, sigma, valid, clock_index, n_clocks, lam_table)
    thr0 = thr_table[jnp.clip(dof0, 0, thr_table.shape[0] - 1)]
    statistic = jnp.where(st0 == Status.OK, wsse / thr0, 0.0)
    detected = used_epoch & (dof0 >= 1) & (wsse > thr0)
    st0 = jnp.where(used_epoch, st0, Status.TOO_FEW_SOURCES).astype(jnp.int8)
    hpl0 = jnp.where(used_epoch, hpl0, jnp.inf)
    vpl0 = jnp.where(used_epoch, vpl0, jnp.inf)

    # leave-one-out candidates: batch (T, L) over the excluded source
    keep = valid[..., None, :] & ~jnp.eye(n_l, dtype=bool)  # (T, L, L)
    bc = lambda a: jnp.broadcast_to(a[..., None, :], a.shape[:-1] + (n_l,) + a.shape[-1:])  # noqa: E731
    g_b = jnp.broadcast_to(g[..., None, :, :], keep.shape + (3,))
    dx, wsse_s, ok_s = _subset_fits(g_b, bc(y), bc(sigma), keep, bc(clock_index), n_clocks)
    hpl_s, vpl_s, dof_s, st_s = _slope_pls(g_b, bc(sigma), keep, bc(clock_index), n_clocks,
                                           lam_table)
    thr_s = thr_table[jnp.clip(dof_s, 0, thr_table.shape[0] - 1)]
    acceptable = valid & ok_s & (st_s == Status.OK) & (dof_s >= 1) & (wsse_s <= thr_s)
    score = jnp.where(acceptable, wsse_s, jnp.inf)
    best = jnp.argmin(score, axis=-1)  # (T,)
    found = jnp.any(acceptable, axis=-1)

    def pick(a):  # (T, L, ...) -> (T, ...) at the chosen candidate
        idx = best.reshape(best.shape + (1,) * (a.ndim - best.ndim))
        return jnp.take_along_axis(a, idx, axis=best.ndim)[(slice(None),) * best.ndim + (0,)]

    excl = detected & found
    fail = detected & ~found
    hpl = jnp.where(excl, pick(hpl_s), jnp.where(fail, jnp.inf, hpl0))
    vpl = jnp.where(excl, pick(vpl_s), jnp.where(fail, jnp.inf, vpl0))
    status = jnp.where(excl, pick(st_s), jnp.where(fail, Status.EXCLUSION_FAILED, st0))
    d_enu = jnp.stack([pick(dx[0]), pick(dx[1]), pick(dx[2])], -1)
    d_ecef = jnp.einsum("...ji,...j->...i", _enu_axes(sol_x, frame_ecef), d_enu)
    pos = jnp.where(excl[..., None], sol_x + d_ecef,
                    jnp.where(fail[..., None], jnp.inf, sol_x))
    excluded = excl[..., None] & (jnp.arange(n_l) == best[..., None])
    err, hpe, vpe = _errors(pos, truth, frame_ecef, used_epoch & ~fail)
    return MonitorReplay(hpl0, vpl0, detected, statistic, excluded, hpl, vpl, pos, err, hpe, vpe,
                         status.astype(jnp.int8))


@partial(jax.jit, static_argnames=("frame_ecef",))
def _solution_terms(x, tx, valid, wnls_status, truth, frame_ecef):
    used_epoch = wnls_status == Status.OK
    used = valid & used_epoch[..., None]
    g = _rows(x, tx, used, frame_ecef)
    err, hpe, vpe = _errors(x, truth, frame_ecef, used_epoch)
    return used_epoch, used, g, err, hpe, vpe


@partial(jax.jit, static_argnames=("frame_ecef",))
def _mhss_terms(x, correction_enu, ok, truth, frame_ecef):
    r = _enu_axes(x, frame_ecef)
    fin = jnp.all(jnp.isfinite(correction_enu), -1)
    dx = jnp.einsum("...ji,...j->...i", r, jnp.where(fin[..., None], correction_enu, 0.0))
    pos = jnp.where((ok & fin)[..., None], x + dx, jnp.inf)
    err, hpe, vpe = _errors(pos, truth, frame_ecef, ok & fin)
    return pos, err, hpe, vpe


# --------------------------------------------------------------------------- public


class ReplayConfig(NamedTuple):
    """How a snapshot replay solves and monitors (everything that is not per-epoch data).

    ``replay(..., config=ReplayConfig(monitors=("slope",), p_fa=1e-5))``; ``_replace`` gives a
    variant. Checked when the replay starts (a bad value raises ``ValueError`` naming it)."""

    monitors: tuple = ("slope", "mhss")
    """Integrity monitors to run, by their name in ``MONITORS``: "slope" (seed 001 chi-square
    slope RAIM), "mhss" (seed 004 / ADD MHSS with exclusion) or one added by
    ``register_monitor``; slope or mhss left out is ``None`` in the result (the MHSS compiles
    for tens of seconds per (L, C) shape on a 2-core CPU, slope RAIM in seconds)."""
    budget: IntegrityBudget = BUDGET_SEED004_TABLE_I
    """MHSS integrity budget (default seed 004 Table I by its symbols)."""
    fault_modes: object = None
    """MHSS fault-mode convention, a name or ``araim.FaultModeRule`` (default ``add-v4.2``,
    the current ADD; ``araim.protection_levels``)."""
    max_order: int | None = None
    """MHSS fault-mode order; None picks the smallest meeting P_thresh over the batch (give it
    to make an epoch's result independent of its batch)."""
    p_fa: float = DEFAULT_P_FA
    """Slope RAIM false-alarm probability (default 1e-5, as our seed 001 studies)."""
    p_md: float = DEFAULT_P_MD
    """Slope RAIM missed-detection probability (default 1e-3)."""
    n_iter: int = 10
    """Gauss-Newton iterations of the WNLS (static)."""
    frame: str = "ecef"
    """"ecef" or "enu": the frame of the transmitter and truth positions (module docstring)."""


#: the default configuration: slope RAIM and MHSS, seed 004 Table I budget, ADD v4.2 modes
DEFAULT_REPLAY = ReplayConfig()


#: a per-source input of ``replay``: (T, L) or anything that broadcasts to it
_PerSource = Real[ArrayLike, "*#t #L"] | Real[ArrayLike, ""]


class ReplaySources(NamedTuple):
    """What the receiver of ``replay`` assumes of each source: arrays (T, L) or anything
    that broadcasts to them."""

    var_int_m2: object
    """(T, L) nominal error VARIANCES for integrity (the ADD's C_int, m^2;
    ``araim.error_models``). WNLS and slope RAIM weight with C_int^-1."""
    var_acc_m2: object
    """(T, L) nominal error variances for accuracy and continuity (C_acc, m^2)."""
    valid: object
    """(T, L) bool: sources used (observed, healthy, above the mask, not padding)."""
    constellation: object = None
    """(T, L) clock groups 0..C-1 (None: all 0); C = len(p_const)."""
    p_sat: object = 1e-5
    """P_s per source (Table I GPS: 1e-5)."""
    b_nom_m: object = 0.75
    """b_nom per source, m (Table I GPS: 0.75 m)."""
    slope_sigma_m: object = None
    """(T, L) sigmas of slope RAIM, m; None: sqrt(var_int_m2)."""


def replay(pseudorange_m: Real[ArrayLike, "T L"], tx_pos_m: Real[ArrayLike, "*#t #L 3"],
           sources: ReplaySources, truth_m: Real[ArrayLike, "*#t 3"],
           p_const: Real[ArrayLike, "*#t C"] | Sequence[float] = (1e-8,), *,
           correction_m: _PerSource = 0.0,
           x0_m: Real[ArrayLike, "*#t state"] | None = None,
           config: ReplayConfig = DEFAULT_REPLAY) -> ReplayResult:
    """Snapshot replay of T epochs of L sources (module docstring).

    Args:
      pseudorange_m: (T, L) measured pseudoranges, metres (anything where not valid).
      tx_pos_m: (T, L, 3) transmitter positions in the frame of the reception time (GNSS:
        broadcast position at transmit time, Sagnac-rotated; SOP: the tower).
      sources: ``ReplaySources``: the C_int and C_acc variances, ``valid``, the clock groups,
        P_s, b_nom and the slope RAIM sigmas of each source.
      truth_m: (3,) or (T, 3) true receiver position (same frame).
      p_const: (C,) P_const per group (seed 004 Table I: GPS 1e-8, SOP 1e-4).
      correction_m: (T, L) known corrections added to the pseudorange (GNSS: + c (dt_sv -
        T_GD) - iono - tropo).
      x0_m: (3,) or (T, 3) WNLS start (default the frame origin: the Earth's centre converges
        for GNSS; give a nearby point for SOP-only epochs).
      config: ``ReplayConfig``: monitors, MHSS budget, fault modes and order, slope RAIM
        P_FA / P_MD, WNLS iterations, frame.

    Returns:
      ``ReplayResult``; every PL and error is finite or inf, never NaN.
    """
    if not isinstance(config, ReplayConfig):
        raise ValueError(f"config must be an araim.snapshot.ReplayConfig, got "
                         f"{type(config).__name__}")
    if not isinstance(sources, ReplaySources):
        raise ValueError(f"sources must be an araim.snapshot.ReplaySources, got "
                         f"{type(sources).__name__}")
    var_int_m2, var_acc_m2, valid, constellation, p_sat, b_nom_m, slope_sigma_m = sources
    monitors, budget, fault_modes = config.monitors, config.budget, config.fault_modes
    max_order, p_fa, p_md = config.max_order, config.p_fa, config.p_md
    n_iter, frame = config.n_iter, config.frame
    bad = set(monitors) - set(MONITORS)
    if bad or not monitors:
        raise ValueError(f"monitors must be a non-empty subset of {tuple(MONITORS)!r} (others "
                         f"are added with araim.snapshot.register_monitor), got "
                         f"{tuple(monitors)!r}")
    if frame not in ("ecef", "enu"):
        raise ValueError(f"frame must be 'ecef' or 'enu', got {frame!r}")
    if not isinstance(budget, IntegrityBudget):
        raise ValueError("budget must be an araim.IntegrityBudget")
    p_fa = check_probability("p_fa", p_fa)
    p_md = check_probability("p_md", p_md)
    frame_ecef = frame == "ecef"
    pr = np.asarray(pseudorange_m, np.float64)
    if pr.ndim != 2:
        raise ValueError(f"pseudorange_m must have shape (T, L), got {pr.shape}")
    shape = pr.shape
    tx = np.broadcast_to(np.asarray(tx_pos_m, np.float64), shape + (3,))
    valid = np.broadcast_to(np.asarray(valid, bool), shape)
    corr = np.broadcast_to(np.asarray(correction_m, np.float64), shape)
    z = np.where(valid, pr + corr, 0.0)
    var_int = np.broadcast_to(np.asarray(var_int_m2, np.float64), shape)
    var_acc = np.broadcast_to(np.asarray(var_acc_m2, np.float64), shape)
    for name, v in (("var_int_m2", var_int), ("var_acc_m2", var_acc)):
        bad = valid & ~(np.isfinite(v) & (v > 0))
        if bad.any():
            raise ValueError(f"{name} of a valid source must be finite and > 0 (m^2), got "
                             f"{float(v[bad][0])!r}")
    if not np.all(np.isfinite(np.where(valid, z, 0.0))) or not np.all(
            np.isfinite(np.where(valid[..., None], tx, 0.0))):
        raise ValueError("pseudorange_m + correction_m and tx_pos_m must be finite where valid")
    p_const = np.asarray(p_const, np.float64)
    n_clocks = int(p_const.shape[-1])
    cons = (np.zeros(shape, np.int32) if constellation is None
            else np.broadcast_to(np.asarray(constellation, np.int32), shape))
    if np.any(valid & ((cons < 0) | (cons >= n_clocks))):
        raise ValueError(f"constellation labels must lie in 0..{n_clocks - 1} "
                         f"(p_const has {n_clocks} entries)")
    sigma = (np.sqrt(np.where(valid, var_int, 1.0)) if slope_sigma_m is None
             else np.broadcast_to(np.asarray(slope_sigma_m, np.float64), shape))
    truth = np.broadcast_to(np.asarray(truth_m, np.float64), shape[:1] + (3,))
    if not np.all(np.isfinite(truth)):
        raise ValueError("truth_m must be finite")

    sol = wnls(z, tx, np.sqrt(np.where(valid, var_int, 1.0)), x0_m=x0_m, valid=valid,
               clock_index=cons, options=WNLSOptions(n_clocks, n_iter))
    used_epoch, used, g, err, hpe, vpe = _solution_terms(sol.position_m, tx, valid, sol.status,
                                                         truth, frame_ecef)

    if max_order is None and any(MONITORS[name].needs_order for name in monitors):
        pc0 = np.broadcast_to(p_const, shape[:1] + (n_clocks,))
        max_order = required_order(used, jnp.asarray(cons), jnp.asarray(
            np.broadcast_to(np.asarray(p_sat, np.float64), shape)), jnp.asarray(pc0),
            budget, fault_modes=fault_modes)
    inputs = ReplayInputs(sol, g, used, used_epoch, cons, sigma, var_int, var_acc, p_sat,
                          b_nom_m, p_const, truth, frame_ecef, err, hpe, vpe)
    checked = config._replace(p_fa=p_fa, p_md=p_md,
                              max_order=None if max_order is None else int(max_order))
    runs = {name: MONITORS[name].run(inputs, checked) for name in monitors}
    return ReplayResult(sol, g, used, err, hpe, vpe, runs.get("slope"), runs.get("mhss"),
                        0 if max_order is None else int(max_order), runs)


class ReplayInputs(NamedTuple):
    """What every replay monitor sees (host arrays, T epochs of L sources): the all-in-view
    solution and the epoch's data, as ``replay`` checked them."""

    sol: WNLSResult
    """The all-in-view WNLS solution (``residual_m`` (T, L), ``position_m`` (T, 3))."""
    g_enu: jax.Array
    """(T, L, 3) geometry rows in the ENU frame at the solution (0 for unused sources)."""
    used: jax.Array
    """(T, L) bool: the sources used (valid, and the epoch solvable)."""
    used_epoch: jax.Array
    """(T,) bool: the epoch's WNLS converged (``Status.OK``)."""
    constellation: np.ndarray
    """(T, L) int32 clock groups 0..C-1."""
    sigma_m: np.ndarray
    """(T, L) slope RAIM sigmas, m (``slope_sigma_m`` or sqrt(var_int_m2))."""
    var_int_m2: np.ndarray
    """(T, L) integrity variances, m^2."""
    var_acc_m2: np.ndarray
    """(T, L) accuracy variances, m^2."""
    p_sat: object
    """P_s per source, broadcastable to (T, L)."""
    b_nom_m: object
    """b_nom per source, m, broadcastable to (T, L)."""
    p_const: np.ndarray
    """(C,) P_const per clock group."""
    truth_m: np.ndarray
    """(T, 3) true receiver position, frame of the inputs."""
    frame_ecef: bool
    """Whether positions are ECEF (else one local ENU frame)."""
    error_enu_m: jax.Array
    """(T, 3) the all-in-view solution's error in the ENU frame at the truth, m (inf where
    the WNLS failed): a monitor that keeps that solution reports it as its own."""
    hpe_m: jax.Array
    """(T,) its horizontal error, m."""
    vpe_m: jax.Array
    """(T,) its vertical error, m."""


@runtime_checkable
class Monitor(Protocol):
    """A replay monitor: what ``register_monitor`` takes."""

    name: str
    """Its key in ``MONITORS`` and in ``ReplayConfig.monitors``; metrics use it as suffix."""
    needs_order: bool
    """Whether it reads ``config.max_order`` (then ``replay`` resolves a None order)."""

    def run(self, inputs: ReplayInputs, config: ReplayConfig) -> MonitorReplay:
        """The monitor over the T epochs: one ``MonitorReplay``, finite or inf, no NaN."""


class SlopeMonitor(NamedTuple):
    """Chi-square slope RAIM with single-source exclusion (module docstring, step 3)."""

    name: str = "slope"
    needs_order: bool = False

    def run(self, inputs: ReplayInputs, config: ReplayConfig) -> MonitorReplay:
        """Slope RAIM at ``config.p_fa`` / ``config.p_md``."""
        i = inputs
        return _slope_monitor(i.sol, i.g_enu, i.sigma_m, i.used, i.constellation, i.used_epoch,
                              i.truth_m, config.p_fa, config.p_md, int(i.p_const.shape[-1]),
                              i.frame_ecef)


class MhssMonitor(NamedTuple):
    """MHSS all-in-view PLs, detection and exclusion with the residuals (step 4)."""

    name: str = "mhss"
    needs_order: bool = True

    def run(self, inputs: ReplayInputs, config: ReplayConfig) -> MonitorReplay:
        """The MHSS under ``config.budget``, ``fault_modes`` and ``max_order``."""
        i = inputs
        return _mhss_monitor(i.sol, i.g_enu, i.used, i.constellation, i.used_epoch, i.truth_m,
                             i.var_int_m2, i.var_acc_m2, i.p_sat, i.b_nom_m, i.p_const,
                             config.budget, int(config.max_order), i.frame_ecef,
                             config.fault_modes)


#: name -> monitor, in the order ``replay_metrics`` reports them after mhss and slope
MONITORS: dict = {}


def register_monitor(monitor: Monitor) -> Monitor:
    """Add ``monitor`` to ``MONITORS`` under ``monitor.name`` (returned, so it can decorate
    an instance's construction). A name already taken is refused: remove it from ``MONITORS``
    first to replace it."""
    name = getattr(monitor, "name", None)
    if not isinstance(name, str) or not name or not callable(getattr(monitor, "run", None)):
        raise ValueError("a monitor needs a non-empty str name and a run(inputs, config) "
                         f"method, got {monitor!r}")
    if name in MONITORS:
        raise ValueError(f"a monitor named {name!r} is registered already "
                         f"({MONITORS[name]!r}); pick another name")
    if not isinstance(getattr(monitor, "needs_order", None), bool):
        raise ValueError(f"monitor {name!r} must say needs_order (True or False)")
    MONITORS[name] = monitor
    return monitor


register_monitor(SlopeMonitor())
register_monitor(MhssMonitor())


def _slope_monitor(sol, g, sigma, used, cons, used_epoch, truth, p_fa, p_md, n_clocks,
                   frame_ecef):
    """Chi-square slope RAIM with exclusion (module docstring, step 3)."""
    shape = used.shape
    max_dof = max(1, shape[1] - 3)
    lam = jnp.asarray(lambda_det_table(p_fa, p_md, max_dof))
    thr = jnp.asarray([np.inf] + [detection_threshold(p_fa, d) for d in range(1, max_dof + 1)])
    return _slope_raim(g, sol.residual_m, jnp.asarray(sigma), used, jnp.asarray(cons),
                       sol.position_m, sol.wsse, used_epoch, jnp.asarray(truth), lam, thr,
                       n_clocks=n_clocks, frame_ecef=frame_ecef)


def _mhss_monitor(sol, g, used, cons, used_epoch, truth, var_int, var_acc, p_sat, b_nom_m,
                  p_const, budget, max_order, frame_ecef, fault_modes=None):
    """MHSS all-in-view PLs, detection and exclusion with the residuals (step 4)."""
    shape = used.shape
    n_clocks = int(p_const.shape[-1])
    p_sat_a = np.broadcast_to(np.asarray(p_sat, np.float64), shape)
    b_nom = np.broadcast_to(np.asarray(b_nom_m, np.float64), shape)
    var_int_u = np.where(np.asarray(used), var_int, 1.0)
    var_acc_u = np.where(np.asarray(used), var_acc, 1.0)
    pc = np.broadcast_to(p_const, shape[:1] + (n_clocks,))
    sources = Sources(g, cons, var_int_u, var_acc_u, b_nom, p_sat_a, used)
    options = MHSSOptions(max_order, fault_modes=fault_modes)
    pl = protection_levels(sources, pc, budget, options)
    fde = detect_and_exclude(sources, pc, budget, sol.residual_m, options)
    pos, m_err, m_hpe, m_vpe = _mhss_terms(sol.position_m, fde.position_m, used_epoch, truth,
                                           frame_ecef)
    sep_tau = jnp.max(jnp.where(jnp.isfinite(fde.tau), fde.tau, 0.0), axis=(-2, -1))
    ok_fde = used_epoch & (fde.pl.status == Status.OK)
    mhss = MonitorReplay(
        jnp.where(used_epoch, pl.hpl_m, jnp.inf), jnp.where(used_epoch, pl.vpl_m, jnp.inf),
        fde.detected & used_epoch, sep_tau, fde.excluded & used,
        jnp.where(ok_fde, fde.pl.hpl_m, jnp.inf), jnp.where(ok_fde, fde.pl.vpl_m, jnp.inf),
        pos, m_err, m_hpe, m_vpe,
        jnp.where(used_epoch, fde.pl.status, sol.status).astype(jnp.int8),
        jnp.where(ok_fde, fde.pl.emt_m, jnp.inf), jnp.where(ok_fde, fde.pl.sigma_acc_u_m, jnp.inf))
    return mhss


def _median(x):
    x = np.asarray(x, np.float64)
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else float("inf")


def _max(x):
    x = np.asarray(x, np.float64)
    x = x[np.isfinite(x)]
    return float(np.max(x)) if x.size else float("inf")


def replay_metrics(result: ReplayResult) -> dict:
    """Summary numbers of a replay: medians and maxima over the epochs where the quantity is
    finite (the shares of finite PLs are given), misleading-information counts (HPE > HPL with
    both finite) per monitor, detections and exclusions.

    ``hpl_median_m`` / ``vpl_median_m`` are the MHSS (ARAIM) PLs of the solution kept; the
    slope-RAIM ones are ``hpl_slope_median_m`` / ``vpl_slope_median_m``; ``hpe_*`` is the
    all-in-view WNLS error.
    """
    n = int(np.asarray(result.hpe_m).shape[0])
    out = {
        "epochs": n,
        "epochs_solved": int(np.sum(np.isfinite(result.hpe_m))),
        "sources_used_median": float(np.median(np.sum(np.asarray(result.used), -1))),
        "hpe_median_m": _median(result.hpe_m), "hpe_max_m": _max(result.hpe_m),
        "hpe_95_m": (float(np.percentile(np.asarray(result.hpe_m)[np.isfinite(result.hpe_m)],
                                         95)) if np.isfinite(result.hpe_m).any()
                     else float("inf")),
        "vpe_median_m": _median(result.vpe_m), "vpe_max_m": _max(result.vpe_m),
        "mhss_max_order": result.max_order,
    }
    runs = dict(result.monitors or {})
    runs.update({k: v for k, v in (("mhss", result.mhss), ("slope", result.slope))
                 if v is not None})
    order = ["mhss", "slope"] + [k for k in runs if k not in ("mhss", "slope")]
    for name in order:
        m = runs.get(name)
        if m is None:
            continue
        hpl, vpl = np.asarray(m.hpl_m), np.asarray(m.vpl_m)
        hpe, vpe = np.asarray(m.hpe_m), np.asarray(m.vpe_m)
        fin_h, fin_v = np.isfinite(hpl), np.isfinite(vpl)
        out[f"hpl_{name}_median_m"] = _median(hpl)
        out[f"hpl_{name}_max_m"] = _max(hpl)
        out[f"hpl_{name}_finite_share"] = float(np.mean(fin_h)) if n else 0.0
        out[f"vpl_{name}_median_m"] = _median(vpl)
        out[f"vpl_{name}_max_m"] = _max(vpl)
        out[f"hpe_{name}_median_m"] = _median(hpe)
        out[f"hpe_{name}_max_m"] = _max(hpe)
        out[f"misleading_information_epochs_{name}"] = int(np.sum(fin_h & np.isfinite(hpe)
                                                                & (hpe > hpl)))
        out[f"vertical_misleading_information_epochs_{name}"] = int(
            np.sum(fin_v & np.isfinite(vpe) & (vpe > vpl)))
        out[f"detections_{name}"] = int(np.sum(np.asarray(m.detected)))
        out[f"exclusions_{name}"] = int(np.sum(np.any(np.asarray(m.excluded), -1)))
        out[f"exclusion_failures_{name}"] = int(np.sum(np.asarray(m.status)
                                                       == Status.EXCLUSION_FAILED))
    main = "mhss" if result.mhss is not None else "slope" if result.slope is not None else (
        next(iter(runs)))
    out["hpl_median_m"] = out[f"hpl_{main}_median_m"]
    out["vpl_median_m"] = out[f"vpl_{main}_median_m"]
    out["misleading_information_epochs"] = out[f"misleading_information_epochs_{main}"]
    return out
