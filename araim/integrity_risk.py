"""Does the protection level bound the risk? Fault injection and importance sampling.

**Model.** For one geometry the measurement error is y = eps + b + f: eps ~ N(0, C_int) (the
integrity error model of seed 004 App. A, variances added as DESIGN.md corrects), b a nominal
bias with |b_l| <= b_nom,l, and f an injected fault on a set E of sources. In the linear model
the all-in-view position error is S^(0) y and the solution separations are (S^(k) - S^(0)) y
(``araim.fde``), so every decision of the snapshot MHSS receiver (detection, which subset is
excluded, the position kept and its PLs) is a function of a few linear maps of y and of the
quadratic forms of the exclusion rule. ``monitor_maps`` computes them once per geometry with the
receiver's own kernel (``araim.fde`` on the unit residuals), so ``evaluate`` reproduces
``detect_and_exclude`` sample by sample (tested) at the cost of matrix products.

**Events**, per direction (horizontal, vertical):
  missed-detection HMI (MD): nothing detected and HPE > HPL (VPE > VPL);
  wrong-exclusion HMI (WE): detected, a subset accepted, and its error exceeds its own PL.

**Fault scenarios** of a geometry (static slots, inactive ones flagged): fault-free; a bias on
each source (GPS satellite or SOP tower); a constellation-wide fault (every source of a
constellation with at least two); two simultaneous biases in a constellation (the two sources
with the largest position slope, for constellations with at least three). A fault of magnitude
A (the Euclidean norm of f, m) points along f^ = (u^T S^(0))_E / |(u^T S^(0))_E|, the direction
within E that moves the position most along the unit vector u of the direction evaluated (up;
for the horizontal the principal direction of S^(0)_EN restricted to E, or of the horizontal
error covariance when E is empty). For one source that is the sign of its slope; a common bias
on a constellation moves nothing (its clock absorbs it) and f^ is orthogonal to it. Magnitudes
are x A_det with A_det the magnitude at which the mean separation of the fault's own monitored
mode reaches its threshold (the PL where the scenario is not monitored), and x A_PL with A_PL
the magnitude at which the fault alone puts the mean error along u on the PL: HMI needs the
error beyond the PL and no alert, so the worst magnitude lies near one of the two scales (a
mode whose threshold is far above the PL, e.g. a subset with a poor geometry, peaks near
A_PL, far below its A_det). The nominal bias is
b_nom with the sign of u^T S^(0) ("worst") or zero.

**Measured risk** of a geometry and direction: each scenario is assigned to the monitored mode
with the smallest exclusion set containing E (the grouping of ``araim.fault_modes``), and

    R = P(HMI | fault-free) + sum_k P_k max_{scenarios -> k} max_A P(HMI | scenario, A),

against the allocation of the PL equations, PHMI (1 - P_NM / (PHMI_V + PHMI_H)) (seed 004 eqs.
14-16; the horizontal one is PHMI_H, split evenly between east and north there). The maximum
over the magnitude grid stands for the supremum over A; faults not monitored (P_NM) are charged
to P_thresh by the PL equation and are reported, not summed.

**Importance sampling** (docs/integrity-risk.md): eps = sigma z, z ~ N(0, I), proposal N(mu, I)
(a symmetric pair fault-free) mixed with a share ``DEFENSIVE`` of N(0, I); mu starts at the
minimum-norm shift onto the missed-detection event and ``ce_rounds`` cross-entropy rounds
(elite ``CE_ELITE``) move it. Crude Monte Carlo is the same code with mu = 0 and no rounds.
"""

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.fault_modes import (
    DEFAULT_RULE,
    select_fault_modes,
    to_batch_first,
    to_batch_last,
)
from oaraim.araim.fde import checked_inputs, separation_kernel, weighted_sse
from oaraim.araim.mhss import MHSSOptions, Sources
from oaraim.araim.risk_options import DEFAULT_SAMPLING, Ramp, Sampling, Scenario
from oaraim.araim.status import Status
from oaraim.araim.validate import check_int

#: elite fraction of each cross-entropy round
CE_ELITE = 0.1
#: share of the proposal drawn from the nominal distribution itself (defensive mixture,
#: Hesterberg 1995): likelihood ratios stay below 1 / DEFENSIVE, so events the shift does not
#: aim at (wrong exclusions, the far side) are estimated with honest standard errors
DEFENSIVE = 0.1
#: scenario kinds (``scenario_slots``)
FAULT_FREE, SINGLE, CONSTELLATION, PAIR = 0, 1, 2, 3
KIND_NAMES = ("fault-free", "single source", "constellation", "two sources")
#: magnitudes of the injected fault, in units of A_det and of A_PL (module docstring)
DEFAULT_X_GRID = (0.0, 0.25, 0.5, 0.75, 0.9, 1.0, 1.1, 1.25, 1.5, 2.0, 3.0)
HORIZONTAL, VERTICAL = 0, 1


