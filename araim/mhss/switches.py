"""Where the derivatives of the MHSS protection levels are not defined: the switches.

The PLs are smooth functions of the inputs for a fixed set of decisions (which modes are live
and monitored, the status, which mode sets the EMT); the decisions are piecewise constant.
``jax.grad`` through ``protection_levels_kernel`` gives the derivative of the active set
(docs/gradients.md); ``switch_flags_kernel`` says, as data and under ``jax.jit``, where a
geometry lies within a relative distance of a switch, so that a caller can discard or treat
such gradients apart. Bits of the returned int8 (``SWITCH_*``):

- ``SWITCH_UNMONITORED`` (1): P_NM within ``rtol`` (relative) of P_thresh: the status flips
  between OK and UNMONITORED_RISK (eq. 8), the PLs between finite and inf.
- ``SWITCH_SINGULAR`` (2): a live mode (the all-in-view one included) whose clock-eliminated
  position normal matrix passes the pivot test at a tolerance ``band`` times looser and fails
  it at one ``band`` times stricter than ``linalg.RELATIVE_PIVOT_TOLERANCE``: a mode near
  becoming singular (its prior moves to P_NM, N_f and K_fa change). The oracle's "borderline"
  band (``reference_mhss.BORDERLINE_FACTOR``, 1e3) around the kernel's test of the
  all-in-view and whole-constellation modes; the kernel's other tests (single-source
  redundancy, generic pivots) differ from it by less than the band.
- ``SWITCH_MODE_SET`` (4): the convention's selection of live modes or of the order changes
  when every P_s and P_const is scaled by 1 - ``rtol`` or 1 + ``rtol``.
- ``SWITCH_EMT`` (8): two monitored modes of different thresholds set the EMT within ``rtol``
  of each other, or a monitored prior lies within ``rtol`` of P_EMT.
"""

import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Array, Float, Int8

from oaraim.araim import linalg
from oaraim.araim.budget import IntegrityBudget
from oaraim.araim.fault_modes import select_fault_modes
from oaraim.araim.mhss.entry import batch_last_inputs, kernel_options
from oaraim.araim.mhss.inputs import Sources, broadcast_batch
from oaraim.araim.mhss.options import MHSSOptions
from oaraim.araim.mhss.projection import project
from oaraim.batching import jit_kernel, map_tiles

__all__ = ["SINGULAR_BAND", "SWITCH_EMT", "SWITCH_MODE_SET", "SWITCH_RTOL", "SWITCH_SINGULAR",
           "SWITCH_UNMONITORED", "switch_flags_kernel"]

SWITCH_UNMONITORED = 1
SWITCH_SINGULAR = 2
SWITCH_MODE_SET = 4
SWITCH_EMT = 8
#: default relative distance to a probability threshold counted as "on a switch"
SWITCH_RTOL = 1e-6
#: default factor either side of the pivot tolerance counted as "near singular" (the oracle's)
SINGULAR_BAND = 1e3


def _near_singular(keep, live, g, w_int, member, band):
    """(B,) bool: a live mode (keep (K, L, B)) whose position normal matrix after clock
    elimination (rows centred on their constellation's weighted mean over the mode's kept
    sources: the Schur complement, as the kernel's ``_whole_modes``) passes the pivot test
    at tolerance / band and fails it at tolerance x band (``linalg.cholesky``, scale the sum
    of the mode's weights as there). One test for every mode: the kernel's single-source
    test (``SINGLE_REDUNDANCY_TOLERANCE`` on the redundancy) and its generic modes' pivot scale
    (the largest diagonal entry) lie within the band of it."""
    w = jnp.where(keep, w_int[None], 0.0)  # (K, L, B)
    memf = member.astype(g.dtype)  # (L, C, B)
    gt = [g[None, :, a] for a in range(3)]
    for c in range(member.shape[1]):
        wc = w * memf[None, :, c]
        s_c = linalg.sum_axis(wc, 1)
        inv = jnp.where(s_c > 0, 1.0 / jnp.where(s_c > 0, s_c, 1.0), 0.0)
        for a in range(3):
            mean = linalg.sum_axis(wc * g[None, :, a], 1) * inv  # (K, B)
            gt[a] = gt[a] - memf[None, :, c] * mean[:, None]
    n = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i + 1):
            n[i][j] = n[j][i] = linalg.sum_axis(w * gt[i] * gt[j], 1)
    scale = linalg.sum_axis(w, 1)
    _, ok_loose = linalg.cholesky(n, scale=scale / band)
    _, ok_strict = linalg.cholesky(n, scale=scale * band)
    return jnp.any(live & ok_loose & ~ok_strict, axis=0)


