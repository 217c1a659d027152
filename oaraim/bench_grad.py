"""Benchmark: the value and the gradient of the MHSS HPL, beside the value alone.

The Table I bench case (9 GPS + 4 BPP SOPs, ``grouped``, order 1; ``bench.mhss_bench_inputs``)
through ``araim.protection_levels_kernel`` inside one ``jit_kernel`` program each (the
kernels' compiler options, one host thread): the HPLs alone (the kernel's own tiles), and
``jax.value_and_grad`` of the sum of the finite HPLs with respect to every real input (the
line-of-sight rows, both variances, b_nom, P_s and P_const), which, the geometries being
independent, is every geometry's HPL and its gradient; taken per tile of 128 geometries
inside a ``lax.map`` over the tiles (the pattern docs/gradients.md recommends for large
batches). The PL roots are differentiated by the implicit function theorem
(``araim.mhss.implicit``) and the fault modes' least squares by their closed-form tangent
(``araim.mhss.tangent``), so the gradient costs the transposed rules and two evaluations of
the risk terms, not the root finder's iterations nor a replay of the factorisations. The
goal set for the gradients: at most 3x the cost of the value (docs/gradients.md).
"""

import time

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import araim
from oaraim.batching import TILE, jit_kernel
from oaraim.bench import host_info, mhss_bench_inputs

#: the differentiated inputs (``araim.Sources`` fields, and P_const)
GRAD_INPUTS = ("g", "var_int_m2", "var_acc_m2", "b_nom_m", "p_sat", "p_const")


def bench_gradient(batch: int = 16_384, repeats: int = 3) -> dict:
    """HPLs per second, value alone and value with its gradient (best of ``repeats`` after a
    compiling call), their cost ratio, and the compile times; a JSON-able dict. ``batch`` a
    multiple of ``oaraim.batching.TILE`` (128): the gradient is taken tile by tile."""
    if batch % TILE:
        raise ValueError(f"batch must be a multiple of {TILE}, got {batch}")
    x = mhss_bench_inputs(batch, seed=11)
    budget = araim.BUDGET_SEED004_TABLE_I
    fixed = {k: x[k] for k in ("constellation", "valid")}

    def hpl(p, fixed=fixed):
        sources = araim.Sources(p["g"], fixed["constellation"], p["var_int_m2"],
                                p["var_acc_m2"], p["b_nom_m"], p["p_sat"], fixed["valid"])
        return araim.protection_levels_kernel(sources, p["p_const"], budget, araim.MHSSOptions(
            1, fault_modes="grouped")).hpl_m

    def total(p, fixed):
        h = hpl(p, fixed)
        return jnp.sum(jnp.where(jnp.isfinite(h), h, 0.0)), h

    grad_tile = jax.value_and_grad(total, has_aux=True)

    def value_and_grad(p):
        # differentiate inside each tile and loop over the tiles outside: reverse mode
        # through the kernel's own loop over tiles (``lax.map``) stores and replays every
        # tile's residuals, measured 16x the value's cost at 4,096 geometries against 3.8x
        # this way (docs/gradients.md)
        tiles = jax.tree.map(lambda a: a.reshape((-1, TILE) + a.shape[1:]), (p, fixed))
        (_, h), g = jax.lax.map(lambda c: grad_tile(*c), tiles)
        return h.reshape(-1), jax.tree.map(lambda a: a.reshape((-1,) + a.shape[2:]), g)

    value = jit_kernel(hpl)
    value_and_grad = jit_kernel(value_and_grad)
    p = {k: x[k] for k in GRAD_INPUTS}
    out = {"case": "table-i", "fault_modes": "grouped", "batch": batch, "threads": 1,
           "inputs": list(GRAD_INPUTS), "host": host_info()}
    for name, fn in (("value", value), ("value_and_grad", value_and_grad)):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(p))
        out[f"{name}_compile_s"] = time.perf_counter() - t0
        best = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(p))
            best = min(best, time.perf_counter() - t0)
        out[f"{name}_s"] = best
        out[f"{name}_hpl_per_s"] = batch / best
    h, grads = value_and_grad(p)
    out["ratio"] = out["value_and_grad_s"] / out["value_s"]
    out["status_ok_share"] = float(np.mean(np.isfinite(np.asarray(h))))
    out["gradients_finite"] = bool(all(np.all(np.isfinite(np.asarray(g)))
                                       for g in grads.values()))
    return out
