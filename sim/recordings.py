"""Synthesized recordings: a simulated run written in the recorded-data format
(``geometry.recording``), so synthetic drives go through exactly the loader and the replay a
user's real drive goes through.

``synthesize_recording`` writes one run of a drive scenario with the draws of
``sim.simulate_drive`` for the same key (``sim.measurement.drive_epoch``: the one measurement
model); ``example_recording`` is a tiny noise-free drive for the documentation and the tests.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from oaraim.araim.ekf_raim import InitialUncertainty
from oaraim.constants import C_M_S
from oaraim.errors import ErrorModel, imu
from oaraim.geometry import frames
from oaraim.readers import recording
from oaraim.sim.drive import DriveSetup, drive_setup, filter_sigma, initial_draw
from oaraim.sim.measurement import EpochTowers, EpochTruth, drive_epoch
from oaraim.sim.trajectory import Scenario


@jax.jit
def _synth(key, setup: DriveSetup, err: ErrorModel, filter_sigma_pr_m=0.0):
    """The draws of ``simulate_drive`` for ``key`` (``initial_draw``, then ``drive_epoch`` on
    ``fold_in(epoch key, e)``): IMU samples, receiver clock, pseudoranges and their bias per
    epoch, the initial estimate, the initial receiver clock and the filter's sigma."""
    d = initial_draw(key, setup, err)

    def body(world, inp):
        e, g_true, a_true, t_e, pos_e, tclk = inp
        world, m = drive_epoch(jax.random.fold_in(d.epoch_key, e), world,
                               EpochTruth(g_true, a_true, t_e, pos_e),
                               EpochTowers(setup.towers, tclk, setup.operator), err,
                               setup.sensors(), unrolled_imu=True)
        return world, (m.gyro_rad_s, m.accel_m_s2, m.pseudorange_m, world.rx_clock_m, m.bias_m)

    n_ep = setup.t_s.shape[0]
    xs = (jnp.arange(n_ep), setup.gyro, setup.accel, setup.t_s, setup.pos[1:], setup.tower_clk_m)
    _, (gm, am, z, clk, bias) = jax.lax.scan(body, d.world, xs)
    return (gm, am, z, clk, bias, (d.quat_est, d.pos_est_m, d.vel_est_m_s), d.world.rx_clock_m,
            filter_sigma(d, err, filter_sigma_pr_m))


