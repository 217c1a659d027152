"""Multiple-hypothesis solution separation (MHSS) protection levels, seed 004 eqs. (8)-(16).

State: [east, north, up, one clock per constellation slot]. For every geometry of a batch the
kernel builds the all-in-view solution (mode 0) and one fault-tolerant solution per candidate
fault mode of ``araim.fault_modes`` (static template, live modes masked), all at once on arrays
of shape (..., K) with K = 1 + number of candidate modes, and:

    W^(i)(l,l) = C_int^-1(l,l) if l is NOT hypothesised faulty, else 0  (after eq. 9, corrected)
    S^(i) = (H^T W^(i) H)^-1 H^T W^(i)                                   (after eq. 9)
    sigma_q^(i)^2 = (H^T W^(i) H)^-1_qq                                  (9)
    b_q^(i) = sum_l |S^(i)_ql| b_nom,l                                   (10)
    sigma_ss,q^(i)^2 = e_q^T (S^(i) - S^(0)) C_acc (S^(i) - S^(0))^T e_q  (11)
    T_i,q = K_fa,q sigma_ss,q^(i), K_fa,H = Q^-1(P_FA_H / (4 N_f)),
                                  K_fa,V = Q^-1(P_FA_V / (2 N_f))        (12)
    PL_q: 2 Q((PL - b^(0))/sigma^(0)) + sum_i P_f^(i) Q((PL - T_i,q - b^(i))/sigma^(i)) = rhs_q
          rhs_H = PHMI_H / 2 (1 - P_nm / (PHMI_V + PHMI_H)),  rhs_V = PHMI_V (...)  (14), (16)
    HPL = sqrt(PL_1^2 + PL_2^2)                                          (15)

All projectors are weighted with C_int^-1, S^(0) included (the ADD and MAAST; DESIGN.md);
``all_in_view_weighting="acc"`` restores the seed's C_acc^-1 for S^(0) (sigma^(0) is then
sqrt(S^(0) C_int S^(0)T)_qq). The all-in-view, single-source and whole-constellation modes
eliminate the clock states exactly (rows centred on their constellation's weighted mean row:
``_centered_rows``); the other modes keep one clock column per constellation, and a clock whose
constellation has no source left in a mode is dropped by putting 1 on its (otherwise all-zero)
diagonal: the position block is unchanged.

Each PL equation is solved in log space (``solve_pl``): two Halley steps from the largest
single-term root, the second from exact values and a bound of the third derivative, which
prove by Taylor's theorem that the returned (conservative, upper) PL lies within
``FAST_PROOF_TOL_M`` above the root (R(PL) <= rhs and R(PL - tol) >= rhs). What that does not
prove takes a few probes (one exact evaluation each) and Newton steps and then, in a
branch run only where needed, safeguarded Newton steps inside a bracket [lo, hi] that is valid
by construction (lo: below the largest PL at which one term alone reaches the budget; hi: every
term at most its share of the budget; both from bounds of Q^-1), proved within
``PL_TOLERANCE_M``.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfc, ndtri
from scipy import special

from oaraim.araim import linalg
from oaraim.araim.batching import (
    CHUNK,
    _traced,
    bucket,
    jit_kernel,
    map_chunks,
    map_threads,
    pad_rows,
    slice_rows,
    unpad,
)
from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.fault_modes import (
    DEFAULT_RULE,
    FaultModeRule,
    check_order,
    event_modes_batch_last,
    fault_mode_rule,
    select_fault_modes,
    template_source,
    to_batch_first,
    to_batch_last,
)
from oaraim.araim.position_opt import adjusted_rows, check_position_optimization
from oaraim.araim.status import Status
from oaraim.araim.validate import batch_source, check_int

#: the PL returned lies within this distance above the exact root of eqs. (14)/(16) (issue: 1e-3)
PL_TOLERANCE_M = 1e-3
#: at most this many iterations (the loop stops earlier once every element of the batch has
#: converged). Measured (PLs not converged, of 3 per geometry) on the 2000 random geometries of
#: tests/test_mhss.py (Table I, up to 150 modes, P_s^S up to 0.1, sigma_URA^S up to 25 m,
#: orders up to 3): 5 iterations leave 41, 8 leave 9, 12 leave 1, 16 none; order 1 needs 5;
#: the 9 GPS + 4 SOP bench case 2 (Newton's last step taken unevaluated).
#: Non-convergence is reported, never hidden.
PL_ITERATIONS = 20
#: a Newton step shorter than this ends the iteration of its element (the PL tolerance is 1e-3 m):
#: below the root the step is then taken without evaluation (its error is ~ step^2), above it
#: the PL is the last iterate, at most this (+ PL_MARGIN_M) above the root. 1e-7 m cost one more
#: evaluation per chunk (measured: 3 instead of 2 loop iterations, 9 GPS + 4 SOPs)
NEWTON_STEP_TOL_M = 1e-5
#: the PL returned is the converged Newton iterate plus this (covers the iterate's error, which
#: after a step below NEWTON_STEP_TOL_M is of the order of that step squared)
PL_MARGIN_M = 1e-6
_SQRT1_2 = 0.7071067811865476
_INV_SQRT_2PI = 0.3989422804014327  # 1 / sqrt(2 pi)
#: sigma_ss below this fraction of sigma^(0) is rounding noise: the mode's separation is zero
ZERO_SEPARATION_RTOL = 1e-9


def q_function(x):
    """Q(x) = P(N(0,1) > x) = erfc(x / sqrt 2) / 2 (cheaper than ndtr; DESIGN.md)."""
    return 0.5 * erfc(x * _SQRT1_2)


# Cephes ndtr.c coefficients (the ones XLA's erfc uses): erfc(x) = exp(-x^2) P(x) / Q(x) for
# 1 <= x < 8 (relative error 3e-10 when continued beyond 8, where Q(t) < 1e-29 adds nothing to
# a PL equation), erf(x) = x T(x^2) / U(x^2) for |x| < 1
_ERFC_P = (2.46196981473530512524e-10, 5.64189564831068821977e-1, 7.46321056442269912687e0,
           4.86371970985681366614e1, 1.96520832956077098242e2, 5.26445194995477358631e2,
           9.34528527171957607540e2, 1.02755188689515710272e3, 5.57535335369399327526e2)
_ERFC_Q = (1.0, 1.32281951154744992508e1, 8.67072140885989742329e1, 3.54937778887819891062e2,
           9.75708501743205489753e2, 1.82390916687909736289e3, 2.24633760818710981792e3,
           1.65666309194161350182e3, 5.57535340817727675546e2)
_ERF_T = (9.60497373987051638749e0, 9.00260197203842689217e1, 2.23200534594684319226e3,
          7.00332514112805075473e3, 5.55923013010394962768e4)
_ERF_U = (1.0, 3.35617141647503099647e1, 5.21357949780152679795e2, 4.59432382970980127987e3,
          2.26290000613890934246e4, 4.92673942608635921086e4)


def _poly(c, x):
    out = c[0]
    for a in c[1:]:
        out = out * x + a
    return out


def _q_and_density(t):
    """(Q(t), phi(t)) for the root finder. Q as q_function but with two of erfc's three Cephes
    branches and one division instead of three (about half the cost of
    jax.scipy.special.erfc on CPU; agrees with it to 1e-15 relative wherever Q(t) > 1e-29);
    phi(t) = exp(-t^2/2) / sqrt(2 pi), the standard normal density, shares erfc's exponential,
    so the derivative of a PL equation costs one multiply per term."""
    return _q_density_square(t)[:2]


def _q_density_square(t):
    """(Q(t), phi(t), z) of ``_q_and_density`` and z = min(|t| / sqrt 2, 27)^2, which is t^2 / 2
    for |t| < 38.18 (where phi(t) > 0 in float64)."""
    x = jnp.minimum(jnp.abs(t) * _SQRT1_2, 27.0)  # erfc(27) underflows to 0
    small = x < 1.0
    z = x * x
    e = jnp.exp(-z)
    u = _poly(_ERF_U, z)
    num = jnp.where(small, u - x * _poly(_ERF_T, z), e * _poly(_ERFC_P, x))
    neg = t < 0
    # Q(t) = Q(|t|) or 1 - Q(|t|), written with the division used once: XLA keeps a division
    # with two users out of the consumer's fusion (one small loop per term, measured 3x slower)
    q = jnp.where(neg, 1.0, 0.0) + jnp.where(neg, -0.5, 0.5) * num / jnp.where(
        small, u, _poly(_ERFC_Q, x))
    return q, e * _INV_SQRT_2PI, z


def _q_and_density_fast(t):
    """(Q(t), phi(t)) as ``_q_and_density`` with erfc's 1 <= x < 8 branch used for all x
    (relative error of erfc below 1e-8 on [0, 1), measured against SciPy; tests/test_mhss.py):
    for the fast path's Halley steps, whose result the probe proves with the exact Q (an error
    of 1e-8 in R moves their root by ~1e-8 sd / z, well inside ``PL_MARGIN_M``)."""
    x = jnp.minimum(jnp.abs(t) * _SQRT1_2, 27.0)
    e = jnp.exp(-x * x)
    neg = t < 0
    q = jnp.where(neg, 1.0, 0.0) + jnp.where(neg, -0.5, 0.5) * e * _poly(_ERFC_P, x) / _poly(
        _ERFC_Q, x)
    return q, e * _INV_SQRT_2PI


def q_inverse(p):
    """Q^-1(p) = -Phi^-1(p)."""
    return -ndtri(p)


class MHSSResult(NamedTuple):
    hpl_m: jax.Array  # (...) eq. (15); inf where status != OK
    vpl_m: jax.Array  # (...) eq. (16)
    emt_m: jax.Array  # (...) effective monitor threshold (vertical), ADD
    sigma_acc_u_m: jax.Array  # (...) vertical accuracy sigma of the all-in-view solution
    n_modes: jax.Array  # (...) N_f: monitored fault modes
    p_not_monitored: jax.Array  # (...) P_NM of eqs. (14), (16)
    status: jax.Array  # (...) Status
    order: jax.Array  # (...) number of simultaneous faulty constellations monitored
    pl_enu_m: jax.Array  # (..., 3) PL_1, PL_2, PL_3
    position_adjusted: jax.Array  # (...) bool: the PLs are those of the Blanch et al. (2015)
    #                               estimator (``position_optimization``), not of the WLS one


class Projection(NamedTuple):
    """Everything the PL equations and the solution-separation test need, per mode.

    Batch-last inside the kernels (one flattened batch axis B last); K = 1 + candidate modes,
    mode 0 the all-in-view solution."""

    s_pos: jax.Array  # (K, 3, L, B) position rows of S^(i)
    sigma: jax.Array  # (K, 3, B) sigma_q^(i)
    bias: jax.Array  # (K, 3, B) b_q^(i)
    sigma_ss: jax.Array  # (K, 3, B) sigma_ss,q^(i) (0 for i = 0)
    threshold: jax.Array  # (K, 3, B) T_i,q (0 for i = 0 and for unmonitored modes)
    monitored: jax.Array  # (K, B) live and nonsingular, False for i = 0
    prior: jax.Array  # (K, B) P_f^(i) of monitored modes, 0 otherwise
    excluded: jax.Array  # (K, L, B) sources hypothesised faulty (none for i = 0)
    n_modes: jax.Array  # (B,)
    p_not_monitored: jax.Array  # (B,)
    order: jax.Array  # (B,)
    status: jax.Array  # (B,) status before root finding
    sigma_acc_u: jax.Array  # (B,)


# Stores dropped: where an intermediate is not stored with ``linalg.materialize`` although an
# earlier version of the kernel stored it. Every remaining store site of the
# bench kernel was measured dropped alone (one core, CPU time, interleaved), then together.
# Seven stores cost more than they saved once the root finder evaluates its terms twice
# instead of three times: cw and cw2 of ``solve_pl``, the start factors of
# ``_pls_from_projection``, 1 / s_c of ``_centered_rows``, the inverse entries of
# ``_whole_modes``, the single modes' outputs and the masked rows g of ``_project``. Without
# them, outputs bit-identical: one core 1.84 -> 1.69 CPU-us per PL (cw/cw2 alone: 2.01 ->
# 1.83), 2 threads 848k -> 929k PL/s (cw/cw2), then 884k -> 922k (the other five); 8 SOPs at
# order 2 +1.4 %. Dropping also the stores of the centred rows, s_pos, whole-mode bias and
# sigma_ss, w_int and member made it slower (one core 2.06 against 1.84).


def _blocks(parts):
    """jnp.concatenate(parts, axis=0), written as in-place updates of one buffer: XLA fuses a
    concatenation with the computations of its parts into one loop that branches on every
    element (measured: a scalar loop, 10x slower than the parts alone); an update slice loops
    over its part only."""
    out = jnp.zeros((sum(p.shape[0] for p in parts),) + parts[0].shape[1:], parts[0].dtype)
    start = 0
    for p in parts:
        out = jax.lax.dynamic_update_slice_in_dim(out, p, start, axis=0)
        start += p.shape[0]
    return out


#: sums and maxima over short static axes written out (``linalg.unrolled``)
_sum = linalg.sum_axis
_max = linalg.max_axis


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
    bias, sigma_ss = linalg.materialize(bias), linalg.materialize(jnp.sqrt(ss2))
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
        # (not stored: note above ``_blocks``)
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
           for q in range(3)]  # (not stored: note above ``_blocks``)
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
    return (s_pos, var_pos, linalg.materialize(bias), linalg.materialize(jnp.sqrt(ss2)), ok,
            inv)


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
    bias (L, 3, B), sigma_ss (L, 3, B), ok (L, B).
    """
    L = w_int.shape[0]
    u = [linalg.materialize(sum(inv0[q][a][None] * gt[a] for a in range(3)))
         for q in range(3)]  # (L, B)
    memf = member.astype(w_int.dtype)
    same = sum(memf[:, None, c] * memf[None, :, c] for c in range(member.shape[1]))  # (L, L, B)
    p = sum(gt[a][:, None, :] * u[a][None, :, :] for a in range(3)) + same * inv_s_src[:, None]
    s0 = jnp.stack([w_int * u[q] for q in range(3)], axis=0)  # (3, L, B)
    p_ll = sum(gt[a] * u[a] for a in range(3)) + inv_s_src  # (L, B)
    r = 1.0 - w_int * p_ll
    ok = r > SINGLE_REDUNDANCY_TOLERANCE
    r_safe = jnp.where(ok, r, 1.0)
    eye = jnp.eye(L, dtype=bool)[:, :, None]
    c = linalg.materialize(
        jnp.where(eye, 0.0, (w_int / r_safe)[:, None, :] * p * w_int[None, :, :]))
    u_pos = jnp.stack(u, axis=1)  # (L, 3, B): u_l,q
    s_pos = s0[None] + u_pos[:, :, None, :] * c[:, None, :, :]  # (L, 3, L, B), m = l wrong
    s_pos = jnp.where(eye[:, None], 0.0, s_pos)
    s_pos = jnp.where(ok[:, None, None, :], s_pos, 0.0)
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
    sigma_ss = jnp.abs(u_pos) * jnp.sqrt(spread)[:, None, :]
    # (not stored before ``_blocks`` writes them into the mode arrays: note above it)
    return s_pos, var_pos, bias, sigma_ss, ok