class MonitorMaps(NamedTuple):
    """Everything the MHSS receiver computes from y, as linear maps of y (one geometry per
    leading index). K counts the all-in-view solution (index 0) and the mode template."""

    s0: jax.Array  # (..., 3, L) all-in-view ENU position error per metre of y
    sep: jax.Array  # (..., K, 3, L) S^(k) - S^(0) (0 where the mode is unmonitored / T = 0)
    threshold_m: jax.Array  # (..., K, 3) T_k,q (eq. 12)
    monitored: jax.Array  # (..., K)
    excluded: jax.Array  # (..., K, L) sources hypothesised faulty by mode k
    prior: jax.Array  # (..., K) P_f^(k) of monitored modes
    hpl_m: jax.Array  # (...)
    vpl_m: jax.Array  # (...)
    pl_enu_m: jax.Array  # (..., 3)
    status: jax.Array  # (...)
    p_not_monitored: jax.Array  # (...)
    cand_s: jax.Array  # (..., K, 3, L) position error of candidate subset k (kept sources)
    cand_sep: jax.Array  # (..., K, K, 3, L) the candidate's own separations
    cand_threshold_m: jax.Array  # (..., K, K, 3)
    cand_ok: jax.Array  # (..., K) the candidate's PLs have status OK
    cand_hpl_m: jax.Array  # (..., K)
    cand_vpl_m: jax.Array  # (..., K)
    cand_wsse: jax.Array  # (..., K, L, L) weighted SSE quadratic form of the candidate's fit
    cand_wsse_ok: jax.Array  # (..., K)
    sigma_m: jax.Array  # (..., L) sqrt(C_int), 0 where not valid
    b_nom_m: jax.Array  # (..., L), 0 where not valid
    constellation: jax.Array  # (..., L)
    valid: jax.Array  # (..., L)
    p_const: jax.Array  # (..., C)


class Outcome(NamedTuple):
    """What the receiver does with residuals y (..., L); all (...)."""

    detected: jax.Array
    md_h: jax.Array  # missed-detection HMI, horizontal
    md_v: jax.Array
    we_h: jax.Array  # wrong-exclusion HMI, horizontal
    we_v: jax.Array
    excluded_mode: jax.Array  # mode index excluded, -1 if none (detected and none accepted: -1)
    hpe_m: jax.Array  # all-in-view errors
    vpe_m: jax.Array
    max_tau: jax.Array


def _exclusion_sets(valid, constellation, p_sat, p_const, budget, max_order, rule):
    """(..., K, L): the sources each mode of the template excludes (mode 0: none), as the
    receiver's kernel builds them (``fault_modes``)."""
    batch = valid.shape[:-1]
    fm = select_fault_modes(to_batch_last(valid, 1), to_batch_last(constellation, 1),
                            to_batch_last(p_sat, 1), to_batch_last(p_const, 1), budget, rule,
                            max_order)
    ex = jnp.concatenate([jnp.zeros_like(fm.excluded[:1]), fm.excluded], axis=0)  # (K, L, B)
    return to_batch_first(ex, batch)


def _add_unit_axis(args, n_units, axis_of_sources):
    """Insert a residual axis of n_units before the source axis of each input."""
    out = []
    for x, tail in zip(args, axis_of_sources, strict=True):
        x = jnp.asarray(x)
        lead = x.shape[:x.ndim - tail]
        out.append(jnp.broadcast_to(x[(...,) + (None,) + (slice(None),) * tail],
                                    lead + (n_units,) + x.shape[x.ndim - tail:]))
    return out


#: trailing dims per input of the kernel: g (L, 3), per-source (L,), p_const (C,)
_TAILS = (2, 1, 1, 1, 1, 1, 1, 1)


