"""Per-epoch GNSS + SOP measurements along a scenario's trajectory (snapshot studies).

A drive or flight of ``sim.trajectory`` (receiver truth in a local ENU frame at the
scenario's origin, LTE towers with known clocks) is placed on the Earth at its origin and
combined with the GPS satellites of a sky source (a broadcast navigation file, or the nominal
constellation) at a stated GPS start time. The result is a set of arrays over epochs T and
sources L (GPS satellites that are ever in view above the mask, then the towers) in WGS-84 ECEF,
exactly what ``araim.snapshot.replay`` takes (``geometry.epoch_geometry.EpochGeometry``);
``to_recording`` / ``geometry.epoch_geometry.from_recording`` write and read the same content
in the recorded-data format (``geometry.recording``), so a real recorded drive or flight goes
through the same replay path as a synthesized one.

Measurement model (synthesized; stated choices; the pseudorange is
``sim.measurement.pseudorange_from_range``, the drives' model):
  * GPS: z = |r_rx - r_sat| + c dt_rx + eps, eps ~ N(0, sigma^2) with sigma(el) given by the
    caller (studies: the ADD accuracy model sqrt(C_acc)); satellite clocks, ionosphere and
    troposphere are taken as known and removed (the residual is what sigma models), so the
    synthesized satellite clock and model delays are 0; satellite positions are the broadcast
    positions at the epoch (the transit-time and Sagnac terms cancel in a self-consistent
    synthesis and are left out).
  * LTE tower n: z = |r_rx - r_n| + c dt_rx - c dt_n(t) + eps, c dt_n the scenario's known
    first-order polynomial (seed 000 eq. 3), eps ~ N(0, sigma_lte^2). ``correction_m`` adds
    c dt_n back.
  * Receiver clock c dt_rx = RX_CLOCK_BIAS_M + RX_CLOCK_DRIFT_MPS t (it is estimated per epoch;
    its value never changes a snapshot result).
  * Epochs t_k = k duration / n_epochs, k = 0..n_epochs - 1 (seed 004's UAV: 2880 epochs over
    the 220 s flight, 13.09 Hz); the truth is interpolated linearly from the trajectory's
    100 Hz samples (error < 1 mm at UAV/car accelerations).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from oaraim import errors
from oaraim.constants import C_M_S
from oaraim.errors import ErrorModel, GnssErrorModel
from oaraim.geometry import EpochGeometry, frames, look_angles, satellites
from oaraim.mc import stream
from oaraim.readers import FORMAT_NAME, FORMAT_VERSION, Recording, gpstime, validate_recording
from oaraim.sim.measurement import (
    gauss_markov_step,
    pseudorange_from_range,
    sop_errors,
)
from oaraim.sim.trajectory import Scenario

#: synthesized receiver clock (illustrative: a 1 km offset and a 0.3 m/s drift)
RX_CLOCK_BIAS_M, RX_CLOCK_DRIFT_MPS = 1000.0, 0.3


def gnss_errors(key, t_s, el_rad, sigma_ura_m, gm: GnssErrorModel):
    """GNSS pseudorange errors (T, L) of ``GnssErrorModel`` ``gm`` at the epochs ``t_s`` (T,)
    for sources at elevations ``el_rad`` (T, L) with ``sigma_ura_m`` (scalar or (L,)); draws
    from the named stream ``world_gnss`` of ``key`` (the snapshot draw's key), one ``fold_in``
    per epoch (index T: the initial state and the biases). jit-safe."""
    n_t, n_l = el_rad.shape
    k0 = stream(key, "world_gnss")
    w0 = jax.random.normal(jax.random.fold_in(k0, n_t), (4, n_l))
    b = gm.b_nom_m * (2.0 * jax.random.uniform(jax.random.fold_in(k0, n_t + 1), (n_l,)) - 1.0)
    iff = errors.iono_free_factor()
    s_ure = gm.ure_over_ura * sigma_ura_m * jnp.ones(n_l)
    x0 = jnp.stack([s_ure * w0[0], w0[1], gm.sigma_iono_m * w0[2], w0[3]])
    dts = jnp.diff(t_s, prepend=t_s[0])

    def body(x, inp):
        e, dt, el = inp
        w = jax.random.normal(jax.random.fold_in(k0, e), (5, n_l))
        # x[1] and x[3]: unit processes, scaled by their elevation-dependent sigma below
        x = jnp.stack([gauss_markov_step(x[0], w[0], s_ure, gm.ure_tau_s, dt),
                       gauss_markov_step(x[1], w[1], 1.0, gm.tropo_tau_s, dt),
                       gauss_markov_step(x[2], w[2], gm.sigma_iono_m, gm.ure_tau_s, dt),
                       gauss_markov_step(x[3], w[3], 1.0, gm.mp_tau_s, dt)])
        err = (b + x[0] + errors.sigma_tropo_m(el) * x[1] + x[2]
               + gm.mp_scale * iff * errors.sigma_multipath_m(el) * x[3]
               + iff * errors.sigma_noise_m(el) * w[4])
        return x, err

    _, y = jax.lax.scan(body, x0, (jnp.arange(n_t), dts, el_rad))
    return y


class SnapshotWorld(NamedTuple):
    """The error world of a GNSS + SOP snapshot scenario (``gnss_sop_errors``)."""

    sop: ErrorModel
    """The towers' world (``sim.sop_errors``)."""
    t_cal_s: jax.Array
    """(n_cal,) s: the GNSS period's epochs, before t = 0, in which the towers' clocks are
    fitted."""
    operator: jax.Array | None = None
    """(L_towers,) int: each tower's operator (its common clock term); None: all one."""
    gnss: GnssErrorModel | None = None
    """The satellites' world; None: ``GnssErrorModel()``."""


def gnss_sop_errors(key, t_s, el_rad, is_gps, sigma_ura_gps_m, world: SnapshotWorld):
    """Pseudorange errors (T, L) of a GNSS + SOP scenario in the realistic world, and the SOPs'
    empirical sigma of the GNSS period (m): ``gnss_errors`` (``world.gnss``,
    ``sigma_ura_gps_m``) on the GNSS columns (``is_gps``, a static (L,) bool), ``sop_errors``
    (``world.sop``, the GNSS period ``world.t_cal_s``, the towers' ``world.operator``) on the
    others in column order, both from ``key``. jit-safe."""
    err, t_cal_s, operator, gm = world
    gm = GnssErrorModel() if gm is None else gm
    is_gps = np.asarray(is_gps, bool)
    towers = np.flatnonzero(~is_gps)
    g = gnss_errors(key, t_s, el_rad, sigma_ura_gps_m, gm)
    sop, sigma_m = sop_errors(key, err, t_s, towers.size, t_cal_s, operator)
    return g.at[:, towers].set(sop), sigma_m


def epoch_times(duration_s, n_epochs):
    """t_k = k duration / n (k < n): n epochs spread uniformly over the run."""
    return np.arange(int(n_epochs), dtype=np.float64) * (float(duration_s) / int(n_epochs))


def truth_at(scenario: Scenario, t_s):
    """Truth ENU (T, 3) at times t_s, linear interpolation of the trajectory samples."""
    ts = np.asarray(scenario.traj.t_s)
    pos = np.asarray(scenario.traj.pos_m)
    return np.stack([np.interp(t_s, ts, pos[:, i]) for i in range(3)], -1)


def scenario_geometry(scenario: Scenario, t_s, t0_gps_s, sky_source="nominal-gps",
                      sky_description=None, real=False, mask_deg=15.0,
                      carriers=None) -> EpochGeometry:
    """The noise-free geometry of ``scenario`` at times ``t_s`` (s from its start), GPS time of
    t = 0 ``t0_gps_s``, GPS satellites of ``sky_source`` (a ``geometry.sky`` source) above
    ``mask_deg`` at the true receiver position. ``carriers`` (L_towers,) names each tower's
    clock group (default one group "LTE")."""
    t_s = np.asarray(t_s, np.float64)
    lat, lon, h = (np.deg2rad(scenario.origin_lat_deg), np.deg2rad(scenario.origin_lon_deg),
                   scenario.origin_h_m)
    origin = np.asarray(frames.geodetic_to_ecef(lat, lon, h))
    truth = np.asarray(frames.enu_to_ecef(truth_at(scenario, t_s), origin))
    towers = np.asarray(frames.enu_to_ecef(np.asarray(scenario.towers_enu_m), origin))
    n_tw = towers.shape[0]
    t_gps = t0_gps_s + t_s
    ecef, usable, _, _, sv, desc = satellites(sky_source, t_gps, ("gps",))
    ecef, usable = np.asarray(ecef), np.asarray(usable)
    # look angles from each epoch's receiver (T, S)
    az, el, _, vis = jax.vmap(lambda r, e, u: look_angles(r, e[None], u[None],
                                                              np.deg2rad(mask_deg)))(
        truth, ecef, usable)
    el, vis = np.asarray(el)[:, 0], np.asarray(vis)[:, 0]
    keep = vis.any(0)
    sv = np.asarray(sv)[keep]
    ecef, vis, el = ecef[:, keep], vis[:, keep], el[:, keep]
    n_t = t_s.size
    tw_pos = np.broadcast_to(towers, (n_t, n_tw, 3))
    tx = np.concatenate([np.where(vis[..., None], ecef, 0.0), tw_pos], 1)
    valid = np.concatenate([vis, np.ones((n_t, n_tw), bool)], 1)
    rng = np.where(valid, np.linalg.norm(truth[:, None] - tx, axis=-1), 0.0)
    d_tw = towers[None] - truth[:, None]
    enu_rot = np.asarray(frames.enu_rotation(lat, lon))
    up = np.einsum("j,tlj->tl", enu_rot[2], d_tw)
    el_tw = np.arcsin(np.clip(up / np.linalg.norm(d_tw, axis=-1), -1, 1))
    el_all = np.concatenate([np.where(vis, el, 0.0), el_tw], 1)
    tw_clk = C_M_S * (np.asarray(scenario.tower_clk_bias0_s)[None]
                      + np.asarray(scenario.tower_clk_drift)[None] * t_s[:, None])
    tx_clock = np.concatenate([np.zeros((n_t, sv.size)), tw_clk], 1)
    carriers = np.asarray(["LTE"] * n_tw if carriers is None else list(carriers), dtype=object)
    if carriers.shape != (n_tw,):
        raise ValueError(f"carriers must name the clock group of each of the {n_tw} towers")
    ids = np.asarray([str(s) for s in sv] + [f"T{i + 1}" for i in range(n_tw)], dtype=object)
    return EpochGeometry(
        t_s=t_s, t_gps_s=t_gps, truth_m=truth, tx_pos_m=tx, range_m=rng, valid=valid,
        el_rad=el_all, is_gps=np.arange(sv.size + n_tw) < sv.size, ids=ids,
        group=np.concatenate([np.asarray(["GPS"] * sv.size, dtype=object), carriers]),
        tx_clock_m=tx_clock, rx_clock_m=RX_CLOCK_BIAS_M + RX_CLOCK_DRIFT_MPS * t_s,
        origin_ecef_m=origin, sky_source=sky_description or desc, real_ephemeris=bool(real))


def pseudoranges(geom: EpochGeometry, noise_m):
    """Measured pseudoranges (T, L): range + c dt_rx - c dt_tx + noise_m (0 where not valid)."""
    z = (pseudorange_from_range(geom.range_m, geom.rx_clock_m, geom.tx_clock_m)
         + np.asarray(noise_m))
    return np.where(geom.valid, z, 0.0)


# ----------------------------------------------------------------------------- recordings


def to_recording(geom: EpochGeometry, pseudorange_m, sigma_m=None, name="synthesized",
                 description="", source_params=None) -> Recording:
    """The measurements in the recorded-data format (``geometry.recording``): GPS rows in
    ``gnss`` (sat_clock_m = 0: the synthesis removes satellite clocks), tower rows in
    ``pseudoranges`` with the towers' clock polynomials in ``transmitters``, truth at the
    epochs."""
    pr = np.asarray(pseudorange_m, np.float64)
    sig = None if sigma_m is None else np.broadcast_to(np.asarray(sigma_m, np.float64), pr.shape)
    lat, lon, h = (float(np.rad2deg(v)) if i < 2 else float(v)
                   for i, v in enumerate(frames.ecef_to_geodetic(geom.origin_ecef_m)))
    t = geom.t_s
    gi = np.flatnonzero(geom.is_gps)
    ti = np.flatnonzero(~geom.is_gps)
    rows_t, cols = np.nonzero(geom.valid[:, gi])
    cols = gi[cols]
    gnss = pd.DataFrame({
        "t_s": t[rows_t], "sv_id": geom.ids[cols].astype(str), "pseudorange_m": pr[rows_t, cols],
        "sat_x_m": geom.tx_pos_m[rows_t, cols, 0], "sat_y_m": geom.tx_pos_m[rows_t, cols, 1],
        "sat_z_m": geom.tx_pos_m[rows_t, cols, 2], "sat_clock_m": np.zeros(rows_t.size),
        "el_deg": np.rad2deg(geom.el_rad[rows_t, cols])})
    tw = geom.tx_pos_m[0, ti]
    # c dt_n(t) = bias + drift t: recover the polynomial from the first two epochs
    clk = geom.tx_clock_m[:, ti]
    drift = (clk[1] - clk[0]) / (t[1] - t[0]) if t.size > 1 else np.zeros(ti.size)
    transmitters = pd.DataFrame({
        "tx_id": geom.ids[ti].astype(str), "kind": ["lte"] * ti.size,
        "group": geom.group[ti].astype(str), "x_m": tw[:, 0], "y_m": tw[:, 1], "z_m": tw[:, 2],
        "clock_bias_m": clk[0] - drift * t[0], "clock_drift_mps": drift,
        "clock_t0_s": np.zeros(ti.size)})
    rt, ct = np.nonzero(geom.valid[:, ti])
    prt = pd.DataFrame({"t_s": t[rt], "tx_id": geom.ids[ti][ct].astype(str),
                        "pseudorange_m": pr[rt, ti[ct]]})
    if sig is not None:
        gnss["sigma_m"] = sig[rows_t, cols]
        prt["sigma_m"] = sig[rt, ti[ct]]
    truth = pd.DataFrame({"t_s": t, "x_m": geom.truth_m[:, 0], "y_m": geom.truth_m[:, 1],
                          "z_m": geom.truth_m[:, 2], "rx_clock_m": geom.rx_clock_m})
    week = int(geom.t_gps_s[0] // gpstime.SECONDS_PER_WEEK)
    meta = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "name": name,
            "description": description, "origin": {"lat_deg": lat, "lon_deg": lon, "h_m": h},
            "t0_gps_week": week,
            "t0_gps_tow_s": float(geom.t_gps_s[0] - week * gpstime.SECONDS_PER_WEEK),
            "source": {"kind": "synthesized", "generator": "sim.gnss",
                       "sky": geom.sky_source, **(source_params or {})}}
    return validate_recording(Recording(meta=meta, transmitters=transmitters, pseudoranges=prt,
                                        gnss=gnss, truth=truth))
