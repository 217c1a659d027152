"""Chi-square detection threshold and missed-detection non-centrality (seed 001 section 3.1).

These depend only on (P_FA, P_MD, degrees of freedom), never on the geometry, so they are
computed once on the host with SciPy and handed to the batched kernels as small tables indexed by
the per-geometry degrees of freedom.

Residual test statistic: WSSE = r^T R^-1 r of the weighted least-squares residuals, chi-square
with dof = n - n_states under H0 and non-central chi-square with non-centrality
lambda = b^2 S_ii / R_ii under a bias b on source i (Brown & Chin 1998, "GPS RAIM: calculation
of thresholds and protection radius using chi-square methods"; Walter & Enge 1995).
"""

from functools import lru_cache

import numpy as np
from jaxtyping import Float

from oaraim.araim.validate import check_int, check_probability


def detection_threshold(p_fa: float, dof: int) -> float:
    """Threshold T with P(chi2_dof > T) = P_FA."""
    p_fa = check_probability("p_fa", p_fa)
    dof = check_int("dof", dof, 1)
    from scipy import stats  # ~0.3 s to import: here, not on `import oaraim.araim`

    return float(stats.chi2.isf(p_fa, dof))


def noncentrality(p_fa: float, p_md: float, dof: int) -> float:
    """lambda_det: the non-centrality with P(chi2_dof(lambda) < T(P_FA)) = P_MD.

    The smallest non-centrality a fault must produce to be detected with probability 1 - P_MD.
    Solved with Brent's method on the non-central chi-square cdf (monotone decreasing in lambda).
    """
    p_fa = check_probability("p_fa", p_fa)
    p_md = check_probability("p_md", p_md)
    threshold = detection_threshold(p_fa, dof)
    from scipy import optimize, stats

    if stats.chi2.cdf(threshold, dof) <= p_md:
        # Already P(H0 stat < T) <= P_MD with no bias: impossible only when 1 - P_FA <= P_MD.
        return 0.0

    def excess(lam):
        return stats.ncx2.cdf(threshold, dof, lam) - p_md

    hi = 1.0
    while excess(hi) > 0.0:
        hi *= 2.0
    return float(optimize.brentq(excess, 0.0, hi, xtol=1e-12, rtol=1e-14, maxiter=200))


@lru_cache(maxsize=64)
def lambda_det_table(p_fa: float, p_md: float, max_dof: int) -> Float[np.ndarray, " dof"]:
    """``table[d] = lambda_det(P_FA, P_MD, d)`` for d = 0..max_dof; ``table[0] = inf``.

    Cached: a sweep calls it once per (P_FA, P_MD) pair. The returned array is read-only.
    """
    table = np.full(max_dof + 1, np.inf)
    for dof in range(1, max_dof + 1):
        table[dof] = noncentrality(p_fa, p_md, dof)
    table.setflags(write=False)
    return table