@partial(jax.jit, static_argnames=("budget", "max_order", "weighting", "fault_modes"))
def _maps(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, budget, max_order,
          weighting, fault_modes=DEFAULT_RULE):
    L = g.shape[-2]
    C = p_const.shape[-1]
    eye = jnp.eye(L)
    args = (g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid)
    # candidate subsets: each mode's kept sources as a new all-in-view set; candidate 0 keeps
    # every source, so it is the receiver's own all-in-view solution (one kernel call, traced
    # and compiled once, serves both)
    excluded = _exclusion_sets(valid, constellation, p_sat, p_const, budget, max_order,
                               fault_modes)  # (..., K, L)
    keep = valid[..., None, :] & ~excluded
    K = keep.shape[-2]
    cargs = _add_unit_axis(args, K, _TAILS)[:-1] + [keep]
    a = _add_unit_axis(cargs, L, _TAILS)
    sub = separation_kernel(Sources(*a[:6], a[7]), a[6], budget, jnp.broadcast_to(
        eye, keep.shape[:-1] + (L, L)), MHSSOptions(max_order, weighting, fault_modes))
    top = jax.tree.map(lambda x: x[(Ellipsis, 0) + (slice(None),) * (x.ndim - valid.ndim)],
                       sub)  # candidate 0: (..., L units, ...)
    s0 = jnp.swapaxes(top.position_m, -1, -2)  # (..., 3, L)
    sep = jnp.moveaxis(top.separation_m, -3, -1)  # (..., K, 3, L)
    monitored = top.monitored[..., 0, :]
    cand_s = jnp.swapaxes(sub.position_m, -1, -2)  # (..., K, 3, L)
    cand_sep = jnp.moveaxis(sub.separation_m, -3, -1)  # (..., K, K, 3, L)
    cand_ok = sub.pl.status[..., 0] == Status.OK
    # weighted SSE of each candidate's fit as a quadratic form, by polarisation of the
    # receiver's own function: M_ab = (q(e_a + e_b) - q(e_a) - q(e_b)) / 2
    pairs = eye[:, None, :] + eye[None, :, :]  # (L, L, L)
    gk = jnp.broadcast_to(g[..., None, :, :], keep.shape + (3,))
    ck = jnp.broadcast_to(constellation[..., None, :], keep.shape)
    vk = jnp.broadcast_to(var_int[..., None, :], keep.shape)

    def q(y, extra):
        shape = keep.shape[:-1] + extra + (L,)
        bc = lambda x, t: jnp.broadcast_to(  # noqa: E731
            x[(...,) + (None,) * len(extra) + (slice(None),) * t],
            keep.shape[:-1] + extra + x.shape[x.ndim - t:])
        return weighted_sse(bc(gk, 2), bc(ck, 1), bc(vk, 1), bc(keep, 1),
                            jnp.broadcast_to(y, shape), C)

    q1 = q(eye, (L,))  # (..., K, L)
    q2 = q(pairs, (L, L))  # (..., K, L, L)
    wsse_ok = jnp.all(jnp.isfinite(q1), axis=-1)
    q1 = jnp.where(wsse_ok[..., None], q1, 0.0)
    q2 = jnp.where(wsse_ok[..., None, None], q2, 0.0)
    m = 0.5 * (q2 - q1[..., :, None] - q1[..., None, :])
    m = jnp.where(jnp.eye(L, dtype=bool), q1[..., :, None] * jnp.ones(L), m)
    sigma = jnp.where(valid, jnp.sqrt(jnp.where(valid, var_int, 1.0)), 0.0)
    return MonitorMaps(
        s0=jnp.where(valid[..., None, :], s0, 0.0), sep=sep,
        threshold_m=top.threshold_m[..., 0, :, :],
        monitored=monitored, excluded=excluded, prior=top.prior[..., 0, :],
        hpl_m=top.pl.hpl_m[..., 0], vpl_m=top.pl.vpl_m[..., 0],
        pl_enu_m=top.pl.pl_enu_m[..., 0, :], status=top.pl.status[..., 0],
        p_not_monitored=top.pl.p_not_monitored[..., 0], cand_s=cand_s, cand_sep=cand_sep,
        cand_threshold_m=sub.threshold_m[..., 0, :, :], cand_ok=cand_ok,
        cand_hpl_m=sub.pl.hpl_m[..., 0], cand_vpl_m=sub.pl.vpl_m[..., 0], cand_wsse=m,
        cand_wsse_ok=wsse_ok, sigma_m=sigma, b_nom_m=jnp.where(valid, b_nom, 0.0),
        constellation=constellation, valid=valid, p_const=p_const)


def monitor_maps(sources: Sources, p_const, budget: IntegrityBudget,
                 options: MHSSOptions | None = None) -> MonitorMaps:
    """The MHSS receiver of ``detect_and_exclude`` as linear maps of the residual (module
    docstring). Arguments as ``araim.protection_levels`` (variances, m^2; ``options`` without
    ``position_optimization``); batch first."""
    s, p_const, options = checked_inputs(sources, p_const, budget, options)
    if options.position_optimization is not None:
        raise ValueError("monitor_maps models the weighted least-squares all-in-view estimate: "
                         "MHSSOptions(position_optimization=None)")
    return _maps(*s[:6], p_const, s.valid, budget=budget, max_order=options.max_order,
                 weighting=options.all_in_view_weighting, fault_modes=options.fault_modes)


def _tau(d, thr):
    return jnp.where(thr > 0, jnp.abs(d) / jnp.where(thr > 0, thr, 1.0), 0.0)


def evaluate(maps: MonitorMaps, residual_m, exclusion=True) -> Outcome:
    """The receiver's decisions and HMI events for residuals y (N, L) of ONE geometry
    (``maps`` without batch axes; ``jax.vmap`` over geometries). ``exclusion=False`` skips
    the exclusion branch (``we_*`` False, ``excluded_mode`` -1)."""
    y = jnp.where(maps.valid, jnp.asarray(residual_m, jnp.float64), 0.0)
    n = y.shape[:-1]
    e = y @ maps.s0.T  # (N, 3)
    d = jnp.einsum("...l,kql->...kq", y, maps.sep)
    tau = _tau(d, maps.threshold_m)
    max_tau = jnp.max(tau, axis=(-2, -1))
    ok = maps.status == Status.OK
    detected = (max_tau > 1.0) & ok
    hpe = jnp.hypot(e[..., 0], e[..., 1])
    vpe = jnp.abs(e[..., 2])
    md_h = ~detected & (hpe > maps.hpl_m)
    md_v = ~detected & (vpe > maps.vpl_m)
    if not exclusion:
        false = jnp.zeros(n, bool)
        return Outcome(detected, md_h, md_v, false, false, jnp.full(n, -1), hpe, vpe, max_tau)
    ce = jnp.einsum("...l,kql->...kq", y, maps.cand_s)
    cd = jnp.einsum("...l,kjql->...kjq", y, maps.cand_sep)
    cdet = jnp.any(_tau(cd, maps.cand_threshold_m) > 1.0, axis=(-2, -1)) & maps.cand_ok
    acceptable = maps.monitored & ~cdet & maps.cand_ok
    wsse = jnp.einsum("...l,klm,...m->...k", y, maps.cand_wsse, y)
    wsse = jnp.where(maps.cand_wsse_ok, wsse, jnp.inf)
    score = jnp.where(acceptable, wsse, jnp.inf)
    best = jnp.argmin(score, axis=-1)
    found = jnp.any(acceptable, axis=-1)
    eb = jnp.take_along_axis(ce, best[..., None, None], axis=-2)[..., 0, :]
    kept = detected & found
    we_h = kept & (jnp.hypot(eb[..., 0], eb[..., 1]) > maps.cand_hpl_m[best])
    we_v = kept & (jnp.abs(eb[..., 2]) > maps.cand_vpl_m[best])
    return Outcome(detected, md_h, md_v, we_h, we_v, jnp.where(kept, best, -1), hpe, vpe,
                   max_tau)


