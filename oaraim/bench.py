"""``oaraim bench``: throughput of the batched kernels against the NumPy reference, same run.

The reference is the per-geometry NumPy/SciPy oracle of the tests (``oaraim.reference``,
``reference_mhss``); it ships with the package, so an installed bench always reports the ratio.
"""

import datetime
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import errors, geometry, reference, reference_mhss
from oaraim.araim import lambda_det_table, slope_hpl_tiled


def host_info() -> dict:
    """When and where a benchmark ran: UTC date, CPU count and model, JAX version, JAX's default
    backend (``cpu``, ``gpu``, ...) and, off the CPU, the device's name (``NVIDIA H200``)."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            model = next((ln.split(":", 1)[1].strip() for ln in f
                          if ln.startswith("model name")), model)
    except OSError:
        pass
    out = {"date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d"),
           "cpus": os.cpu_count(), "cpu_model": model, "jax": jax.__version__,
           "backend": jax.default_backend()}
    if out["backend"] != "cpu":
        out["device"] = jax.devices()[0].device_kind
    return out


def _geometries(n, seed=0):
    """5 GPS (15 deg mask) + 4 BPP towers at 0 deg: the Fig. 4 GPS-SOP case, M + N = 9."""
    k1, k2 = jax.random.split(jax.random.key(seed))
    az, el = geometry.random_sky(k1, 5, np.deg2rad(15.0), (n,))
    t = geometry.bpp_towers(k2, 4, 5.0, 3000.0, 0.0, 0.0, (n,))
    return geometry.geometry_rows(jnp.concatenate([az, t.az_rad], -1),
                                  jnp.concatenate([el, t.el_rad], -1))


#: passes of the NumPy references (best of), also reported as ``reference_repeats``
SLOPE_REFERENCE_REPEATS = 2
MHSS_REFERENCE_REPEATS = 3


def _best_time(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_slope_hpl(batch=262_144, ref_geometries=2_000, repeats=5):
    """Slope HPLs per second (seed 001, 9 sources) and the NumPy reference in the same run."""
    g = _geometries(batch)
    sigma = jnp.ones(g.shape[:-1])
    valid = jnp.ones(g.shape[:-1], bool)
    table = jnp.asarray(lambda_det_table(1e-5, 1e-3, 5))
    run = lambda: slope_hpl_tiled(g, sigma, valid, table).hpl_m.block_until_ready()  # noqa: E731
    run()  # compile
    t = _best_time(run, repeats)
    out = {"batch": batch, "jax_s": t, "jax_hpl_per_s": batch / t, "host": host_info()}
    gn = np.asarray(g[:ref_geometries])
    sq = float(np.sqrt(table[5]))

    def run_ref():
        return [np.max(reference.slopes_reference(gi, 1.0)) * sq for gi in gn]

    hpl_ref = np.array(run_ref())
    t_ref = _best_time(run_ref, SLOPE_REFERENCE_REPEATS)
    hpl_jax = np.asarray(slope_hpl_tiled(g[:ref_geometries], sigma[:ref_geometries],
                                            valid[:ref_geometries], table).hpl_m)
    out.update(reference_geometries=ref_geometries, reference_repeats=SLOPE_REFERENCE_REPEATS,
               reference_s=t_ref,
               reference_hpl_per_s=ref_geometries / t_ref,
               speedup=(batch / t) / (ref_geometries / t_ref),
               max_rel_diff=float(np.max(np.abs(hpl_jax / hpl_ref - 1))))
    return out


def bench_fig3(realizations=1_000_000):
    """Wall time of seed001-fig3-elevation at ``realizations`` (compilation included)."""
    from oaraim.studies.seed001_fig3 import Fig3Elevation

    study = Fig3Elevation()
    params = study.validate({})
    t0 = time.perf_counter()
    result = study.run(params, realizations, 0, None)
    return {"realizations": realizations, "wall_s": time.perf_counter() - t0,
            "share_el_star_0deg_pct": result.metrics["share_el_star_0deg_pct"],
            "host": host_info()}


def mhss_bench_inputs(n, seed=0, n_gps=9, n_sop=4, sigma_ura_sop_m=3.0, p_sat_sop=1e-4):
    """The issue-3 benchmark case: 9 GPS (5 deg mask, ADD error models, Table I) + 4 BPP SOPs in
    one SOP constellation (sigma_URA^S = 3 m, P_s^S = 1e-4, P_const^S = 1e-4, b_nom 0)."""

    k1, k2 = jax.random.split(jax.random.key(seed))
    az, el = geometry.random_sky(k1, n_gps, np.deg2rad(5.0), (n,))
    t = geometry.bpp_towers(k2, n_sop, 5.0, 3000.0, 0.0, 0.0, (n,))
    g = geometry.geometry_rows(jnp.concatenate([az, t.az_rad], -1),
                               jnp.concatenate([el, t.el_rad], -1))
    vi, va = errors.gnss_variances(el)
    si, sa = errors.sop_variances(jnp.full((n, n_sop), sigma_ura_sop_m))
    L = n_gps + n_sop
    shape = (n, L)
    return dict(
        g=g, constellation=jnp.broadcast_to(jnp.array([0] * n_gps + [1] * n_sop), shape),
        var_int_m2=jnp.concatenate([vi, si], -1), var_acc_m2=jnp.concatenate([va, sa], -1),
        b_nom_m=jnp.broadcast_to(jnp.array([0.75] * n_gps + [0.0] * n_sop), shape),
        p_sat=jnp.broadcast_to(jnp.array([1e-5] * n_gps + [p_sat_sop] * n_sop), shape),
        p_const=jnp.broadcast_to(jnp.array([1e-8, 1e-4]), (n, 2)),
        valid=jnp.ones(shape, bool))


def blanch_2012_inputs(n, seed=1):
    """n random 5 GPS + 5 Galileo skies with the inputs of Blanch et al. 2012 Appendix J
    (P_sat 1e-4, P_const 1e-4, b_nom 0.5 m, ADD error models): under ``blanch-2012`` each
    monitors 57 modes (10 satellites, 45 pairs, 2 constellations)."""

    k1, k2 = jax.random.split(jax.random.key(seed))
    az1, el1 = geometry.random_sky(k1, 5, np.deg2rad(5.0), (n,))
    az2, el2 = geometry.random_sky(k2, 5, np.deg2rad(5.0), (n,))
    az, el = jnp.concatenate([az1, az2], -1), jnp.concatenate([el1, el2], -1)
    vi, va = errors.gnss_variances(el, 0.75)
    shape = (n, 10)
    return dict(g=geometry.geometry_rows(az, el),
                constellation=jnp.broadcast_to(jnp.array([0] * 5 + [1] * 5), shape),
                var_int_m2=vi, var_acc_m2=va, b_nom_m=jnp.full(shape, 0.5),
                p_sat=jnp.full(shape, 1e-4), p_const=jnp.full((n, 2), 1e-4),
                valid=jnp.ones(shape, bool))


#: the cases of ``bench_mhss``: inputs, budget, template order, fault-mode convention
MHSS_CASES = {
    # seed 004 Table I, the seed 004 studies' convention; order 1 is what max_order=None picks
    # (P(> 1 faulty constellation) = 4.5e-8)
    "table-i": (mhss_bench_inputs, "BUDGET_SEED004_TABLE_I", 1, "grouped"),
    # the same geometries under the current ADD (the kernels' default)
    "table-i-add-v4.2": (mhss_bench_inputs, "BUDGET_SEED004_TABLE_I", 1, "add-v4.2"),
    # pairs of satellites: Blanch et al. 2012 Appendix J's inputs, 57 modes
    "blanch-2012-57-modes": (blanch_2012_inputs, "BUDGET_LPV200", 2, "blanch-2012"),
}


def bench_mhss(batch=65_536, ref_geometries=200, repeats=5, case="table-i"):
    """MHSS protection levels (HPL, VPL, EMT) per second, and the NumPy reference of tests/,
    for one of ``MHSS_CASES``."""
    from oaraim import araim
    from oaraim.config import default_threads

    inputs, budget_name, order, fault_modes = MHSS_CASES[case]
    x = inputs(batch)
    budget = getattr(araim, budget_name)

    def call(threads=None):
        # the public entry point, host-side input checks and thread split included
        sources = araim.Sources(*(x[k] for k in araim.Sources._fields))
        return araim.protection_levels(sources, x["p_const"], budget,
                                       araim.MHSSOptions(order, fault_modes=fault_modes),
                                       threads=threads)

    def run():
        return call().hpl_m.block_until_ready()

    run()
    t = _best_time(run, repeats)
    call(1).hpl_m.block_until_ready()
    t1 = _best_time(lambda: call(1).hpl_m.block_until_ready(), repeats)
    res = call()
    out = {"case": case, "fault_modes": fault_modes, "order": order,
           "batch": batch, "jax_s": t, "jax_pl_per_s": batch / t,
           "threads": default_threads(), "one_thread_pl_per_s": batch / t1,
           "status_ok_share": float(np.mean(np.asarray(res.status) == 0)),
           "n_modes": int(np.max(np.asarray(res.n_modes))), "host": host_info()}
    xs = {k: np.asarray(v[:ref_geometries]) for k, v in x.items()}

    def run_ref():
        opts = reference_mhss.ReferenceOptions(max_order=order, fault_modes=fault_modes)
        return [reference_mhss.protection_levels_reference(
            tuple(xs[k][i] for k in araim.Sources._fields), xs["p_const"][i], budget, opts)
            for i in range(ref_geometries)]

    # best of 3, as the JAX side is best of ``repeats`` after a warm-up call: one cold
    # pass of 200 geometries (~0.4 s) took the load spikes of this shared host alone
    # (the reference measured 315-509 PL/s in three runs within 3 minutes)
    refs = []
    t_ref = _best_time(lambda: refs.append(run_ref()), MHSS_REFERENCE_REPEATS)
    refs = refs[-1]
    hpl_ref = np.array([r.hpl_m for r in refs])
    vpl_ref = np.array([r.vpl_m for r in refs])
    hpl = np.asarray(res.hpl_m[:ref_geometries])
    vpl = np.asarray(res.vpl_m[:ref_geometries])
    fin = np.isfinite(hpl_ref) & np.isfinite(hpl)
    out.update(reference_geometries=ref_geometries, reference_repeats=MHSS_REFERENCE_REPEATS,
               reference_s=t_ref,
               reference_pl_per_s=ref_geometries / t_ref,
               speedup=(batch / t) / (ref_geometries / t_ref),
               max_abs_diff_m=float(max(np.max(np.abs(hpl - hpl_ref)[fin], initial=0),
                                        np.max(np.abs(vpl - vpl_ref)[fin], initial=0))))
    return out


def profile_mhss(batch=65_536, repeats=3):
    """Where the MHSS time goes: fault modes, projectors (eqs. 9-12) and PL root finding, in CPU
    seconds of cumulative stages (each stage timed on its own, differences reported)."""
    from oaraim import araim
    from oaraim.araim import FaultModeRule, fault_modes_batch_last
    from oaraim.araim.mhss import PL_ITERATIONS, batch_last_inputs, pls_from_projection, project
    from oaraim.batching import jit_kernel, map_tiles

    GROUPED = FaultModeRule("grouped")  # the Table I case's convention (``MHSS_CASES``)

    x = mhss_bench_inputs(batch)
    budget = araim.BUDGET_SEED004_TABLE_I
    arrays = [x[k] for k in ("g", "constellation", "var_int_m2", "var_acc_m2", "b_nom_m",
                             "p_sat", "p_const", "valid")]

    def stage(upto):
        def kernel(*xs):
            a = batch_last_inputs(*xs)
            if upto == "fault_modes":
                out = fault_modes_batch_last(a[7], a[1], a[5], a[6], budget.p_thresh, 1).prior
            else:
                pr = project(araim.Sources(*a[:6], a[7]), a[6], budget,
                             araim.MHSSOptions(1, fault_modes=GROUPED))
                if upto == "projectors":
                    out = pr.threshold + pr.bias + pr.sigma
                else:
                    out = pls_from_projection(pr, budget, PL_ITERATIONS)[0]
            return jnp.moveaxis(out, -1, 0)

        f = jit_kernel(lambda *xs: map_tiles(kernel, xs, (batch,)))
        jax.block_until_ready(f(*arrays))
        best = np.inf
        for _ in range(repeats):  # CPU time: steadier than wall time on a shared machine
            t0 = time.process_time()
            jax.block_until_ready(f(*arrays))
            best = min(best, time.process_time() - t0)
        return best

    t = {s: stage(s) for s in ("fault_modes", "projectors", "all")}
    return {"batch": batch, "fault_modes_s": t["fault_modes"],
            "projectors_s": max(t["projectors"] - t["fault_modes"], 0.0),
            "pl_root_finding_s": max(t["all"] - t["projectors"], 0.0), "total_s": t["all"],
            "cpu_us_per_pl": 1e6 * t["all"] / batch}


def bench_sky(repeats=3):
    """GPS + Galileo skies. (a) one receiver, 24 h at 30 s (2,880 epochs) of the
    nominal 48-satellite sky, and of the Villafranca broadcast file when the data are present;
    (b) 1,000 receivers (a 0.1-degree grid around Madrid) x 288 epochs (24 h at 5 min).
    Best of ``repeats`` after a compiling call; the file's parse is cached per process and
    reported separately."""
    from oaraim.readers import gpstime

    t0 = float(gpstime.gps_seconds(2018, 6, 19))
    day30 = t0 + 30.0 * np.arange(2880)
    day300 = t0 + 300.0 * np.arange(288)
    rx = np.array([4849210.0, -360329.7, 4114920.0])

    def one(source, t, receivers):
        s = geometry.sky(receivers, t, source=source, mask_deg=5.0)
        s.valid.block_until_ready()
        return s

    out = {"host": host_info()}
    one("nominal", day30, rx)
    out["one_receiver_2880_epochs_nominal_s"] = _best_time(lambda: one("nominal", day30, rx),
                                                           repeats)
    from oaraim import data

    try:  # the broadcast row only where the file is already here (a bench never downloads)
        nav = data.path("nav/VILL00ESP_R_20181700000_01D_MN.rnx.gz", fetch=False)
    except data.DataUnavailable:
        nav = None
    if nav is not None:
        t_load = time.perf_counter()
        eph = geometry.load_navigation(nav)
        out["vill_parse_s"] = time.perf_counter() - t_load
        one(eph, day30, rx)
        out["one_receiver_2880_epochs_broadcast_s"] = _best_time(
            lambda: one(eph, day30, rx), repeats)
        out["broadcast_satellites"] = int(eph.prns.size)
    lat = np.deg2rad(40.0 + 0.1 * (np.arange(1000) // 40))
    lon = np.deg2rad(-6.0 + 0.1 * (np.arange(1000) % 40))
    grid = np.asarray(geometry.geodetic_to_ecef(lat, lon, np.zeros(1000)))
    one("nominal", day300, grid)
    out["receivers_1000_x_288_epochs_nominal_s"] = _best_time(
        lambda: one("nominal", day300, grid), repeats)
    return out


#: batch sizes of the latency rows (a notebook user and the per-epoch replays)
LATENCY_BATCHES = (1, 8, 64)


def bench_latency(batches=LATENCY_BATCHES, calls=300, fault_modes=None):
    """Warm ``araim.protection_levels`` calls as a user makes them (NumPy in, the default
    ``max_order=None`` and fault-mode convention, host checks included, result ready):
    median and 99th percentile of ``calls`` calls per batch size, after one compiling call
    per size. The bench geometries (9 GPS + 4 SOPs, Table I)."""
    from oaraim import araim

    x = {k: np.asarray(v) for k, v in mhss_bench_inputs(max(batches), seed=3).items()}
    budget = araim.BUDGET_SEED004_TABLE_I
    out = {"fault_modes": fault_modes or "add-v4.2", "calls": calls, "host": host_info()}
    for n in batches:
        a = {k: v[:n] for k, v in x.items()}

        def call(a=a):
            r = araim.protection_levels(araim.Sources(*(a[k] for k in araim.Sources._fields)),
                                        a["p_const"], budget,
                                        araim.MHSSOptions(fault_modes=fault_modes))
            return r.hpl_m.block_until_ready()

        call()
        times = []
        for _ in range(calls):
            t0 = time.perf_counter()
            call()
            times.append(time.perf_counter() - t0)
        out[f"batch_{n}"] = {"median_ms": 1e3 * float(np.median(times)),
                             "p99_ms": 1e3 * float(np.percentile(times, 99))}
    return out


_STARTUP_PROBE = """
import time
t0 = time.perf_counter()
import numpy as np
from oaraim import araim
from oaraim.bench import mhss_bench_inputs
t1 = time.perf_counter()
x = mhss_bench_inputs(64, seed=4)
r = araim.protection_levels(araim.Sources(*(x[k] for k in araim.Sources._fields)), x["p_const"],
                            araim.BUDGET_SEED004_TABLE_I)
