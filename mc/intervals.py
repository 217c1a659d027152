"""Confidence intervals of Monte Carlo counts: the Clopper-Pearson (exact binomial) interval of
a rate k / n, used wherever a study reports a misleading-information (MI) or alarm rate.

Clopper and Pearson, "The use of confidence or fiducial limits illustrated in the case of the
binomial", Biometrika 26(4), 1934: with confidence 1 - alpha, the interval is
``[B(alpha/2; k, n - k + 1), B(1 - alpha/2; k + 1, n - k)]``, B the beta quantile, with the
lower limit 0 at k = 0 and the upper limit 1 at k = n. It covers the true rate with
probability >= 1 - alpha for every rate (conservative), which the studies want for integrity
claims. The counts must be of independent trials (runs, geometries); epochs of one drive are
correlated, and an interval over them is narrower than the truth (say so where it is used).
"""

import numpy as np


def clopper_pearson(k, n, confidence=0.95):
    """Exact binomial interval ``(low, high)`` of the rate k / n at ``confidence``; k and n
    non-negative integers (arrays broadcast), k <= n. n = 0 gives (0, 1): nothing is known."""
    k = np.asarray(k, dtype=float)
    n = np.asarray(n, dtype=float)
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    if np.any(k < 0) or np.any(k > n) or np.any(k != np.round(k)) or np.any(n != np.round(n)):
        raise ValueError(f"need integers 0 <= k <= n, got k={k!r}, n={n!r}")
    from scipy import stats  # ~0.5-1 s to import: here, not on `import oaraim.mc`

    a = 1.0 - confidence
    with np.errstate(invalid="ignore", divide="ignore"):
        lo = np.where(k > 0, stats.beta.ppf(a / 2, k, n - k + 1), 0.0)
        hi = np.where(k < n, stats.beta.ppf(1 - a / 2, k + 1, n - k), 1.0)
    lo, hi = np.nan_to_num(lo, nan=0.0), np.nan_to_num(hi, nan=1.0)
    if lo.ndim == 0:
        return float(lo), float(hi)
    return lo, hi


def rate_with_interval(k, n, confidence=0.95):
    """A JSON-able summary of the count k of n trials: ``{"count", "trials", "rate",
    "ci_low", "ci_high", "confidence"}`` (Clopper-Pearson; rate nan when n = 0)."""
    k, n = int(k), int(n)
    lo, hi = clopper_pearson(k, n, confidence)
    return {"count": k, "trials": n, "rate": k / n if n else float("nan"), "ci_low": lo,
            "ci_high": hi, "confidence": confidence}
