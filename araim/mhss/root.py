"""The PL root finder of the MHSS protection levels: seed 004 eqs. (14) and (16).

Each PL equation

    PL_q: 2 Q((PL - b^(0))/sigma^(0)) + sum_i P_f^(i) Q((PL - T_i,q - b^(i))/sigma^(i)) = rhs_q
          rhs_H = PHMI_H / 2 (1 - P_nm / (PHMI_V + PHMI_H)),  rhs_V = PHMI_V (...)  (14), (16)

is solved in log space (``solve_pl``): two Halley steps from the largest single-term root, the
second from exact values and a bound of the third derivative, which prove by Taylor's theorem
that the returned (conservative, upper) PL lies within ``FAST_PROOF_TOL_M`` above the root
(R(PL) <= rhs and R(PL - tol) >= rhs). What that does not prove takes a few probes (one exact
evaluation each) and Newton steps and then, in a branch run only where needed, safeguarded
Newton steps inside a bracket [lo, hi] that is valid by construction (lo: below the largest PL
at which one term alone reaches the budget; hi: every term at most its share of the budget;
both from bounds of Q^-1), proved within ``PL_TOLERANCE_M`` (``solve_pl_bracketed``).
``pls_from_projection`` sets up the three equations of a ``Projection`` and solves them.
"""

import jax
import jax.numpy as jnp
from jax.scipy.special import erfc, ndtri

from oaraim.araim import linalg
from oaraim.araim.mhss.implicit import implicit_root
from oaraim.araim.status import Status

__all__ = [
    "FAST_EXTRA_ROUNDS", "FAST_PROOF_TOL_M", "NEWTON_STEP_TOL_M", "PL_ITERATIONS", "PL_MARGIN_M",
    "PL_TOLERANCE_M", "Q_INVERSE_APPROX_MARGIN", "RARE_UNROLL_TERMS", "TAYLOR_B3_FACTOR",
    "TAYLOR_E_MAX", "UNROLL_TERMS", "halley_step", "pls_from_projection", "q_and_density",
    "q_and_density_fast", "q_function", "q_inverse", "q_inverse_approx", "risk_curvature",
    "risk_lower_slope", "risk_sum", "risk_taylor", "solve_pl", "solve_pl_bracketed",
]

_max = linalg.max_axis  # maxima over short static axes written out (``linalg.unrolled``)

#: the PL returned lies within this distance above the exact root of eqs. (14)/(16) (issue: 1e-3)
PL_TOLERANCE_M = 1e-3
#: at most this many iterations of the bracketed solver (the loop stops earlier once every
#: element of the batch has converged; 16 sufficed on the random geometries of
#: tests/test_mhss.py: docs/benchmarks.md). Non-convergence is reported, never hidden.
PL_ITERATIONS = 20
#: a Newton step shorter than this ends the iteration of its element (the PL tolerance is 1e-3 m):
#: below the root the step is then taken without evaluation (its error is ~ step^2), above it
#: the PL is the last iterate, at most this (+ PL_MARGIN_M) above the root
NEWTON_STEP_TOL_M = 1e-5
#: the PL returned is the converged Newton iterate plus this (covers the iterate's error, which
#: after a step below NEWTON_STEP_TOL_M is of the order of that step squared)
PL_MARGIN_M = 1e-6
_SQRT1_2 = 0.7071067811865476
_INV_SQRT_2PI = 0.3989422804014327  # 1 / sqrt(2 pi)

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


def q_and_density(t):
    """(Q(t), phi(t)) for the root finder. Q as q_function but with two of erfc's three Cephes
    branches and one division instead of three (about half the cost of
    jax.scipy.special.erfc on CPU; agrees with it to 1e-15 relative wherever Q(t) > 1e-29);
    phi(t) = exp(-t^2/2) / sqrt(2 pi), the standard normal density, shares erfc's exponential,
    so the derivative of a PL equation costs one multiply per term."""
    return _q_density_square(t)[:2]


def _q_density_square(t):
    """(Q(t), phi(t), z) of ``q_and_density`` and z = min(|t| / sqrt 2, 27)^2, which is t^2 / 2
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


def q_and_density_fast(t):
    """(Q(t), phi(t)) as ``q_and_density`` with erfc's 1 <= x < 8 branch used for all x
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


#: up to this many terms the risk sum is written out term by term (one fused loop over the
#: batch, no (terms, ...) temporary and no reduction over a non-minor axis)
UNROLL_TERMS = 64
#: ... and for the rarely run parts of ``solve_pl`` (its Newton rounds and bracketed fallback):
#: none, one array over the terms (written out, each of their 4 evaluation sites is a separate
#: copy of the per-term loops and the kernel compiles twice as long: docs/benchmarks.md)
RARE_UNROLL_TERMS = 0


