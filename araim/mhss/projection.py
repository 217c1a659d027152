"""The projection of the MHSS protection levels: every fault mode's fault-tolerant solution,
seed 004 eqs. (8)-(12).

State: [east, north, up, one clock per constellation slot]. For every geometry of a batch
``project`` builds the all-in-view solution (mode 0) and one fault-tolerant solution per
candidate fault mode of ``araim.fault_modes`` (static template, live modes masked), all at
once on arrays of shape (..., K) with K = 1 + number of candidate modes, and:

    W^(i)(l,l) = C_int^-1(l,l) if l is NOT hypothesised faulty, else 0  (after eq. 9, corrected)
    S^(i) = (H^T W^(i) H)^-1 H^T W^(i)                                   (after eq. 9)
    sigma_q^(i)^2 = (H^T W^(i) H)^-1_qq                                  (9)
    b_q^(i) = sum_l |S^(i)_ql| b_nom,l                                   (10)
    sigma_ss,q^(i)^2 = e_q^T (S^(i) - S^(0)) C_acc (S^(i) - S^(0))^T e_q  (11)
    T_i,q = K_fa,q sigma_ss,q^(i), K_fa,H = Q^-1(P_FA_H / (4 N_f)),
                                  K_fa,V = Q^-1(P_FA_V / (2 N_f))        (12)

All projectors are weighted with C_int^-1, S^(0) included (the ADD and MAAST; DESIGN.md);
``all_in_view_weighting="acc"`` restores the seed's C_acc^-1 for S^(0) (sigma^(0) is then
sqrt(S^(0) C_int S^(0)T)_qq). The all-in-view, single-source and whole-constellation modes
eliminate the clock states exactly (rows centred on their constellation's weighted mean row:
``_centered_rows``); the other modes keep one clock column per constellation, and a clock whose
constellation has no source left in a mode is dropped by putting 1 on its (otherwise all-zero)
diagonal: the position block is unchanged. Which intermediates are stored
(``linalg.materialize``) and which are not was measured: docs/benchmarks.md.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy import special

from oaraim.araim import linalg
from oaraim.araim.fault_modes import (
    select_fault_modes,
    template_source,
)
from oaraim.araim.mhss.inputs import Sources, invalid_input_flags
from oaraim.araim.mhss.tangent import mode_centering, separation_tangents, wls_tangents
from oaraim.araim.position_opt import adjusted_rows
from oaraim.araim.status import Status

__all__ = ["SINGLE_REDUNDANCY_TOLERANCE", "ZERO_SEPARATION_RTOL", "ModeRows", "Projection",
           "adjusted_projection", "position_rows", "project"]

#: sigma_ss below this fraction of sigma^(0) is rounding noise: the mode's separation is zero
ZERO_SEPARATION_RTOL = 1e-9


class Projection(NamedTuple):
    """Everything the PL equations and the solution-separation test need, per mode.

    Batch-last inside the kernels (one flattened batch axis B last); K = 1 + candidate modes,
    mode 0 the all-in-view solution."""

    s_pos: jax.Array
    """(K, 3, L, B) position rows of S^(i)."""
    sigma: jax.Array
    """(K, 3, B) sigma_q^(i)."""
    bias: jax.Array
    """(K, 3, B) b_q^(i)."""
    sigma_ss: jax.Array
    """(K, 3, B) sigma_ss,q^(i) (0 for i = 0)."""
    threshold: jax.Array
    """(K, 3, B) T_i,q (0 for i = 0 and for unmonitored modes)."""
    monitored: jax.Array
    """(K, B) live and nonsingular, False for i = 0."""
    prior: jax.Array
    """(K, B) P_f^(i) of monitored modes, 0 otherwise."""
    excluded: jax.Array
    """(K, L, B) sources hypothesised faulty (none for i = 0)."""
    n_modes: jax.Array
    """(B,)."""
    p_not_monitored: jax.Array
    """(B,)."""
    order: jax.Array
    """(B,)."""
    status: jax.Array
    """(B,) status before root finding."""
    sigma_acc_u: jax.Array
    """(B,)."""
    rows: "ModeRows | None" = None
    """The pieces ``s_pos`` is built from, where it is not built (``project(lazy_rows=True)``:
    ``s_pos`` is None then); ``position_rows`` builds it."""
    invalid_input: jax.Array | None = None
    """(B,) bool: a valid source has an unusable input (``invalid_input_flags``; the status
    is INVALID_INPUT there)."""


class ModeRows(NamedTuple):
    """S^(i) (K, 3, L, B) as the pieces it is made of: ``head`` (the modes before the single
    sources), the single-source rows' factors (``_single_rows``: S^(0) rows ``s0`` (3, L, B),
    ``u_pos`` (L, 3, B), ``c`` (L, L, B), ``ok`` (L, B)), ``tail`` (the modes after them) and
    ``usable`` (K, B), the modes kept. Built where it is read (``position_rows``) from the
    same stored pieces as the full array would be, so it has the same bits (tested on 828
    outputs): the MAAST estimator's branch reads S^(i), and building it for every tile
    was 0.85 of 11.4 us per geometry of the 1 x 1 deg map kernel."""

    head: tuple
    s0: jax.Array
    u_pos: jax.Array
    c: jax.Array
    ok: jax.Array
    tail: tuple
    usable: jax.Array | None = None


def _single_rows(s0, u_pos, c, ok):
    """The single-source modes' rows S^(l) (L, 3, L, B) = S^(0) + u_l c_l (m != l), 0 at
    m = l and where the downdate is singular (``_single_modes``)."""
    eye = jnp.eye(c.shape[0], dtype=bool)[:, :, None]
    s_pos = s0[None] + u_pos[:, :, None, :] * c[:, None, :, :]  # (L, 3, L, B), m = l wrong
    s_pos = jnp.where(eye[:, None], 0.0, s_pos)
    return jnp.where(ok[:, None, None, :], s_pos, 0.0)


def position_rows(pr):
    """``pr.s_pos``, built from ``pr.rows`` where ``project`` left it to its reader."""
    if pr.rows is None:
        return pr.s_pos
    r = pr.rows
    s_pos = jnp.concatenate([*r.head, _single_rows(r.s0, r.u_pos, r.c, r.ok), *r.tail], axis=0)
    return linalg.materialize(jnp.where(r.usable[:, None, None, :], s_pos, 0.0))


_blocks = linalg.blocks  # concatenation on axis 0 without a branch per element


#: sums and maxima over short static axes written out (``linalg.unrolled``)
_sum = linalg.sum_axis
_max = linalg.max_axis
_any = linalg.any_axis


def _normal(cols, w, axis):
    """Upper-and-lower nested list of sum_l w c_a c_b over ``axis`` (symmetric, each once)."""
    k = len(cols)
    wc = [w * c for c in cols]
    n = [[None] * k for _ in range(k)]
    for i in range(k):
        for j in range(i + 1):
            n[i][j] = n[j][i] = linalg.materialize(_sum(wc[i] * cols[j], axis))
    return n


def _generic_modes(keep, w_int, cols, member, b_nom, var_acc, s0):
    """Fault-tolerant solutions of arbitrary exclusion sets, by Cholesky of each normal matrix.

    keep (M, L, B); cols: 3 + C arrays (1, L, B); s0: (3, L, B) all-in-view position rows, or
    None to use mode 0 of ``keep`` as the all-in-view. Returns s_pos (M, 3, L, B), var_pos
    (M, 3, B), bias (M, 3, B), sigma_ss (M, 3, B), nonsingular (M, B).
    """
    n_states = len(cols)
    C = n_states - 3
    w = jnp.where(keep, w_int[None], 0.0)
    n = _normal(cols, w, axis=1)  # (M, B) entries
    kept_c = jnp.any(keep[:, :, None, :] & member[None], axis=1)  # (M, C, B)
    for c in range(C):  # drop the clock of a constellation with no kept source
        n[3 + c][3 + c] = n[3 + c][3 + c] + jnp.where(kept_c[:, c], 0.0, 1.0)
    lower, nonsingular = linalg.cholesky(n)
    zero = jnp.zeros_like(n[0][0])
    y = [[linalg.materialize(e) for e in linalg.cholesky_solve(
        lower, [zero + (1.0 if j == q else 0.0) for j in range(n_states)])] for q in range(3)]
    # S_q,l = w_l sum_a (N^-1)_{q a} H_{l a}
    s_pos = jnp.stack([w * sum(y[q][a][:, None, :] * cols[a] for a in range(n_states))
                       for q in range(3)], axis=1)  # (M, 3, L, B)
    s_pos = linalg.materialize(jnp.where(nonsingular[:, None, None, :], s_pos, 0.0))
    var_pos = jnp.stack([y[q][q] for q in range(3)], axis=1)  # (M, 3, B)
    ref = s_pos[:1] if s0 is None else s0[None]
    bias = 0.0
    ss2 = 0.0
    for m in range(w.shape[1]):  # loops over sources: one fused (M, 3, B) loop each
        bias = bias + jnp.abs(s_pos[:, :, m]) * b_nom[m]
        ss2 = ss2 + (s_pos[:, :, m] - ref[:, :, m]) ** 2 * var_acc[m]
    bias, sigma_ss = linalg.materialize(bias), linalg.materialize(linalg.sqrt0(ss2))
    return s_pos, var_pos, bias, sigma_ss, nonsingular


def _centered_rows(g, w_int, member):
    """Clock elimination: every row minus the w-weighted mean row of its constellation.

    g (L, 3, B), w_int (L, B), member (L, C, B). With one clock per constellation, the position
    block of the inverse normal matrix is the inverse of the centred normal matrix
    sum_l w_l g~_l g~_l^T (a Schur complement), the position part of N^-1 h_l is that inverse
    times g~_l, and h_l^T N^-1 h_m = g~_l^T M g~_m + [same constellation] / s_c with
    s_c = sum of the constellation's weights. A constellation without sources has no clock.
    Returns g~ (3 arrays (L, B)) and 1 / s_c of each source's constellation (L, B; 0 for
    padding)."""
    memf = member.astype(g.dtype)
    gt = [g[:, a] for a in range(3)]
    inv_s_src = 0.0
    for c in range(member.shape[1]):
        wc = w_int * memf[:, c]
        s_c = _sum(wc, 0)
        # (not stored: docs/benchmarks.md)
        inv = jnp.where(s_c > 0, 1.0 / jnp.where(s_c > 0, s_c, 1.0), 0.0)
        for a in range(3):
            mean = linalg.materialize(_sum(wc * g[:, a], 0) * inv)
            gt[a] = gt[a] - memf[:, c] * mean[None]
        inv_s_src = inv_s_src + memf[:, c] * inv[None]
    return [linalg.materialize(x) for x in gt], linalg.materialize(inv_s_src)


def _whole_modes(keep, w_int, gt, b_nom, var_acc):
    """The all-in-view solution (mode 0 of ``keep``) and modes that exclude whole
    constellations, on the centred rows of ``_centered_rows`` (a kept constellation keeps all
    its sources, so its mean row is the all-in-view one). keep (M, L, B).

    One 3 x 3 Cholesky per mode instead of a (3 + C)-state one: the clock pivots are the
    weight sums s_c and need no test; the position pivots are tested against the sum of the
    mode's weights (at most C times the largest diagonal entry of the full normal matrix, the
    scale of ``linalg.cholesky``; the oracle's borderline band is 1e3). Measured on the bench
    case: the whole kernel 7-11 % faster than with the 5-state factor.
    Returns s_pos (M, 3, L, B), var_pos, bias, sigma_ss (M, 3, B), nonsingular (M, B) and the
    position block of the inverse normal matrices (nested 3 x 3 lists of (M, B) arrays)."""
    w = jnp.where(keep, w_int[None], 0.0)  # (M, L, B)
    wg = [w * x[None] for x in gt]
    n = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i + 1):
            n[i][j] = n[j][i] = linalg.materialize(_sum(wg[i] * gt[j][None], 1))
    lower, ok = linalg.cholesky(n, scale=_sum(w, 1))
    zero = jnp.zeros_like(n[0][0])
    inv = [linalg.cholesky_solve(lower, [zero + (1.0 if j == q else 0.0) for j in range(3)])
           for q in range(3)]  # (not stored: docs/benchmarks.md)
    # S_q,l = sum_a inv_qa w_l g~_l,a from the inverse's columns as (M, 3, B) arrays (zero
    # where singular), by broadcasting: a stack over q of the (M, L, B) rows, fused into the
    # sums below, ran one branchy loop per element (measured 8 % of the kernel slower)
    col = [linalg.materialize(jnp.where(ok[:, None], jnp.stack([inv[q][a] for q in range(3)],
                                                                axis=1), 0.0))
           for a in range(3)]
    s_pos = linalg.materialize(sum(col[a][:, :, None, :] * wg[a][:, None] for a in range(3)))
    bias = ss2 = 0.0
    for m in range(w.shape[1]):  # loops over sources: one fused (M, 3, B) loop each
        bias = bias + jnp.abs(s_pos[:, :, m]) * b_nom[m]
        ss2 = ss2 + (s_pos[:, :, m] - s_pos[:1, :, m]) ** 2 * var_acc[m]
    var_pos = jnp.stack([inv[q][q] for q in range(3)], axis=1)
    return (s_pos, var_pos, linalg.materialize(bias), linalg.materialize(linalg.sqrt0(ss2)),
            ok, inv)


#: a single-source exclusion is singular when 1 - w_l h_l^T N0^-1 h_l (the share of source l's
#: information the others can replace; in [0, 1]) is below this
SINGLE_REDUNDANCY_TOLERANCE = 1e-9


def _single_modes(w_int, gt, inv_s_src, member, b_nom, var_acc, inv0, var0):
    """Every single-source exclusion from the all-in-view solution by rank-one downdates
    (Sherman-Morrison; DESIGN.md performance notes), on the centred rows of
    ``_centered_rows`` and the all-in-view position inverse inv0 (nested 3 x 3 lists of (B,)
    arrays; ``_whole_modes``) with variances var0 (3, B).
    u_l is stored once (``linalg.materialize``): left to itself XLA fused its computation into
    every element of the (L, L, B) products below (13x recomputation, most of the kernel).

    With u_l = (N0^-1 h_l)_pos = inv0 g~_l, P_lm = h_l^T N0^-1 h_m = g~_l . u_m + [c(l) = c(m)]
    / s_c and r_l = 1 - w_l P_ll:
        N_l^-1 = N0^-1 + w_l (N0^-1 h_l) (N0^-1 h_l)^T / r_l
        S^(l)_:,m = S^(0)_:,m + u_l c_lm (m != l), S^(l)_:,l = 0,   c_lm = w_l w_m P_lm / r_l
        sigma_ss,q^(l)^2 = u_l,q^2 (sum_{m != l} c_lm^2 C_acc,m + w_l^2 C_acc,l)
    Returns per single mode l (axis 0 of length L): s_pos (L, 3, L, B), var_pos (L, 3, B),
    bias (L, 3, B), sigma_ss (L, 3, B), ok (L, B), and the factors of s_pos (s0, u_pos, c, ok:
    ``_single_rows``).
    """
    L = w_int.shape[0]
    memf = member.astype(w_int.dtype)
    # a source alone in its constellation: its centred row is zero (to rounding), all its
    # information goes to its own clock, r_l = 0; excluding it removes that clock too and
    # leaves the all-in-view position solution, S^(l) = S^(0) (seed 004 Theorem 1): a
    # solvable mode with zero separation, not a singular one. u_l = 0 exactly there.
    n_c = _sum(memf, 0)  # (C, B) valid members
    lone = _any(member & (n_c == 1.0)[None], 1)  # (L, B)
    u = [linalg.materialize(jnp.where(lone, 0.0, sum(inv0[q][a][None] * gt[a]
                                                      for a in range(3))))
         for q in range(3)]  # (L, B)
    same = sum(memf[:, None, c] * memf[None, :, c] for c in range(member.shape[1]))  # (L, L, B)
    p = sum(gt[a][:, None, :] * u[a][None, :, :] for a in range(3)) + same * inv_s_src[:, None]
    s0 = jnp.stack([w_int * u[q] for q in range(3)], axis=0)  # (3, L, B)
    p_ll = sum(gt[a] * u[a] for a in range(3)) + inv_s_src  # (L, B)
    r = 1.0 - w_int * p_ll
    ok = r > SINGLE_REDUNDANCY_TOLERANCE
    r_safe = jnp.where(ok, r, 1.0)
    eye = jnp.eye(L, dtype=bool)[:, :, None]
    c = linalg.materialize(
        jnp.where(eye | lone[:, None], 0.0, (w_int / r_safe)[:, None, :] * p * w_int[None, :, :]))
    ok = ok | lone
    u_pos = jnp.stack(u, axis=1)  # (L, 3, B): u_l,q
    s_pos = _single_rows(s0, u_pos, c, ok)
    var_pos = var0[None] + u_pos**2 * (w_int / r_safe)[:, None, :]
    # b_l,q = sum_m |S^(l)_qm| b_m as a loop over m of (L, 3, B) terms: one fused loop
    bias = 0.0
    for m in range(L):
        term = jnp.abs(s0[None, :, m] + u_pos * c[:, m][:, None]) * b_nom[m]
        bias = bias + jnp.where(eye[:, m][:, None], 0.0, term)
    bias = jnp.where(ok[:, None], bias, 0.0)
    spread = w_int**2 * var_acc  # (L, B)
    for m in range(L):
        spread = spread + c[:, m] ** 2 * var_acc[m]
    sigma_ss = jnp.abs(u_pos) * linalg.sqrt0(spread)[:, None, :]
    # (not stored before ``_blocks`` writes them into the mode arrays: note above it)
    return s_pos, var_pos, bias, sigma_ss, ok, (s0, u_pos, c, ok)


def _int_weighted_modes(g, w_int, var_acc, b_nom, valid, member, excluded, fault_modes,
                        max_order, single_downdates):
    """``_int_weighted_modes_rows`` without the rows' pieces (the function
    ``int_weighted_modes`` gives a derivative rule)."""
    return _int_weighted_modes_rows(g, w_int, var_acc, b_nom, valid, member, excluded,
                                    fault_modes, max_order, single_downdates)[:5]


def _int_weighted_modes_rows(g, w_int, var_acc, b_nom, valid, member, excluded, fault_modes,
                             max_order, single_downdates):
    """Every mode's solution with C_int^-1 weights (mode 0 the all-in-view one), in template
    order: g (L, 3, B), zero at padding; w_int, var_acc, b_nom (L, B), zero at padding; valid
    (L, B); member (L, C, B); excluded (T, L, B) the candidate modes' exclusions
    (``select_fault_modes``). ``single_downdates``: the all-in-view and whole-constellation
    modes on clock-eliminated rows, the single-source modes by downdates, the others by their
    own Cholesky; else every mode by its own Cholesky. Returns s_pos (K, 3, L, B), var_pos,
    bias, sigma_ss (K, 3, B), nonsingular (K, B) and the ``ModeRows`` pieces of s_pos (None
    without single downdates). Differentiated by ``tangent``'s rule (``int_weighted_modes``),
    not through these steps."""
    L, C = valid.shape[0], member.shape[1]
    cols = [g[None, :, 0], g[None, :, 1], g[None, :, 2]]
    cols += [member[None, :, c].astype(g.dtype) for c in range(C)]
    if not single_downdates:
        keep = jnp.concatenate([valid[None], valid[None] & ~excluded], axis=0)  # (K, L, B)
        return (*_generic_modes(keep, w_int, cols, member, b_nom, var_acc, None), None)
    # the all-in-view solution and the whole-constellation modes on clock-eliminated rows,
    # the singles by downdates of the all-in-view inverse, other modes (a source and
    # whole constellations, order >= 2) by their own Cholesky; assembled in template order
    src = template_source(fault_modes, L, C, max_order)
    rest = np.arange(L, src.size)
    whole = rest[src[rest] < 0]
    gt, inv_s_src = _centered_rows(g, w_int, member)
    keep = jnp.concatenate([valid[None], valid[None] & ~excluded[whole]], axis=0)
    sw, vw, bw, ssw, okw, inv = _whole_modes(keep, w_int, gt, b_nom, var_acc)
    s1, v1, b1, ss1, ok1, factors = _single_modes(w_int, gt, inv_s_src, member, b_nom,
                                                  var_acc, [[e[0] for e in row] for row in inv],
                                                  vw[0])
    parts = {True: (sw, vw, bw, ssw, okw)}
    if whole.size < rest.size:
        parts[False] = _generic_modes(valid[None] & ~excluded[rest[src[rest] >= 0]],
                                      w_int, cols, member, b_nom, var_acc, sw[0])
    runs, next_index = [], {True: 1, False: 0}  # [kind, start, stop] in parts[kind]
    for is_whole in src[rest] < 0:
        k = next_index[bool(is_whole)]
        next_index[bool(is_whole)] += 1
        if runs and runs[-1][0] == is_whole and runs[-1][2] == k:
            runs[-1][2] = k + 1
        else:
            runs.append([bool(is_whole), k, k + 1])

    def modes(field, aiv, singles):
        return [aiv, singles] + [parts[kind][field][a:b] for kind, a, b in runs]

    s_pos = jnp.concatenate(modes(0, sw[:1], s1), axis=0)
    var_pos = _blocks(modes(1, vw[:1], v1))
    bias = _blocks(modes(2, bw[:1], b1))
    sigma_ss = _blocks(modes(3, jnp.zeros_like(ssw[:1]), ss1))
    nonsingular = jnp.concatenate(modes(4, okw[:1], ok1 & okw[0][None]), axis=0)
    rows = ModeRows((sw[:1],), *factors, tuple(modes(0, None, None)[2:]))
    return s_pos, var_pos, bias, sigma_ss, nonsingular, rows


int_weighted_modes = jax.custom_jvp(_int_weighted_modes, nondiff_argnums=(7, 8, 9))


@int_weighted_modes.defjvp
def _int_weighted_modes_jvp(fault_modes, max_order, single_downdates, primals, tangents):
    """The rule of ``tangent`` on the outputs of ``_int_weighted_modes`` (which it calls
    through ``int_weighted_modes``, so that the rule's own coefficients are differentiable
    again): the value is unchanged, bit for bit."""
    g, w_int, var_acc, b_nom, valid, member, excluded = primals
    dg, dw_int, dvar_acc, db_nom = tangents[:4]
    out = int_weighted_modes(*primals, fault_modes, max_order, single_downdates)
    s_pos, _, _, sigma_ss, nonsingular = out
    keep = jnp.concatenate([valid[None], valid[None] & ~excluded], axis=0)  # (K, L, B)
    w = jnp.where(keep, w_int[None], 0.0)
    memf = member.astype(g.dtype)
    g_rows = jnp.moveaxis(g, 1, 0)
    g_centred, inv_s = mode_centering(g_rows, w, memf)
    ds, d_var = wls_tangents(s_pos, w, g_centred, inv_s, memf, jnp.moveaxis(dg, 1, 0),
                             jnp.where(keep, dw_int[None], 0.0))
    d_bias, d_ss = separation_tangents(s_pos, sigma_ss, ds, b_nom, var_acc, db_nom, dvar_acc)
    # (ds is already 0 where a mode's S was set to 0; the mask covers the single modes of a
    # singular all-in-view solution, whose S is kept)
    ds = jnp.where(nonsingular[:, None, None], jnp.stack(ds, axis=1), 0.0)
    return out, (ds, d_var, d_bias, d_ss, np.zeros(nonsingular.shape, jax.dtypes.float0))


def project(sources: Sources, p_const, budget, options, *, single_downdates=True,
            lazy_rows=False) -> Projection:
    """Batch-last: ``sources`` a ``Sources`` of g (L, 3, B) and constellation, var_*, b_nom,
    p_sat, valid (L, B); p_const (C, B); ``options`` a checked ``MHSSOptions`` (its
    ``max_order`` an int, ``fault_modes`` a ``FaultModeRule``). ``single_downdates`` computes
    the L single-source modes by rank-one downdates of the all-in-view factor (C_int weighting
    only); otherwise every mode by its own Cholesky. ``lazy_rows``: a Projection whose S^(i)
    its reader builds (``position_rows``) where the downdates allow (``mode_solutions``).
    ``Projection.invalid_input`` holds ``invalid_input_flags``."""
    C = p_const.shape[0]
    # the inputs arrive transposed (batch-first to batch-last): store them once, or every
    # fused consumer reads them with a stride
    g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid = (
        linalg.materialize(x) for x in (*sources[:6], p_const, sources.valid))
    # from the stored batch-last inputs (cheaper than from the caller's batch-first arrays);
    # always: a flagged geometry's status is INVALID_INPUT (the host raises where it can)
    flags = linalg.materialize(invalid_input_flags(g, constellation, var_int, var_acc, b_nom, p_sat,
                                            valid, C))
    fm = select_fault_modes(valid, constellation, p_sat, p_const, budget, options.fault_modes,
                            options.max_order)
    modes = mode_solutions(Sources(g, constellation, var_int, var_acc, b_nom, p_sat, valid),
                           fm.excluded, C, options, single_downdates=single_downdates,
                           lazy_rows=lazy_rows)
    return finish_projection(fm, modes, budget, flags)


class ModeSolutions(NamedTuple):
    """Every mode's fault-tolerant solution of a batch-last batch, before the priors: what
    ``mode_solutions`` computes from the geometry, weights and biases alone (the fault-mode
    template's exclusions do not depend on the probabilities), and ``finish_projection`` turns
    into a ``Projection`` for one set of priors. K = 1 + candidate modes."""

    s_pos: jax.Array
    """(K, 3, L, B) position rows of S^(i)."""
    var_pos: jax.Array
    """(K, 3, B) sigma_q^(i)^2."""
    bias: jax.Array
    """(K, 3, B) b_q^(i)."""
    sigma_ss: jax.Array
    """(K, 3, B) sigma_ss,q^(i)."""
    nonsingular: jax.Array
    """(K, B)."""
    valid: jax.Array
    """(L, B) the sources used."""
    member: jax.Array
    """(L, C, B) source l is a valid member of constellation c."""
    var_acc: jax.Array
    """(L, B) C_acc diagonal, 0 at padding."""
    rows: ModeRows | None = None
    """``s_pos``'s pieces where ``mode_solutions(lazy_rows=True)`` kept them."""


def mode_solutions(sources: Sources, excluded, n_constellations, options, *,
                   single_downdates=True, lazy_rows=False) -> ModeSolutions:
    """The per-mode solutions of ``project`` (eqs. 8-11) for the candidate modes' exclusions
    ``excluded`` (T, L, B) of ``select_fault_modes``; stored batch-last inputs (``project``:
    ``sources``, whose ``p_sat`` is not read), C = ``n_constellations`` clock slots, the
    checked ``MHSSOptions`` (``max_order``, ``all_in_view_weighting``, ``fault_modes``).
    ``lazy_rows`` (C_int weighting, single downdates): also the pieces of S^(i) (``ModeRows``)
    for a ``Projection`` that leaves S^(i) to its reader; these solutions are then computed
    without ``int_weighted_modes``' derivative rule (autodiff would go through the steps)."""
    g, constellation, var_int, var_acc, b_nom, _, valid = sources
    C, max_order, fault_modes = n_constellations, options.max_order, options.fault_modes
    all_in_view_weighting = options.all_in_view_weighting
    g = jnp.where(valid[:, None, :], g, 0.0)  # (not stored: docs/benchmarks.md)
    w_int = linalg.materialize(linalg.inverse_variance_weights(
        jnp.sqrt(jnp.where(valid, var_int, 1.0)), valid))
    var_acc = linalg.materialize(jnp.where(valid, var_acc, 0.0))
    var_int = jnp.where(valid, var_int, 0.0)
    b_nom = linalg.materialize(jnp.where(valid, b_nom, 0.0))
    member = linalg.materialize(
        valid[:, None, :] & (constellation[:, None, :] == jnp.arange(C)[None, :, None]))
    rows = None
    if all_in_view_weighting == "int" and lazy_rows:
        s_pos, var_pos, bias, sigma_ss, nonsingular, rows = _int_weighted_modes_rows(
            g, w_int, var_acc, b_nom, valid, member, excluded, fault_modes, max_order,
            single_downdates)
    elif all_in_view_weighting == "int":
        s_pos, var_pos, bias, sigma_ss, nonsingular = int_weighted_modes(
            g, w_int, var_acc, b_nom, valid, member, excluded, fault_modes, max_order,
            single_downdates)
    else:
        cols = [g[None, :, 0], g[None, :, 1], g[None, :, 2]]
        cols += [member[None, :, c].astype(g.dtype) for c in range(C)]
        keep = jnp.concatenate([valid[None], valid[None] & ~excluded], axis=0)  # (K, L, B)
        s_pos, var_pos, bias, sigma_ss, nonsingular = _generic_modes(
            keep, w_int, cols, member, b_nom, var_acc, None)
        w_acc = linalg.inverse_variance_weights(
            jnp.sqrt(jnp.where(valid, var_acc, 1.0)), valid)
        s0, _, b0, _, ok0 = _generic_modes(
            valid[None], w_acc, cols, member, b_nom, var_acc, None)
        # seed 004 after eq. 5: S^(0) weighted by C_acc^-1; its integrity sigma is
        # sqrt(S^(0) C_int S^(0)T)_qq
        var0 = jnp.sum(s0[0] ** 2 * var_int[None], axis=1)
        s_pos = s_pos.at[0].set(s0[0])
        var_pos = var_pos.at[0].set(var0)
        bias = bias.at[0].set(b0[0])
        nonsingular = nonsingular.at[0].set(ok0[0])
        sigma_ss = linalg.sqrt0(jnp.sum((s_pos - s_pos[:1]) ** 2 * var_acc[None, None],
                                          axis=2))
        sigma_ss = jnp.where(nonsingular[:, None], sigma_ss, 0.0)
    return ModeSolutions(s_pos, var_pos, bias, sigma_ss, nonsingular, valid, member, var_acc,
                         rows)


def finish_projection(fm, modes: ModeSolutions, budget, invalid_input=False) -> Projection:
    """The ``Projection`` of one set of priors: the fault modes ``fm`` of
    ``select_fault_modes`` (live modes, priors, order) over the solutions ``modes``."""
    return _finish(fm, modes.s_pos, modes.var_pos, modes.bias, modes.sigma_ss,
                   modes.nonsingular, modes.valid, modes.member, modes.var_acc, budget,
                   modes.var_acc.dtype, invalid_input, modes.rows)


def _k_fa(n_modes, K, budget, dtype):
    """K_fa (3, B) of eq. (12) for N_f = n_modes (B,). A table over N_f = 0..K (N_f = 0 read
    as 1), evaluated on the host (an ndtri per geometry and direction was 2 % of the kernel)."""
    nf = np.maximum(np.arange(K + 1), 1)
    pfa_h, pfa_v = budget.p_fa_h / budget.n_es_cont, budget.p_fa_v / budget.n_es_cont
    k_h = jnp.take(jnp.asarray(-special.ndtri(pfa_h / (4.0 * nf)), dtype), n_modes)
    k_v = jnp.take(jnp.asarray(-special.ndtri(pfa_v / (2.0 * nf)), dtype), n_modes)
    return linalg.materialize(jnp.stack([k_h, k_h, k_v], axis=0))


def adjusted_projection(pr, var_int, var_acc, b_nom, valid, budget, opt):
    """The Projection of the Blanch et al. (2015) all-in-view estimator
    (``araim.position_opt``): mode 0's row, sigma, bias and sigma_acc and every mode's
    separation and threshold from the moved rows; the modes, priors and P_NM unchanged.
    var_int, var_acc, b_nom, valid: the kernel's batch-last (L, B) inputs."""
    var_int = jnp.where(valid, var_int, 0.0)
    var_acc = jnp.where(valid, var_acc, 0.0)
    b_nom = jnp.where(valid, b_nom, 0.0)
    s_opt, _ = adjusted_rows(pr.s_pos, pr.sigma, pr.prior, pr.monitored, var_acc,
                             opt.sigma_acc_max_m, opt.prior_min)
    aiv_ok = pr.status != Status.SINGULAR_GEOMETRY
    s_opt = jnp.where(aiv_ok[None, None], s_opt, pr.s_pos[0])
    sigma0 = jnp.sqrt(_sum(s_opt ** 2 * var_int[None], 1))  # (3, B)
    sigma0 = jnp.where(aiv_ok[None], sigma0, pr.sigma[0])
    bias0 = _sum(jnp.abs(s_opt) * b_nom[None], 1)
    ss2 = 0.0
    for m in range(valid.shape[0]):
        ss2 = ss2 + (pr.s_pos[:, :, m] - s_opt[None, :, m]) ** 2 * var_acc[m]
    sigma_ss = jnp.where(pr.monitored[:, None], linalg.sqrt0(ss2), 0.0)
    sigma_ss = jnp.where(sigma_ss <= ZERO_SEPARATION_RTOL * sigma0[None], 0.0, sigma_ss)
    k_fa = _k_fa(pr.n_modes, pr.monitored.shape[0], budget, var_acc.dtype)
    threshold = jnp.where(pr.monitored[:, None], k_fa[None] * sigma_ss, 0.0)
    sigma_acc_u = linalg.sqrt0(_sum(s_opt[2] ** 2 * var_acc, 0))
    return pr._replace(s_pos=pr.s_pos.at[0].set(s_opt), sigma=pr.sigma.at[0].set(sigma0),
                       bias=pr.bias.at[0].set(bias0), sigma_ss=sigma_ss, threshold=threshold,
                       sigma_acc_u=sigma_acc_u)


def _finish(fm, s_pos, var_pos, bias, sigma_ss, nonsingular, valid, member, var_acc, budget,
            dtype, invalid_input=False, rows=None):
    """Thresholds (eq. 12), priors, P_nm and status from the per-mode quantities;
    ``invalid_input`` (B,) marks geometries with an unusable input (status INVALID_INPUT).
    With ``rows`` (``ModeRows``) the Projection carries them instead of S^(i)."""
    false0 = jnp.zeros_like(fm.live[:1])
    live = jnp.concatenate([false0, fm.live], axis=0)
    prior_all = jnp.concatenate([jnp.zeros_like(fm.prior[:1]), fm.prior], axis=0)
    monitored = live & nonsingular
    aiv_ok = nonsingular[0]
    usable = monitored.at[0].set(aiv_ok)
    s_pos_raw = s_pos
    s_pos = jnp.where(usable[:, None, None, :], s_pos, 0.0)
    sigma = jnp.sqrt(jnp.where(usable[:, None, :], jnp.maximum(var_pos, 0.0), 1.0))
    bias = jnp.where(usable[:, None, :], bias, 0.0)
    sigma_ss = jnp.where(usable[:, None, :], sigma_ss, 0.0)
    # A mode whose fault-tolerant solution equals the all-in-view one (a lone SOP in its own
    # constellation, Theorem 1) has S^(i) = S^(0) up to rounding: make its separation and
    # threshold exactly 0 so that tau = 0 (DESIGN.md) instead of a ratio of rounding noise.
    sigma_ss = jnp.where(sigma_ss <= ZERO_SEPARATION_RTOL * sigma[:1], 0.0, sigma_ss)

    n_modes = jnp.sum(monitored, axis=0)
    k_fa = _k_fa(n_modes, monitored.shape[0], budget, dtype)
    threshold = jnp.where(monitored[:, None, :], k_fa[None] * sigma_ss, 0.0)

    prior = jnp.where(monitored, prior_all, 0.0)
    p_nm = fm.p_beyond_order + jnp.sum(jnp.where(live & ~nonsingular, prior_all, 0.0), axis=0)

    n_valid = jnp.sum(valid, axis=0)
    n_present = jnp.sum(jnp.any(member, axis=0), axis=0)
    status = jnp.where(
        n_valid < 3 + n_present + 1, Status.TOO_FEW_SOURCES,
        jnp.where(~aiv_ok, Status.SINGULAR_GEOMETRY,
                  jnp.where(p_nm > budget.p_thresh, Status.UNMONITORED_RISK, Status.OK)))
    status = linalg.materialize(jnp.where(invalid_input, Status.INVALID_INPUT, status))
    sigma_acc_u = linalg.sqrt0(jnp.sum(jnp.where(aiv_ok, s_pos_raw[0, 2], 0.0) ** 2
                                       * var_acc, axis=0))
    excluded = jnp.concatenate([jnp.zeros_like(fm.excluded[:1]), fm.excluded], axis=0)
    if rows is not None:
        s_pos, rows = None, rows._replace(usable=usable)
    return Projection(s_pos, sigma, bias, sigma_ss, threshold, monitored.at[0].set(False),
                      prior, excluded, n_modes, p_nm, fm.order, status.astype(jnp.int8),
                      sigma_acc_u, rows, invalid_input)