def synthesize_recording(scenario: Scenario, key, *, err: ErrorModel | None = None,
                         filter_sigma_pr_m: float = 0.0, spec: imu.ImuSpec | None = None,
                         init_uncertainty: InitialUncertainty | None = None,
                         duration_s: float | None = None) -> recording.Recording:
    """One run of ``scenario`` in the error world ``err`` as a validated ``Recording``. ``err``
    None: the realistic ``ErrorModel()`` with the scenario's fault; another world (a thermal
    noise, multipath or fault of its own) is an ``ErrorModel`` with those fields replaced
    (``sim.ErrorModel(fault_tower=scenario.fault_tower, ...)._replace(sigma_pr_m=2.0)``). The
    draws are those of ``sim.simulate_drive(key, setup, err, filter_sigma_pr_m)``: the same IMU
    samples, clock, SOP errors, pseudoranges and initial estimate error, and the pseudoranges'
    ``sigma_m`` is the filter's sigma of that run (``sim.drive.filter_sigma``: the empirical
    one unless ``filter_sigma_pr_m`` > 0), so replaying the recording reproduces that run (up
    to the ENU -> ECEF -> ENU round trip, ~1e-9 m).

    Tables: imu (100 Hz, stamps at the end of each interval-mean sample), transmitters (ECEF,
    clock polynomials c dt = bias + drift t), pseudoranges (10 Hz, ``sigma_m``), truth at t = 0
    and every epoch (ECEF position and velocity, JPL quaternion, receiver clock). meta.json
    carries ``initial_state`` (truth at t = 0 minus the drawn initial error: what the GNSS
    period leaves), ``imu_spec`` and every scenario and draw parameter under ``source``."""
    sc = scenario
    spec = imu.vn100() if spec is None else spec
    if err is None:
        err = ErrorModel(fault_tower=sc.fault_tower, fault_onset_s=sc.fault_onset_s,
                         fault_bias_m=sc.fault_bias_m)
    kw = {k: (int(v) if k == "fault_tower" else float(v)) for k, v in err._asdict().items()}
    setup = drive_setup(sc, spec, init_uncertainty, duration_s=duration_s)
    gm, am, z, clk, bias, est, clk0, sig_f = jax.device_get(
        _synth(key, setup, ErrorModel(**kw), float(filter_sigma_pr_m)))
    e, n = gm.shape[:2]
    dt = float(setup.params.dt_s)
    lat, lon, h = sc.origin_lat_deg, sc.origin_lon_deg, sc.origin_h_m
    origin = np.asarray(frames.geodetic_to_ecef(np.deg2rad(lat), np.deg2rad(lon), h))
    rot = np.asarray(frames.enu_rotation(np.deg2rad(lat), np.deg2rad(lon)))  # ECEF -> ENU rows

    def ecef(p_enu):
        return origin + np.asarray(p_enu) @ rot

    # stamps: multiples of dt via integer counts (bit-identical epoch / IMU stamps)
    t_imu = np.arange(1, e * n + 1) * dt
    t_ep = np.asarray(setup.t_s)
    ids = [f"T{i + 1}" for i in range(sc.towers_enu_m.shape[0])]
    l = len(ids)
    tw = ecef(np.asarray(sc.towers_enu_m))
    c = C_M_S
    transmitters = pd.DataFrame({
        "tx_id": ids, "kind": "lte", "group": "carrier_a",
        "x_m": tw[:, 0], "y_m": tw[:, 1], "z_m": tw[:, 2],
        "clock_bias_m": c * np.asarray(sc.tower_clk_bias0_s),
        "clock_drift_mps": c * np.asarray(sc.tower_clk_drift), "clock_t0_s": 0.0})
    pseudoranges = pd.DataFrame({
        "t_s": np.repeat(t_imu[n - 1::n], l), "tx_id": np.tile(ids, e),
        "pseudorange_m": np.asarray(z).reshape(-1), "sigma_m": float(sig_f),
        "injected_bias_m": np.asarray(bias).reshape(-1)})
    g, a = np.asarray(gm).reshape(-1, 3), np.asarray(am).reshape(-1, 3)
    imu_df = pd.DataFrame({"t_s": t_imu, "gyro_x_radps": g[:, 0], "gyro_y_radps": g[:, 1],
                           "gyro_z_radps": g[:, 2], "accel_x_mps2": a[:, 0],
                           "accel_y_mps2": a[:, 1], "accel_z_mps2": a[:, 2]})
    pos = ecef(np.asarray(setup.pos))
    vel = np.asarray(setup.vel) @ rot
    q = np.asarray(setup.quat)
    clk_all = np.concatenate([np.asarray(clk0)[None], np.asarray(clk)])
    truth = pd.DataFrame({
        "t_s": np.concatenate([[0.0], t_imu[n - 1::n]]), "x_m": pos[:, 0], "y_m": pos[:, 1],
        "z_m": pos[:, 2], "vx_mps": vel[:, 0], "vy_mps": vel[:, 1], "vz_mps": vel[:, 2],
        "qx": q[:, 0], "qy": q[:, 1], "qz": q[:, 2], "qw": q[:, 3],
        "rx_clock_m": clk_all[:, 0], "rx_clock_drift_mps": clk_all[:, 1]})
    q0, r0, v0 = (np.asarray(x, float) for x in est)
    meta = {
        "format": recording.FORMAT_NAME, "format_version": recording.FORMAT_VERSION,
        "name": sc.name, "description": f"synthesized run of {sc.name} (sim.recordings)",
        "origin": {"lat_deg": lat, "lon_deg": lon, "h_m": h},
        "imu_rate_hz": 1.0 / dt, "body_frame": "FLU", "quaternion": "JPL",
        "initial_state": {"t_s": 0.0, "position_enu_m": r0.tolist(),
                          "velocity_enu_mps": v0.tolist(), "quaternion_jpl": q0.tolist(),
                          "gyro_bias_radps": [0.0] * 3, "accel_bias_mps2": [0.0] * 3,
                          "rx_clock_m": 0.0, "rx_clock_drift_mps": 0.0},
        "imu_spec": {k: float(v) for k, v in spec._asdict().items()},
        "source": {"kind": "synthesized", "generator": "sim.recordings.synthesize_recording",
                   "scenario": sc.name, "key_data": np.asarray(
                       jax.random.key_data(key)).astype(int).tolist(),
                   "parameters": {**kw, "fault_tower_id": ids[kw["fault_tower"]],
                                  "filter_sigma_pr_m": float(sig_f),
                                  "duration_s": float(t_ep[-1]),
                                  "meas_rate_hz": float(sc.meas_rate_hz)},
                   "notes": {k: str(v) for k, v in sc.notes.items()}},
    }
    return recording.validate_recording(recording.Recording(
        meta=meta, transmitters=transmitters, pseudoranges=pseudoranges, imu=imu_df,
        truth=truth))