def risk_sum(x, coef, mean, inv_sd, unroll_terms=UNROLL_TERMS):
    """(R, D): R(x) = sum_j coef_j Q((x - mean_j) / sd_j) and D(x) = -dR/dx = sum_j coef_j
    phi((x - mean_j) / sd_j) / sd_j >= 0; terms on axis 0, x of shape coef.shape[1:]."""
    if coef.shape[0] <= unroll_terms:
        r = d = 0.0
        for j in range(coef.shape[0]):
            q, phi = q_and_density((x - mean[j]) * inv_sd[j])
            r = r + coef[j] * q
            d = d + (coef[j] * inv_sd[j]) * phi
        return r, d
    q, phi = q_and_density((x[None] - mean) * inv_sd)
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


def risk_curvature(x, coef, mean, inv_sd, cw, cw2):
    """(R, D, D2) at x: R and D = -R' as ``risk_sum``, and D2 = R'' = sum_j coef_j t_j
    phi(t_j) / sd_j^2 (t_j = (x - mean_j) / sd_j); cw = coef / sd and cw2 = coef / sd^2. Q from
    ``q_and_density_fast`` (relative error < 1e-8): only the fast path's steps use this."""
    if coef.shape[0] <= UNROLL_TERMS:
        r = d = d2 = 0.0
        for j in range(coef.shape[0]):
            t = (x - mean[j]) * inv_sd[j]
            q, phi = q_and_density_fast(t)
            r = r + coef[j] * q
            d = d + cw[j] * phi
            d2 = d2 + cw2[j] * (t * phi)
        return r, d, d2
    t = (x[None] - mean) * inv_sd
    q, phi = q_and_density_fast(t)
    return jnp.sum(coef * q, axis=0), jnp.sum(cw * phi, axis=0), jnp.sum(cw2 * t * phi, axis=0)


def risk_lower_slope(x, delta, coef, mean, inv_sd, cw, unroll_terms=UNROLL_TERMS):
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
            q, phi = q_and_density(t)
            e = delta * inv_sd[j]
            r = r + coef[j] * q
            dl = dl + cw[j] * phi * jnp.clip(1.0 + e * (t - 0.5 * e), 0.0, 1.0)
        return r, dl
    t = (x[None] - mean) * inv_sd
    q, phi = q_and_density(t)
    e = delta * inv_sd
    return (jnp.sum(coef * q, axis=0),
            jnp.sum(cw * phi * jnp.clip(1.0 + e * (t - 0.5 * e), 0.0, 1.0), axis=0))


def _third_bound_term(phi, z):
    """phi(t) (2 + 1.01 t^2) + 1e-290 with z = t^2 / 2: one term's share of ``risk_taylor``'s
    B3 before its weight cw3_j."""
    return phi * (2.0 + 2.02 * z) + 1e-290