# ---------------------------------------------------------------------------------- scenarios


def scenario_slots(n_sources, n_constellations):
    """Static scenario table: (kind (S,), source (S,), constellation (S,)); S = 1 + L + 2 C."""
    L, C = n_sources, n_constellations
    kind = [FAULT_FREE] + [SINGLE] * L + [CONSTELLATION] * C + [PAIR] * C
    source = [-1] + list(range(L)) + [-1] * (2 * C)
    const = [-1] + [-1] * L + list(range(C)) * 2
    return np.array(kind), np.array(source), np.array(const)


class Injection(NamedTuple):
    """One scenario and direction of one geometry (``injection``)."""

    active: jax.Array  # the scenario exists in this geometry
    fault_set: jax.Array  # (L,) E
    direction: jax.Array  # (3,) unit u (ENU)
    fault_dir: jax.Array  # (L,) f^, unit norm (0 if the fault cannot move the position)
    bias_m: jax.Array  # (L,) nominal bias b
    mode: jax.Array  # assigned monitored mode k* (0 for fault-free)
    monitored: jax.Array  # the scenario is covered by a monitored mode
    prior: jax.Array  # P_k* (1 for fault-free)
    a_det_m: jax.Array  # magnitude at which the mode's mean separation reaches T (or the PL)
    a_pl_m: jax.Array  # magnitude at which the fault's mean error along u reaches the PL
    pl_m: jax.Array  # HPL or VPL


def _top_eigvec_2x2(m):
    """Unit eigenvector of the largest eigenvalue of a symmetric 2x2 matrix (closed form)."""
    a, b, d = m[0, 0], m[0, 1], m[1, 1]
    lam = 0.5 * (a + d) + jnp.sqrt(0.25 * (a - d) ** 2 + b**2)
    v1 = jnp.stack([b, lam - a])
    v2 = jnp.stack([lam - d, b])
    v = jnp.where(jnp.sum(v1**2) >= jnp.sum(v2**2), v1, v2)
    nrm = jnp.sqrt(jnp.sum(v**2))
    return jnp.where(nrm > 0, v / jnp.where(nrm > 0, nrm, 1.0), jnp.array([1.0, 0.0]))


def injection(maps: MonitorMaps, kind, source, const, direction, worst_bias=True) -> Injection:
    """The fault set, fault direction, nominal bias, assigned mode and A_det of one scenario
    (``scenario_slots``) and direction (0 horizontal, 1 vertical) of ONE geometry."""
    L = maps.valid.shape[-1]
    idx = jnp.arange(L)
    member = maps.valid & (maps.constellation == const)
    n_member = jnp.sum(member)
    col_v = jnp.abs(maps.s0[2])
    col_h = jnp.hypot(maps.s0[0], maps.s0[1])
    col = jnp.where(direction == VERTICAL, col_v, col_h)
    # the two sources of the constellation with the largest slopes (PAIR)
    r1 = jnp.argmax(jnp.where(member, col, -1.0))
    r2 = jnp.argmax(jnp.where(member & (idx != r1), col, -1.0))
    pair = (idx == r1) | (idx == r2)
    fault_set = jnp.select(
        [kind == SINGLE, kind == CONSTELLATION, kind == PAIR],
        [(idx == source) & maps.valid, member, pair & member], jnp.zeros(L, bool))
    active = jnp.select(
        [kind == FAULT_FREE, kind == SINGLE, kind == CONSTELLATION, kind == PAIR],
        [True, maps.valid[jnp.maximum(source, 0)], n_member >= 2, n_member >= 3], False)
    active = active & (maps.status == Status.OK)
    # direction u: up, or the principal horizontal direction of S0 restricted to E (or of the
    # horizontal error covariance when E is empty)
    s0h = maps.s0[:2]
    w = jnp.where(jnp.any(fault_set), fault_set.astype(float), maps.sigma_m**2)
    uh = _top_eigvec_2x2((s0h * w) @ s0h.T)
    u = jnp.where(direction == VERTICAL, jnp.array([0.0, 0.0, 1.0]),
                  jnp.concatenate([uh, jnp.zeros(1)]))
    row = u @ maps.s0  # (L,)
    fr = jnp.where(fault_set, row, 0.0)
    fn = jnp.sqrt(jnp.sum(fr**2))
    fault_dir = jnp.where(fn > 1e-12, fr / jnp.where(fn > 1e-12, fn, 1.0), 0.0)
    bias = jnp.where(worst_bias, maps.b_nom_m * jnp.where(row >= 0, 1.0, -1.0), 0.0)
    # assigned mode: monitored, exclusion set contains E, fewest excluded sources
    cover = maps.monitored & jnp.all(maps.excluded | ~fault_set, axis=-1)
    size = jnp.where(cover, jnp.sum(maps.excluded, axis=-1), L + 1)
    k = jnp.argmin(size)
    is_ff = kind == FAULT_FREE
    monitored = is_ff | jnp.any(cover)
    mode = jnp.where(is_ff | ~monitored, 0, k)
    prior = jnp.where(is_ff, 1.0, jnp.where(monitored, maps.prior[mode], 0.0))
    pl = jnp.where(direction == VERTICAL, maps.vpl_m, maps.hpl_m)
    slope = jnp.abs(maps.s0 @ fault_dir)  # (3,)
    thr = maps.threshold_m[mode]
    axes = jnp.where(direction == VERTICAL, jnp.array([False, False, True]),
                     jnp.array([True, True, False]))
    a_mode = jnp.min(jnp.where(axes & (slope > 1e-12) & (thr > 0),
                               thr / jnp.where(slope > 1e-12, slope, 1.0), jnp.inf))
    u_slope = jnp.abs(row @ fault_dir)
    a_pl = jnp.where(u_slope > 1e-12, pl / jnp.where(u_slope > 1e-12, u_slope, 1.0), 0.0)
    a_det = jnp.where(is_ff, 0.0, jnp.where(monitored & jnp.isfinite(a_mode), a_mode, a_pl))
    a_det = jnp.where(jnp.isfinite(a_det), a_det, 0.0)
    a_pl = jnp.where(is_ff | ~jnp.isfinite(a_pl), 0.0, a_pl)
    return Injection(active, fault_set, u, fault_dir, bias, mode, monitored, prior, a_det, a_pl,
                     pl)