def example_recording(duration_s: float = 5.0, imu_rate_hz: float = 100.0,
                      pr_rate_hz: float = 10.0, with_gnss: bool = False) -> recording.Recording:
    """A tiny synthesized drive: a car at 10 m/s on a straight road heading 30 deg north of
    east past 3 LTE towers (two carriers), exact pseudoranges (no noise:
    |r - r_tx| + c dt_rx - c dt_tx), an ideal IMU and full truth (position, velocity, JPL
    attitude, receiver clock); with ``with_gnss`` also 5 GNSS satellites at 1 Hz (fixed
    positions, an illustration only). Values are illustrative, not from a paper: origin in
    downtown Riverside, CA (the area of seed 000's drive); tower clock biases of a few hundred
    metres, well inside LTE's 3 us (900 m) synchronization requirement quoted in seed 004 sec. I.

    The IMU is ideal in a flat, non-rotating ENU frame: zero angular rate (Earth rotation,
    7.3e-5 rad/s, is left out) and specific force (0, 0, g) with WGS-84 normal gravity.
    """
    lat, lon, h = 33.9806, -117.3755, 250.0
    psi = np.deg2rad(30.0)
    speed = 10.0
    n_imu = int(round(duration_s * imu_rate_hz)) + 1
    n_pr = int(round(duration_s * pr_rate_hz)) + 1
    t_imu = np.arange(n_imu) / imu_rate_hz
    t_pr = np.arange(n_pr) / pr_rate_hz
    origin = np.asarray(frames.geodetic_to_ecef(np.deg2rad(lat), np.deg2rad(lon), h))
    r_enu = np.asarray(frames.enu_rotation(np.deg2rad(lat), np.deg2rad(lon)))
    heading = np.array([np.cos(psi), np.sin(psi), 0.0])

    def pos_ecef(t):
        return origin + (speed * t[:, None] * heading) @ r_enu

    def rx_clock(t):  # c dt_rx: 1 km offset, 0.3 m/s drift (a free-running TCXO-like rate)
        return 1000.0 + 0.3 * t

    tx_enu = np.array([[200.0, 150.0, 30.0], [-150.0, 300.0, 25.0], [100.0, -250.0, 35.0]])
    tx_ecef = origin + tx_enu @ r_enu
    transmitters = pd.DataFrame({
        "tx_id": ["T1", "T2", "T3"], "kind": ["lte"] * 3,
        "group": ["carrier_a", "carrier_a", "carrier_b"],
        "x_m": tx_ecef[:, 0], "y_m": tx_ecef[:, 1], "z_m": tx_ecef[:, 2],
        "clock_bias_m": [150.0, -320.5, 75.25], "clock_drift_mps": [0.02, -0.015, 0.01],
        "clock_t0_s": [0.0, 0.0, 0.0]})
    p = pos_ecef(t_pr)
    rng = np.linalg.norm(p[:, None, :] - tx_ecef[None], axis=-1)
    clk = (transmitters["clock_bias_m"].to_numpy()
           + transmitters["clock_drift_mps"].to_numpy() * t_pr[:, None])
    rho = rng + rx_clock(t_pr)[:, None] - clk
    pseudoranges = pd.DataFrame({
        "t_s": np.repeat(t_pr, 3), "tx_id": np.tile(["T1", "T2", "T3"], n_pr),
        "pseudorange_m": rho.reshape(-1), "sigma_m": np.full(3 * n_pr, 2.0),
        "cn0_dbhz": np.tile([55.0, 48.0, 51.0], n_pr)})
    g = frames.normal_gravity_mps2(np.deg2rad(lat), h)
    zeros = np.zeros(n_imu)
    imu_df = pd.DataFrame({"t_s": t_imu, "gyro_x_radps": zeros, "gyro_y_radps": zeros,
                        "gyro_z_radps": zeros, "accel_x_mps2": zeros, "accel_y_mps2": zeros,
                        "accel_z_mps2": np.full(n_imu, g)})
    pt = pos_ecef(t_imu)
    v = np.broadcast_to(speed * heading @ r_enu, (n_imu, 3))
    truth = pd.DataFrame({
        "t_s": t_imu, "x_m": pt[:, 0], "y_m": pt[:, 1], "z_m": pt[:, 2],
        "vx_mps": v[:, 0], "vy_mps": v[:, 1], "vz_mps": v[:, 2],
        "qx": zeros, "qy": zeros, "qz": np.full(n_imu, np.sin(psi / 2)),
        "qw": np.full(n_imu, np.cos(psi / 2)),
        "rx_clock_m": rx_clock(t_imu), "rx_clock_drift_mps": np.full(n_imu, 0.3)})
    gnss = None
    if with_gnss:
        sv = ["E11", "G02", "G05", "G12", "G25"]
        az = np.deg2rad([40.0, 100.0, 200.0, 290.0, 0.0])
        el = np.deg2rad([35.0, 60.0, 25.0, 45.0, 80.0])
        los = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)
        sat = origin + (21.0e6 * los) @ r_enu
        sat_clk = np.array([12.5, -30.25, 4.0, 101.0, -7.75])
        t_g = np.arange(int(math.floor(duration_s)) + 1, dtype=np.float64)
        pg = pos_ecef(t_g)
        rg = np.linalg.norm(pg[:, None, :] - sat[None], axis=-1)
        iono = np.broadcast_to(2.0 + 3.0 * (1 - np.sin(el)), rg.shape)
        tropo = np.broadcast_to(2.4 / np.sin(el), rg.shape)
        pr = rg + rx_clock(t_g)[:, None] - sat_clk + iono + tropo
        n = len(t_g)
        gnss = pd.DataFrame({
            "t_s": np.repeat(t_g, 5), "sv_id": np.tile(sv, n), "pseudorange_m": pr.reshape(-1),
            "sat_x_m": np.tile(sat[:, 0], n), "sat_y_m": np.tile(sat[:, 1], n),
            "sat_z_m": np.tile(sat[:, 2], n), "sat_clock_m": np.tile(sat_clk, n),
            "iono_m": iono.reshape(-1), "tropo_m": tropo.reshape(-1),
            "sigma_m": np.full(5 * n, 1.0), "el_deg": np.tile(np.rad2deg(el), n)})
    meta = {
        "format": recording.FORMAT_NAME, "format_version": recording.FORMAT_VERSION,
        "name": "example-straight-drive",
        "description": "Straight 10 m/s drive past 3 LTE towers, exact pseudoranges",
        "origin": {"lat_deg": lat, "lon_deg": lon, "h_m": h},
        "t0_gps_week": 2290, "t0_gps_tow_s": 345600.0, "imu_rate_hz": imu_rate_hz,
        "body_frame": "FLU", "quaternion": "JPL",
        "source": {"kind": "synthesized", "generator": "sim.recordings.example_recording",
                   "parameters": {"duration_s": duration_s, "imu_rate_hz": imu_rate_hz,
                                  "pr_rate_hz": pr_rate_hz, "with_gnss": with_gnss,
                                  "speed_mps": speed, "heading_deg_from_east": 30.0}},
    }
    return recording.validate_recording(recording.Recording(
        meta=meta, transmitters=transmitters, pseudoranges=pseudoranges, imu=imu_df, gnss=gnss,
        truth=truth))
