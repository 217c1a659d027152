"""Benchmark: Monte Carlo runs of the seed 000 drive (1.35 km, 5 LTE towers, 100 Hz IMU, 10 Hz
pseudoranges, fault on tower 1 from t = 25 s), EKF without and with exclusion, vmapped over runs.

Target: >= 1000 runs in <= 60 s on 2 cores. Wall time and process CPU time are both
reported (CPU time is steadier on a shared machine); compilation is timed separately. The
run is single-stream: XLA's CPU backend executes this program on about one core (process CPU
time ~ wall time), so the load average at the measurement is recorded too.
"""

import os
import time

import jax
import numpy as np

from oaraim import araim, errors, sim


def bench_ekf_drive(runs: int = 1000, seed: int = 0, repeats: int = 1) -> dict:
    """Time ``runs`` Monte Carlo runs of the whole seed 000 drive; returns a JSON-able dict."""
    scenario = sim.drive_seed000()
    setup = sim.drive_setup(scenario)
    keys = jax.random.split(jax.random.key(seed), runs)
    # the default (realistic) error world with the scenario's fault (docs/error-world.md)
    err = errors.ErrorModel(fault_tower=scenario.fault_tower, fault_onset_s=scenario.fault_onset_s,
                         fault_bias_m=scenario.fault_bias_m)
    fn = jax.jit(lambda k: sim.monte_carlo_drive(k, setup, err=err))
    t0, c0 = time.perf_counter(), time.process_time()
    out = jax.block_until_ready(fn(keys))
    compile_wall = time.perf_counter() - t0
    best_wall, best_cpu = np.inf, np.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = jax.block_until_ready(fn(keys))
        best_wall = min(best_wall, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    load = os.getloadavg()
    mean = {k: np.asarray(v, float).mean(0).tolist() for k, v in out._asdict().items()}
    return {
        "runs": runs,
        "epochs_per_run": int(setup.t_s.shape[0]),
        "imu_samples_per_run": int(setup.gyro.shape[0] * setup.gyro.shape[1]),
        "first_call_wall_s": compile_wall,
        "compile_s_est": compile_wall - best_wall,   # first call = compilation + one run
        "load_avg_1_5_15": list(load),                # other processes share the 2 cores
        "wall_s": best_wall,
        "cpu_s": best_cpu,
        "runs_per_s": runs / best_wall,
        "summary_means_[no_excl,excl]": mean,
    }


def bench_filter_bank(runs: int = 1000, seed: int = 0, batch: int = 100) -> dict:
    """Time ``runs`` Monte Carlo runs of the whole seed 000 drive through the solution-separation
    filter bank (``sim.simulate_filter_drive``: 7 EKFs, the main one and one per order-1 mode of
    add-v4.2 with 5 towers and one operator, plus seed 000's Xi-slope EKF and the snapshot MHSS
    of every epoch) beside the plain EKF-RAIM (``sim.monte_carlo_drive``: 2 EKFs, without and
    with exclusion) on the same keys in the same process, both in vmapped batches of ``batch``
    runs; returns a JSON-able dict with the cost ratio."""
    scenario = sim.drive_seed000()
    setup = sim.drive_setup(scenario)
    err = errors.ErrorModel(fault_tower=scenario.fault_tower, fault_onset_s=scenario.fault_onset_s,
                         fault_bias_m=scenario.fault_bias_m)
    keys = jax.random.split(jax.random.key(seed), runs)
    bank = jax.jit(jax.vmap(lambda k: sim.simulate_filter_drive(k, setup, err, sim.no_fault())))
    plain = jax.jit(lambda k: sim.monte_carlo_drive(k, setup, err=err))
    out = {"runs": runs, "batch": batch, "epochs_per_run": int(setup.t_s.shape[0]),
           "bank_filters": int(araim.filter_monitor.n_bank_filters(
               int(setup.towers.shape[0]), 1, 1, "add-v4.2"))}
    for name, fn in (("filter_bank", bank), ("ekf_raim", plain)):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(keys[:batch]))
        out[f"{name}_first_call_s"] = time.perf_counter() - t0
        t0, c0 = time.perf_counter(), time.process_time()
        for start in range(0, runs, batch):
            jax.block_until_ready(fn(keys[start:start + batch]))
        out[f"{name}_wall_s"] = time.perf_counter() - t0
        out[f"{name}_cpu_s"] = time.process_time() - c0
    out["cost_ratio_wall"] = out["filter_bank_wall_s"] / out["ekf_raim_wall_s"]
    out["load_avg_1_5_15"] = list(os.getloadavg())
    return out


def filter_bank_rows(fb, host):
    """The benchmark-table row of a ``bench_filter_bank`` result (``host`` formats its
    machine and date columns)."""
    return [("Solution-separation filter bank (seed 000 drive, `sim.simulate_filter_drive`: "
             f"{fb['bank_filters']} EKFs + the Xi-slope EKF + the snapshot MHSS per epoch)",
             f"{fb['runs']:,} runs x {fb['epochs_per_run']:,} epochs, batches of {fb['batch']}",
             f"{fb['filter_bank_wall_s']:.1f} s wall", "-", "-", *host(fb)),
            ("the plain EKF-RAIM on the same runs (2 EKFs)", f"{fb['runs']:,} runs",
             f"{fb['ekf_raim_wall_s']:.1f} s wall (the bank costs "
             f"{fb['cost_ratio_wall']:.1f}x)", "-", "-", *host(fb))]


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(bench_ekf_drive(int(sys.argv[1]) if len(sys.argv) > 1 else 1000),
                     indent=1))
