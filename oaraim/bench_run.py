"""The parts of ``oaraim bench``: each one runs a measurement of ``oaraim.bench`` and says it.

``run_bench`` runs the parts a user chose (``--only``, ``--fig4``, ``--world-map``,
``--dask-map``) and returns the dictionary ``oaraim bench --json`` writes; ``python -m
oaraim.bench --table`` turns it into the README's table. On an accelerator (JAX's default
backend is not the CPU) every record's ``host`` names the device, so its rows are told apart.
"""

from collections.abc import Callable

#: the parts of ``oaraim bench`` that ``--only`` chooses from (all run by default)
BENCH_PARTS = ("startup", "latency", "slope", "mhss", "fig3", "sky", "ekf", "filterbank", "map",
               "risk", "leo")
#: the 1 x 1 deg world grid of the ``world-map`` and ``dask-map`` parts
WORLD_1DEG = {"lat_deg": "-90:90:1", "lon_deg": "-180:179:1"}


def run_bench(parts, quick: bool = False, mhss_batch: int | None = None,
              say: Callable[[str], None] = print) -> dict:
    """Run the chosen ``parts`` (names of ``BENCH_PARTS``, and the long parts "world-map",
    "dask-map" and "fig4" that only their own flags choose) in that order, print one line per
    result through ``say``, and return the records by key (``startup``, ``latency``,
    ``slope_hpl``, ``mhss``, ..., ``fig4``, ``availability_map_world``,
    ``availability_map_dask``). ``mhss_batch`` is the batch of the MHSS throughput rows
    (default 65,536, 16,384 when ``quick``)."""
    from oaraim import bench as b

    batch = mhss_batch or (16_384 if quick else 65_536)
    hi = b.host_info()
    if hi.get("backend", "cpu") != "cpu":
        say(f"JAX backend: {hi['backend']} ({hi.get('device', '?')})")
    res = {}
    if "startup" in parts:
        res["startup"] = st = b.bench_startup()
        say(f"start-up: import oaraim {st['import_oaraim_s']:.2f} s, from oaraim import "
            f"araim, geometry {st['import_araim_geometry_s']:.2f} s, oaraim --help "
            f"{st['cli_help_s']:.2f} s; first protection_levels call (64 geometries) in a new "
            f"process {st['first_call_cold_s']:.1f} s compiling, "
            f"{st['first_call_cached_s']:.1f} s from the compilation cache")
    if "latency" in parts:
        res["latency"] = lat = b.bench_latency(calls=100 if quick else 300)
        say("protection_levels latency (warm, " + lat["fault_modes"] + "): " + ", ".join(
            f"batch {n}: median {lat[f'batch_{n}']['median_ms']:.2f} ms, p99 "
            f"{lat[f'batch_{n}']['p99_ms']:.2f} ms" for n in b.LATENCY_BATCHES))
    if "slope" in parts:
        res["slope_hpl"] = s = b.bench_slope_hpl(batch=65_536 if quick else 262_144,
                                                  ref_geometries=500 if quick else 2_000)
        say(f"slope HPL (M + N = 9): {s['jax_hpl_per_s']:,.0f} HPL/s "
            f"(batch {s['batch']:,}, best of 5)")
        say(f"  NumPy reference: {s['reference_hpl_per_s']:,.0f} HPL/s -> "
            f"{s['speedup']:,.0f}x; max relative difference {s['max_rel_diff']:.1e}")
    if "mhss" in parts:
        res.update(_mhss(b, quick, batch, say))
    if "fig3" in parts:
        n3 = 100_000 if quick else 1_000_000
        res["fig3"] = f = b.bench_fig3(n3)
        say(f"seed001-fig3-elevation at {n3:,} realizations: {f['wall_s']:.1f} s wall "
            "(compile included)")
    if "sky" in parts:
        res["sky"] = _sky(b, say)
    if "ekf" in parts:
        from oaraim.bench_ekf import bench_ekf_drive

        runs = 100 if quick else 1000
        res["ekf_drive"] = e = bench_ekf_drive(runs)
        e.setdefault("host", hi)  # its date and machine (the table fell back on another row's)
        say(f"EKF-RAIM Monte Carlo, seed 000 drive (1.35 km, 100 Hz IMU), {runs:,} runs, "
            f"without and with exclusion: {e['wall_s']:.1f} s wall, {e['cpu_s']:.1f} s CPU "
            f"(first call with compilation {e['first_call_wall_s']:.1f} s; target 1000 runs "
            "<= 60 s)")
    if "filterbank" in parts:
        from oaraim.bench_ekf import bench_filter_bank

        runs = 100 if quick else 1000
        res["filter_bank"] = fb = bench_filter_bank(runs)
        fb.setdefault("host", hi)
        say(f"solution-separation filter bank, seed 000 drive, {runs:,} runs x "
            f"{fb['epochs_per_run']:,} epochs ({fb['bank_filters']} EKFs + the Xi-slope EKF + "
            f"the snapshot MHSS per epoch): {fb['filter_bank_wall_s']:.1f} s wall; plain "
            f"EKF-RAIM (2 EKFs) on the same runs {fb['ekf_raim_wall_s']:.1f} s: cost ratio "
            f"{fb['cost_ratio_wall']:.1f} (target <= 5 min for 1,000 runs)")
    if "map" in parts:
        res["availability_map"] = a = b.bench_availability_map(
            {"lat_deg": "30:50:10", "lon_deg": "0:20:10"} if quick else None)
        say(f"availability-map ({a['service_level']}), {a['users']:,} users x {a['epochs']} "
            f"epochs: {a['wall_s']:.1f} s wall, compile included ({a['pl_per_s']:,.0f} PL/s; "
            "target < 60 s for the world map)")
    if "risk" in parts:
        res["integrity_risk"] = r = b.bench_integrity_risk(
            samples=50_000 if quick else 200_000, ref_samples=50 if quick else 200)
        say(f"integrity risk, MHSS decisions from the linear maps: {r['samples_per_s']:,.0f} "
            f"samples/s; NumPy reference {r['reference_samples_per_s']:,.1f} samples/s -> "
            f"{r['speedup']:,.0f}x (detections agree on {r['detection_agreement']:.0%}); one "
            f"geometry's risk table {r['risk_table_s']:.1f} s; IS vs crude at equal relative "
            f"error (P = {r['ff_vertical_p']:.1e}): {r['is_speedup_equal_rel_error']:.1e}x")
    if "world-map" in parts:
        res["availability_map_world"] = a = b.bench_availability_map(WORLD_1DEG)
        say(f"availability-map 1 x 1 deg in this process ({a['threads']} threads), "
            f"{a['users']:,} users x {a['epochs']} epochs: {a['wall_s']:.1f} s wall "
            f"({a['pl_per_s']:,.0f} PL/s)")
    if "dask-map" in parts:
        res["availability_map_dask"] = a = b.bench_availability_map(WORLD_1DEG, workers=2)
        say(f"availability-map 1 x 1 deg on Dask (2 workers), {a['users']:,} users x "
            f"{a['epochs']} epochs: {a['wall_s']:.1f} s wall ({a['pl_per_s']:,.0f} PL/s)")
    if "leo" in parts:
        from oaraim.bench_leo import bench_leo

        res["leo_mhss"] = recs = bench_leo(b.host_info, batch=1_024 if quick else 4_096)
        for m in recs:
            say(f"MHSS with LEO, L = {m['L']} ({m['fault_modes']}, order {m['order']}, "
                f"{m['n_modes']} modes): {m['jax_pl_per_s']:,.0f} PL/s; NumPy reference "
                f"{m['reference_pl_per_s']:,.1f} PL/s; max |VPL difference| "
                f"{m['max_abs_diff_vpl_m']:.1e} m")
    if "fig4" in parts:
        res["fig4"] = f = b.bench_fig4()
        say(f"seed004-fig4-hpl-maps full size ({f['cells']:,} cells x "
            f"{f['realizations']:,}): {f['wall_s']:.1f} s wall, compile included "
            f"({f['draws_per_s']:,.0f} draws/s)")
    return res