# ------------------------------------------------------------------------ importance sampling


class Estimate(NamedTuple):
    """P(HMI) estimates of one scenario, magnitude and direction."""

    p_md: jax.Array  # missed-detection HMI
    se_md: jax.Array
    hits_md: jax.Array
    p_we: jax.Array  # wrong-exclusion HMI
    se_we: jax.Array
    hits_we: jax.Array
    upper_md: jax.Array  # 95 % upper bound (normal; rule of three with no hit)
    weight_sup: jax.Array  # sup of the likelihood ratio: min(exp(|mu|^2 / 2), 1 / DEFENSIVE)
    mu_norm: jax.Array  # |mu| of the final proposal
    p_detect: jax.Array  # P(detection) (IS estimate)


def _logcosh(x):
    a = jnp.abs(x)
    return a + jnp.log1p(jnp.exp(-2.0 * a)) - jnp.log(2.0)


def _log_weight(z, mu, symmetric):
    """log phi(z) / q(z) of the defensive mixture q = a phi + (1 - a) N(+-mu, I)."""
    m2 = 0.5 * jnp.sum(mu**2)
    t = z @ mu
    lw_shift = jnp.where(symmetric, m2 - _logcosh(t), m2 - t)
    return -jnp.logaddexp(jnp.log(DEFENSIVE), jnp.log1p(-DEFENSIVE) - lw_shift)


def _draw(key, mu, symmetric, n):
    k1, k2, k3 = jax.random.split(key, 3)
    eps = jax.random.normal(k1, (n, mu.shape[-1]))
    sign = jnp.where(symmetric & jax.random.bernoulli(k2, 0.5, (n,)), -1.0, 1.0)
    shifted = ~jax.random.bernoulli(k3, DEFENSIVE, (n,))
    return jnp.where(shifted, sign, 0.0)[:, None] * mu + eps


def _score(out, inj, direction):
    """>= 1 exactly where the MD event holds: min(PE / PL, 1 / max tau)."""
    pe = jnp.where(direction == VERTICAL, out.vpe_m, out.hpe_m)
    ratio = jnp.where(jnp.isfinite(inj.pl_m), pe / inj.pl_m, 0.0)
    return jnp.minimum(ratio, 1.0 / jnp.maximum(out.max_tau, 1e-300))


def _start_mean(maps, inj, mean_y, direction):
    """Minimum-norm whitened shift putting the mean error along u on the PL and the mean
    separations of the assigned mode within their thresholds."""
    sig = maps.sigma_m
    row = inj.direction @ maps.s0
    t0 = jnp.maximum(jnp.where(jnp.isfinite(inj.pl_m), inj.pl_m, 0.0) - row @ mean_y, 0.0)
    sep = maps.sep[inj.mode]  # (3, L)
    thr = maps.threshold_m[inj.mode]
    dm = sep @ mean_y
    axes = jnp.where(direction == VERTICAL, jnp.array([False, False, True]),
                     jnp.array([True, True, False]))
    td = jnp.where(axes & (thr > 0), jnp.clip(dm, -thr, thr) - dm, 0.0)
    a = jnp.concatenate([(sig * row)[None], jnp.where(axes[:, None], sig * sep, 0.0)], axis=0)
    t = jnp.concatenate([t0[None], td])
    gram = a @ a.T + 1e-12 * jnp.trace(a @ a.T) * jnp.eye(4) + 1e-300 * jnp.eye(4)
    return a.T @ jnp.linalg.solve(gram, t)


