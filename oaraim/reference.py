"""Obvious per-geometry NumPy/SciPy reference implementations: the oracle for the JAX kernels.

Written for clarity, straight from the seed's matrices, one geometry at a time. Also the
"NumPy reference" that ``oaraim bench`` reports speed-ups against (DESIGN.md).
"""

import numpy as np
from scipy import optimize, stats


def slopes_reference(g, sigma_m):
    """Seed 001 section 3.1, literally: B = (H^T R^-1 H)^-1 H^T R^-1, S = I - H B,
    slope_i = sqrt(B_1i^2 + B_2i^2) sqrt(R_ii) / sqrt(S_ii).

    g: (L, 3) rows of the valid sources only; sigma_m: (L,) standard deviations.
    """
    g = np.asarray(g, float)
    n = g.shape[0]
    h = np.hstack([g, np.ones((n, 1))])
    r = np.diag(np.broadcast_to(np.asarray(sigma_m, float), (n,)) ** 2)
    r_inv = np.linalg.inv(r)
    b = np.linalg.inv(h.T @ r_inv @ h) @ h.T @ r_inv
    s = np.eye(n) - h @ b
    return np.sqrt(b[0] ** 2 + b[1] ** 2) * np.sqrt(np.diag(r)) / np.sqrt(np.diag(s))


def lambda_det_reference(p_fa, p_md, dof):
    """Non-centrality with P(ncx2(dof, lambda) < chi2.isf(P_FA, dof)) = P_MD, by bisection."""
    t = stats.chi2.isf(p_fa, dof)
    return optimize.bisect(lambda lam: stats.ncx2.cdf(t, dof, lam) - p_md, 0.0, 1e4, xtol=1e-12)


def slope_hpl_reference(g, sigma_m, p_fa, p_md):
    """HPL = slope_max sqrt(lambda_det), seed 001 section 3.1, for one geometry."""
    s = slopes_reference(g, sigma_m)
    dof = g.shape[0] - 4
    return float(np.max(s) * np.sqrt(lambda_det_reference(p_fa, p_md, dof)))


def wnls_reference(pr, tx, sigma_m, x0, n_iter=20):
    """Gauss-Newton WNLS for one epoch, one receiver clock: the textbook loop."""
    x = np.array(x0, float)
    w = np.diag(1.0 / np.broadcast_to(np.asarray(sigma_m, float), pr.shape) ** 2)
    for _ in range(n_iter):
        d = x[:3] - tx
        rng = np.linalg.norm(d, axis=1)
        h = np.hstack([d / rng[:, None], np.ones((len(pr), 1))])
        dz = pr - (rng + x[3])
        x = x + np.linalg.solve(h.T @ w @ h, h.T @ w @ dz)
    return x