r.hpl_m.block_until_ready()
print(t1 - t0, time.perf_counter() - t1)
"""


def _python_s(code, env=None, repeats=3):
    """Best wall time of a fresh interpreter running ``code`` (seconds)."""
    import subprocess
    import sys

    def run():
        subprocess.run([sys.executable, "-c", code], check=True, env=env,
                       capture_output=True)

    return _best_time(run, repeats)


def bench_startup(repeats=3):
    """What a user waits for before the first result: ``import oaraim``, ``from oaraim import
    araim, geometry`` and ``oaraim --help`` (best of ``repeats`` fresh interpreters), and the
    first ``protection_levels`` call on 64 geometries in a new process, compiled (an empty
    compilation cache) and from the persistent cache (the same folder again)."""
    import os
    import shutil
    import subprocess
    import sys
    import tempfile

    out = {"host": host_info(),
           "import_oaraim_s": _python_s("import oaraim", repeats=repeats),
           "import_araim_geometry_s": _python_s("from oaraim import araim, geometry",
                                                repeats=repeats),
           "cli_help_s": _python_s("import sys; sys.argv = ['oaraim', '--help']\n"
                                   "from oaraim.cli import main\n"
                                   "try:\n    main()\nexcept SystemExit:\n    pass",
                                   repeats=repeats)}
    folder = tempfile.mkdtemp(prefix="oaraim-bench-cache-")
    try:
        env = dict(os.environ, OARAIM_JAX_CACHE=folder)
        for key in ("first_call_cold_s", "first_call_cached_s"):
            res = subprocess.run([sys.executable, "-c", _STARTUP_PROBE], check=True, env=env,
                                 capture_output=True, text=True)
            out[key] = float(res.stdout.split()[-1])
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return out


def bench_fig4(realizations=5_000):
    """The ``seed004-fig4-hpl-maps`` study end to end at its full size (26 x 13 cells x 6 SOP
    counts x 5,000 realizations, in a temporary folder, compile included): wall time and
    draws (cell x realization: one geometry's HPL without and with the SOPs) per second."""
    import tempfile

    from oaraim.execute import run_sweep_study
    from oaraim.registry import STUDIES

    study = STUDIES["seed004-fig4-hpl-maps"]
    params = study.validate({})
    with tempfile.TemporaryDirectory(prefix="oaraim-bench-fig4-") as tmp:
        t0 = time.perf_counter()
        _, sweep = run_sweep_study(study, params, realizations, 0, tmp, progress=False)
        wall = time.perf_counter() - t0
    draws = sweep.cells * realizations
    return {"realizations": realizations, "cells": sweep.cells, "draws": draws, "wall_s": wall,
            "draws_per_s": draws / wall, "threads": sweep.threads, "host": host_info()}


def _rate(x: float, unit: str) -> str:
    return f"{x:,.0f} {unit}"


def bench_availability_map(sets=None, workers=None):
    """The ``availability-map`` study end to end in a temporary folder (sky pass, compilation,
    sweep, cube and maps; no figure): wall time and protection levels per second. ``sets``
    overrides parameters (default: MAAST's 10 x 10 deg world, 24 h at 300 s); ``workers`` runs
    it on a local Dask cluster of that many processes."""
    import tempfile

    from oaraim.execute import RunOptions, run_sweep_study
    from oaraim.mc import Execution
    from oaraim.registry import STUDIES

    study = STUDIES["availability-map"]
    params = study.validate(dict(sets or {}))
    n = study.fixed_realizations(params)
    with tempfile.TemporaryDirectory(prefix="oaraim-bench-map-") as tmp:
        t0 = time.perf_counter()
        res, sweep = run_sweep_study(study, params, n, 0, tmp, progress=False,
                                     options=RunOptions(execution=Execution(workers=workers)))
        wall = time.perf_counter() - t0
    m = res.metrics
    return {"lat_step_deg": _step(params["lat_deg"]), "lon_step_deg": _step(params["lon_deg"]),
            "users": m["grid_points"], "epochs": m["epochs"],
            "protection_levels": m["protection_levels"], "wall_s": wall,
            "sweep_wall_s": sweep.wall_s, "pl_per_s": m["protection_levels"] / wall,
            "coverage_pct": m["coverage_pct"], "service_level": m["service_level"],
            "fault_modes": params["fault_modes"], "workers": workers, "threads": sweep.threads,
            "host": host_info()}


def bench_integrity_risk(samples=200_000, ref_samples=200, repeats=3):
    """``araim.integrity_risk`` on the MHSS bench geometry (9 GPS + 4 SOPs, Table I): the
    receiver's decisions per second from the linear maps (detection, exclusion, both HMI
    events) against ``reference_mhss.detect_and_exclude_reference`` on the same residuals; one
    geometry's full risk table; and the importance-sampling speed-up over crude Monte Carlo at
    equal relative error on the fault-free vertical risk (crude: (1 - p) / (p r^2) samples at
    its measured cost per sample)."""
    from oaraim import araim
    from oaraim.araim import integrity_risk as ir

    # the integrity-risk study's convention (seed 004's grouping), as the Table I MHSS case
    x = mhss_bench_inputs(1)
    budget = araim.BUDGET_SEED004_TABLE_I
    args = (x["g"][0], x["constellation"][0], x["var_int_m2"][0], x["var_acc_m2"][0],
            x["b_nom_m"][0], x["p_sat"][0], x["p_const"][0])
    t0 = time.perf_counter()
    maps = ir.monitor_maps(araim.Sources(*args[:6], x["valid"][0]), args[6], budget,
                           araim.MHSSOptions(1, fault_modes="grouped"))
    jax.block_until_ready(maps)
    t_maps = time.perf_counter() - t0
    sig = np.sqrt(np.asarray(x["var_int_m2"][0]))
    y = jax.random.normal(jax.random.key(1), (samples, sig.size)) * sig * 3.0
    ev = jax.jit(ir.evaluate)
    jax.block_until_ready(ev(maps, y))
    t = _best_time(lambda: jax.block_until_ready(ev(maps, y)), repeats)
    out = ev(maps, y)
    ys = np.asarray(y[:ref_samples])
    nargs = [np.asarray(a) for a in args]

    def run_ref():
        src = araim.Sources(*nargs[:6], np.asarray(x["valid"][0]))
        opts = reference_mhss.ReferenceOptions(1, fault_modes="grouped")
        return [reference_mhss.detect_and_exclude_reference(src, nargs[6], budget, ys[i], opts)
                for i in range(ref_samples)]

    refs = []
    t_ref = _best_time(lambda: refs.append(run_ref()), 1)
    agree = float(np.mean([bool(r.detected) == bool(d) for r, d in
                           zip(refs[-1], np.asarray(out.detected[:ref_samples]), strict=True)]))
    key = jax.random.key(2)
    jax.block_until_ready(ir.risk_table(maps, key))
    t_table = _best_time(lambda: jax.block_until_ready(ir.risk_table(maps, key).estimate), 1)
    # equal relative error: fault-free vertical P(HMI), IS vs crude at the measured costs
    opts = ir.Sampling(n_samples=2000, ce_samples=1000, ce_rounds=2)
    crude = ir.Sampling(n_samples=samples, crude=True)
    est = lambda sampling: ir.scenario_estimate(  # noqa: E731
        maps, ir.Scenario(ir.FAULT_FREE, ir.VERTICAL, 0.0), key, sampling)[2]
    jax.block_until_ready(est(opts))
    t_is = _best_time(lambda: jax.block_until_ready(est(opts)), repeats)
    e = est(opts)
    p, rel = float(e.p_md), float(e.se_md) / float(e.p_md)
    jax.block_until_ready(est(crude))
    t_crude = _best_time(lambda: jax.block_until_ready(est(crude)), repeats)
    crude_s = t_crude / samples * (1 - p) / (p * rel**2)
    return {"samples": samples, "evaluate_s": t, "samples_per_s": samples / t,
            "reference_samples": ref_samples, "reference_s": t_ref,
            "reference_samples_per_s": ref_samples / t_ref,
            "speedup": (samples / t) / (ref_samples / t_ref), "detection_agreement": agree,
            "maps_s_compile_included": t_maps, "risk_table_s": t_table,
            "scenario_slots": int(1 + sig.size + 4), "x_grid": len(ir.DEFAULT_X_GRID),
            "ff_vertical_p": p, "ff_vertical_rel_error": rel, "is_s": t_is,
            "crude_s_equal_rel_error": crude_s, "is_speedup_equal_rel_error": crude_s / t_is,
            "host": host_info()}


def _step(values):
    v = np.diff(np.asarray(values, float))
    return float(v.min()) if v.size else 0.0


def markdown_table(bench_json: dict) -> str:
    """The benchmark table of the README and docs/benchmarks.md, from ``oaraim bench --json``.

    One row per measured kernel: what it computes, the workload, its throughput, the NumPy
    reference's throughput measured in the same run (where there is one), their ratio, the
    machine (CPU count from the run's ``host`` record) and the date of the run.
    """
    def host(entry):
        h = entry.get("host") or {}
        cpus = h.get("cpus")
        machine = f"{cpus} cores" if cpus else "-"
        if h.get("backend", "cpu") != "cpu":
            machine = f"{h.get('device') or h['backend']} ({machine} host)"
        if h.get("jax"):
            machine += f", JAX {h['jax']}"
        return machine, h.get("date", "-")

    rows = []
    if "startup" in bench_json:
        st = bench_json["startup"]
        rows.append(("start-up: `import oaraim` / `from oaraim import araim, geometry` / "
                     "`oaraim --help`", "a fresh interpreter, best of 3",
                     f"{st['import_oaraim_s']:.2f} s / {st['import_araim_geometry_s']:.2f} s / "
                     f"{st['cli_help_s']:.2f} s", "-", "-", *host(st)))
        rows.append(("first `araim.protection_levels` call in a new process",
                     "9 GPS + 4 SOPs, batch 64, `add-v4.2`",
                     f"{st['first_call_cold_s']:.1f} s compiling, "
                     f"{st['first_call_cached_s']:.1f} s from the compilation cache", "-", "-",
                     *host(st)))
    if "latency" in bench_json:
        lat = bench_json["latency"]
        for key in sorted((k for k in lat if k.startswith("batch_")),
                          key=lambda k: int(k.split("_")[1])):
            n = int(key.split("_")[1])
            rows.append(("`araim.protection_levels` latency, warm, NumPy in",
                         f"9 GPS + 4 SOPs, batch {n}, `{lat['fault_modes']}`, "
                         "`max_order=None`",
                         f"median {lat[key]['median_ms']:.2f} ms, p99 {lat[key]['p99_ms']:.2f} ms",
                         "-", "-", *host(lat)))
    if "slope_hpl" in bench_json:
        s = bench_json["slope_hpl"]
        rows.append(("slope HPL (seed 001), `araim.slope_hpl` kernel",
                     f"5 GPS + 4 SOPs, batch {s['batch']:,}",
                     _rate(s["jax_hpl_per_s"], "HPL/s"),
                     _rate(s["reference_hpl_per_s"], "HPL/s"), f"{s['speedup']:,.0f}x",
                     *host(s)))
    if "mhss" in bench_json:
        m = bench_json["mhss"]
        ref = (_rate(m["reference_pl_per_s"], "PL/s"), f"{m['speedup']:,.0f}x") \
            if "speedup" in m else ("-", "-")
        rows.append(("MHSS protection levels (seed 004, `grouped`), `araim.protection_levels`",
                     f"9 GPS + 4 SOPs, Table I, {m['n_modes']} modes, batch {m['batch']:,}, "
                     f"{m['threads']} threads",
                     _rate(m["jax_pl_per_s"], "PL/s"), *ref, *host(m)))
    for key, what in (("mhss_add_v42", "the same, `fault_modes=\"add-v4.2\"` (the default)"),
                      ("mhss_blanch_2012", "MHSS, pairs of satellites, `blanch-2012`")):
        if key not in bench_json:
            continue
        m = bench_json[key]
        ref = (_rate(m["reference_pl_per_s"], "PL/s"), f"{m['speedup']:,.0f}x") \
            if "speedup" in m else ("-", "-")
        case = ("9 GPS + 4 SOPs, Table I" if m["case"].startswith("table-i") else
                "5 GPS + 5 Galileo, Blanch 2012 App. J inputs")
        rows.append((what, f"{case}, {m['n_modes']} modes, order {m['order']}, batch "
                     f"{m['batch']:,}, {m['threads']} threads",
                     _rate(m["jax_pl_per_s"], "PL/s"), *ref, *host(m)))
    if "mhss_gradient" in bench_json:
        gr = bench_json["mhss_gradient"]
        rows.append(("value and gradient of HPL per second (`jax.value_and_grad` through "
                     "`araim.protection_levels_kernel`, implicit-function PL derivative)",
                     f"9 GPS + 4 SOPs, Table I, `grouped`, batch {gr['batch']:,}, 1 thread, "
                     "w.r.t. rows, variances, b_nom, P_s, P_const",
                     f"{_rate(gr['value_and_grad_hpl_per_s'], 'HPL/s')} (value alone "
                     f"{_rate(gr['value_hpl_per_s'], 'HPL/s')}: {gr['ratio']:.1f}x its cost)",
                     "-", "-", *host(gr)))
    if "fig3" in bench_json:
        f = bench_json["fig3"]
        rows.append(("`seed001-fig3-elevation` study", f"{f['realizations']:,} realizations",
                     f"{f['wall_s']:.1f} s wall, compile included", "-", "-", *host(f)))
    if "sky" in bench_json:
        k = bench_json["sky"]
        rows.append(("`geometry.sky`, nominal GPS + Galileo", "1 receiver x 2,880 epochs",
                     f"{k['one_receiver_2880_epochs_nominal_s']:.3f} s", "-", "-", *host(k)))
        rows.append(("`geometry.sky`, nominal GPS + Galileo", "1,000 receivers x 288 epochs",
                     f"{k['receivers_1000_x_288_epochs_nominal_s']:.3f} s", "-", "-",
                     *host(k)))
    for key, mod, fn in (("leo_mhss", "bench_leo", "leo_rows"),
                         ("filter_bank", "bench_ekf", "filter_bank_rows")):
        if key in bench_json:  # rows of parts whose timing code lives beside the bench
            rows += getattr(__import__(f"oaraim.{mod}", fromlist=[fn]), fn)(bench_json[key], host)
    if "ekf_drive" in bench_json:
        e = bench_json["ekf_drive"]
        fallback = next((b.get("host") for b in bench_json.values()
                         if isinstance(b, dict) and b.get("host")), {})
        rows.append(("EKF-RAIM Monte Carlo (seed 000 drive), without and with exclusion",
                     f"{e['runs']:,} runs x {e['epochs_per_run']:,} epochs",
                     f"{e['wall_s']:.1f} s wall ({e['runs_per_s']:,.1f} runs/s)", "-", "-",
                     *host({"host": e.get("host", fallback)})))
    for key in ("availability_map", "availability_map_world", "availability_map_dask"):
        if key in bench_json:
            a = bench_json[key]
            how = (f"Dask, {a['workers']} worker processes" if a.get("workers")
                   else f"one process, {a.get('threads', 2)} threads")
            # runs before the fault-mode conventions existed used the grouping
            rows.append((f"`availability-map` study ({a['service_level']}), compile included",
                         f"{a['lat_step_deg']:g} x {a['lon_step_deg']:g} deg, {a['users']:,} "
                         f"users x {a['epochs']} epochs, {how}, "
                         f"`{a.get('fault_modes', 'grouped')}`",
                         f"{a['wall_s']:.1f} s wall ({_rate(a['pl_per_s'], 'PL/s')})", "-",
                         "-", *host(a)))
    if "fig4" in bench_json:
        f = bench_json["fig4"]
        rows.append(("`seed004-fig4-hpl-maps` study, full size, compile included",
                     f"{f['cells']:,} cells x {f['realizations']:,} realizations, "
                     f"{f['threads']} threads",
                     f"{f['wall_s']:.1f} s wall ({_rate(f['draws_per_s'], 'draws/s')})", "-",
                     "-", *host(f)))
    if "integrity_risk" in bench_json:
        r = bench_json["integrity_risk"]
        rows.append(("MHSS detection + exclusion per residual sample, `araim.integrity_risk."
                     "evaluate` (linear maps)", f"9 GPS + 4 SOPs, Table I, {r['samples']:,} "
                     "samples, one geometry", _rate(r["samples_per_s"], "samples/s"),
                     _rate(r["reference_samples_per_s"], "samples/s"), f"{r['speedup']:,.0f}x",
                     *host(r)))
        rows.append(("`araim.integrity_risk.risk_table`, one geometry",
                     f"{r['scenario_slots']} scenarios x 2 x {r['x_grid']} magnitudes x 2 "
                     "directions, 4,000 samples each", f"{r['risk_table_s']:.1f} s", "-", "-",
                     *host(r)))
        rows.append(("importance sampling vs crude Monte Carlo, equal relative error",
                     f"fault-free vertical P(HMI) = {r['ff_vertical_p']:.1e}, relative error "
                     f"{r['ff_vertical_rel_error']:.0%}", f"{r['is_s']:.2f} s",
                     f"crude Monte Carlo: {r['crude_s_equal_rel_error']:.1e} s",
                     f"{r['is_speedup_equal_rel_error']:.1e}x", *host(r)))
    head = ("| kernel | workload | throughput | NumPy reference | ratio | machine | date |\n"
            "|---|---|---|---|---|---|---|")
    return "\n".join([head] + ["| " + " | ".join(r) + " |" for r in rows])


def combined_table(bench_jsons) -> str:
    """One table of several ``oaraim bench --json`` records (e.g. the CPU run and a GPU run):
    the rows of each ``markdown_table`` in the given order under one header."""
    tables = [markdown_table(j) for j in bench_jsons]
    return "\n".join([tables[0]] + [row for t in tables[1:] for row in t.split("\n")[2:]])


#: the generated table sits between these two lines in README.md and docs/benchmarks.md
TABLE_BEGIN = "<!-- bench-table: generated by python -m oaraim.bench -->"
TABLE_END = "<!-- /bench-table -->"


def replace_table(text: str, table: str) -> str:
    """``text`` with the block between ``TABLE_BEGIN`` and ``TABLE_END`` replaced by ``table``."""
    try:
        head, rest = text.split(TABLE_BEGIN, 1)
        _, tail = rest.split(TABLE_END, 1)
    except ValueError:
        raise ValueError(f"no {TABLE_BEGIN!r} ... {TABLE_END!r} block") from None
    return f"{head}{TABLE_BEGIN}\n{table}\n{TABLE_END}{tail}"


if __name__ == "__main__":
    import argparse
    import json
    from pathlib import Path

    parser = argparse.ArgumentParser(
        prog="python -m oaraim.bench",
        description="Print the Markdown benchmark table of an `oaraim bench --json` file.")
    parser.add_argument("--table", metavar="JSON", required=True, nargs="+",
                        help="files written by `oaraim bench --json` (e.g. a CPU and a GPU "
                        "run): their rows in this order")
    parser.add_argument("--update", metavar="MD", nargs="*", default=[],
                        help="also rewrite the table block of these Markdown files")
    args = parser.parse_args()
    records = []
    for name in args.table:
        with open(name) as fh:
            records.append(json.load(fh))
    table = combined_table(records)
    for md in map(Path, args.update):
        md.write_text(replace_table(md.read_text(), table))
    print(table)
