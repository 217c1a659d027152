"""The all-in-view position estimator of Blanch, Walter, Enge and Kropp (2015), as MAAST uses it.

J. Blanch, T. Walter, P. Enge, V. Kropp, "A Simple Position Estimator that Improves Advanced
RAIM Performance", IEEE Trans. Aerospace and Electronic Systems 51(3), July 2015; MAAST for
ARAIM's ``prm.opt = 1`` (on by default in ``main_maast_araim.m``, 2015-2024 releases).

The weighted least-squares all-in-view estimate minimises the accuracy sigma but not the
protection level: the PL of a fault mode grows with its solution separation. The estimator
moves, per axis q, the all-in-view coefficient row toward the row of the weakest monitored
fault-tolerant solution (the largest sigma_q^(k) among the modes with prior >= ``prior_min``):

    s_q(t) = s_q^(0) + t (s_q^(k) - s_q^(0)),   t in [0, 1],

as far as the accuracy sigma allows: the largest t with
sqrt(s_q(t)^T C_acc s_q(t)) <= sigma_acc_max,q - 1e-5 m, the root of

    a t^2 + 2 b t + c = 0,   a = ||d||^2_acc = sigma_ss,q^(k)^2,   b = s_q^(0) C_acc d,
    c = sigma_acc,q^2 - (sigma_acc_max,q - 1e-5)^2,   d = s_q^(k) - s_q^(0)

(t = 0 where the all-in-view sigma already exceeds the limit). The separations, thresholds,
the all-in-view sigma and bias (from C_int and b_nom) and sigma_acc are then those of the moved
row; the PL equations are solved again. MAAST tries it only where the baseline fails a target
(VPL > vpl_target, HPL > hpl_target or EMT > emt_target) with sigma_acc,U below its limit, and
keeps the adjusted VPL, HPL, EMT and sigma_acc (all four) where the adjusted VPL or HPL is
lower (``usr_vhpl_araim.m``); ``PositionOptimization`` carries MAAST's LPV-200 values.
"""

from typing import NamedTuple

import jax.numpy as jnp

from oaraim.araim import linalg

#: MAAST's margin below sigma_acc_max (``compute_adjusted_position_1D``: sig_acc_max - 1e-5)
SIGMA_ACC_MARGIN_M = 1e-5


class PositionOptimization(NamedTuple):
    """Configuration of the Blanch et al. (2015) all-in-view estimator (``protection_levels``'
    ``position_optimization``). Defaults: MAAST for ARAIM's LPV-200 settings
    (``main_maast_araim.m``: ``sig_acc_max_hor1 = sig_acc_max_hor2 = 3``,
    ``sig_acc_max_vert = 1.86``, ``vpl_target = 35``, ``hpl_target = 40``, ``emt_target = 15``;
    modes with prior >= 1e-11 are candidates, ``compute_adjusted_position_1D``).

    Attributes:
      sigma_acc_max_m: (east, north, up) accuracy sigma the moved row may reach.
      vpl_target_m, hpl_target_m, emt_target_m: the estimator is tried where the baseline VPL,
        HPL or EMT exceeds its target (inf: never for that quantity).
      prior_min: candidate weakest modes have a prior at least this.
      keep: "lower" (MAAST): where tried, the adjusted results replace the baseline's where
        the adjusted VPL or HPL is lower; "always": the estimator at every geometry whose
        baseline is computed, targets ignored (the estimator alone, e.g. to study it).
    """

    sigma_acc_max_m: tuple = (3.0, 3.0, 1.86)
    vpl_target_m: float = 35.0
    hpl_target_m: float = 40.0
    emt_target_m: float = 15.0
    prior_min: float = 1e-11
    keep: str = "lower"


def check_position_optimization(opt):
    """None, or a ``PositionOptimization`` with finite positive limits; one-line errors."""
    if opt is None:
        return None
    if not isinstance(opt, PositionOptimization):
        raise ValueError("position_optimization must be None or an "
                         f"araim.PositionOptimization, got {type(opt).__name__}")
    limits = tuple(float(x) for x in opt.sigma_acc_max_m)
    if len(limits) != 3 or not all(x > SIGMA_ACC_MARGIN_M and x < float("inf")
                                   for x in limits):
        raise ValueError("position_optimization.sigma_acc_max_m must be three finite sigmas "
                         f"(east, north, up) above {SIGMA_ACC_MARGIN_M} m, got "
                         f"{opt.sigma_acc_max_m!r}")
    targets = (float(opt.vpl_target_m), float(opt.hpl_target_m), float(opt.emt_target_m))
    if not all(t >= 0 for t in targets):
        raise ValueError("position_optimization targets must be >= 0 (inf: never), got "
                         f"{targets}")
    if not 0 <= float(opt.prior_min) <= 1:
        raise ValueError(f"position_optimization.prior_min must be in [0, 1], got "
                         f"{opt.prior_min!r}")
    if opt.keep not in ("lower", "always"):
        raise ValueError(f"position_optimization.keep must be 'lower' or 'always', got "
                         f"{opt.keep!r}")
    return PositionOptimization(limits, *targets, float(opt.prior_min), opt.keep)


def adjusted_rows(s_pos, sigma, prior, monitored, var_acc, sigma_acc_max_m, prior_min):
    """The moved all-in-view rows, batch-last.

    s_pos (K, 3, L, B): position rows of every mode (mode 0 the all-in-view); sigma (K, 3, B);
    prior, monitored (K, B); var_acc (L, B) (0 for padding). Returns (3, L, B) and t (3, B)."""
    s0 = s_pos[0]
    cand = monitored & (prior >= prior_min)  # mode 0 is never monitored: d = 0 there anyway
    rows, ts = [], []
    for q in range(3):
        score = jnp.where(cand, sigma[:, q], -jnp.inf)  # (K, B)
        weak = jnp.argmax(score, axis=0)  # (B,)
        found = jnp.any(cand, axis=0)
        s_k = jnp.take_along_axis(s_pos[:, q], weak[None, None], axis=0)[0]  # (L, B)
        d = jnp.where(found[None], s_k - s0[q], 0.0)
        a = linalg.sum_axis(d * d * var_acc, 0)
        b = linalg.sum_axis(s0[q] * d * var_acc, 0)
        c = (linalg.sum_axis(s0[q] ** 2 * var_acc, 0)
             - (sigma_acc_max_m[q] - SIGMA_ACC_MARGIN_M) ** 2)
        move = (c < 0) & (a > 0)
        a_safe = jnp.where(move, a, 1.0)
        t = (-b + jnp.sqrt(jnp.maximum(b * b - a_safe * c, 0.0))) / a_safe
        t = jnp.where(move, jnp.minimum(t, 1.0), 0.0)
        rows.append(s0[q] + t[None] * d)
        ts.append(t)
    return jnp.stack(rows, axis=0), jnp.stack(ts, axis=0)