def importance_estimate(maps: MonitorMaps, inj: Injection, magnitude_m, direction, key,
                        sampling: Sampling) -> Estimate:
    """P(HMI | scenario, magnitude) of ONE geometry by importance sampling (module docstring);
    ``sampling.crude``: plain Monte Carlo (mu = 0, no rounds); ``sampling.nominal_bias`` is
    the injection's (``inj``), not read here."""
    n_samples, ce_samples, ce_rounds, crude, _, exclusion = sampling
    mean_y = inj.bias_m + magnitude_m * inj.fault_dir
    sig = maps.sigma_m
    symmetric = jnp.asarray((magnitude_m == 0.0) & ~crude)
    if crude:
        mu = jnp.zeros_like(sig)
    else:
        mu = _start_mean(maps, inj, mean_y, direction)

        def ce_round(mu, k):
            z = _draw(k, mu, symmetric, ce_samples)
            out = evaluate(maps, z * sig + mean_y, exclusion=False)
            s = _score(out, inj, direction)
            level = jnp.minimum(jnp.quantile(s, 1.0 - CE_ELITE), 1.0)
            elite = s >= level
            lw = _log_weight(z, mu, symmetric)
            lw = jnp.where(elite, lw, -jnp.inf)
            w = jnp.exp(lw - jnp.max(lw))
            fold = jnp.where(symmetric & (z @ mu < 0), -1.0, 1.0)[:, None]
            tot = jnp.sum(w)
            new = jnp.sum(w[:, None] * z * fold, axis=0) / jnp.where(tot > 0, tot, 1.0)
            return jnp.where((tot > 0) & jnp.all(jnp.isfinite(new)), new, mu), None

        if ce_rounds:
            mu, _ = jax.lax.scan(ce_round, mu, jax.random.split(jax.random.fold_in(key, 1),
                                                                ce_rounds))
    z = _draw(jax.random.fold_in(key, 0), mu, symmetric, n_samples)
    out = evaluate(maps, z * sig + mean_y, exclusion=exclusion)
    w = jnp.exp(_log_weight(z, mu, symmetric))
    md = jnp.where(direction == VERTICAL, out.md_v, out.md_h)
    we = jnp.where(direction == VERTICAL, out.we_v, out.we_h)
    n = n_samples

    def stats(hit):
        x = jnp.where(hit, w, 0.0)
        p = jnp.mean(x)
        se = jnp.sqrt(jnp.maximum(jnp.mean(x**2) - p**2, 0.0) / (n - 1))
        return p, se, jnp.sum(hit)

    p_md, se_md, h_md = stats(md)
    p_we, se_we, h_we = stats(we)
    sup = jnp.minimum(jnp.exp(jnp.minimum(0.5 * jnp.sum(mu**2), 700.0)), 1.0 / DEFENSIVE)
    upper = jnp.where(h_md > 0, p_md + 1.96 * se_md, jnp.minimum(1.0, 3.0 / n * sup))
    ok = maps.status == Status.OK
    zero = jnp.zeros(())
    return Estimate(jnp.where(ok, p_md, zero), jnp.where(ok, se_md, zero), h_md,
                    jnp.where(ok, p_we, zero), jnp.where(ok, se_we, zero), h_we,
                    jnp.where(ok, upper, zero), sup, jnp.sqrt(jnp.sum(mu**2)),
                    jnp.mean(jnp.where(out.detected, w, 0.0)))


class RiskTable(NamedTuple):
    """Per scenario (S), magnitude (X) and direction (2: horizontal, vertical) of one
    geometry."""

    kind: np.ndarray  # (S,)
    source: np.ndarray  # (S,)
    constellation: np.ndarray  # (S,)
    active: jax.Array  # (S, 2)
    monitored: jax.Array  # (S, 2)
    mode: jax.Array  # (S, 2)
    prior: jax.Array  # (S, 2)
    a_det_m: jax.Array  # (S, 2)
    a_pl_m: jax.Array  # (S, 2)
    magnitude_m: jax.Array  # (S, X, 2)
    estimate: Estimate  # fields (S, X, 2)


def _one(maps, kind, source, const, direction, x, scale, key, n_samples, ce_samples, ce_rounds,
         crude, worst_bias, exclusion):
    inj = injection(maps, kind, source, const, direction, worst_bias)
    unit = jnp.select([scale == 0, scale == 1], [inj.a_det_m, inj.a_pl_m], 1.0)  # 2: metres
    a = jnp.where(inj.active, x * unit, 0.0)
    est = importance_estimate(maps, inj, a, direction, key, Sampling(
        n_samples, ce_samples, ce_rounds, crude, "worst" if worst_bias else "zero", exclusion))
    est = jax.tree.map(lambda v: jnp.where(inj.active, v, jnp.zeros_like(v)), est)
    return inj, a, est


_SIZES = ("n_samples", "ce_samples", "ce_rounds", "crude", "worst_bias", "exclusion")


@partial(jax.jit, static_argnames=("n_constellations",) + _SIZES)
def _risk_table(maps, key, x_grid, n_constellations, n_samples, ce_samples, ce_rounds, crude,
                worst_bias, exclusion):
    L = maps.valid.shape[-1]
    kind, source, const = (jnp.asarray(a) for a in scenario_slots(L, n_constellations))
    S, X = kind.shape[0], 2 * x_grid.shape[0]  # x A_det, then x A_PL
    si, xi, di = (a.ravel() for a in jnp.meshgrid(jnp.arange(S), jnp.arange(X), jnp.arange(2),
                                                  indexing="ij"))
    xs = jnp.concatenate([x_grid, x_grid])

    def one(args):
        s, x, d = args
        k = jax.random.fold_in(jax.random.fold_in(jax.random.fold_in(key, s), x), d)
        return _one(maps, kind[s], source[s], const[s], d, xs[x], x // x_grid.shape[0], k,
                    n_samples, ce_samples, ce_rounds, crude, worst_bias, exclusion)

    inj, a, est = jax.lax.map(one, (si, xi, di))
    shp = lambda v: v.reshape((S, X, 2) + v.shape[1:])  # noqa: E731
    first_x = lambda v: shp(v)[:, 0]  # noqa: E731
    return (first_x(inj.active), first_x(inj.monitored), first_x(inj.mode),
            first_x(inj.prior), first_x(inj.a_det_m), first_x(inj.a_pl_m), shp(a),
            jax.tree.map(shp, est))


