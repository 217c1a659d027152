"""Vehicle trajectories and LTE tower layouts of the synthetic drives and flight (the scenarios).

Their measurements and errors are drawn by ``sim.measurement`` (one model for every drive,
flight and synthesized recording); ``Scenario.errors`` is a scenario's ``ErrorModel``.

Frame and gravity. Everything is expressed in a local East-North-Up (ENU) frame fixed at the
start point (DESIGN.md: the EKF navigates in such a frame), treated as inertial: a flat,
non-rotating Earth with constant normal gravity g_n = [0, 0, -g(lat, h)] of the start point
(WGS-84 Somigliana formula with the free-air height term, ``geometry.normal_gravity_mps2``).
Earth rate and transport rate are neglected in the truth and in the filter alike, so the
synthetic world is self-consistent; replaying real IMU data would need them (Groves 2013, ch. 5).

Body frame: right-handed x front, y left, z up (DESIGN.md corrects seed 000's left-handed
"y right"). Attitude: JPL quaternion q = [q_vec, q_w] (scalar last) of the rotation from the
global frame G to the body (IMU) frame I, so C(q) maps global coordinates to body coordinates.

Motion. A trajectory is a list of segments; in each the horizontal speed, the heading (angle of
the body x axis from East towards North) and the climb rate change by given amounts along a
raised-cosine rate profile, rate(tau) = (Delta / D) (1 - cos(2 pi tau / D)), which is zero at both
ends, so acceleration and yaw rate are continuous (a smooth trajectory). Roll and pitch are zero:
a road vehicle on flat ground; for the multirotor this neglects the few degrees of tilt it uses
to accelerate (the specific force is computed for the attitude we specify, so the IMU data stay
exactly consistent with the motion).

IMU outputs are interval means over [t_k, t_k + dt] (an integrating IMU): gyro = [0, 0, (psi_{k+1}
- psi_k) / dt] and specific force f_b = C (a_n - g_n) = [v', v psi', w' + g], averaged. Speeds,
heading and climb are analytic; positions and the lateral term v psi' are integrated with the
trapezoid rule on a grid ``substeps`` times finer than the IMU.
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from oaraim.constants import STANDARD_GRAVITY_MPS2
from oaraim.errors import ErrorModel
from oaraim.geometry import normal_gravity_mps2


class Segment(NamedTuple):
    """One motion segment: duration and the changes of speed, heading and climb rate over it."""

    duration_s: float
    dspeed_m_s: float = 0.0
    dheading_rad: float = 0.0
    dclimb_m_s: float = 0.0


class Trajectory(NamedTuple):
    """Truth at the IMU epochs t_k = k dt, k = 0..K (K IMU intervals).

    t_s (K+1,), pos_m (K+1, 3) ENU, vel_m_s (K+1, 3) ENU, quat (K+1, 4) JPL G->body,
    gyro_rad_s (K, 3) and accel_m_s2 (K, 3): interval-mean body rate and specific force over
    [t_k, t_{k+1}]; gravity_m_s2 (3,) the ENU gravity vector; length_m the 3-D path length.
    """

    t_s: jnp.ndarray
    pos_m: jnp.ndarray
    vel_m_s: jnp.ndarray
    quat: jnp.ndarray
    gyro_rad_s: jnp.ndarray
    accel_m_s2: jnp.ndarray
    gravity_m_s2: jnp.ndarray
    length_m: float


def _profile(tau, duration, delta):
    """Raised-cosine rate and its integral at time ``tau`` into a segment."""
    w = 2.0 * np.pi / duration
    rate = (delta / duration) * (1.0 - np.cos(w * tau))
    integral = (delta / duration) * (tau - np.sin(w * tau) / w)
    return rate, integral


def _kinematics(segments, t, speed0, heading0, climb0):
    """Speed, heading, climb and their rates at times ``t`` (NumPy float64 arrays)."""
    dur = np.array([s.duration_s for s in segments], float)
    dv = np.array([s.dspeed_m_s for s in segments], float)
    dpsi = np.array([s.dheading_rad for s in segments], float)
    dw = np.array([s.dclimb_m_s for s in segments], float)
    start = np.concatenate([[0.0], np.cumsum(dur)[:-1]])
    v0 = speed0 + np.concatenate([[0.0], np.cumsum(dv)[:-1]])
    psi0 = heading0 + np.concatenate([[0.0], np.cumsum(dpsi)[:-1]])
    w0 = climb0 + np.concatenate([[0.0], np.cumsum(dw)[:-1]])
    idx = np.clip(np.searchsorted(start, t, side="right") - 1, 0, len(segments) - 1)
    tau = np.clip(t - start[idx], 0.0, dur[idx])
    d = dur[idx]
    vr, vi = _profile(tau, d, dv[idx])
    pr, pi = _profile(tau, d, dpsi[idx])
    wr, wi = _profile(tau, d, dw[idx])
    return (np.asarray(v0[idx] + vi), np.asarray(vr), np.asarray(psi0[idx] + pi), np.asarray(pr),
            np.asarray(w0[idx] + wi), np.asarray(wr))


def heading_quaternion(psi_rad):
    """JPL quaternion (G -> body) of a level body with heading psi (x axis from East to North)."""
    psi = jnp.asarray(psi_rad, jnp.float64)
    z = jnp.zeros_like(psi)
    return jnp.stack([z, z, jnp.sin(psi / 2.0), jnp.cos(psi / 2.0)], -1)


def trajectory(segments, dt_s=0.01, substeps=16, start_enu_m=(0.0, 0.0, 0.0), heading0_rad=0.0,
               speed0_m_s=0.0, climb0_m_s=0.0, gravity_m_s2=STANDARD_GRAVITY_MPS2) -> Trajectory:
    """Truth trajectory and ideal IMU samples at ``1 / dt_s`` Hz from motion segments.

    Host-side and deterministic (one truth is shared by every Monte Carlo run). The total
    duration is rounded down to a whole number of IMU intervals.
    """
    total = float(sum(s.duration_s for s in segments))
    k = int(np.floor(total / dt_s + 1e-9))
    n_fine = k * substeps
    h = dt_s / substeps
    tf = np.arange(n_fine + 1) * h
    v, vdot, psi, psidot, w, wdot = _kinematics(segments, tf, speed0_m_s, heading0_rad,
                                                climb0_m_s)
    vel = np.stack([v * np.cos(psi), v * np.sin(psi), w], -1)

    def cumtrapz(y):
        out = np.zeros_like(y)
        out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * h, axis=0)
        return out

    pos = np.asarray(start_enu_m, float) + cumtrapz(vel)
    lateral = cumtrapz(v * psidot)  # integral of v psi' (body y specific force)
    speed3 = np.sqrt(v**2 + w**2)
    length = float(cumtrapz(speed3)[-1])
    sl = slice(None, None, substeps)
    vs, psis, ws, lat = v[sl], psi[sl], w[sl], lateral[sl]
    gyro = np.stack([np.zeros(k), np.zeros(k), np.diff(psis) / dt_s], -1)
    accel = np.stack([np.diff(vs) / dt_s, np.diff(lat) / dt_s, np.diff(ws) / dt_s + gravity_m_s2],
                     -1)
    return Trajectory(
        t_s=jnp.asarray(tf[sl]), pos_m=jnp.asarray(pos[sl]), vel_m_s=jnp.asarray(vel[sl]),
        quat=heading_quaternion(psis), gyro_rad_s=jnp.asarray(gyro),
        accel_m_s2=jnp.asarray(accel), gravity_m_s2=jnp.asarray([0.0, 0.0, -gravity_m_s2]),
        length_m=length)


def path_length(segments, speed0_m_s=0.0, climb0_m_s=0.0, samples_per_s=200):
    """3-D path length of a segment list (host side), for sizing legs to a stated length."""
    total = float(sum(s.duration_s for s in segments))
    t = np.linspace(0.0, total, int(total * samples_per_s) + 1)
    v, _, _, _, w, _ = _kinematics(segments, t, speed0_m_s, 0.0, climb0_m_s)
    s = np.sqrt(v**2 + w**2)
    return float(np.sum(0.5 * (s[1:] + s[:-1]) * np.diff(t)))


# --------------------------------------------------------------------------------------------
# Scenarios


class Scenario(NamedTuple):
    """A drive or flight: truth, towers, clocks, measurement model and the injected fault.

    towers_enu_m (L, 3); tower_clk_bias0_s, tower_clk_drift (L,): the first-order polynomial
    tower clocks (known to the receiver); fault_tower is 0-based (tower 1 of the seeds = 0).
    mp_sigma_m / mp_tau_s: optional first-order GM multipath/NLOS bias per tower (0 = off).
    notes: every parameter with its source or reasoning.
    """

    name: str
    traj: Trajectory
    towers_enu_m: jnp.ndarray
    tower_clk_bias0_s: jnp.ndarray
    tower_clk_drift: jnp.ndarray
    meas_rate_hz: float
    sigma_pr_m: float
    mp_sigma_m: float
    mp_tau_s: float
    fault_tower: int
    fault_onset_s: float
    fault_bias_m: float
    origin_lat_deg: float
    origin_lon_deg: float
    origin_h_m: float
    notes: dict

    @property
    def errors(self) -> ErrorModel:
        """The scenario's own (clean, pre-issue-25) error parameters as the measurement model
        takes them: ``ErrorModel.clean`` with its sigma, multipath and fault. The realistic
        world is ``ErrorModel(fault_tower=..., ...)`` (docs/error-world.md)."""
        return ErrorModel.clean(self.sigma_pr_m, self.fault_tower, self.fault_onset_s,
                                self.fault_bias_m, self.mp_sigma_m, self.mp_tau_s)


#: downtown Riverside, California (seed 000 section IV-A), WGS-84, approximate city centre
RIVERSIDE_LAT_DEG, RIVERSIDE_LON_DEG, RIVERSIDE_H_M = 33.9806, -117.3755, 250.0
#: urban cruise speed: 25 mph, the usual downtown Riverside speed limit, m/s
URBAN_SPEED_M_S = 25 * 0.44704
#: speed through 90-degree intersection turns (about 11 mph), m/s
TURN_SPEED_M_S = 5.0
#: duration of a 90-degree turn at TURN_SPEED (mean radius v D / (pi / 2) = 19 m, peak lateral
#: acceleration 2 v (pi / 2) / D = 2.6 m/s^2: a comfortable urban turn)
TURN_S = 6.0
#: accelerate/brake between TURN_SPEED and URBAN_SPEED in 4 s (mean 1.6 m/s^2); start from and
#: stop at rest in 8 s (mean 1.4 m/s^2): ordinary passenger-car values
SPEED_CHANGE_S, START_STOP_S = 4.0, 8.0

#: tower clocks: offsets of a few microseconds and drifts within the 3GPP TS 36.104 frequency
#: accuracy of +-0.05 ppm for wide-area base stations; they are known polynomials (seed 000
#: after eq. 3), so their values do not affect the errors
_TOWER_BIAS0_S = np.array([2.1e-6, -3.4e-6, 0.7e-6, 4.6e-6, -1.2e-6, 3.3e-6, -2.8e-6, 1.5e-6,
                           -4.1e-6, 0.3e-6, 2.9e-6])
_TOWER_DRIFT = np.array([1.2e-8, -2.5e-8, 3.1e-8, -0.8e-8, 4.0e-8, -3.6e-8, 0.5e-8, 2.2e-8,
                         -1.7e-8, 3.8e-8, -4.4e-8])

_COMMON_NOTES = {
    "frame": "local ENU at the start point, flat non-rotating Earth, WGS-84 normal gravity there",
    "imu": "VN-100 datasheet (geometry.imu): 0.0035 deg/s/rtHz, 10 deg/h; 0.14 mg/rtHz, 0.04 mg",
    "imu_rate_hz": "100 (seed 000 section IV-A)",
    "rx_clock": "OCXO PSDs S_wdt = 1.3e-22 s, S_wdtdot = 7.89e-25 1/s (seed 000 section IV-A)",
    "tower_clocks": "first-order polynomials (seed 000 after eq. 3), known from the GNSS period",
    "meas_rate_hz": "10: our choice (the seed gives no LTE pseudorange rate)",
    "sigma_pr_m": "2 m: 'meter-level' LTE ranging of ground vehicles (seed 000 section I, refs "
                  "9-12); the seed's variances were 'determined empirically' and are not given",
    "fault_bias_m": "30 m: our choice, an NLOS excess path of tens of metres in a street canyon "
                    "(the seeds give no magnitude)",
    "towers": "placed around the route at 1-2.6 km with macro-cell heights 25-40 m, spread in "
              "azimuth as in the seeds' figures' description; not tuned to any result",
}


def _drive_segments(cruise_s, turns, final_cruise_s):
    """Start from rest, cruise legs separated by 90-degree turns, stop. ``turns``: +1 left,
    -1 right."""
    segs = [Segment(START_STOP_S, URBAN_SPEED_M_S)]
    for c, turn in zip(cruise_s, turns, strict=True):
        segs += [Segment(c), Segment(SPEED_CHANGE_S, TURN_SPEED_M_S - URBAN_SPEED_M_S),
                 Segment(TURN_S, 0.0, turn * np.pi / 2.0),
                 Segment(SPEED_CHANGE_S, URBAN_SPEED_M_S - TURN_SPEED_M_S)]
    segs += [Segment(final_cruise_s), Segment(START_STOP_S, -URBAN_SPEED_M_S)]
    return segs


def _size_last_cruise(cruise_s, turns, length_m):
    """Duration of the last cruise leg that makes the route ``length_m`` long."""
    base = path_length(_drive_segments(cruise_s, turns, 0.0))
    return (length_m - base) / URBAN_SPEED_M_S


def _scenario(name, segs, heading0, towers, n_towers, onset_s, notes, lat, lon, h, dt_s,
              speed0=0.0, climb0=0.0):
    g = normal_gravity_mps2(np.deg2rad(lat), h)
    traj = trajectory(segs, dt_s=dt_s, heading0_rad=heading0, speed0_m_s=speed0,
                      climb0_m_s=climb0, gravity_m_s2=g)
    return Scenario(
        name=name, traj=traj, towers_enu_m=jnp.asarray(np.asarray(towers, float)),
        tower_clk_bias0_s=jnp.asarray(_TOWER_BIAS0_S[:n_towers]),
        tower_clk_drift=jnp.asarray(_TOWER_DRIFT[:n_towers]), meas_rate_hz=10.0,
        sigma_pr_m=2.0, mp_sigma_m=0.0, mp_tau_s=5.0, fault_tower=0, fault_onset_s=onset_s,
        fault_bias_m=30.0, origin_lat_deg=lat, origin_lon_deg=lon, origin_h_m=h,
        notes={**_COMMON_NOTES, **notes, "gravity_m_s2": g, "length_m": traj.length_m,
               "duration_s": float(traj.t_s[-1])})


def drive_seed000(dt_s=0.01) -> Scenario:
    """The 1.35 km downtown drive of seed 000 (Fig. 2) with 5 LTE towers; fault on tower 1 from
    t = 25 s.

    Route: from rest heading East, 25 mph legs joined by a left, a right and a left 90-degree
    turn, then a stop; the last leg is sized so that the route is 1350 m long (seed 000
    abstract). About 145 s.
    """
    cruise, turns = [20.0, 25.0, 30.0], [1, -1, 1]
    segs = _drive_segments(cruise, turns, _size_last_cruise(cruise, turns, 1350.0))
    towers = [[-900.0, 1400.0, 25.0], [1900.0, 1600.0, 35.0], [2300.0, -700.0, 30.0],
              [200.0, -1500.0, 28.0], [-1600.0, -300.0, 40.0]]
    notes = {"route": "E, left to N, right to E, left to N; cruise 20/25/30 s + sized last leg",
             "fault": "tower 1 from t = 25 s (seed 000 section IV-B, Fig. 3a)"}
    return _scenario("seed000-drive", segs, 0.0, towers, 5, 25.0, notes, RIVERSIDE_LAT_DEG,
                     RIVERSIDE_LON_DEG, RIVERSIDE_H_M, dt_s)


def drive_seed002(dt_s=0.01) -> Scenario:
    """The 1.4 km drive of seed 002 with 5 LTE towers (the poster gives no count: the same
    receiver and city as seed 000); fault on tower 1 from t = 95 s.

    Route: from rest heading North, right, right, left turns, a stop; last leg sized to 1400 m.
    """
    cruise, turns = [30.0, 35.0, 20.0], [-1, -1, 1]
    segs = _drive_segments(cruise, turns, _size_last_cruise(cruise, turns, 1400.0))
    towers = [[1500.0, 1900.0, 30.0], [-1300.0, 900.0, 25.0], [-400.0, -1200.0, 35.0],
              [2100.0, -900.0, 30.0], [2600.0, 900.0, 40.0]]
    notes = {"route": "N, right to E, right to S, left to E; cruise 30/35/20 s + sized last leg",
             "fault": "tower 1 from t = 95 s (our reading of seed 002's demo; stated choice)"}
    return _scenario("seed002-drive", segs, np.pi / 2.0, towers, 5, 95.0, notes,
                     RIVERSIDE_LAT_DEG, RIVERSIDE_LON_DEG, RIVERSIDE_H_M, dt_s)


#: multirotor cruise speed, m/s (a DJI Matrice 600 survey pace; 815 m / 220 s = 3.7 m/s mean)
UAV_SPEED_M_S = 5.0
UAV_TURN_SPEED_M_S = 3.0
UAV_CLIMB_M_S = 3.0


def _uav_segments(final_cruise_s, hover_s):
    climb = [Segment(3.0, dclimb_m_s=UAV_CLIMB_M_S), Segment(12.0),
             Segment(3.0, dclimb_m_s=-UAV_CLIMB_M_S), Segment(4.0)]
    legs = [Segment(5.0, UAV_SPEED_M_S)]
    for c in (30.0, 25.0, 30.0):
        legs += [Segment(c), Segment(2.0, UAV_TURN_SPEED_M_S - UAV_SPEED_M_S),
                 Segment(5.0, 0.0, np.pi / 2.0), Segment(2.0, UAV_SPEED_M_S - UAV_TURN_SPEED_M_S)]
    legs += [Segment(final_cruise_s), Segment(5.0, -UAV_SPEED_M_S), Segment(hover_s)]
    descent = [Segment(3.0, dclimb_m_s=-UAV_CLIMB_M_S), Segment(12.0),
               Segment(3.0, dclimb_m_s=UAV_CLIMB_M_S)]
    return climb + legs + descent


def uav_seed004(dt_s=0.01) -> Scenario:
    """The UAV flight of seed 004 section VII: 815 m in 220 s with 11 LTE towers.

    Climb to 45 m at 3 m/s, a four-leg pattern at 5 m/s with 90-degree left turns at 3 m/s, stop,
    hover, descend. The last leg is sized to make the 3-D path 815 m and the final hover to make
    the flight 220 s. No fault is injected by default (seed 004's experiment injects none in the
    SOPs); fault_onset_s = inf.
    """
    base = path_length(_uav_segments(0.0, 0.0))
    final = (815.0 - base) / UAV_SPEED_M_S
    dur = sum(s.duration_s for s in _uav_segments(final, 0.0))
    segs = _uav_segments(final, 220.0 - dur)
    rng = np.random.default_rng(4)  # fixed layout; documented in the notes
    az = np.sort(rng.uniform(0.0, 2.0 * np.pi, 11))
    dist = rng.uniform(600.0, 3000.0, 11)
    hgt = rng.uniform(20.0, 40.0, 11)
    towers = np.stack([dist * np.cos(az), dist * np.sin(az), hgt], -1)
    notes = {"route": "climb 45 m, 4 legs at 5 m/s with 3 left turns, stop, hover, descend; "
                      "last leg sized to 815 m, hover to 220 s (seed 004 section VII-A)",
             "towers": "11 towers (seed 004): azimuths uniform, 0.6-3 km, heights 20-40 m, drawn "
                       "once with numpy default_rng(4)",
             "fault": "none"}
    return _scenario("seed004-uav", segs, 0.0, towers, 11, np.inf, notes, RIVERSIDE_LAT_DEG,
                     RIVERSIDE_LON_DEG, RIVERSIDE_H_M, dt_s)


SCENARIOS = {"seed000-drive": drive_seed000, "seed002-drive": drive_seed002,
             "seed004-uav": uav_seed004}