def _mhss(b, quick, batch, say):
    m = b.bench_mhss(batch=batch, ref_geometries=50 if quick else 200)
    res = {"mhss": m}
    say(f"MHSS PLs (9 GPS + 4 SOPs, Table I, {m['n_modes']} modes): "
        f"{m['jax_pl_per_s']:,.0f} PL/s (batch {m['batch']:,}, best of 5, "
        f"{m['threads']} host threads; one thread {m['one_thread_pl_per_s']:,.0f} PL/s)")
    if "speedup" in m:
        say(f"  NumPy reference: {m['reference_pl_per_s']:,.1f} PL/s -> "
            f"{m['speedup']:,.0f}x; max |difference| {m['max_abs_diff_m']:.1e} m")
    for key, case in (("mhss_add_v42", "table-i-add-v4.2"),
                      ("mhss_blanch_2012", "blanch-2012-57-modes")):
        res[key] = m = b.bench_mhss(batch=batch, ref_geometries=20 if quick else 50, case=case)
        say(f"  {case} ({m['fault_modes']}, order {m['order']}, {m['n_modes']} modes): "
            f"{m['jax_pl_per_s']:,.0f} PL/s; NumPy reference "
            f"{m['reference_pl_per_s']:,.1f} PL/s -> {m['speedup']:,.0f}x; max "
            f"|difference| {m['max_abs_diff_m']:.1e} m")
    res["mhss_profile"] = p = b.profile_mhss(batch=batch)
    say(f"  profile ({p['cpu_us_per_pl']:.1f} CPU-us per PL): fault modes "
        f"{p['fault_modes_s'] / p['total_s']:.0%}, projectors (eqs. 9-12) "
        f"{p['projectors_s'] / p['total_s']:.0%}, PL root finding "
        f"{p['pl_root_finding_s'] / p['total_s']:.0%}")
    from oaraim.bench_grad import bench_gradient

    res["mhss_gradient"] = gr = bench_gradient(batch=4_096 if quick else 16_384)
    say(f"  value and gradient of HPL (all {len(gr['inputs'])} real inputs, one thread, batch "
        f"{gr['batch']:,}): {gr['value_and_grad_hpl_per_s']:,.0f} HPL/s against "
        f"{gr['value_hpl_per_s']:,.0f} HPL/s for the value alone: {gr['ratio']:.1f}x its "
        "cost (goal <= 3x)")
    return res


def _sky(b, say):
    sk = b.bench_sky()
    say(f"sky, 1 receiver x 2,880 epochs (24 h at 30 s), nominal GPS + Galileo: "
        f"{sk['one_receiver_2880_epochs_nominal_s']:.3f} s (target < 1 s)")
    if "one_receiver_2880_epochs_broadcast_s" in sk:
        say(f"  same from the Villafranca broadcast file ({sk['broadcast_satellites']} "
            f"satellites): {sk['one_receiver_2880_epochs_broadcast_s']:.3f} s "
            f"(parse {sk['vill_parse_s']:.2f} s, cached per process)")
    say(f"sky, 1,000 receivers x 288 epochs, nominal GPS + Galileo: "
        f"{sk['receivers_1000_x_288_epochs_nominal_s']:.3f} s (target < 10 s)")
    return sk