_one_jit = jax.jit(_one, static_argnames=_SIZES)


def _check_options(maps, sampling):
    """(n_samples, ce_samples, ce_rounds) of ``sampling``, checked, and the maps' shape."""
    if sampling.nominal_bias not in ("worst", "zero"):
        raise ValueError(f"nominal_bias must be 'worst' or 'zero', got {sampling.nominal_bias!r}")
    if maps.valid.ndim != 1:
        raise ValueError("the maps of one geometry are needed (no batch axes); pick geometry i "
                         "with jax.tree.map(lambda a: a[i], maps)")
    return (check_int("n_samples", sampling.n_samples, 2),
            check_int("ce_samples", sampling.ce_samples, 10),
            check_int("ce_rounds", sampling.ce_rounds, 0))


def scenario_estimate(maps: MonitorMaps, scenario: Scenario, key,
                      sampling: Sampling = DEFAULT_SAMPLING
                      ) -> tuple[Injection, jax.Array, Estimate]:
    """P(HMI) of ONE scenario of one geometry (``Scenario``: kind, direction, magnitude x in
    units of A_det or A_PL, the faulty source or constellation). Returns (Injection,
    magnitude (m), Estimate)."""
    kind, direction, x, source, constellation, scale = scenario
    if scale not in ("det", "pl"):
        raise ValueError(f"scale must be 'det' or 'pl', got {scale!r}")
    sizes = _check_options(maps, sampling)
    if direction not in (HORIZONTAL, VERTICAL):
        raise ValueError(f"direction must be HORIZONTAL (0) or VERTICAL (1), got {direction!r}")
    if not np.isfinite(x) or x < 0:
        raise ValueError(f"x (magnitude in units of A_det) must be >= 0, got {x!r}")
    return _one_jit(maps, jnp.asarray(kind), jnp.asarray(source), jnp.asarray(constellation),
                    jnp.asarray(direction), jnp.asarray(float(x)),
                    jnp.asarray(0 if scale == "det" else 1), key, *sizes,
                    bool(sampling.crude), sampling.nominal_bias == "worst",
                    bool(sampling.exclusion))


def risk_table(maps: MonitorMaps, key, x_grid=DEFAULT_X_GRID,
               sampling: Sampling = DEFAULT_SAMPLING) -> RiskTable:
    """P(HMI | scenario, magnitude) for every scenario slot, magnitude and direction of ONE
    geometry (``maps`` without batch axes): 2 X magnitudes, ``x_grid`` x A_det then ``x_grid``
    x A_PL. ``Sampling(crude=True)`` for plain Monte Carlo."""
    n_samples, ce_samples, ce_rounds = _check_options(maps, sampling)
    x = np.asarray(x_grid, float)
    if x.ndim != 1 or x.size == 0 or np.any(~np.isfinite(x)) or np.any(x < 0):
        raise ValueError(f"x_grid must be a non-empty list of magnitudes >= 0 (units of A_det), "
                         f"got {x_grid!r}")
    C = maps.p_const.shape[-1]
    out = _risk_table(maps, key, jnp.asarray(x), C, n_samples, ce_samples, ce_rounds,
                      bool(sampling.crude), sampling.nominal_bias == "worst",
                      bool(sampling.exclusion))
    kind, source, const = scenario_slots(maps.valid.shape[-1], C)
    return RiskTable(kind, source, const, *out)


class RampRisk(NamedTuple):
    """A ramp fault on one source, seen by the snapshot receiver epoch by epoch."""

    time_s: np.ndarray  # (n,) epochs since the ramp started
    magnitude_m: np.ndarray  # (n,) rate x time
    p_md: np.ndarray  # (n,) P(missed-detection HMI) at each epoch
    se_md: np.ndarray  # (n,)
    p_we: np.ndarray  # (n,) P(wrong-exclusion HMI)
    p_detect: np.ndarray  # (n,) P(detection) at each epoch
    mean_p_md: float  # per-epoch risk averaged over the ramp
    union_p_md: float  # P(HMI at some epoch of the ramp) <= sum of the epochs' risks


@partial(jax.jit, static_argnames=_SIZES)
def _ramp(maps, source, direction, magnitudes, key, n_samples, ce_samples, ce_rounds, crude,
          worst_bias, exclusion):
    def one(args):
        i, a = args
        return _one(maps, jnp.asarray(SINGLE), source, jnp.asarray(-1), direction, a,
                    jnp.asarray(2), jax.random.fold_in(key, i),
                    n_samples, ce_samples, ce_rounds, crude, worst_bias, exclusion)[2]

    return jax.lax.map(one, (jnp.arange(magnitudes.shape[0]), magnitudes))