def risk_taylor(x, coef, mean, inv_sd, cw, cw2, cw3, unroll_terms=UNROLL_TERMS):
    """(R, D, D2, B3) at x with the exact Q: R, D = -R' and D2 = R'' as ``risk_curvature``,
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


#: ``risk_taylor``'s bound holds for steps h with h / sd_j at most this (every term with
#: coef_j > 0), and with the factor below (>= exp(38 TAYLOR_E_MAX) = 1.46)
TAYLOR_E_MAX = 0.01
TAYLOR_B3_FACTOR = 1.5


def halley_step(x, r, d, d2, z_rhs):
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


#: ``solve_pl``'s fast path: two Halley steps proved by Taylor's theorem; then at most this many
#: probes for the elements that proof does not cover, the first at the second Halley step's
#: point, each later one a Newton step from the last probe; the rest goes to the bracketed
#: solver (how many each stage settles: docs/benchmarks.md)
FAST_EXTRA_ROUNDS = 5
#: the fast path proves its PLs within this of the root (tighter than ``PL_TOLERANCE_M``, which
#: the bracketed solver proves): after its Halley steps the bench case is within 3e-11 m, and
#: an element proved only to 1e-3 m would carry up to 1e-3 m of needless margin
FAST_PROOF_TOL_M = 1e-4


def solve_pl(coef, mean, sd, rhs, iterations=PL_ITERATIONS, start=None, ignore=None):
    """Root of sum_j coef_j Q((PL - mean_j)/sd_j) = rhs; terms on axis 0 (J, ...), rhs (...).

    Same contract as ``solve_pl_bracketed``: returns (pl, converged), pl never below the root
    and within ``PL_TOLERANCE_M`` of it where converged.

    Fast path, two evaluations of the terms: a Halley step (z space, ``halley_step``) from the
    start of ``solve_pl_bracketed`` with the approximate Q of ``risk_curvature`` to x1; at
    x1 the exact R, R', R'' and a bound of |R'''| near x1 (``risk_taylor``), and a second
    Halley step to x2. pl = x2 + ``PL_MARGIN_M`` is proved from x1 by Taylor's theorem with
    tol = ``FAST_PROOF_TOL_M``, for h = pl - x1 and pl - tol - x1:
      R(x1 + h) <= R - D h + D2 h^2 / 2 + |R'''|max |h|^3 / 6 <= rhs at pl (at or above the
      root), and R(x1 + h) >= ... - |R'''|max |h|^3 / 6 >= rhs at pl - tol (at or below it).
    (the third-order term is ~1e-8 of R for the bench's |h| ~ 1e-3 m; the proof needs ~1e-6.)
    Elements that proof does not cover take up to ``FAST_EXTRA_ROUNDS`` probes, each an exact
    evaluation at its point that proves both sides at once (R(pl) <= rhs, and R(pl) + tol
    Dl(pl) >= rhs with Dl a lower bound of the slope on [pl - tol, pl], ``risk_lower_slope``),
    the first at x2, the next ones a Newton step from the last probe (a loop that ends at once
    when every element is proved). What is still not proved is solved by the bracketed solver,
    in a branch taken only when a tile has such an element (``jax.lax.cond``). Each element's
    result depends on its own terms only, never on the rest of the batch.

    ``start``: the starting point, max_j mean_j + sd_j ``_fast_start_factor``_j (about the
    largest single-term root), when the caller has it. ``ignore``: elements whose result the
    caller discards (they never trigger the loop or the bracketed branch).
    """
    coef = jnp.broadcast_to(coef, mean.shape)
    if start is None:
        k = _fast_start_factor(coef, rhs)
        start = jnp.max(jnp.where(k > -jnp.inf, mean + sd * k, -jnp.inf), axis=0)
    inv_sd = 1.0 / sd
    cw = coef * inv_sd  # (not stored: note above ``_blocks``)
    cw2 = cw * inv_sd
    z_rhs = jnp.sqrt(-2.0 * jnp.log(rhs))
    x1 = halley_step(start, *risk_curvature(start, coef, mean, inv_sd, cw, cw2), z_rhs)
    r, d, d2, b3 = risk_taylor(x1, coef, mean, inv_sd, cw, cw2, cw2 * inv_sd)
    tol = FAST_PROOF_TOL_M
    x2 = halley_step(x1, r, d, d2, z_rhs)
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
        r, dl = risk_lower_slope(pl2, tol, coef, mean, inv_sd, cw, RARE_UNROLL_TERMS)
        proved2 = (r <= rhs) & (r + tol * dl >= rhs)
        z = jnp.sqrt(jnp.maximum(-2.0 * jnp.log(r), 0.0))
        keep = lambda old, new: jnp.where(settled, old, new)  # noqa: E731
        return (i + 1, keep(x, pl2 + (z_rhs - z) * r * z / dl), keep(pl, pl2),
                keep(proved, proved2), settled | proved2)

    _, _, pl, proved, settled = jax.lax.while_loop(more, probe_and_step, (
        jnp.int32(0), x2, pl, proved, settled))

    def bracketed(_):
        pl_b, converged_b = solve_pl_bracketed(coef, mean, sd, rhs, iterations,
                                                unroll_terms=RARE_UNROLL_TERMS)
        return jnp.where(proved, pl, pl_b), proved | converged_b

    return jax.lax.cond(jnp.all(settled), lambda _: (pl, proved), bracketed, None)


def solve_pl_bracketed(coef, mean, sd, rhs, iterations=PL_ITERATIONS, factors=None,
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
        r, d = risk_sum(x, coef, mean, inv_sd, unroll_terms)
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


def pls_from_projection(pr, budget, iterations):
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
    # differentiated by the implicit function theorem, not through the solver's loops
    pl, converged = implicit_root(
        lambda c, m, s, r, st, ig: solve_pl(c, m, s, r, iterations, st, ig),
        coef, mean, pr.sigma, rhs, jax.lax.stop_gradient(start),
        (pr.status != Status.OK)[None])
    status = jnp.where((pr.status == Status.OK) & ~jnp.all(converged, axis=0),
                       Status.NOT_CONVERGED, pr.status).astype(jnp.int8)
    ok = status == Status.OK
    pl = jnp.where(ok[None], pl, jnp.inf)
    emt_mask = pr.monitored & (pr.prior >= budget.p_emt)
    emt = jnp.where(ok, jnp.max(jnp.where(emt_mask, pr.threshold[:, 2], 0.0), axis=0), jnp.inf)
    return pl, status, emt


