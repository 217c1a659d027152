"""``oaraim bench --only leo``: MHSS throughput with LEO satellites, L = 20, 40, 52 and 60
sources, and the NumPy oracle at the same inputs.

A geometry: 16 GNSS satellites (8 GPS, 8 Galileo; random sky above 5 deg, ADD error models,
sigma_URA 1 m, b_nom 0.75 m, P_sat 1e-5, P_const 1e-8 / 1e-4) and L - 16 LEO satellites of one
SOP constellation (random sky above 25 deg, ``errors.leo``: Starlink's Ku downlink,
the ``estimated`` ISM: sigma_URA 1 m, P_s 1e-5, P_const 1e-4). ``add-v4.2`` (the default) up
to its 52 sources at the order its P_thresh rule asks (2 from L = 40: the pairs' priors exceed
P_thresh); L = 60 under ``grouped`` (seed 004's convention: no source limit).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import errors, geometry, reference_mhss

#: (L, fault-mode convention) of the rows
LEO_CASES = ((20, "add-v4.2"), (40, "add-v4.2"), (52, "add-v4.2"), (60, "grouped"))
N_GNSS = 16
#: the batch above L = 20 (order 2 at ~40 PL/s: a 4,096 batch would take minutes per call)
ORDER2_BATCH = 256


def leo_inputs(n, L, seed=0):
    """n geometries of N_GNSS GNSS + L - N_GNSS LEO sources (module docstring)."""
    from oaraim import araim

    k1, k2 = jax.random.split(jax.random.key(seed))
    az_g, el_g = geometry.random_sky(k1, N_GNSS, np.deg2rad(5.0), (n,))
    az_l, el_l = geometry.random_sky(k2, L - N_GNSS, np.deg2rad(25.0), (n,))
    vi, va = errors.gnss_variances(el_g)
    vl, val = errors.leo_variances(el_l, araim.LEO_ISM["estimated"], errors.LEO_SIGNALS["starlink"])
    labels = jnp.array([0] * (N_GNSS // 2) + [1] * (N_GNSS // 2) + [2] * (L - N_GNSS))
    shape = (n, L)
    return dict(
        g=geometry.geometry_rows(jnp.concatenate([az_g, az_l], -1),
                                 jnp.concatenate([el_g, el_l], -1)),
        constellation=jnp.broadcast_to(labels, shape),
        var_int_m2=jnp.concatenate([vi, vl], -1), var_acc_m2=jnp.concatenate([va, val], -1),
        b_nom_m=jnp.broadcast_to(jnp.where(labels < 2, 0.75, 0.0), shape),
        p_sat=jnp.full(shape, 1e-5),
        p_const=jnp.broadcast_to(jnp.array([1e-8, 1e-4, 1e-4]), (n, 3)),
        valid=jnp.ones(shape, bool))


def bench_leo(host_info, batch=4_096, ref_geometries=10, repeats=3):
    """Per case of ``LEO_CASES``: PL/s of ``araim.protection_levels`` (order from the rule),
    the oracle's PL/s on ``ref_geometries`` of them, and the largest difference;
    ``host_info`` is ``oaraim.bench.host_info`` (each record's host)."""
    import time

    from oaraim import araim

    out = []
    for L, rule in LEO_CASES:
        n = batch if L <= 20 else min(batch, ORDER2_BATCH)
        x = leo_inputs(n, L)
        budget = araim.BUDGET_LPV200
        order = int(araim.required_order(x["valid"][:1], x["constellation"][:1],
                                         x["p_sat"][:1], x["p_const"][:1],
                                         budget if rule != "grouped" else budget.p_thresh,
                                         cap=2, fault_modes=rule))

        reps = repeats if order == 1 else 1
        sources = araim.Sources(*(x[k] for k in ("g", "constellation", "var_int_m2",
                                                 "var_acc_m2", "b_nom_m", "p_sat", "valid")))
        call = functools.partial(araim.protection_levels, sources, x["p_const"],
                                 budget, araim.MHSSOptions(order, fault_modes=rule))

        res = call()
        res.hpl_m.block_until_ready()
        times = []
        for _ in range(reps):
            t0 = time.perf_counter()
            call().hpl_m.block_until_ready()
            times.append(time.perf_counter() - t0)
        t = min(times)
        xs = {k: np.asarray(v[:ref_geometries]) for k, v in x.items()}
        t0 = time.perf_counter()
        opts = reference_mhss.ReferenceOptions(max_order=order, fault_modes=rule)
        refs = [reference_mhss.protection_levels_reference(
            tuple(xs[k][i] for k in araim.Sources._fields), xs["p_const"][i], budget, opts)
            for i in range(ref_geometries)]
        t_ref = time.perf_counter() - t0
        diff = max(abs(float(a) - r.vpl_m) if np.isfinite(r.vpl_m) else 0.0
                   for a, r in zip(np.asarray(res.vpl_m[:ref_geometries]), refs, strict=True))
        out.append({"L": L, "fault_modes": rule, "order": order, "batch": n,
                    "n_modes": int(np.max(np.asarray(res.n_modes))),
                    "status_ok_share": float(np.mean(np.asarray(res.status) == 0)),
                    "jax_pl_per_s": n / t, "reference_pl_per_s": ref_geometries / t_ref,
                    "speedup": (n / t) / (ref_geometries / t_ref),
                    "max_abs_diff_vpl_m": diff, "host": host_info()})
    return out


def leo_rows(records, host):
    """The README bench table's rows of ``bench_leo``'s records."""
    return [(f"MHSS with LEO satellites, L = {m['L']} (`{m['fault_modes']}`)",
             f"16 GNSS + {m['L'] - N_GNSS} LEO (Starlink Ku, estimated ISM), order "
             f"{m['order']}, {m['n_modes']} modes, batch {m['batch']:,}",
             f"{m['jax_pl_per_s']:,.0f} PL/s", f"{m['reference_pl_per_s']:,.1f} PL/s",
             f"{m['speedup']:,.0f}x", *host(m)) for m in records]