def ramp_risk(maps: MonitorMaps, ramp: Ramp, key,
              sampling: Sampling = DEFAULT_SAMPLING) -> RampRisk:
    """A ramp on ``ramp.source`` (a tower clock drifting away, a slowly growing multipath or
    ephemeris error): at epoch t = epoch_s, 2 epoch_s, ..., duration_s the fault is rate x t
    along the source's slope sign (``injection``), and each epoch is a snapshot with fresh
    nominal noise. Returns every epoch's P(HMI) and two summaries: the mean per-epoch risk over
    the ramp and the union bound on an HMI at some epoch (no independence assumed)."""
    source, direction, rate_mps, duration_s, epoch_s = ramp
    sizes = _check_options(maps, sampling)
    if direction not in (HORIZONTAL, VERTICAL):
        raise ValueError(f"direction must be HORIZONTAL (0) or VERTICAL (1), got {direction!r}")
    for name, v in (("rate_mps", rate_mps), ("duration_s", duration_s), ("epoch_s", epoch_s)):
        if not np.isfinite(v) or v < 0 or (name != "rate_mps" and v == 0):
            raise ValueError(f"{name} must be finite and > 0 (rate >= 0), got {v!r}")
    n = int(np.floor(duration_s / epoch_s + 1e-9))
    if n < 1:
        raise ValueError(f"duration_s ({duration_s}) must cover at least one epoch_s "
                         f"({epoch_s})")
    t = epoch_s * np.arange(1, n + 1)
    mags = rate_mps * t
    e = _ramp(maps, jnp.asarray(source), jnp.asarray(direction), jnp.asarray(mags), key,
              *sizes, bool(sampling.crude), sampling.nominal_bias == "worst",
              bool(sampling.exclusion))
    p = np.asarray(e.p_md)
    return RampRisk(t, mags, p, np.asarray(e.se_md), np.asarray(e.p_we),
                    np.asarray(e.p_detect), float(p.mean()), float(min(1.0, p.sum())))


# ------------------------------------------------------------------------------- measured risk


def allocated_budget(budget: IntegrityBudget, p_not_monitored):
    """(horizontal, vertical) integrity risk the PL equations allocate to the monitored modes
    and the fault-free case: PHMI (1 - P_NM / (PHMI_V + PHMI_H)) (seed 004 eqs. 14-16)."""
    scale = (1.0 - np.asarray(p_not_monitored) / (budget.phmi_v + budget.phmi_h)
             ) / budget.n_es_int
    return budget.phmi_h * scale, budget.phmi_v * scale


def total_risk(risk, p_not_monitored, budget):
    """(risk + P_NM x PHMI_d / (PHMI_V + PHMI_H), PHMI_d / N_es): the measured risk of the
    monitored modes with every unmonitored mode counted as HMI, and the whole budget, per
    direction (..., 2). Their ratio is <= 1 exactly where risk <= ``allocated_budget``."""
    share = np.array([budget.phmi_h, budget.phmi_v]) / (budget.phmi_v + budget.phmi_h)
    phmi = np.array([budget.phmi_h, budget.phmi_v]) / budget.n_es_int
    return (np.asarray(risk) + np.asarray(p_not_monitored)[..., None] * share / budget.n_es_int,
            phmi)


def measured_risk(table: RiskTable, include_wrong_exclusion=False):
    """Measured integrity risk of one geometry per direction (module docstring): returns
    (risk (2,), upper (2,), per-scenario worst conditional P(HMI) (S, 2), arg max over x
    (S, 2)). Scenarios not covered by a monitored mode are left out of the sum."""
    e = table.estimate
    p = np.asarray(e.p_md) + (np.asarray(e.p_we) if include_wrong_exclusion else 0.0)
    up = np.asarray(e.upper_md) + (np.asarray(e.p_we) + 1.96 * np.asarray(e.se_we)
                                   if include_wrong_exclusion else 0.0)
    return risk_sum(table.kind, np.asarray(table.active), np.asarray(table.monitored),
                    np.asarray(table.mode), np.asarray(table.prior), p, up)


def risk_sum(kind, active, monitored, mode, prior, p, upper):
    """``measured_risk`` on arrays: kind (S,); active, monitored, mode, prior (S, 2); p and
    its upper bound (S, X, 2) -> (risk (2,), upper (2,), worst (S, 2), worst_x (S, 2))."""
    p = np.where(active[:, None], p, 0.0)
    upper = np.where(active[:, None], upper, 0.0)
    worst_x = np.argmax(p, axis=1)  # (S, 2)
    worst = np.take_along_axis(p, worst_x[:, None], 1)[:, 0]
    worst_up = np.take_along_axis(upper, worst_x[:, None], 1)[:, 0]
    mon = monitored & active
    ff = np.asarray(kind) == FAULT_FREE
    risk, up = np.zeros(2), np.zeros(2)
    for d in range(2):
        risk[d] = worst[ff, d].sum()
        up[d] = worst_up[ff, d].sum()
        faulty = mon[:, d] & ~ff
        for k in np.unique(mode[faulty, d]):
            sel = faulty & (mode[:, d] == k)
            j = np.flatnonzero(sel)[np.argmax(worst[sel, d])]
            risk[d] += prior[j, d] * worst[j, d]
            up[d] += prior[j, d] * worst_up[j, d]
    return risk, up, worst, worst_x