def _project(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, budget,
             max_order, all_in_view_weighting, single_downdates=True, input_flags=False,
             fault_modes: FaultModeRule = DEFAULT_RULE):
    """Batch-last: g (L, 3, B); constellation, var_*, b_nom, p_sat, valid (L, B); p_const
    (C, B). ``single_downdates`` computes the L single-source modes by rank-one downdates of
    the all-in-view factor (C_int weighting only); otherwise every mode by its own Cholesky.
    ``input_flags``: returns (Projection, ``_input_flags``) instead. ``fault_modes``: the
    convention (``araim.FaultModeRule``)."""
    C = p_const.shape[0]
    L = valid.shape[0]
    # the inputs arrive transposed (batch-first to batch-last): store them once, or every
    # fused consumer reads them with a stride
    g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid = (
        linalg.materialize(x) for x in (g, constellation, var_int, var_acc, b_nom, p_sat,
                                        p_const, valid))
    # from the stored batch-last inputs (measured, bench case, 2 threads: the flags from the
    # caller's batch-first arrays cost 4 % of the kernel); always: a flagged geometry's status
    # is INVALID_INPUT (the host raises where it can)
    flags = linalg.materialize(_input_flags(g, constellation, var_int, var_acc, b_nom, p_sat,
                                            valid, C))
    fm = select_fault_modes(valid, constellation, p_sat, p_const, budget, fault_modes,
                            max_order)
    g = jnp.where(valid[:, None, :], g, 0.0)  # (not stored: note above ``_blocks``)
    w_int = linalg.materialize(linalg.inverse_variance_weights(
        jnp.sqrt(jnp.where(valid, var_int, 1.0)), valid))
    var_acc = linalg.materialize(jnp.where(valid, var_acc, 0.0))
    var_int = jnp.where(valid, var_int, 0.0)
    b_nom = linalg.materialize(jnp.where(valid, b_nom, 0.0))
    member = linalg.materialize(
        valid[:, None, :] & (constellation[:, None, :] == jnp.arange(C)[None, :, None]))
    cols = [g[None, :, 0], g[None, :, 1], g[None, :, 2]]
    cols += [member[None, :, c].astype(g.dtype) for c in range(C)]

    if single_downdates and all_in_view_weighting == "int":
        # the all-in-view solution and the whole-constellation modes on clock-eliminated rows,
        # the singles by downdates of the all-in-view inverse, other modes (a source and
        # whole constellations, order >= 2) by their own Cholesky; assembled in template order
        src = template_source(fault_modes, L, C, max_order)
        rest = np.arange(L, src.size)
        whole = rest[src[rest] < 0]
        gt, inv_s_src = _centered_rows(g, w_int, member)
        keep = jnp.concatenate([valid[None], valid[None] & ~fm.excluded[whole]], axis=0)
        sw, vw, bw, ssw, okw, inv = _whole_modes(keep, w_int, gt, b_nom, var_acc)
        s1, v1, b1, ss1, ok1 = _single_modes(w_int, gt, inv_s_src, member, b_nom, var_acc,
                                             [[e[0] for e in row] for row in inv], vw[0])
        parts = {True: (sw, vw, bw, ssw, okw)}
        if whole.size < rest.size:
            parts[False] = _generic_modes(valid[None] & ~fm.excluded[rest[src[rest] >= 0]],
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
    else:
        keep = jnp.concatenate([valid[None], valid[None] & ~fm.excluded], axis=0)  # (K, L, B)
        s_pos, var_pos, bias, sigma_ss, nonsingular = _generic_modes(
            keep, w_int, cols, member, b_nom, var_acc, None)
        if all_in_view_weighting == "acc":
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
            sigma_ss = jnp.sqrt(jnp.sum((s_pos - s_pos[:1]) ** 2 * var_acc[None, None], axis=2))
            sigma_ss = jnp.where(nonsingular[:, None], sigma_ss, 0.0)
    pr = _finish(fm, s_pos, var_pos, bias, sigma_ss, nonsingular, valid, member, var_acc,
                 budget, g.dtype, flags)
    return (pr, flags) if input_flags else pr


def _k_fa(n_modes, K, budget, dtype):
    """K_fa (3, B) of eq. (12) for N_f = n_modes (B,). A table over N_f = 0..K (N_f = 0 read
    as 1), evaluated on the host (an ndtri per geometry and direction was 2 % of the kernel)."""
    nf = np.maximum(np.arange(K + 1), 1)
    pfa_h, pfa_v = budget.p_fa_h / budget.n_es_cont, budget.p_fa_v / budget.n_es_cont
    k_h = jnp.take(jnp.asarray(-special.ndtri(pfa_h / (4.0 * nf)), dtype), n_modes)
    k_v = jnp.take(jnp.asarray(-special.ndtri(pfa_v / (2.0 * nf)), dtype), n_modes)
    return linalg.materialize(jnp.stack([k_h, k_h, k_v], axis=0))


def _adjusted_projection(pr, var_int, var_acc, b_nom, valid, budget, opt):
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
    sigma_ss = jnp.where(pr.monitored[:, None], jnp.sqrt(ss2), 0.0)
    sigma_ss = jnp.where(sigma_ss <= ZERO_SEPARATION_RTOL * sigma0[None], 0.0, sigma_ss)
    k_fa = _k_fa(pr.n_modes, pr.monitored.shape[0], budget, var_acc.dtype)
    threshold = jnp.where(pr.monitored[:, None], k_fa[None] * sigma_ss, 0.0)
    sigma_acc_u = jnp.sqrt(_sum(s_opt[2] ** 2 * var_acc, 0))
    return pr._replace(s_pos=pr.s_pos.at[0].set(s_opt), sigma=pr.sigma.at[0].set(sigma0),
                       bias=pr.bias.at[0].set(bias0), sigma_ss=sigma_ss, threshold=threshold,
                       sigma_acc_u=sigma_acc_u)


def _finish(fm, s_pos, var_pos, bias, sigma_ss, nonsingular, valid, member, var_acc, budget,
            dtype, invalid_input=False):
    """Thresholds (eq. 12), priors, P_nm and status from the per-mode quantities;
    ``invalid_input`` (B,) marks geometries with an unusable input (status INVALID_INPUT)."""
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
    sigma_acc_u = jnp.sqrt(jnp.sum(jnp.where(aiv_ok, s_pos_raw[0, 2], 0.0) ** 2 * var_acc,
                                   axis=0))
    excluded = jnp.concatenate([jnp.zeros_like(fm.excluded[:1]), fm.excluded], axis=0)
    return Projection(s_pos, sigma, bias, sigma_ss, threshold, monitored.at[0].set(False),
                      prior, excluded, n_modes, p_nm, fm.order, status.astype(jnp.int8),
                      sigma_acc_u)


#: up to this many terms the risk sum is written out term by term (one fused loop over the
#: batch, no (terms, ...) temporary and no reduction over a non-minor axis)
UNROLL_TERMS = 64
#: ... and for the rarely run parts of ``solve_pl`` (its Newton rounds and bracketed fallback):
#: none, one array over the terms. Written out, each of their 4 evaluation sites is a separate
#: copy of the per-term loops, and compiling the kernel took twice as long (measured, bench
#: inputs: order 1 9.5 s -> 5.3 s, order 2 19.5 s -> 8.6 s; the full test suite, which
#: compiles it dozens of times, 19 -> 15 min). The bench case never runs them
RARE_UNROLL_TERMS = 0


def _risk(x, coef, mean, inv_sd, unroll_terms=UNROLL_TERMS):
    """(R, D): R(x) = sum_j coef_j Q((x - mean_j) / sd_j) and D(x) = -dR/dx = sum_j coef_j
    phi((x - mean_j) / sd_j) / sd_j >= 0; terms on axis 0, x of shape coef.shape[1:]."""
    if coef.shape[0] <= unroll_terms:
        r = d = 0.0
        for j in range(coef.shape[0]):
            q, phi = _q_and_density((x - mean[j]) * inv_sd[j])
            r = r + coef[j] * q
            d = d + (coef[j] * inv_sd[j]) * phi
        return r, d
    q, phi = _q_and_density((x[None] - mean) * inv_sd)
    return jnp.sum(coef * q, axis=0), jnp.sum(coef * inv_sd * phi, axis=0)


#: A&S 26.2.23 (Abramowitz & Stegun, Handbook, 1964): Q^-1(p) ~ t - (c0 + c1 t + c2 t^2) /
#: (1 + d1 t + d2 t^2 + d3 t^3), t = sqrt(-2 ln p), for 0 < p <= 1/2, |error| < 4.5e-4 (measured
#: 4.44e-4 against scipy.special.ndtri on a log grid over [1e-300, 0.5]: tests/test_mhss.py)
_AS_C = (2.515517, 0.802853, 0.010328)
_AS_D = (1.432788, 0.189269, 0.001308)
#: the bracket ends use the approximation widened by this (more than twice its error bound)
Q_INVERSE_APPROX_MARGIN = 1e-3


def _as_26_2_23(t):
    """A&S 26.2.23 in terms of t = sqrt(-2 ln p): Q^-1(p) ~ t - (c0 + c1 t + c2 t^2) /
    (1 + d1 t + d2 t^2 + d3 t^3) for 0 < p <= 1/2."""
    return t - (_AS_C[0] + t * (_AS_C[1] + t * _AS_C[2])) / (
        1.0 + t * (_AS_D[0] + t * (_AS_D[1] + t * _AS_D[2])))


def q_inverse_approx(p):
    """Q^-1(p) for 0 < p < 1 to within 4.5e-4 (A&S 26.2.23, by symmetry above 1/2): one log,
    one square root and one division, against two logs and three branches of ndtri. The root
    finder's bracket only has to be valid, so it uses this widened by
    ``Q_INVERSE_APPROX_MARGIN`` (measured: the exact ndtri per term and bracket end was 28 % of
    the whole MHSS kernel)."""
    upper = p > 0.5
    t = jnp.sqrt(-2.0 * jnp.log(jnp.where(upper, 1.0 - p, p)))
    k = _as_26_2_23(t)
    return jnp.where(upper, -k, k)


def _start_factor(coef, rhs):
    """k_start of ``_bound_factors``: ``q_inverse_approx(rhs / coef)`` for the terms that alone
    can reach the budget (coef > rhs), -inf for the others."""
    active = coef > 0
    p_lo = rhs[None] / jnp.where(active, coef, 1.0)
    active = active & (p_lo < 1)
    return jnp.where(active, q_inverse_approx(jnp.where(active, p_lo, 0.5)), -jnp.inf)


def _fast_start_factor(coef, rhs, log_coef=None):
    """The fast path's start factor: ``q_inverse_approx(rhs / coef)`` for the terms that alone
    can reach the budget (coef > rhs; -inf for the others), with p = rhs / coef above 1/2 taken
    as 1/2 (factor ~0; a start needs no bound) and ln p = ln rhs - ln coef, no division for p.
    ``log_coef``: ln coef (1 where coef is 0) when the caller shares it between right-hand sides
    (measured: the kernel 5 % faster than with ln coef per right-hand side)."""
    active = coef > rhs[None]
    if log_coef is None:
        log_coef = jnp.log(jnp.where(coef > 0, coef, 1.0))
    t = jnp.sqrt(-2.0 * jnp.minimum(jnp.log(rhs)[None] - log_coef, -0.6931471805599453))
    return jnp.where(active, _as_26_2_23(t), -jnp.inf)


def _bound_factors(coef, rhs):
    """Per-term factors of the bracket of ``solve_pl``: (k_start, k_hi) with the start and the
    bracket ends max_j mean_j + sd_j k_j (k = -inf: the term does not count).

    lo: one term alone reaches the budget (there k_lo = k_start - ``Q_INVERSE_APPROX_MARGIN``
    <= Q^-1(rhs / coef)); the start uses the approximate Q^-1 itself. hi: terms that cannot
    reach the budget even together (coef < rhs, total D < rhs) are bounded by D; the other
    n_big terms get (rhs - D) / n_big each (k_hi >= Q^-1 of that share, Chernoff). Without
    that split, one mode with a tiny prior and a huge mean (e.g. an SOP-only subset) pushed hi
    to hundreds of metres and regula falsi crawled. These depend on coef and rhs only, not on
    mean and sd."""
    k_start = _start_factor(coef, rhs)
    active = coef > 0
    safe = jnp.where(active, coef, 1.0)
    small = active & (coef < rhs[None])
    d_small = jnp.sum(jnp.where(small, coef, 0.0), axis=0)
    split = d_small < rhs
    big = active & ~(small & split[None])
    n_big = jnp.sum(big, axis=0).astype(coef.dtype)
    # (stored: fused into the per-term consumers, the two sums over terms ran once per term)
    share = linalg.materialize(jnp.where(split, rhs - d_small, rhs) / n_big)
    big = big & (share[None] < safe)  # p_hi = share / coef < 1
    # Chernoff: Q(k) <= exp(-k^2 / 2) / 2, so k = sqrt(-2 ln(2 p)) (0 for p >= 1/2) has
    # Q(k) <= p: a valid upper end, up to ~0.5 sd looser than Q^-1 (only the rare secant
    # fallback sees it), with ln coef once per term (coef may come without the right-hand
    # sides' axis) and a square root per term and right-hand side
    log_2p_hi = jnp.log(2.0 * share)[None] - jnp.log(jnp.where(coef > 0, coef, 1.0))
    k_hi = jnp.where(big, jnp.sqrt(jnp.maximum(-2.0 * log_2p_hi, 0.0)), -jnp.inf)
    return k_start, k_hi


def _risk_curvature(x, coef, mean, inv_sd, cw, cw2):
    """(R, D, D2) at x: R and D = -R' as ``_risk``, and D2 = R'' = sum_j coef_j t_j
    phi(t_j) / sd_j^2 (t_j = (x - mean_j) / sd_j); cw = coef / sd and cw2 = coef / sd^2. Q from
    ``_q_and_density_fast`` (relative error < 1e-8): only the fast path's steps use this."""
    if coef.shape[0] <= UNROLL_TERMS:
        r = d = d2 = 0.0
        for j in range(coef.shape[0]):
            t = (x - mean[j]) * inv_sd[j]
            q, phi = _q_and_density_fast(t)
            r = r + coef[j] * q
            d = d + cw[j] * phi
            d2 = d2 + cw2[j] * (t * phi)
        return r, d, d2
    t = (x[None] - mean) * inv_sd
    q, phi = _q_and_density_fast(t)
    return jnp.sum(coef * q, axis=0), jnp.sum(cw * phi, axis=0), jnp.sum(cw2 * t * phi, axis=0)


def _risk_lower_slope(x, delta, coef, mean, inv_sd, cw, unroll_terms=UNROLL_TERMS):
    """(R(x), Dl(x)) with R(x - delta) >= R(x) + delta Dl(x), delta >= 0; Dl <= D = -R'(x).

    Per term f = coef Q((x - mean) / sd): by the mean value theorem f(x - delta) - f(x) =
    delta |f'| somewhere in [x - delta, x], and |f'| = coef phi(t) / sd is smallest at an end
    of the interval (phi is unimodal), so it is at least coef phi(t) / sd min(1, phi(t - e) /
    phi(t)), e = delta / sd, with phi(t - e) / phi(t) = exp(t e - e^2 / 2) >= 1 + t e - e^2 / 2.
    Where t >= e / 2 (every term convex on the interval, the usual case) the factor is 1 and
    Dl = D."""
    if coef.shape[0] <= unroll_terms:
        r = dl = 0.0
        for j in range(coef.shape[0]):
            t = (x - mean[j]) * inv_sd[j]
            q, phi = _q_and_density(t)
            e = delta * inv_sd[j]
            r = r + coef[j] * q
            dl = dl + cw[j] * phi * jnp.clip(1.0 + e * (t - 0.5 * e), 0.0, 1.0)
        return r, dl
    t = (x[None] - mean) * inv_sd
    q, phi = _q_and_density(t)
    e = delta * inv_sd
    return (jnp.sum(coef * q, axis=0),
            jnp.sum(cw * phi * jnp.clip(1.0 + e * (t - 0.5 * e), 0.0, 1.0), axis=0))


def _third_bound_term(phi, z):
    """phi(t) (2 + 1.01 t^2) + 1e-290 with z = t^2 / 2: one term's share of ``_risk_taylor``'s
    B3 before its weight cw3_j."""
    return phi * (2.0 + 2.02 * z) + 1e-290


def _risk_taylor(x, coef, mean, inv_sd, cw, cw2, cw3, unroll_terms=UNROLL_TERMS):
    """(R, D, D2, B3) at x with the exact Q: R, D = -R' and D2 = R'' as ``_risk_curvature``,
    and B3 with |R'''| <= ``TAYLOR_B3_FACTOR`` B3 on [x - h, x + h] wherever h max_j(1 / sd_j)
    <= ``TAYLOR_E_MAX`` (terms with coef_j > 0), which ``solve_pl``'s proof checks.

    R''' = sum_j coef_j (1 - t_j^2) phi(t_j) / sd_j^3; a point s of the interval lies within
    e = h / sd_j <= 0.01 of t_j, so |1 - s^2| <= 1 + (|t_j| + e)^2 <= 2 + 1.01 t_j^2 and
    phi(s) <= phi(t_j) exp(|t_j| e) <= 1.5 phi(t_j) for |t_j| <= 38 (|t_j| e <= 0.38). B3 =
    sum_j cw3_j phi(t_j) (2 + 2.02 z_j) (z_j = t_j^2 / 2, ``_q_density_square``) plus 1e-290
    sum_j cw3_j, which covers the terms whose phi underflows or whose z is clamped (|t_j| >
    37.5: there |1 - s^2| phi(s) < 1e-303) (``_third_bound_term``)."""
    if coef.shape[0] <= unroll_terms:
        r = d = d2 = b3 = 0.0
        for j in range(coef.shape[0]):
            t = (x - mean[j]) * inv_sd[j]
            q, phi, z = _q_density_square(t)
            r = r + coef[j] * q
            d = d + cw[j] * phi
            d2 = d2 + cw2[j] * (t * phi)
            b3 = b3 + cw3[j] * _third_bound_term(phi, z)
        return r, d, d2, b3
    t = (x[None] - mean) * inv_sd
    q, phi, z = _q_density_square(t)
    return (jnp.sum(coef * q, axis=0), jnp.sum(cw * phi, axis=0),
            jnp.sum(cw2 * t * phi, axis=0), jnp.sum(cw3 * _third_bound_term(phi, z), axis=0))


#: ``_risk_taylor``'s bound holds for steps h with h / sd_j at most this (every term with
#: coef_j > 0), and with the factor below (>= exp(38 TAYLOR_E_MAX) = 1.46)
TAYLOR_E_MAX = 0.01
TAYLOR_B3_FACTOR = 1.5


def _halley_step(x, r, d, d2, z_rhs):
    """One Halley step on h(x) = z(rhs) - z(R(x)), z(S) = sqrt(-2 ln S), from R, D = -R' and
    D2 = R'' at x: with g = -h' = D / (R z) and h'' = D2 / (R z) - D^2 (1 - 1 / z^2) / (R^2 z),
    x + n / (1 - n h'' / (2 g)), n = h / g the Newton step (the factor's denominator kept
    >= 1/2). NaN or inf where R >= 1 or R underflows: the caller's proof then fails."""
    z = jnp.sqrt(jnp.maximum(-2.0 * jnp.log(r), 0.0))
    rz = r * z
    g = d / rz
    hpp = d2 / rz - (d / r) ** 2 * (1.0 - 1.0 / (z * z)) / z
    n = (z_rhs - z) / g
    return x + n / jnp.maximum(1.0 - n * hpp / (2.0 * g), 0.5)


#: ``solve_pl``'s fast path: two Halley steps (measured on 3000 PL equations of the 9 GPS + 4
#: SOP bench case: after the first, with the approximate Q, the error is up to 9.1e-4 m, below
#: the root in 21 % of them; after the second, from exact values, up to 3e-11 m), proved by
#: Taylor's theorem; then at most this many probes for the elements that proof does not cover,
#: the first at the second Halley step's point, each later one a Newton step from the last
#: probe; the rest goes to the bracketed solver. Measured on the 2000 random geometries of
#: tests/test_mhss.py (bracketed solver disabled), geometries with a PL not proved after 0..5
#: probes: order 1 141 / 78 / 2 / 0; order 2 439 / 188 / 39 / 17 / 5 / 2; order 3 516 / 232 /
#: 65 / 38 / 17 / 11 (the earlier probe-only path: exactly these shifted by one probe); the bench
#: case: 1 geometry of 65,536 after the Taylor proof, none after one probe
FAST_EXTRA_ROUNDS = 5
#: the fast path proves its PLs within this of the root (tighter than ``PL_TOLERANCE_M``, which
#: the bracketed solver proves): after its Halley steps the bench case is within 3e-11 m, and
#: an element proved only to 1e-3 m would carry up to 1e-3 m of needless margin
FAST_PROOF_TOL_M = 1e-4


def solve_pl(coef, mean, sd, rhs, iterations=PL_ITERATIONS, start=None, ignore=None):
    """Root of sum_j coef_j Q((PL - mean_j)/sd_j) = rhs; terms on axis 0 (J, ...), rhs (...).

    Same contract as ``_solve_pl_bracketed``: returns (pl, converged), pl never below the root
    and within ``PL_TOLERANCE_M`` of it where converged.

    Fast path, two evaluations of the terms: a Halley step (z space, ``_halley_step``) from the
    start of ``_solve_pl_bracketed`` with the approximate Q of ``_risk_curvature`` to x1; at
    x1 the exact R, R', R'' and a bound of |R'''| near x1 (``_risk_taylor``), and a second
    Halley step to x2. pl = x2 + ``PL_MARGIN_M`` is proved from x1 by Taylor's theorem with
    tol = ``FAST_PROOF_TOL_M``, for h = pl - x1 and pl - tol - x1:
      R(x1 + h) <= R - D h + D2 h^2 / 2 + |R'''|max |h|^3 / 6 <= rhs at pl (at or above the
      root), and R(x1 + h) >= ... - |R'''|max |h|^3 / 6 >= rhs at pl - tol (at or below it).
    (the third-order term is ~1e-8 of R for the bench's |h| ~ 1e-3 m; the proof needs ~1e-6.)
    Elements that proof does not cover take up to ``FAST_EXTRA_ROUNDS`` probes, each an exact
    evaluation at its point that proves both sides at once (R(pl) <= rhs, and R(pl) + tol
    Dl(pl) >= rhs with Dl a lower bound of the slope on [pl - tol, pl], ``_risk_lower_slope``),
    the first at x2, the next ones a Newton step from the last probe (a loop that ends at once
    when every element is proved). What is still not proved is solved by the bracketed solver,
    in a branch taken only when a chunk has such an element (``jax.lax.cond``). Each element's
    result depends on its own terms only, never on the rest of the batch.

    ``start``: the starting point, max_j mean_j + sd_j ``_fast_start_factor``_j (about the
    largest single-term root), when the caller has it. ``ignore``: elements whose result the
    caller discards (they never trigger the loop or the bracketed branch). Measured on the 9
    GPS + 4 SOP bench case: every element proved by the Taylor step; three evaluations (two
    Halley steps, then a probe, as an earlier version did) took 4-5 % more of the whole kernel.
    """
    coef = jnp.broadcast_to(coef, mean.shape)
    if start is None:
        k = _fast_start_factor(coef, rhs)
        start = jnp.max(jnp.where(k > -jnp.inf, mean + sd * k, -jnp.inf), axis=0)
    inv_sd = 1.0 / sd
    cw = coef * inv_sd  # (not stored: note above ``_blocks``)
    cw2 = cw * inv_sd
    z_rhs = jnp.sqrt(-2.0 * jnp.log(rhs))
    x1 = _halley_step(start, *_risk_curvature(start, coef, mean, inv_sd, cw, cw2), z_rhs)
    r, d, d2, b3 = _risk_taylor(x1, coef, mean, inv_sd, cw, cw2, cw2 * inv_sd)
    tol = FAST_PROOF_TOL_M
    x2 = _halley_step(x1, r, d, d2, z_rhs)
    pl = x2 + PL_MARGIN_M
    hp = pl - x1
    hm = hp - tol
    h = jnp.maximum(jnp.abs(hp), jnp.abs(hm))
    rem = (TAYLOR_B3_FACTOR / 6.0) * b3 * h**3
    inv_sd_max = _max(jnp.where(coef > 0, inv_sd, 0.0), 0)
    proved = ((h * inv_sd_max <= TAYLOR_E_MAX) & (r - d * hp + 0.5 * d2 * hp * hp + rem <= rhs)
              & (r - d * hm + 0.5 * d2 * hm * hm - rem >= rhs))
    settled = proved if ignore is None else proved | ignore

    def more(carry):
        return (carry[0] < FAST_EXTRA_ROUNDS) & ~jnp.all(carry[-1])

    def probe_and_step(carry):
        """Probe the candidate point of the elements not yet proved, and propose a Newton step
        (z space) from there; the others keep their values. The slope is the probe's Dl (= D
        where every term is convex near the probe; smaller, so a longer step, elsewhere)."""
        i, x, pl, proved, settled = carry
        pl2 = x + PL_MARGIN_M
        r, dl = _risk_lower_slope(pl2, tol, coef, mean, inv_sd, cw, RARE_UNROLL_TERMS)
        proved2 = (r <= rhs) & (r + tol * dl >= rhs)
        z = jnp.sqrt(jnp.maximum(-2.0 * jnp.log(r), 0.0))
        keep = lambda old, new: jnp.where(settled, old, new)  # noqa: E731
        return (i + 1, keep(x, pl2 + (z_rhs - z) * r * z / dl), keep(pl, pl2),
                keep(proved, proved2), settled | proved2)

    _, _, pl, proved, settled = jax.lax.while_loop(more, probe_and_step, (
        jnp.int32(0), x2, pl, proved, settled))

    def bracketed(_):
        pl_b, converged_b = _solve_pl_bracketed(coef, mean, sd, rhs, iterations,
                                                unroll_terms=RARE_UNROLL_TERMS)
        return jnp.where(proved, pl, pl_b), proved | converged_b

    return jax.lax.cond(jnp.all(settled), lambda _: (pl, proved), bracketed, None)


def _solve_pl_bracketed(coef, mean, sd, rhs, iterations=PL_ITERATIONS, factors=None,
                        unroll_terms=UNROLL_TERMS):
    """Root of sum_j coef_j Q((PL - mean_j)/sd_j) = rhs; terms on axis 0 (J, ...), rhs (...).

    coef >= 0 (terms with coef 0 are ignored; their sd must still be > 0), rhs > 0, and at least
    one term with coef > rhs (the fault-free term has coef 2). Returns (pl, converged): pl is never
    below the root, and lies within ``PL_TOLERANCE_M`` of it where converged. ``factors``:
    ``_bound_factors(coef, rhs)`` when the caller has them (shared by equal right-hand sides).

    Safeguarded Newton on h(x) = z(rhs) - z(R(x)), z(S) = sqrt(-2 log S): for one dominant term
    c Q((x - m)/s), z is nearly (x - m)/s, almost linear in x, and the derivative costs one
    multiply per term (the density shares erfc's exponential). Start where the largest single
    term alone meets the budget (to within A&S's 4.5e-4 sd: ``q_inverse_approx``) and keep a
    bracket [a, b] with h(a) >= 0 >= h(b); a Newton step that leaves it, or that is
    not shorter than half the previous step (Numerical Recipes' rtsafe rule: Newton creeps from
    the flat side of a kink where the dominant term changes), is replaced by an Illinois regula
    falsi step between the bracket ends (bisection until both ends are evaluated points). An
    element whose Newton step falls below ``NEWTON_STEP_TOL_M``, or whose bracket between two
    evaluated points is narrower than ``PL_TOLERANCE_M``, is frozen: its values no longer
    change, so an element gets exactly what a fixed ``iterations``-step loop would give it,
    whatever the rest of the batch needs. The loop stops when every element is frozen or after
    ``iterations`` (the bound that keeps it a fixed-count, jit-able solver). Then one
    evaluation proves the tolerance for pl = x + ``PL_MARGIN_M`` (plus the last, unevaluated
    Newton step where x is below the root and that step is at most tol / 2): h(pl - tol) >= 0
    if x is at or above the root, else h(pl) <= 0; where it fails, pl is the bracket's upper
    end if the bracket is narrower than tol, and the element is reported not converged
    otherwise.
    """
    coef = jnp.broadcast_to(coef, mean.shape)
    k_start, k_hi = _bound_factors(coef, rhs) if factors is None else factors

    def end(k, shift=0.0):  # max_j mean_j + sd_j (k_j + shift) over the terms with k_j > -inf
        return jnp.max(jnp.where(k > -jnp.inf, mean + sd * (k + shift), -jnp.inf), axis=0)

    lo, start = end(k_start, -Q_INVERSE_APPROX_MARGIN), end(k_start)
    hi = jnp.maximum(end(k_hi), start)
    z_rhs = jnp.sqrt(-2.0 * jnp.log(rhs))
    inv_sd = 1.0 / sd

    def h_and_slope(x):
        """h(x) and -h'(x) = z'(R) >= 0 (inf where R >= 1, i.e. z = 0)."""
        r, d = _risk(x, coef, mean, inv_sd, unroll_terms)
        z = jnp.sqrt(jnp.maximum(-2.0 * jnp.log(r), 0.0))
        return z_rhs - z, d / (r * z)

    def propose(a, b, ha, hb, x, hx, slope, last, was_right, done):
        """Take the point x just evaluated into the bracket and propose the next one."""
        right = hx <= 0  # x is at or above the root
        # Illinois: halve the value kept at an end that survives twice in a row
        a, ha = jnp.where(right, a, x), jnp.where(right, jnp.where(was_right, 0.5 * ha, ha), hx)
        b, hb = jnp.where(right, x, b), jnp.where(right, hx, jnp.where(was_right, hb, 0.5 * hb))
        step = hx / slope
        newton = x + step
        # finite, nonzero slope: z > 0 there (R < 1), so the step is a real Newton step
        # (a narrow bracket only counts once both ends are evaluated points: the unevaluated
        # ends from ``q_inverse_approx`` lie within ~1e-3 sd of the root, and freezing there
        # returned PLs up to 2.3e-4 m above the root instead of ~1e-6 m)
        frozen = done | ((jnp.abs(step) <= NEWTON_STEP_TOL_M) & (slope < jnp.inf)) | (
            (b - a <= PL_TOLERANCE_M) & (ha == ha) & (hb == hb))
        # where Newton leaves the bracket or does not halve the previous step (the flat side of
        # a kink, from where Newton creeps; Numerical Recipes' rtsafe rule), take the secant
        # of the bracket ends (regula falsi; h is nearly linear in z space)
        good = (newton > a) & (newton < b) & (jnp.abs(step) <= 0.5 * last)
        denom = ha - hb
        falsi = jnp.where(denom > 0, b + hb * (b - a) / jnp.where(denom > 0, denom, 1.0),
                          0.5 * (a + b))
        xn = jnp.where(frozen, x, jnp.where(good, newton, jnp.clip(falsi, a, b)))
        return a, b, ha, hb, right, frozen, xn

    # carry: the bracket, the last evaluated point (x, h, slope), the length of the step that
    # led to it, and the proposal made from it; the loop ends before evaluating proposals when
    # every element is frozen, so no evaluation is spent on a converged batch
    def cond(carry):
        i, frozen = carry[0], carry[10]
        return (i < iterations) & ~jnp.all(frozen)

    def body(carry):
        i, a, b, ha, hb, x, hx, slope, last, right, frozen, xn = carry
        hn, sn = h_and_slope(xn)
        hx, slope = jnp.where(frozen, hx, hn), jnp.where(frozen, slope, sn)
        last = jnp.where(frozen, last, jnp.abs(xn - x))
        a, b, ha, hb, right, frozen, xn2 = propose(a, b, ha, hb, xn, hx, slope, last, right,
                                                   frozen)
        return i + 1, a, b, ha, hb, xn, hx, slope, last, right, frozen, xn2

    h0, s0 = h_and_slope(start)
    done0 = jnp.zeros(lo.shape, bool)
    # h(lo) >= 0 >= h(hi) by construction; their values are only needed by the secant
    # fallback, which bisects until both ends are evaluated points (NaN: no secant), so they
    # are not evaluated
    unknown = jnp.full_like(hi, jnp.nan)
    last0 = jnp.full_like(lo, jnp.inf)
    a, b, ha, hb, right, frozen, xn = propose(lo, hi, unknown, unknown, start, h0, s0, last0,
                                              jnp.zeros(lo.shape, bool), done0)
    _, a, b, _, _, x, hx, slope, _, _, _, _ = jax.lax.while_loop(cond, body, (
        jnp.int32(0), a, b, ha, hb, start, h0, s0, last0, right, frozen, xn))
    right = hx <= 0  # (a, b) already hold the last evaluated point x (``propose``)
    narrow = b - a <= PL_TOLERANCE_M
    # h(x) <= 0 puts the root below x: pl = x + margin >= root, and h(pl - tol) >= 0 proves
    # pl - tol <= root. h(x) > 0 puts the root above x: pl = x + step + margin with the last
    # Newton step (not evaluated; its error is of the order of step^2) when that step is at
    # most tol / 2, so that pl - tol < x < root, and h(pl) <= 0 proves pl >= root.
    step = hx / slope
    step = jnp.where((step > 0) & (step <= 0.5 * PL_TOLERANCE_M), step, 0.0)
    pl_newton = x + jnp.where(right, 0.0, step) + PL_MARGIN_M
    h_probe = h_and_slope(jnp.where(right, pl_newton - PL_TOLERANCE_M, pl_newton))[0]
    proved = jnp.where(right, h_probe >= 0, h_probe <= 0)
    pl = jnp.where(proved, pl_newton, b)
    return pl, narrow | proved


def _pls_from_projection(pr, budget, iterations):
    """PLs (3, B), status (B,), EMT (B,) from a batch-last Projection."""
    scale = (1.0 - pr.p_not_monitored / (budget.phmi_v + budget.phmi_h)) / budget.n_es_int
    rhs_hv = jnp.stack([0.5 * budget.phmi_h * scale, budget.phmi_v * scale], axis=0)  # (2, B)
    rhs_hv = jnp.where(rhs_hv > 0, rhs_hv, budget.phmi_v)  # status marks P_nm > P_thresh
    coef = pr.prior.at[0].set(2.0)[:, None]  # (K, 1, B)
    # east and north share the right-hand side: the start factor (Q^-1 per term) once for both,
    # ln coef once for all three
    log_coef = jnp.log(jnp.where(coef[:, 0] > 0, coef[:, 0], 1.0))
    # (not stored: note above ``_blocks``)
    k = [_fast_start_factor(coef[:, 0], r, log_coef) for r in rhs_hv]
    mean = pr.threshold + pr.bias
    start = jnp.stack([_max(jnp.where(kq > -jnp.inf, mean[:, q] + pr.sigma[:, q] * kq,
                                      -jnp.inf), 0) for q, kq in enumerate((k[0], k[0], k[1]))])
    rhs = jnp.stack([rhs_hv[0], rhs_hv[0], rhs_hv[1]], axis=0)  # (3, B)
    pl, converged = solve_pl(coef, mean, pr.sigma, rhs, iterations, start,
                             ignore=(pr.status != Status.OK)[None])
    status = jnp.where((pr.status == Status.OK) & ~jnp.all(converged, axis=0),
                       Status.NOT_CONVERGED, pr.status).astype(jnp.int8)
    ok = status == Status.OK
    pl = jnp.where(ok[None], pl, jnp.inf)
    emt_mask = pr.monitored & (pr.prior >= budget.p_emt)
    emt = jnp.where(ok, jnp.max(jnp.where(emt_mask, pr.threshold[:, 2], 0.0), axis=0), jnp.inf)
    return pl, status, emt


def _batch_last_inputs(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid):
    tl = to_batch_last
    return (tl(g, 2), tl(constellation, 1), tl(var_int, 1), tl(var_acc, 1), tl(b_nom, 1),
            tl(p_sat, 1), tl(p_const, 1), tl(valid, 1))


def _optimized_position(pr, pl, status, emt, args, budget, iterations, opt):
    """MAAST's use of the Blanch et al. (2015) estimator (``usr_vhpl_araim.m``): tried where
    the baseline is computed, sigma_acc,U < its limit and VPL, HPL or EMT exceeds its target;
    kept (PLs, EMT and sigma_acc together) where its VPL or HPL is lower. Returns (pl,
    status, emt, sigma_acc_u, adjusted). Chunks where no geometry triggers skip the second
    solve (``lax.cond``)."""
    ok = status == Status.OK
    hpl = jnp.sqrt(pl[0] ** 2 + pl[1] ** 2)
    if opt.keep == "always":
        trigger = ok
    else:
        trigger = ok & (pr.sigma_acc_u < opt.sigma_acc_max_m[2]) & (
            (pl[2] > opt.vpl_target_m) | (hpl > opt.hpl_target_m) | (emt > opt.emt_target_m))

    def adjusted(_):
        pr2 = _adjusted_projection(pr, args[2], args[3], args[4], args[7], budget, opt)
        pr2 = pr2._replace(status=jnp.where(trigger, pr2.status, Status.NOT_CONVERGED)
                           .astype(pr2.status.dtype))  # untriggered: not solved
        pl2, status2, emt2 = _pls_from_projection(pr2, budget, iterations)
        hpl2 = jnp.sqrt(pl2[0] ** 2 + pl2[1] ** 2)
        take = trigger & (status2 == Status.OK)
        if opt.keep == "lower":
            take = take & ((pl2[2] < pl[2]) | (hpl2 < hpl))
        return (jnp.where(take[None], pl2, pl), jnp.where(take, emt2, emt),
                jnp.where(take, pr2.sigma_acc_u, pr.sigma_acc_u), take)

    def baseline(_):
        return pl, emt, pr.sigma_acc_u, jnp.zeros_like(trigger)

    pl, emt, sigma_acc_u, take = jax.lax.cond(jnp.any(trigger), adjusted, baseline, None)
    return pl, status, emt, sigma_acc_u, take


def _protection_levels_flat(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid,
                            budget, max_order, all_in_view_weighting, iterations,
                            input_flags=False, fault_modes=DEFAULT_RULE,
                            position_optimization=None, order_flags=False):
    """One flat batch (B, ...) in and out; batch-last inside. ``input_flags``: returns
    (MHSSResult, ``_input_flags``); ``order_flags`` (with ``input_flags``) also
    ``_order_flags``: (MHSSResult, input flags, order flags)."""
    args = _batch_last_inputs(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid)
    more = _order_flags(args[7], args[1], args[5], args[6], budget, fault_modes, max_order) \
        if order_flags else None
    pr = _project(*args, budget, max_order, all_in_view_weighting, input_flags=input_flags,
                  fault_modes=fault_modes)
    if input_flags:
        pr, flags = pr
    pl, status, emt = _pls_from_projection(pr, budget, iterations)
    sigma_acc_u = pr.sigma_acc_u
    adjusted = jnp.zeros_like(status, dtype=bool)
    if position_optimization is not None:
        pl, status, emt, sigma_acc_u, adjusted = _optimized_position(
            pr, pl, status, emt, args, budget, iterations, position_optimization)
    ok = status == Status.OK
    out = MHSSResult(
        hpl_m=jnp.sqrt(pl[0] ** 2 + pl[1] ** 2), vpl_m=pl[2], emt_m=emt,
        sigma_acc_u_m=jnp.where(ok, sigma_acc_u, jnp.inf), n_modes=pr.n_modes,
        p_not_monitored=pr.p_not_monitored, status=status, order=pr.order, pl_enu_m=pl,
        position_adjusted=adjusted)
    out = MHSSResult(*(to_batch_first(x, x.shape[-1:]) for x in out))
    if order_flags:
        return out, flags, more
    return (out, flags) if input_flags else out


def _protection_levels(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid,
                       budget, max_order, all_in_view_weighting="int", iterations=PL_ITERATIONS,
                       input_flags=False, fault_modes=DEFAULT_RULE,
                       position_optimization=None, order_flags=False):
    """Batch-first in and out, every argument broadcast to g's batch shape; evaluated in
    cache-sized chunks (``araim.batching``). ``input_flags`` also returns ``_input_flags``
    (the host's range checks, computed where the kernel reads its inputs anyway)."""
    batch = g.shape[:-2]
    L, C = g.shape[-2], p_const.shape[-1]
    arrays = [jnp.broadcast_to(x, batch + s) for x, s in (
        (g, (L, 3)), (constellation, (L,)), (var_int, (L,)), (var_acc, (L,)), (b_nom, (L,)),
        (p_sat, (L,)), (p_const, (C,)), (valid, (L,)))]

    def kernel(*xs):
        return _protection_levels_flat(*xs, budget, max_order, all_in_view_weighting,
                                       iterations, input_flags, fault_modes,
                                       position_optimization, order_flags)

    return map_chunks(kernel, arrays, batch)


_STATIC = ("budget", "max_order", "all_in_view_weighting", "iterations", "input_flags",
           "fault_modes", "position_optimization", "order_flags")
_protection_levels_jit = jit_kernel(_protection_levels, static_argnames=_STATIC)


def _protection_levels_part(start, *args, size, budget, max_order, all_in_view_weighting="int",
                            iterations=PL_ITERATIONS, input_flags=False,
                            fault_modes=DEFAULT_RULE, position_optimization=None,
                            order_flags=False):
    """``_protection_levels`` on rows [start, start + size) of flat arrays, sliced inside the
    program (``araim.batching.map_threads``'s ``part_fn``)."""
    return _protection_levels(*slice_rows(args, start, size), budget, max_order,
                              all_in_view_weighting, iterations, input_flags, fault_modes,
                              position_optimization, order_flags)


_protection_levels_part_jit = jit_kernel(_protection_levels_part,
                                         static_argnames=("size",) + _STATIC)


#: a line-of-sight row of a valid source must have a Euclidean norm within this of 1 (rows
#: printed to 4 decimals, as the ADD's Appendix D, are within 1e-4; a (0, 0, 0) row or an
#: unnormalised vector is refused)
UNIT_ROW_TOLERANCE = 1e-3


def _unit_norm(n2):
    """Squared row norms n2 (NumPy or JAX) finite with the norm within UNIT_ROW_TOLERANCE of
    1: (1 - tol)^2 <= n2 <= (1 + tol)^2 (no sqrt; NaN and inf fail)."""
    return (n2 >= (1.0 - UNIT_ROW_TOLERANCE) ** 2) & (n2 <= (1.0 + UNIT_ROW_TOLERANCE) ** 2)


def _unit_rows(g, axis):
    """``_unit_norm`` of the rows of g (3 entries along ``axis``), the squares written out."""
    parts = [jax.lax.index_in_dim(g, a, axis % g.ndim, keepdims=False) for a in range(3)]
    return _unit_norm(parts[0] * parts[0] + parts[1] * parts[1] + parts[2] * parts[2])


def _input_flags(g, constellation, var_int, var_acc, b_nom, p_sat, valid, C):
    """(B,) bool, True where a valid source of the geometry fails a check of
    ``_check_inputs`` (a range of ``_INPUT_RANGES``, the constellation label, the
    line-of-sight row): such a geometry gets status INVALID_INPUT, and a host wrapper that
    sees one runs ``_check_inputs`` to name it. Batch-last (L, 3, B) and (L, B) inputs
    (``_project``'s), C constellation slots; one fused elementwise pass and one OR over the
    sources written out (``_max`` on booleans). Stored (``linalg.materialize``), as is the
    status made from it: unstored, XLA copied the OR into every consumer of the status
    (measured on the bench case, 2 threads: 878k PL/s without the checks, 730k with them
    unstored, 839k stored; b130240, before them: 844k the same day)."""
    ok = (constellation >= 0) & (constellation < C) & _unit_rows(g, 1)
    for x, (lo, lo_ok, hi) in zip((var_int, var_acc, b_nom, p_sat), _INPUT_RANGES.values(),
                                  strict=True):
        ok = ok & _in_range(x, lo, lo_ok, hi)
    return _max(valid & ~ok, 0)


#: ``max_order=None`` picks the smallest order meeting P_thresh over the batch, up to this
MAX_AUTO_ORDER = 3


def prepare_inputs(g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat, p_const, valid,
                   check_sources=True):
    """Broadcast the arguments to the batch shape of ``g`` and check them on the host
    (``check_sources=False``: p_const only; the caller checks the per-source arrays, as
    ``protection_levels`` does with the kernel's ``_input_flags``).

    Raises ValueError naming the argument when a valid source has a non-positive or non-finite
    variance, a negative bias, a probability outside [0, 1), or a constellation label outside
    0..C-1 with C = p_const.shape[-1].
    """
    g = jnp.asarray(g, jnp.float64)
    if g.ndim < 2 or g.shape[-1] != 3:
        raise ValueError(f"g must have shape (..., L, 3) (geometry rows), got {g.shape}")
    shape = g.shape[:-1]
    p_const = jnp.asarray(p_const, jnp.float64)
    if p_const.ndim == 0:
        raise ValueError("p_const must have a last axis of one entry per constellation (..., C)")
    C = p_const.shape[-1]
    p_const = jnp.broadcast_to(p_const, shape[:-1] + (C,))
    valid = jnp.ones(shape, bool) if valid is None else jnp.broadcast_to(
        jnp.asarray(valid, bool), shape)
    constellation = jnp.broadcast_to(jnp.asarray(constellation, jnp.int32), shape)
    arrays = {name: jnp.broadcast_to(jnp.asarray(x, jnp.float64), shape) for name, x in (
        ("var_int_m2", var_int_m2), ("var_acc_m2", var_acc_m2), ("b_nom_m", b_nom_m),
        ("p_sat", p_sat))}
    try:
        _check_inputs(arrays, p_const, constellation, valid, C, check_sources, g)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        pass  # traced: the caller validates outside jit
    return (g, constellation, arrays["var_int_m2"], arrays["var_acc_m2"], arrays["b_nom_m"],
            arrays["p_sat"], p_const, valid)


#: what a valid source's value must satisfy: (lowest, whether the lowest is allowed, upper
#: bound, exclusive)
_INPUT_RANGES = {"var_int_m2": (0.0, False, np.inf), "var_acc_m2": (0.0, False, np.inf),
                 "b_nom_m": (0.0, True, np.inf), "p_sat": (0.0, True, 1.0)}


def _in_range(x, lo, lo_ok, hi):
    """x lies in the range (NaN never does)."""
    return ((x >= lo) if lo_ok else (x > lo)) & (x < hi)


def _check_inputs(arrays, p_const, constellation, valid, C, check_sources=True, g=None):
    """ValueError naming the first argument out of range at a valid source, with its batch
    index and source. Fast path: the minimum and maximum over every source, valid or not (two
    passes without temporaries); the masked elementwise test only when that fails, to find a
    valid offender and its value. Measured on the bench batch (65,536 x 13): 2.0 ms against
    3.3 ms for the masked test alone. ``g`` (..., L, 3): rows of valid sources finite, norm
    within UNIT_ROW_TOLERANCE of 1."""
    pc = np.asarray(p_const)
    if not np.all((pc >= 0) & (pc < 1)):
        raise ValueError("p_const must lie in [0, 1), got "
                         f"{float(pc[~((pc >= 0) & (pc < 1))][0])!r}")
    if not check_sources:
        return
    v = None
    for name, (lo, lo_ok, hi) in _INPUT_RANGES.items():
        x = np.asarray(arrays[name])
        if x.size == 0 or (_in_range(x.min(), lo, lo_ok, hi) and _in_range(x.max(), lo, lo_ok,
                                                                            hi)):
            continue
        v = np.asarray(valid) if v is None else v
        bad = v & ~_in_range(x, lo, lo_ok, hi)
        if bad.any():
            value = float(x[bad].ravel()[0])
            raise ValueError(f"{name} of a valid source is invalid at {batch_source(bad)}: "
                             f"{value!r} (variances must be finite and > 0 (m^2), biases >= 0 "
                             "(m), probabilities in [0, 1))")
    lab = np.asarray(constellation)
    if lab.size and (lab.min() < 0 or lab.max() >= C):
        v = np.asarray(valid) if v is None else v
        bad = v & ((lab < 0) | (lab >= C))
        if np.any(bad):
            raise ValueError(f"constellation labels must be integers in 0..{C - 1} "
                             f"(p_const has {C} entries), got {int(lab[bad].ravel()[0])} at "
                             f"{batch_source(bad)}")
    if g is not None:
        gn = np.asarray(g)
        with np.errstate(invalid="ignore"):  # NumPy: no per-shape compilation on the host
            ok = _unit_norm(np.einsum("...i,...i->...", gn, gn))
        if not ok.all():
            v = np.asarray(valid) if v is None else v
            bad = v & ~ok
            if bad.any():
                row = np.asarray(g)[bad][0]
                raise ValueError(
                    f"g (line-of-sight rows) of a valid source is not a unit vector at "
                    f"{batch_source(bad)}: {row.tolist()} (rows must be finite with norm within "
                    f"{UNIT_ROW_TOLERANCE} of 1: geometry.geometry_rows, or mark the source "
                    "invalid)")


def required_order(valid, constellation, p_sat, p_const, budget, cap=MAX_AUTO_ORDER,
                   fault_modes=None):
    """Smallest template order meeting the convention for every geometry of the batch, at most
    ``cap``. ``grouped``: the number of simultaneously faulty constellations r with
    P(more than r) <= P_thresh (``budget`` may then be P_thresh alone); event conventions
    (``budget`` an ``IntegrityBudget``): the smallest order at which no geometry would monitor
    a set beyond it (at most 2)."""
    if isinstance(budget, IntegrityBudget):
        rule = fault_mode_rule(fault_modes)
        p_thresh = budget.p_thresh
    else:
        rule = fault_mode_rule("grouped" if fault_modes is None else fault_modes)
        p_thresh = float(budget)
        if rule.events:
            raise ValueError(f"fault_modes={rule.name!r} needs the IntegrityBudget, "
                             "not P_thresh alone")
    if valid.size == 0:
        return 1
    if rule.events:
        r_max = max(1, min(cap, rule.max_order))
        try:
            for r in range(1, r_max):
                if not bool(_needs_higher_order(valid, constellation, p_sat, p_const, budget,
                                                rule, r)):
                    return r
        except jax.errors.TracerArrayConversionError:
            raise ValueError("max_order=None needs concrete probabilities; under jit pass "
                             "max_order (e.g. 1)") from None
        return r_max
    r_max = max(1, min(cap, p_const.shape[-1]))
    try:
        worst = np.asarray(_worst_tails(valid, constellation, p_sat, p_const, r_max))
    except jax.errors.TracerArrayConversionError:
        raise ValueError("max_order=None needs concrete probabilities; under jit pass "
                         "max_order (e.g. 1 for the Table I GPS budget)") from None
    for r in range(1, r_max + 1):
        if worst[r - 1] <= p_thresh:  # NaN never is
            return r
    return r_max


def _needs_flat(valid, constellation, p_sat, p_const, budget, rule, order):
    fm = event_modes_batch_last(to_batch_last(valid, 1), to_batch_last(constellation, 1),
                                to_batch_last(p_sat, 1), to_batch_last(p_const, 1), budget,
                                rule, order, full=True)
    return fm.needs_higher_order | (fm.p_beyond_order > budget.p_thresh)


def _order_flags(valid, constellation, p_sat, p_const, budget, rule, order):
    """(B,) bool, batch-last inputs: True where a geometry needs a template above ``order``,
    by exactly the test of ``required_order`` (so the batch's required order is ``order``
    where no geometry is flagged); False everywhere when ``required_order`` could not pick
    a higher one (its cap, the convention's order, the constellation count)."""
    B = valid.shape[-1]
    if rule.events:
        if min(MAX_AUTO_ORDER, rule.max_order) <= order:
            return jnp.zeros((B,), bool)
        fm = event_modes_batch_last(valid, constellation, p_sat, p_const, budget, rule, order,
                                    full=True)
        return fm.needs_higher_order | (fm.p_beyond_order > budget.p_thresh)
    if min(MAX_AUTO_ORDER, p_const.shape[0]) <= order:
        return jnp.zeros((B,), bool)
    from oaraim.araim.fault_modes import faulty_constellation_tail, group_probabilities

    gp = group_probabilities(valid, constellation, p_sat, p_const)
    return ~(faulty_constellation_tail(gp.p_fault, order)[order - 1] <= budget.p_thresh)


@functools.partial(jax.jit, static_argnames=("budget", "rule", "order"))
def _needs_higher_order(valid, constellation, p_sat, p_const, budget, rule, order):
    """Whether any geometry of the batch needs a template above ``order`` (event rules)."""
    batch = valid.shape[:-1]
    flags = map_chunks(functools.partial(_needs_flat, budget=budget, rule=rule, order=order),
                       (valid, constellation, p_sat, p_const), batch, chunk=4 * CHUNK)
    return jnp.any(flags)


def _tails_flat(valid, constellation, p_sat, p_const, r_max):
    """P(more than r constellations faulty), r = 1..r_max, per geometry: (B, r_max)."""
    from oaraim.araim.fault_modes import faulty_constellation_tail, group_probabilities

    gp = group_probabilities(to_batch_last(valid, 1), to_batch_last(constellation, 1),
                             to_batch_last(p_sat, 1), to_batch_last(p_const, 1))
    return jnp.moveaxis(faulty_constellation_tail(gp.p_fault, r_max), 0, -1)


@functools.partial(jax.jit, static_argnames="r_max")
def _worst_tails(valid, constellation, p_sat, p_const, r_max):
    """The batch's largest ``_tails_flat`` per order, (r_max,): one compiled program in chunks
    (evaluated op by op on the host it was ~46 ms of a ~125 ms call at the bench batch of
    65,536, measured)."""
    batch = valid.shape[:-1]
    tails = map_chunks(functools.partial(_tails_flat, r_max=r_max),
                       (valid, constellation, p_sat, p_const), batch, chunk=16 * CHUNK)
    return jnp.max(tails.reshape(-1, r_max), axis=0)


def protection_levels(g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat, p_const,
                      budget, valid=None, *, max_order=None, all_in_view_weighting="int",
                      threads=None, fault_modes=None, position_optimization=None):
    """ARAIM / OARAIM protection levels by multiple-hypothesis solution separation.

    Seed 004 eqs. (8)-(16) with the corrections of DESIGN.md. Takes VARIANCES (the ADD's C_int
    and C_acc diagonals, m^2), unlike ``slope_hpl`` which takes standard deviations.

    Args:
      g: geometry rows (..., L, 3), ``geometry.geometry_rows`` (ENU line-of-sight convention).
      constellation: (..., L) integer clock-group labels 0..C-1 (GPS 0, Galileo 1, SOP
        constellations after them).
      var_int_m2, var_acc_m2: C_int and C_acc diagonals (..., L), see ``araim.error_models``.
      b_nom_m: nominal bias bound per source (..., L).
      p_sat: P_s per source (..., L); p_const: P_const per constellation (..., C).
      budget: ``IntegrityBudget`` (e.g. ``BUDGET_SEED004_TABLE_I``).
      valid: (..., L) bool, sources used (in view, healthy, not padding).
      max_order: the template order: most simultaneous events (event conventions, up to 2) or
        faulty constellations (``grouped``, up to 3) a monitored mode stands for; None picks
        the smallest the convention needs over the batch. Geometries needing more get status
        UNMONITORED_RISK (their unmonitored priors stay in P_NM).
      all_in_view_weighting: "int" (C_int^-1, ADD/MAAST, default) or "acc" (seed 004 after
        eq. 5).
      threads: host threads over which a large batch is split (default
        ``araim.batching.default_threads()``: ``OARAIM_THREADS`` or 2); results do not depend
        on it.
      fault_modes: the fault-mode convention, a name or ``araim.FaultModeRule``: ``add-v4.2``
        (default, the current ADD), ``add-v3``, ``add-v3-consolidated``, ``blanch-2012``,
        ``grouped`` (docs/conformance.md).
      position_optimization: None (default: the weighted least-squares all-in-view estimate)
        or an ``araim.PositionOptimization``: where the baseline misses a target, the
        all-in-view estimator of Blanch et al. (2015) as MAAST applies it
        (``araim.position_opt``); ``position_adjusted`` says where it was kept.

    Returns:
      ``MHSSResult``; every PL is inf where status != OK, never NaN.
    """
    if all_in_view_weighting not in ("int", "acc"):
        raise ValueError("all_in_view_weighting must be 'int' or 'acc', "
                         f"got {all_in_view_weighting!r}")
    if not isinstance(budget, IntegrityBudget):
        raise ValueError("budget must be an araim.IntegrityBudget, e.g. "
                         "araim.BUDGET_SEED004_TABLE_I")
    rule = fault_mode_rule(fault_modes)
    opt = check_position_optimization(position_optimization)
    if max_order is not None:
        max_order = check_order(rule, check_int("max_order", max_order, 1))
    if threads is not None:
        threads = check_int("threads", threads, 1)
    if _traced((g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat, p_const, valid)):
        return _protection_levels_traced(g, constellation, var_int_m2, var_acc_m2, b_nom_m,
                                         p_sat, p_const, budget, valid, max_order,
                                         all_in_view_weighting, rule, opt)
    flat, batch = host_inputs(g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat,
                              p_const, valid)
    n = flat[0].shape[0]
    flat = pad_rows(flat, bucket(n))
    static = dict(budget=budget, all_in_view_weighting=all_in_view_weighting, fault_modes=rule,
                  position_optimization=opt)
    res = None
    if max_order is None and flat[0].shape[0] <= CHUNK:
        # one dispatch for a small batch: the kernel at order 1 also says, by the test of
        # required_order, whether any geometry needs more (then the batch runs again there)
        res, flags, more = _protection_levels_jit.jitted(*flat, max_order=1, input_flags=True,
                                                         order_flags=True, **static)
        max_order = 2 if bool(np.any(np.asarray(more))) else 1
        if max_order > 1:
            res, max_order = None, required_order(flat[7], flat[1], flat[5], flat[6], budget,
                                                  fault_modes=rule)
    elif max_order is None:
        max_order = required_order(flat[7], flat[1], flat[5], flat[6], budget,
                                   fault_modes=rule)
    if res is None:
        res, flags = protection_levels_threaded(flat, budget, max_order, all_in_view_weighting,
                                                threads, input_flags=True, fault_modes=rule,
                                                position_optimization=opt)
    if bool(np.any(np.asarray(flags))):  # name the argument, batch index and source
        x = [a[:n].reshape(batch + a.shape[1:]) for a in flat]
        _check_inputs(dict(zip(_INPUT_RANGES, x[2:6], strict=True)), x[6], x[1], x[7],
                      x[6].shape[-1], g=x[0])
        raise AssertionError("the kernel's input flags and the host checks disagree")
    return unpad(res, batch, n)


def host_inputs(g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat, p_const, valid):
    """The receiver's arguments as flat NumPy arrays, broadcast to the batch shape of ``g``:
    ([g (n, L, 3), constellation (n, L) int32, var_int, var_acc, b_nom, p_sat (n, L),
    p_const (n, C), valid (n, L) bool], batch shape). Checks the shapes and P_const (the
    per-source checks run inside the kernel, ``_input_flags``). NumPy, not jnp: each jnp
    conversion or broadcast is a dispatch (~30-60 us), which a single-geometry call cannot
    afford; the kernel's call moves the arrays to the device at once."""
    g = np.asarray(g, np.float64)
    if g.ndim < 2 or g.shape[-1] != 3:
        raise ValueError(f"g must have shape (..., L, 3) (geometry rows), got {g.shape}")
    shape = g.shape[:-1]
    batch = shape[:-1]
    p_const = np.asarray(p_const, np.float64)
    if p_const.ndim == 0:
        raise ValueError("p_const must have a last axis of one entry per constellation (..., C)")
    C = p_const.shape[-1]
    p_const = np.broadcast_to(p_const, batch + (C,))
    _check_inputs({}, p_const, None, None, C, check_sources=False)
    valid = np.ones(shape, bool) if valid is None else np.broadcast_to(
        np.asarray(valid, bool), shape)
    arrays = [g, np.broadcast_to(np.asarray(constellation, np.int32), shape)]
    arrays += [np.broadcast_to(np.asarray(x, np.float64), shape)
               for x in (var_int_m2, var_acc_m2, b_nom_m, p_sat)]
    arrays += [p_const, valid]
    n = int(np.prod(batch, dtype=np.int64))
    return [np.ascontiguousarray(x.reshape((n,) + x.shape[len(batch):])) for x in arrays], batch


def _protection_levels_traced(g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat,
                              p_const, budget, valid, max_order, all_in_view_weighting, rule,
                              opt):
    """``protection_levels`` inside a caller's trace: the kernel inline, failures as data
    (INVALID_INPUT), no host checks; ``max_order`` must be given unless the probabilities are
    concrete."""
    args = prepare_inputs(g, constellation, var_int_m2, var_acc_m2, b_nom_m, p_sat, p_const,
                          valid, check_sources=False)
    if max_order is None:
        max_order = required_order(args[7], args[1], args[5], args[6], budget,
                                   fault_modes=rule)
    res, _ = protection_levels_threaded(args, budget, max_order, all_in_view_weighting,
                                        input_flags=True, fault_modes=rule,
                                        position_optimization=opt)
    return res


def protection_levels_threaded(args, budget, max_order, all_in_view_weighting="int",
                               threads=None, input_flags=False, fault_modes=DEFAULT_RULE,
                               position_optimization=None):
    """The jitted kernel on ``prepare_inputs`` output, large batches split over host threads
    (``araim.batching.map_threads``: bit-identical to one call, ~1.9x faster on 2 cores).
    ``input_flags``: returns (MHSSResult, ``_input_flags``)."""
    static = dict(budget=budget, max_order=max_order,
                  all_in_view_weighting=all_in_view_weighting, input_flags=input_flags,
                  fault_modes=fault_mode_rule(fault_modes),
                  position_optimization=check_position_optimization(position_optimization))

    def fn(*xs):
        return _protection_levels_jit(*xs, **static)

    def part_fn(start, size, *xs):
        return _protection_levels_part_jit(start, *xs, size=size, **static)

    return map_threads(fn, args, args[0].shape[:-2], threads, part_fn=part_fn)