def _flags_flat(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, budget,
                max_order, all_in_view_weighting, rule, rtol, band):
    args = batch_last_inputs(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid)
    gl, cl, vi, _, _, ps, pc, vl = args
    pr = project(Sources(*args[:6], args[7]), args[6], budget, MHSSOptions(
        max_order, all_in_view_weighting, rule))
    flags = jnp.where(jnp.abs(pr.p_not_monitored - budget.p_thresh) <= rtol * budget.p_thresh,
                      SWITCH_UNMONITORED, 0)

    fm = select_fault_modes(vl, cl, ps, pc, budget, rule, max_order)
    live = jnp.concatenate([jnp.ones_like(fm.live[:1]), fm.live], axis=0)
    C = pc.shape[0]
    member = vl[:, None, :] & (cl[:, None, :] == jnp.arange(C)[None, :, None])
    w_int = linalg.inverse_variance_weights(jnp.sqrt(jnp.where(vl, vi, 1.0)), vl)
    keep = vl[None] & ~pr.excluded
    g0 = jnp.where(vl[:, None, :], gl, 0.0)
    flags = flags | jnp.where(_near_singular(keep, live, g0, w_int, member, band),
                              SWITCH_SINGULAR, 0)

    moved = jnp.zeros_like(flags, dtype=bool)
    for f in (1.0 - rtol, 1.0 + rtol):
        fm2 = select_fault_modes(vl, cl, ps * f, pc * f, budget, rule, max_order)
        moved = moved | jnp.any(fm2.live != fm.live, axis=0) | (fm2.order != fm.order)
    flags = flags | jnp.where(moved, SWITCH_MODE_SET, 0)

    emt_mask = pr.monitored & (pr.prior >= budget.p_emt)
    thr = jnp.where(emt_mask, pr.threshold[:, 2], -jnp.inf)
    top = jnp.max(thr, axis=0)
    close = emt_mask & (thr < top) & (thr >= top - rtol * jnp.abs(top)) & (top > 0)
    prior_edge = pr.monitored & (jnp.abs(pr.prior - budget.p_emt) <= rtol * budget.p_emt)
    flags = flags | jnp.where(jnp.any(close | prior_edge, axis=0), SWITCH_EMT, 0)
    return flags.astype(jnp.int8)


def _switch_flags(g, constellation, var_int, var_acc, b_nom, p_sat, p_const, valid, budget,
                  max_order, all_in_view_weighting, rule, rtol, band):
    arrays, batch = broadcast_batch(g, constellation, var_int, var_acc, b_nom, p_sat, p_const,
                                    valid)

    def kernel(*xs):
        return _flags_flat(*xs, budget, max_order, all_in_view_weighting, rule, rtol, band)

    return map_tiles(kernel, arrays, batch)


_switch_flags_jit = jit_kernel(_switch_flags, static_argnames=(
    "budget", "max_order", "all_in_view_weighting", "rule", "rtol", "band"))


def switch_flags_kernel(sources: Sources, p_const: Float[ArrayLike, "*#batch C"],
                        budget: IntegrityBudget, options: MHSSOptions, *,
                        rtol: float = SWITCH_RTOL, band: float = SINGULAR_BAND
                        ) -> Int8[Array, "..."]:
    """(...) int8: the ``SWITCH_*`` bits (module docstring) of each geometry, 0 where its
    derivatives of ``protection_levels_kernel`` (same arguments) are those of a decision set
    that no input within ``rtol`` (relative, probabilities) or ``band`` (pivot test) changes.
    jit- and vmap-safe; ``options`` (``MHSSOptions`` with an int ``max_order``), ``rtol`` and
    ``band`` are static. Costs about one more projection (the PL roots are not solved)."""
    options = kernel_options(budget, options)
    s = Sources(*sources).filled()
    return _switch_flags_jit(s.g, s.constellation, s.var_int_m2, s.var_acc_m2, s.b_nom_m,
                             s.p_sat, p_const, s.valid, budget=budget,
                             max_order=options.max_order,
                             all_in_view_weighting=options.all_in_view_weighting,
                             rule=options.fault_modes, rtol=float(rtol), band=float(band))
