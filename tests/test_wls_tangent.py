"""The hand-written derivative rule of the MHSS projection (``araim.mhss.tangent``)
against automatic differentiation of the same function without it.

``projection.int_weighted_modes`` is a ``jax.custom_jvp`` whose rule is the closed-form
tangent of every fault mode's weighted least squares; ``int_weighted_modes.fun`` is the plain
function (Cholesky factors, rank-one downdates), which JAX differentiates step by step. The
``jax.jvp`` of the two must agree to 1e-10, relative to the largest entry of each output, and
the rule's ``jax.vjp`` must be the transpose of its jvp (the adjoint identity, to 1e-10), on
random geometries: the bench sky with the towers lifted off the receiver's height (so that no
mode is exactly singular), at orders 1 and 2 (the order-2 modes of a source and a
constellation are the Cholesky ones), and the all-Cholesky path. Modes that are singular
carry no derivative downstream (``projection._finish`` masks them), so they are left out of
the comparison.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import araim
from oaraim.araim import linalg
from oaraim.araim.fault_modes import fault_mode_rule, select_fault_modes
from oaraim.araim.mhss.entry import batch_last_inputs
from oaraim.araim.mhss.projection import int_weighted_modes
from oaraim.batching import jit_kernel
from oaraim.bench import mhss_bench_inputs

BUDGET = araim.BUDGET_SEED004_TABLE_I
RTOL = 1e-10
N = 16
#: (fault-mode convention, order, single-source downdates)
CASES = [("grouped", 1, True), ("grouped", 2, True), ("grouped", 1, False)]


def _inputs(rule, order, seed):
    """Batch-last inputs of ``int_weighted_modes`` for N random geometries: the bench case
    with the towers' rows tilted up or down by up to 0.3 (renormalised) and b_nom > 0 for the
    SOPs too. Returns (differentiated args, fixed args)."""
    x = mhss_bench_inputs(N, seed=seed)
    rng = np.random.default_rng(seed)
    g = np.array(x["g"])
    g[:, 9:, 2] = rng.uniform(-0.3, 0.3, (N, 4))
    g /= np.linalg.norm(g, axis=-1, keepdims=True)
    b_nom = np.array(x["b_nom_m"]) + rng.uniform(0.1, 1.0, (N, 13))
    g, const, var_int, var_acc, b_nom, p_sat, p_const, valid = batch_last_inputs(
        jnp.asarray(g), x["constellation"], x["var_int_m2"], x["var_acc_m2"],
        jnp.asarray(b_nom), x["p_sat"], x["p_const"], x["valid"])
    fm = select_fault_modes(valid, const, p_sat, p_const, BUDGET, rule, order)
    w_int = linalg.inverse_variance_weights(jnp.sqrt(var_int), valid)
    member = valid[:, None, :] & (const[:, None, :] == jnp.arange(2)[None, :, None])
    return (g, w_int, var_acc, b_nom), (valid, member, fm.excluded)


def _directions(tree, seed):
    rng = np.random.default_rng(seed)
    return jax.tree.map(lambda a: jnp.asarray(rng.standard_normal(a.shape)), tree)


def _assert_close(got, want, mask, what):
    got, want = np.asarray(got), np.asarray(want)
    mask = np.broadcast_to(np.asarray(mask).reshape(mask.shape[:1] + (1,) * (got.ndim - 2)
                                                    + mask.shape[1:]), got.shape)
    scale = np.max(np.abs(want[mask]))
    err = np.max(np.abs(got - want)[mask])
    assert np.all(np.isfinite(got[mask])), what
    assert err <= RTOL * scale, f"{what}: max error {err:.3e}, largest entry {scale:.3e}"


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}-order{c[1]}-downdates{c[2]}")
def test_rule_matches_autodiff_of_the_plain_projection(case):
    """``jax.jvp`` and ``jax.vjp`` of the custom rule against those of
    ``int_weighted_modes.fun`` (module docstring)."""
    name, order, downdates = case
    rule = fault_mode_rule(name)
    diff, fixed = _inputs(rule, order, seed=len(name) + order)

    def custom(*d):
        return int_weighted_modes(*d, *fixed, rule, order, downdates)[:4]

    def plain(*d):
        return int_weighted_modes.fun(*d, *fixed, rule, order, downdates)[:4]

    nonsingular = np.asarray(int_weighted_modes(*diff, *fixed, rule, order, downdates)[4])
    assert nonsingular[1:].any() and nonsingular[0].all()
    tangents = _directions(diff, 1)
    (_, t_custom), (_, t_plain) = (jit_kernel(lambda *d, f=f: jax.jvp(f, d, tangents))(*diff)
                                   for f in (custom, plain))
    for k, what in enumerate(("s_pos", "var_pos", "bias", "sigma_ss")):
        _assert_close(t_custom[k], t_plain[k], nonsingular, f"jvp {what}")

    # the rule's reverse mode is JAX's transpose of its jvp: check it by the adjoint identity
    # <ct, J t> = <J^T ct, t> for random t and ct (J t is the custom jvp, just checked against
    # autodiff), which spares compiling the plain function's reverse mode (most of this test's
    # time when it compared the two vjps directly)
    out = custom(*diff)
    shaped = [jnp.asarray(nonsingular).reshape(nonsingular.shape[:1] + (1,) * (o.ndim - 2)
                                               + nonsingular.shape[1:]) for o in out]
    cts = tuple(jnp.where(m, c, 0.0)
                for m, c in zip(shaped, _directions(out, 2), strict=True))
    (g_custom,) = (jit_kernel(lambda *d: jax.vjp(custom, *d)[1](cts))(*diff),)
    jvp_custom = jit_kernel(lambda t, *d: jax.jvp(custom, d, t)[1])
    for seed in (1, 3, 4):
        t = _directions(diff, seed)
        jt = jvp_custom(t, *diff)
        terms_out = [jnp.where(m, c * j, 0.0) for m, c, j in zip(shaped, cts, jt, strict=True)]
        terms_in = [a * b for a, b in zip(g_custom, t, strict=True)]
        lhs = float(sum(jnp.sum(x) for x in terms_out))
        rhs = float(sum(jnp.sum(x) for x in terms_in))
        scale = float(sum(jnp.sum(jnp.abs(x)) for x in terms_out + terms_in))
        assert np.isfinite(lhs) and np.isfinite(rhs)
        assert abs(lhs - rhs) <= RTOL * scale, (
            f"adjoint identity, direction {seed}: <ct, J t> = {lhs!r}, <J^T ct, t> = {rhs!r}")
