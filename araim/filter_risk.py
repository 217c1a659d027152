"""The filter bank's integrity risk by conditional Monte Carlo (docs/filter-integrity.md,
"The conditional risk estimate").

A solution-separation bank (``araim.filter_monitor``) is linear in the measurement errors: with
a fault f on one source, filter i's position error at epoch k is e_i = n_i + r_i, n_i the
fault-free (noise) part and r_i the deterministic response of the bank to f alone (the bank
run on the fault profile, zero prior mean). Hazardously misleading information at epoch k is
{|e_0,H| > HPL} and no alert; every monitored mode i, direction q gives an upper-bound event

    A_k,i,q = {|n_0,H + r_0,H| > HPL} and {|Delta_i,q| <= T_i,q},
    Delta_i = (n_i - n_0) + (r_i - r_0).

The fault-free n_0 and n_i - n_0 are jointly Gaussian and uncorrelated (the orthogonality
proof of docs/filter-integrity.md, "The separation and its covariance"), hence independent, so

    P(HMI_k) <= P(|n_0,H + r_0,H| > HPL) * min_{i,q} P(|Delta_i,q| <= T_i,q)        (1)

with n_0,H ~ N(0, P_0,HH) and Delta_i,q ~ N(r_i,q - r_0,q, sigma_ss,i,q^2). Both factors are
computed, not sampled: the first by ``outside_circle_probability`` (a one-dimensional
quadrature, accurate for probabilities of any size), the second in closed form
(``inside_interval_probability``). ``epoch_risk_bound`` is (1). What is left to average is
the fault itself (source, onset, magnitude): the magnitude by quadrature where the response is
linear in it (``log_uniform_nodes``), the source and onset by Monte Carlo, plain or importance
sampled (``weighted_mean``).

The HPL and the thresholds are functions of the covariances alone in the linear bank (the
same for every noise draw), which (1) needs; in the EKF bank they move with the main filter's
linearisation point, to second order in its error.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import ndtr
from jax.typing import ArrayLike
from jaxtyping import Array, Float

__all__ = ["CRUDE_CHECK_Z", "DEFENSIVE", "EpochRisk", "MAGNITUDE_NODES", "WeightedMean",
           "crude_check", "epoch_risk_bound", "inside_interval_probability", "log_uniform_nodes",
           "outside_circle_probability", "source_proposal", "weighted_mean"]

#: Gauss-Legendre nodes of the quadrature over the minor axis (``outside_circle_probability``):
#: the integrand is a Gaussian of at most 2 WINDOW_SIGMAS standard deviations times a smooth
#: factor; over 200 random cases (probabilities 1 to 1e-47) 64 nodes equal 256 to 1e-11
#: relative (48: 2e-7, 32: 6e-4), and SciPy's adaptive quadrature to 1e-9 in
#: tests/test_filter_risk.py
QUAD_NODES = 64
#: Gauss-Legendre nodes in log m of a magnitude average (``log_uniform_nodes``' default): the
#: bank's P(A) peaks over ~0.1 in ln m (docs/filter-integrity.md); on the UAV flight 48 nodes
#: equal 384 to 3e-5 relative (24: 1 %)
MAGNITUDE_NODES = 48
#: half-width of the quadrature window over the minor axis, in its standard deviations: the
#: mass left out is at most 2 Q(12) = 3.6e-33 (absolute), below any risk of interest
WINDOW_SIGMAS = 12.0
#: defensive share of a proposal over the faulty source (``source_proposal``): draws from the
#: prior itself, so no likelihood ratio exceeds 1 / DEFENSIVE (Hesterberg 1995, as
#: ``araim.integrity_risk``)
DEFENSIVE = 0.1
#: the crude check (``crude_check``) flags |observed - expected| beyond this many standard
#: errors (two-sided 4.7e-4 under the model, normal)
CRUDE_CHECK_Z = 3.5
_GL_X, _GL_W = np.polynomial.legendre.leggauss(QUAD_NODES)


def _q(x):
    """Upper Gaussian tail Q(x) = Phi(-x), accurate in the tail."""
    return ndtr(-x)


def inside_interval_probability(mean: Float[ArrayLike, "..."], sigma: Float[ArrayLike, "..."],
                                threshold: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
    """P(|X| <= threshold) for X ~ N(mean, sigma^2) (broadcast; m, m, m): Phi((T - |mu|) /
    sigma) - Phi((-T - |mu|) / sigma), both terms in the far tail when |mu| >> T (no
    cancellation against 1). sigma = 0: the indicator |mu| <= T. Jit-safe."""
    mu = jnp.abs(jnp.asarray(mean, jnp.float64))
    s = jnp.asarray(sigma, jnp.float64)
    t = jnp.asarray(threshold, jnp.float64)
    pos = s > 0.0
    ss = jnp.where(pos, s, 1.0)
    p = ndtr((t - mu) / ss) - ndtr((-t - mu) / ss)
    return jnp.where(pos, jnp.clip(p, 0.0, 1.0), (mu <= t).astype(jnp.float64))


def outside_circle_probability(cov_h: Float[ArrayLike, "... 2 2"],
                               mean_h: Float[ArrayLike, "... 2"],
                               radius: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
    """P(|x| > radius) for a 2-D Gaussian x ~ N(mean_h, cov_h) (m^2, m, m; leading axes
    broadcast). In the covariance's principal axes (x_1 the minor one, standard deviations
    s_1 <= s_2, means m_1, m_2):

        P = Q((R - m_1)/s_1) + Q((R + m_1)/s_1)
            + int_{-pi/2}^{pi/2} phi_1(R sin t) [Q((R cos t - m_2)/s_2) + Q((R cos t + m_2)/s_2)]
              R cos t dt,

    every term non-negative (no 1 - P(inside)), so tiny probabilities keep their digits. The
    integral runs over the window |x_1 - m_1| <= ``WINDOW_SIGMAS`` s_1 with ``QUAD_NODES``
    Gauss-Legendre nodes in t (x_1 = R sin t removes the square root of the circle's edge).
    radius inf (a PL that could not be computed) gives 0, radius <= 0 gives 1; a covariance
    with s_1 = 0 is floored at 1e-9 of the problem's scale. Jit-safe."""
    c = jnp.asarray(cov_h, jnp.float64)
    m = jnp.asarray(mean_h, jnp.float64)
    r = jnp.asarray(radius, jnp.float64)
    a, b, d = c[..., 0, 0], 0.5 * (c[..., 0, 1] + c[..., 1, 0]), c[..., 1, 1]
    half = 0.5 * (a + d)
    disc = jnp.sqrt(jnp.maximum(0.25 * (a - d) ** 2 + b**2, 0.0))
    lam_big, lam_small = half + disc, jnp.maximum(half - disc, 0.0)
    phi = 0.5 * jnp.arctan2(2.0 * b, a - d)  # the major axis
    cph, sph = jnp.cos(phi), jnp.sin(phi)
    m2 = cph * m[..., 0] + sph * m[..., 1]  # along the major axis
    m1 = -sph * m[..., 0] + cph * m[..., 1]  # along the minor axis
    finite_r = jnp.isfinite(r) & (r > 0.0)
    rr = jnp.where(finite_r, r, 1.0)
    scale = rr + jnp.abs(m1) + jnp.abs(m2) + jnp.sqrt(jnp.maximum(lam_big, 0.0))
    s2 = jnp.maximum(jnp.sqrt(jnp.maximum(lam_big, 0.0)), 1e-9 * scale)
    s1 = jnp.maximum(jnp.sqrt(lam_small), 1e-9 * scale)
    edge = _q((rr - m1) / s1) + _q((rr + m1) / s1)
    lo = jnp.arcsin(jnp.clip((m1 - WINDOW_SIGMAS * s1) / rr, -1.0, 1.0))
    hi = jnp.arcsin(jnp.clip((m1 + WINDOW_SIGMAS * s1) / rr, -1.0, 1.0))
    xg, wg = jnp.asarray(_GL_X), jnp.asarray(_GL_W)
    th = 0.5 * (hi - lo)[..., None] * xg + 0.5 * (hi + lo)[..., None]
    x1 = rr[..., None] * jnp.sin(th)
    h = rr[..., None] * jnp.cos(th)
    z1 = (x1 - m1[..., None]) / s1[..., None]
    pdf = jnp.exp(-0.5 * z1**2) / (jnp.sqrt(2.0 * jnp.pi) * s1[..., None])
    g = _q((h - m2[..., None]) / s2[..., None]) + _q((h + m2[..., None]) / s2[..., None])
    integral = 0.5 * (hi - lo) * jnp.sum(wg * pdf * g * h, axis=-1)
    p = jnp.clip(edge + integral, 0.0, 1.0)
    return jnp.where(finite_r, p, jnp.where(jnp.isfinite(r), 1.0, 0.0))


class EpochRisk(NamedTuple):
    """Eq. (1) of the module docstring at one epoch (leading axes: the caller's)."""

    p_hmi_bound: jax.Array
    """() P(|e_0,H| > HPL) * min_{i,q} P(no alert on mode i, direction q): an upper bound on
    P(HMI) at the epoch."""
    p_outside: jax.Array
    """() P(|n_0,H + r_0,H| > HPL)."""
    p_no_alert: jax.Array
    """() the smallest P(|Delta_i,q| <= T_i,q) over the monitored modes and directions with
    T > 0 (1 where none tests anything), evaluated at the test of largest (|mu| - T) /
    sigma_ss (the order of those probabilities up to a term below Phi(-(T + |mu|)/sigma_ss):
    on the UAV flight's 87 filters evaluating one test instead of all is what makes eq. (1)
    cheap)."""
    mode: jax.Array
    """() the bank filter i of that smallest probability (0: none)."""
    direction: jax.Array
    """() its direction q (0 east, 1 north, 2 up)."""


def epoch_risk_bound(p0_h: Float[ArrayLike, "... 2 2"], r0_h: Float[ArrayLike, "... 2"],
                     hpl_m: Float[ArrayLike, "..."], separation_mean_m: Float[ArrayLike, "... K 3"],
                     sigma_ss_m: Float[ArrayLike, "... K 3"],
                     threshold_m: Float[ArrayLike, "... K 3"]) -> EpochRisk:
    """Eq. (1) of the module docstring: ``p0_h`` the main filter's horizontal covariance
    (east, north; m^2), ``r0_h`` its fault response (m), ``hpl_m`` the HPL, and per bank
    filter (K; row 0 the main one, never a test) and direction the separation's mean
    r_i - r_0 ``separation_mean_m``, its standard deviation ``sigma_ss_m`` and threshold
    ``threshold_m`` (``FilterMonitorEpoch.sigma_ss_m``, ``threshold_m``: 0 where the mode is
    not monitored, which tests nothing). Jit-safe; returns ``EpochRisk``."""
    p_out = outside_circle_probability(p0_h, r0_h, hpl_m)
    thr = jnp.asarray(threshold_m, jnp.float64)
    mu = jnp.abs(jnp.asarray(separation_mean_m, jnp.float64))
    sig = jnp.asarray(sigma_ss_m, jnp.float64)
    tests = thr > 0.0
    # P(|Delta| <= T) = Phi((T - |mu|)/s) - Phi((-T - |mu|)/s) falls as z = (|mu| - T)/s grows,
    # up to the second term, which is below Phi(-z - 2 K_fa) and cannot reorder two tests by
    # more than that: the exact value at the test of largest z is the minimum
    z = jnp.where(tests & (sig > 0.0), (mu - thr) / jnp.where(sig > 0.0, sig, 1.0),
                  jnp.where(tests & (mu > thr), jnp.inf, -jnp.inf))
    flat = lambda a: a.reshape(a.shape[:-2] + (-1,))  # noqa: E731
    idx = jnp.argmax(flat(z), axis=-1)
    take = lambda a: jnp.take_along_axis(  # noqa: E731
        flat(jnp.broadcast_to(a, z.shape)), idx[..., None], -1)[..., 0]
    p_na = jnp.where(take(tests), inside_interval_probability(take(mu), take(sig), take(thr)),
                     1.0)
    return EpochRisk(p_out * p_na, p_out, p_na, idx // 3, idx % 3)


def log_uniform_nodes(lo: float, hi: float, n: int = MAGNITUDE_NODES
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights (n,) of the log-uniform distribution on [lo, hi]
    (a magnitude prior): E[g(m)] ~ sum_j w_j g(m_j), weights summing to 1. Host NumPy."""
    if not 0.0 < lo <= hi:
        raise ValueError(f"log_uniform_nodes needs 0 < lo <= hi, got lo={lo!r}, hi={hi!r}")
    x, w = np.polynomial.legendre.leggauss(int(n))
    u = np.log(lo) + 0.5 * (x + 1.0) * (np.log(hi) - np.log(lo))
    return np.exp(u), 0.5 * w


class WeightedMean(NamedTuple):
    """An importance-sampling estimate of E_prior[g] from draws of a proposal."""

    mean: float
    """(1/n) sum_j w_j g_j, w = prior / proposal."""
    std_error: float
    """the standard deviation of w_j g_j over sqrt(n) (the draws independent)."""
    ess: float
    """effective sample size (sum w)^2 / sum w^2 (n for the prior itself)."""
    n: int


def weighted_mean(values, log_weight=None) -> WeightedMean:
    """``WeightedMean`` of ``values`` (n,) drawn from a proposal with log likelihood ratios
    ``log_weight`` (n,) = log prior - log proposal (None: the prior itself, plain Monte
    Carlo). Host NumPy; needs n >= 2."""
    g = np.asarray(values, float).ravel()
    n = g.size
    if n < 2:
        raise ValueError(f"weighted_mean needs at least 2 draws, got {n}")
    w = np.ones(n) if log_weight is None else np.exp(np.asarray(log_weight, float).ravel())
    if w.shape != g.shape:
        raise ValueError(f"values and log_weight must have one length, got {n} and {w.size}")
    wg = w * g
    return WeightedMean(float(wg.mean()), float(wg.std(ddof=1) / np.sqrt(n)),
                        float(w.sum() ** 2 / np.sum(w**2)), n)


def source_proposal(pilot) -> np.ndarray:
    """The proposal (n,) over n faulty sources from a pilot's per-source risk ``pilot`` (n,)
    (any non-negative scale): its shares mixed with ``DEFENSIVE`` of the uniform prior.
    Host NumPy."""
    p = np.maximum(np.asarray(pilot, float), 0.0)
    share = p / p.sum() if p.sum() > 0 else np.full(p.size, 1.0 / p.size)
    return (1.0 - DEFENSIVE) * share + DEFENSIVE / p.size


def crude_check(observed, expected, hmi_c, hpl_fraction) -> dict:
    """Eq. (1) against crude counts where these resolve it (the HPL scaled by c =
    ``hpl_fraction`` < 1), over n runs: per run the epochs of the event whose probability eq.
    (1) is (``observed`` (n,)), the sum of those probabilities (``expected`` (n,)) and the
    epochs with |e_0,H| > c HPL and no alert (``hmi_c`` (n,), which eq. (1) bounds). Under
    the model the runs' differences observed - expected have mean 0; the standard error is
    their spread times sqrt(n) (the epochs of a run are correlated), floored at the Poisson
    sqrt(max(expected, 1)). ``flagged`` where |z| > ``CRUDE_CHECK_Z``. JSON-able dict."""
    ob, ex, hm = (np.asarray(a, float).ravel() for a in (observed, expected, hmi_c))
    n = ob.size
    d = ob - ex
    se = float(np.sqrt(max(n * d.var(ddof=1) if n > 1 else 0.0, ex.sum(), 1.0)))
    z = float(d.sum() / se)
    return {"hpl_fraction": float(hpl_fraction), "observed": int(ob.sum()),
            "expected": float(ex.sum()), "std_error": se, "z": z,
            "flagged": bool(abs(z) > CRUDE_CHECK_Z), "hmi_at_fraction": int(hm.sum()),
            "runs": int(n)}
