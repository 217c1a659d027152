"""Replay a recorded (or synthesized) LTE + IMU drive through the EKF-RAIM of seed 000.

``replay_ekf_raim(recording, ...)`` takes a ``geometry.Recording`` (``geometry.load_recording``:
the on-disk format of ``geometry/recording.py``) holding an IMU table, LTE pseudoranges and their
transmitters with the clock polynomials of seed 000 eq. (3), and optionally ground truth, and runs
two filters side by side over it: the EKF with NIS detection only, and the EKF with NIS detection
and subset exclusion (``araim.ekf_raim.raim_update``: detection, exclusion, Joseph update, Xi
recursion, slope HPL, HAL alarm). It returns per-epoch traces of both (``ReplayTrace``) and, when
the recording has truth, the position errors.

The other direction, one simulated run written as a ``Recording``, is
``oaraim.sim.synthesize_recording``; studies write it to disk, load it back and replay it here,
so the synthetic drives go through exactly the loader and replay path a user's real drive goes
through.

Replay rules (what a recording must satisfy beyond the loader's checks):

- IMU time stamps are the END of each sample's interval (the sample is the interval mean of the
  angular rate and specific force, as ``errors.imu`` synthesizes and as most IMUs output); the
  step is uniform (every step within 1 % of the median, which is the ``dt`` the filter uses).
- Pseudorange epochs lie on IMU time stamps (within 1 % of a step) and on a regular grid of n IMU
  steps (n = the median epoch step / IMU step, rounded). A missing epoch inside the grid becomes
  an epoch with no valid measurement (prediction only). Epochs with fewer than n IMU samples
  before them at the start are dropped.
- ``sigma_m`` of the pseudorange table, where present, is each measurement's noise sigma;
  otherwise ``sigma_pr_m`` (argument) is used for all.
- Initial state, at t0 = first used epoch - n IMU steps, in this order of precedence: the
  ``initial`` argument; ``meta.json``'s ``"initial_state"`` object (keys below; what the GNSS
  period of seed 000 section IV-A would leave); the truth table at t0 (linearly interpolated;
  needs the velocity and quaternion columns; biases 0; receiver clock from ``rx_clock_m`` /
  ``rx_clock_drift_mps`` if present, else the bias from the first epoch's pseudoranges given the
  truth position and drift 0). Without any of them the replay refuses (ValueError naming the
  three ways). The initial covariance is ``araim.ekf_raim.initial_covariance`` of the IMU spec
  and ``InitialUncertainty`` (0.1/0.1/0.5 deg, 0.5 m, 0.05 m/s, 1 m, 0.1 m/s) in every case.
  ``"initial_state"`` keys: ``position_enu_m`` (3), ``velocity_enu_mps`` (3), ``quaternion_jpl``
  (4, [qx, qy, qz, qw], ^B_G q in the ENU frame of ``origin``), optional ``gyro_bias_radps`` (3),
  ``accel_bias_mps2`` (3), ``rx_clock_m``, ``rx_clock_drift_mps`` (default 0).
- The navigation frame is the local ENU frame of ``meta.json``'s origin, flat and non-rotating
  with WGS-84 normal gravity at the origin (as the synthesized drives; over 1-2 km the neglected
  Earth rate, 7.3e-5 rad/s, and frame curvature are far below the VN-100 gyro noise).
- IMU noise model of the filter: ``spec`` (default ``errors.imu.vn100()``), or meta.json's
  ``"imu_spec"`` object with the ``ImuSpec`` fields (synthesized recordings write it).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.araim import ekf as _ekf
from oaraim.araim import ekf_raim as _er
from oaraim.araim import filter_gradients as _fg
from oaraim.araim import filter_monitor as _fm
from oaraim.araim.budget import BUDGET_SEED004_TABLE_I, IntegrityBudget
from oaraim.errors import imu
from oaraim.geometry import frames, recording_frame
from oaraim.readers import recording

#: tolerance, in IMU steps, for uniform IMU stamps and for epochs lying on IMU stamps
_STEP_TOL = 0.01


class ReplayTrace(NamedTuple):
    """Per-epoch traces; arrays with a leading axis of 2 are [without, with exclusion].

    ``t_s`` (E,) epoch times; ``position_enu_m`` (2, E, 3) posterior position and
    ``sigma_enu_m`` (2, E, 3) its standard deviations (sqrt diag P); ``nis`` (2, E)
    NIS over the valid towers before exclusion, ``dof``, ``threshold`` T_h, ``detected``,
    ``excluded`` (tower index, -1 none), ``n_used``, ``hpl_m`` (inf when unavailable), ``alarm``
    (HPL > HAL), ``status`` (``araim.status.Status``); ``n_valid`` (E,) towers measured;
    ``truth_enu_m`` (E, 3) and ``err_enu_m`` (2, E, 3), ``err_2d_m`` (2, E) when the recording
    has truth (else None); ``tx_ids`` (L,), ``towers_enu_m`` (L, 3); ``init_source`` (str)."""

    t_s: np.ndarray
    position_enu_m: np.ndarray
    sigma_enu_m: np.ndarray
    nis: np.ndarray
    dof: np.ndarray
    threshold: np.ndarray
    detected: np.ndarray
    excluded: np.ndarray
    n_used: np.ndarray
    hpl_m: np.ndarray
    alarm: np.ndarray
    status: np.ndarray
    n_valid: np.ndarray
    truth_enu_m: np.ndarray | None
    err_enu_m: np.ndarray | None
    err_2d_m: np.ndarray | None
    tx_ids: np.ndarray
    towers_enu_m: np.ndarray
    init_source: str


# ----------------------------------------------------------------------------- the filter scan

@jax.jit
def _replay_scan(est0, gyro, accel, z, valid, sigma, tx_pos, tx_clk, params, tables,
                 dof_offset, hal_m):
    """Both filters (exclude False, True) over the epochs, vmapped like ``simulate_drive``."""
    n_t = tx_pos.shape[0]
    carry = _er.raim_init(est0, n_t)
    carry = jax.tree.map(lambda x: jnp.stack([x, x]), carry)
    exclude = jnp.array([False, True])

    def body(c, inp):
        g, a, zz, vv, ss, tc = inp

        def one_filter(cf, excl):
            prior, phi = _ekf.ekf_predict(cf.state, g, a, params)
            cf, out = _er.raim_update(cf, prior, phi, _ekf.EkfInputs(g, a, zz, vv, tc, ss),
                                      tx_pos, _er.RaimOptions(tables, dof_offset, excl, hal_m))
            sd = jnp.sqrt(jnp.diagonal(cf.state.P)[_ekf.POS])
            return cf, (cf.state.r, sd, out)

        return jax.vmap(one_filter)(c, exclude)

    _, (r, sd, out) = jax.lax.scan(body, carry, (gyro, accel, z, valid, sigma, tx_clk))
    return r, sd, out


# ----------------------------------------------------------------------------- preparation

def _uniform_step(t, what):
    d = np.diff(t)
    if len(d) == 0:
        raise ValueError(f"the {what} table needs at least two samples")
    step = float(np.median(d))
    bad = np.abs(d - step) > _STEP_TOL * step
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(
            f"{what} time stamps are not uniform: step {d[i]!r} s after t_s = {t[i]!r} s against "
            f"the median {step!r} s (tolerance 1 %). Resample the {what} onto a uniform grid "
            "(the filter uses one fixed IMU step)")
    return step


def _imu_spec(rec, spec):
    if spec is not None:
        return spec
    s = rec.meta.get("imu_spec")
    if isinstance(s, dict):
        try:
            return imu.ImuSpec(**{k: float(s[k]) for k in imu.ImuSpec._fields})
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"meta.json 'imu_spec' must give the numbers "
                             f"{list(imu.ImuSpec._fields)} ({e})") from None
    return imu.vn100()


class _Prepared(NamedTuple):
    t_s: np.ndarray         # (E,)
    gyro: np.ndarray        # (E, n, 3)
    accel: np.ndarray
    z: np.ndarray           # (E, L)
    valid: np.ndarray
    sigma: np.ndarray
    tx_clk: np.ndarray
    towers: np.ndarray      # (L, 3)
    tx_ids: np.ndarray
    t0_s: float
    dt_s: float


def _prepare(rec: recording.Recording, sigma_pr_m: float) -> _Prepared:
    if rec.imu is None:
        raise ValueError("the recording has no imu table; the EKF replay needs the IMU "
                         "(imu.parquet or imu.csv, README 'Recorded drives and flights')")
    if rec.pseudoranges is None or rec.transmitters is None:
        raise ValueError("the recording has no pseudoranges/transmitters tables; the EKF "
                         "replay needs LTE pseudoranges")
    t_imu = rec.imu["t_s"].to_numpy(np.float64)
    dt = _uniform_step(t_imu, "imu")
    pm = recording.pseudorange_matrix(rec)
    cols = ["pseudorange_m"] + (["sigma_m"] if "sigma_m" in rec.pseudoranges else [])
    vals = recording.pseudorange_matrix(rec, value=cols).values
    t_pr = pm.t_s
    if len(t_pr) < 2:
        raise ValueError("the recording needs at least two pseudorange epochs")
    step = float(np.median(np.diff(t_pr)))
    n = int(round(step / dt))
    if n < 1 or abs(n * dt - step) > _STEP_TOL * dt:
        raise ValueError(f"the pseudorange epoch step {step!r} s is not a whole number of IMU "
                         f"steps ({dt!r} s)")
    # IMU stamp index of each epoch
    idx = np.searchsorted(t_imu, t_pr - _STEP_TOL * dt)
    idx_c = np.minimum(idx, len(t_imu) - 1)
    off = np.abs(t_imu[idx_c] - t_pr) > _STEP_TOL * dt
    if off.any():
        i = int(np.argmax(off))
        raise ValueError(f"pseudorange epoch t_s = {t_pr[i]!r} s does not lie on an IMU time "
                         "stamp; the replay needs epochs on the IMU grid (stamps = end of each "
                         "IMU interval)")
    keep = idx >= n - 1
    if not keep.any():
        raise ValueError("no pseudorange epoch has a full interval of IMU samples before it")
    first = int(np.argmax(keep))
    idx, t_pr, vals, valid = idx[first:], t_pr[first:], vals[first:], pm.valid[first:]
    gaps = np.diff(idx)
    if np.any(gaps % n):
        i = int(np.argmax(gaps % n != 0))
        raise ValueError(f"pseudorange epochs at {t_pr[i]!r} and {t_pr[i + 1]!r} s are not a "
                         f"whole number of epoch steps ({n} IMU steps) apart")
    slot = (idx - idx[0]) // n
    e = int(slot[-1]) + 1
    z = np.zeros((e, vals.shape[1]))
    sig = np.ones((e, vals.shape[1]))
    v = np.zeros((e, vals.shape[1]), bool)
    z[slot] = vals[..., 0] if vals.ndim == 3 else vals
    if len(cols) == 2:
        sig[slot] = np.where(valid, vals[..., 1], 1.0)
    else:
        sig[slot] = np.where(valid, sigma_pr_m, 1.0)
    v[slot] = valid
    start = idx[0] - n + 1
    gi = start + np.arange(e * n)
    g = rec.imu[["gyro_x_radps", "gyro_y_radps", "gyro_z_radps"]].to_numpy(np.float64)[gi]
    a = rec.imu[["accel_x_mps2", "accel_y_mps2", "accel_z_mps2"]].to_numpy(np.float64)[gi]
    t_ep = t_imu[idx[0]] + np.arange(e) * n * dt
    t_ep[slot] = t_pr  # the recorded stamps where there are epochs
    return _Prepared(t_ep, g.reshape(e, n, 3), a.reshape(e, n, 3), z, v, sig,
                     recording.tower_clock_m(rec, t_ep), recording_frame.transmitters_enu_m(rec),
                     pm.ids, float(t_imu[start] - dt), dt)


def _interp(t, tt, x):
    return np.stack([np.interp(t, tt, x[:, j]) for j in range(x.shape[1])], -1)


def _initial_state(rec, prep: _Prepared, initial, p0):
    """(EkfState, source) at prep.t0_s: ``initial`` > meta initial_state > truth at t0."""
    src = None
    if initial is None and isinstance(rec.meta.get("initial_state"), dict):
        initial, src = rec.meta["initial_state"], "meta.json initial_state"
    if initial is not None:
        src = src or "initial argument"
        try:
            q = np.asarray(initial["quaternion_jpl"], float)
            r = np.asarray(initial["position_enu_m"], float)
            v = np.asarray(initial["velocity_enu_mps"], float)
            bg = np.asarray(initial.get("gyro_bias_radps", [0.0] * 3), float)
            ba = np.asarray(initial.get("accel_bias_mps2", [0.0] * 3), float)
            clk = np.array([float(initial.get("rx_clock_m", 0.0)),
                            float(initial.get("rx_clock_drift_mps", 0.0))])
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{src} needs quaternion_jpl (4), position_enu_m (3), "
                             f"velocity_enu_mps (3) ({e!r})") from None
        if q.shape != (4,) or r.shape != (3,) or v.shape != (3,) or not np.all(
                np.isfinite(np.concatenate([q, r, v, bg, ba, clk]))):
            raise ValueError(f"{src}: quaternion_jpl must have 4 finite numbers, position_enu_m "
                             "and velocity_enu_mps 3 each")
        return _ekf.ekf_init(q / np.linalg.norm(q), r, v, bg, ba, clk, p0), src
    if rec.truth is None:
        raise ValueError(
            "no initial state: the replay needs the truth table (with velocity and quaternion "
            "columns), a meta.json 'initial_state' object, or the initial= argument (seed 000 "
            "initializes the EKF from a period of GNSS availability)")
    tr = recording_frame.truth_enu(rec)
    if tr.velocity_enu_mps is None or tr.quaternion is None:
        raise ValueError("initializing from truth needs its velocity (vx_mps, vy_mps, vz_mps) "
                         "and quaternion (qx, qy, qz, qw) columns; or give meta.json "
                         "'initial_state'")
    t0 = prep.t0_s
    if not tr.t_s[0] - 1e-9 <= t0 <= tr.t_s[-1] + 1e-9:
        raise ValueError(f"the truth table does not cover the start t0 = {t0!r} s")
    r = _interp(np.array([t0]), tr.t_s, tr.position_enu_m)[0]
    v = _interp(np.array([t0]), tr.t_s, tr.velocity_enu_mps)[0]
    j = int(np.argmin(np.abs(tr.t_s - t0)))
    q = tr.quaternion[j]
    if "rx_clock_m" in rec.truth:
        cb = float(np.interp(t0, tr.t_s, rec.truth["rx_clock_m"].to_numpy(np.float64)))
        cd = (float(np.interp(t0, tr.t_s, rec.truth["rx_clock_drift_mps"].to_numpy(np.float64)))
              if "rx_clock_drift_mps" in rec.truth else 0.0)
    else:  # the bias that makes the first epoch's pseudoranges consistent with the truth
        vv = prep.valid[0]
        if not vv.any():
            raise ValueError("the first epoch has no pseudorange to fix the receiver clock; add "
                             "rx_clock_m to the truth table")
        rng = np.linalg.norm(r - prep.towers, axis=-1)
        cb = float(np.mean((prep.z[0] - rng + prep.tx_clk[0])[vv]))
        cd = 0.0
    return _ekf.ekf_init(q / np.linalg.norm(q), r, v, np.zeros(3), np.zeros(3),
                         np.array([cb, cd]), p0), "truth at t0"


def replay_ekf_raim(rec: recording.Recording, *, sigma_pr_m: float = 2.0,
                    cfg: _er.RaimConfig | None = None, spec: imu.ImuSpec | None = None,
                    init_uncertainty: _er.InitialUncertainty | None = None,
                    initial: dict | None = None) -> ReplayTrace:
    """EKF + NIS detection + exclusion + HPL over a recorded drive, without and with exclusion.

    ``rec``: a ``geometry.Recording`` (load it with ``geometry.load_recording``). ``cfg``:
    ``RaimConfig`` (P_FA, P_MD, HAL, dof_offset 0: d = N_s, 4: d = N_s - 4). ``sigma_pr_m``
    where the table has no ``sigma_m``. See the module docstring for the rules and the initial
    state. Returns a ``ReplayTrace`` of NumPy arrays."""
    cfg = _er.RaimConfig() if cfg is None else cfg
    init_uncertainty = _er.InitialUncertainty() if init_uncertainty is None else init_uncertainty
    if not (np.isfinite(sigma_pr_m) and sigma_pr_m > 0):
        raise ValueError(f"sigma_pr_m must be a positive number, got {sigma_pr_m!r}")
    spec = _imu_spec(rec, spec)
    prep = _prepare(rec, sigma_pr_m)
    p0 = _er.initial_covariance(spec, init_uncertainty)
    est0, src = _initial_state(rec, prep, initial, p0)
    o = rec.meta["origin"]
    grav = np.array([0.0, 0.0, -frames.normal_gravity_mps2(np.deg2rad(o["lat_deg"]), o["h_m"])])
    params = _ekf.params_from_imu(spec, prep.dt_s, grav)
    tables = _er.raim_tables(cfg.p_fa, cfg.p_md, prep.towers.shape[0])
    r, sd, out = _replay_scan(est0, jnp.asarray(prep.gyro), jnp.asarray(prep.accel),
                          jnp.asarray(prep.z), jnp.asarray(prep.valid), jnp.asarray(prep.sigma),
                          jnp.asarray(prep.towers), jnp.asarray(prep.tx_clk), params, tables,
                          jnp.asarray(cfg.dof_offset), jnp.asarray(cfg.hal_m, jnp.float64))
    sw = lambda x: np.swapaxes(np.asarray(x), 0, 1)  # noqa: E731  (E, 2, ...) -> (2, E, ...)
    pos = sw(r)
    truth = err = err2 = None
    if rec.truth is not None:
        tr = recording_frame.truth_enu(rec)
        inside = (prep.t_s >= tr.t_s[0] - 1e-9) & (prep.t_s <= tr.t_s[-1] + 1e-9)
        truth = _interp(prep.t_s, tr.t_s, tr.position_enu_m)
        truth[~inside] = np.nan  # outside the truth table: no error (NaN marks "unknown")
        err = pos - truth[None]
        err2 = np.hypot(err[..., 0], err[..., 1])
    return ReplayTrace(
        t_s=prep.t_s, position_enu_m=pos, sigma_enu_m=sw(sd), nis=sw(out.nis), dof=sw(out.dof),
        threshold=sw(out.threshold), detected=sw(out.detected), excluded=sw(out.excluded),
        n_used=sw(out.n_used), hpl_m=sw(out.hpl_m), alarm=sw(out.alarm), status=sw(out.status),
        n_valid=prep.valid.sum(1), truth_enu_m=truth, err_enu_m=err, err_2d_m=err2,
        tx_ids=np.asarray(prep.tx_ids), towers_enu_m=prep.towers, init_source=src)


class FilterReplay(NamedTuple):
    """What ``replay_filter_monitor`` returns (NumPy arrays, E epochs)."""

    t_s: np.ndarray
    """(E,) epoch times, s."""
    monitor: _fm.FilterMonitorEpoch
    """Per-epoch outputs of the filter bank (leading axis E)."""
    err_2d_m: np.ndarray | None
    """(E,) horizontal error of the main filter against the truth (None without truth)."""
    tx_ids: np.ndarray
    """(L,) transmitter ids."""
    init_source: str
    """Where the initial state came from (module docstring)."""


class FilterReplayConfig(NamedTuple):
    """Settings of ``replay_filter_monitor``: the pseudorange sigma ``sigma_pr_m`` (m), the
    integrity ``budget``, P_s ``p_sat`` per tower and epoch, P_const ``p_const`` of the one
    operator, the ``fault_modes`` convention (order 1), the IMU ``spec`` (None: the
    recording's), the initial uncertainty ``init_uncertainty`` and state ``initial`` (as
    ``replay_ekf_raim``), ``exclusion`` by restart and the sub-filters' ``linearisation``
    (``araim.filter_monitor.LINEARISATIONS``)."""

    sigma_pr_m: float = 2.0
    budget: IntegrityBudget = BUDGET_SEED004_TABLE_I
    p_sat: float = 1e-5
    p_const: float = 1e-8
    fault_modes: str = "add-v4.2"
    spec: imu.ImuSpec | None = None
    init_uncertainty: _er.InitialUncertainty | None = None
    initial: dict | None = None
    exclusion: bool = False
    linearisation: str = "main"


def _filter_bank_setup(rec: recording.Recording, c: FilterReplayConfig):
    """(prepared recording, initial state source, ``run_ekf_monitor``'s arguments) of
    ``replay_filter_monitor`` and ``replay_filter_gradient``."""
    sigma_pr_m, spec, init_uncertainty = c.sigma_pr_m, c.spec, c.init_uncertainty
    init_uncertainty = _er.InitialUncertainty() if init_uncertainty is None else init_uncertainty
    if not (np.isfinite(sigma_pr_m) and sigma_pr_m > 0):
        raise ValueError(f"sigma_pr_m must be a positive number, got {sigma_pr_m!r}")
    spec = _imu_spec(rec, spec)
    prep = _prepare(rec, sigma_pr_m)
    est0, src = _initial_state(rec, prep, c.initial,
                               _er.initial_covariance(spec, init_uncertainty))
    o = rec.meta["origin"]
    grav = np.array([0.0, 0.0, -frames.normal_gravity_mps2(np.deg2rad(o["lat_deg"]), o["h_m"])])
    params = _ekf.params_from_imu(spec, prep.dt_s, grav)
    n_t = prep.towers.shape[0]
    inputs = _ekf.EkfInputs(jnp.asarray(prep.gyro), jnp.asarray(prep.accel),
                            jnp.asarray(prep.z), jnp.asarray(prep.valid),
                            jnp.asarray(prep.tx_clk), jnp.asarray(prep.sigma))
    sources = _fm.BankSources(np.zeros(n_t, int), np.full(n_t, c.p_sat), np.array([c.p_const]))
    options = _fm.BankOptions(c.budget, 1, c.fault_modes, exclusion=bool(c.exclusion),
                              linearisation=c.linearisation)
    return prep, src, (est0, inputs, jnp.asarray(prep.towers), params, sources, options)


def _truth_at(rec, t_s):
    """(E, 3) the recording's true ENU position at ``t_s``, nan outside its truth table."""
    tr = recording_frame.truth_enu(rec)
    inside = (t_s >= tr.t_s[0] - 1e-9) & (t_s <= tr.t_s[-1] + 1e-9)
    truth = _interp(t_s, tr.t_s, tr.position_enu_m)
    truth[~inside] = np.nan
    return truth


def replay_filter_monitor(rec: recording.Recording,
                          config: FilterReplayConfig | None = None) -> FilterReplay:
    """The solution-separation filter bank (``araim.run_ekf_monitor``, docs/filter-integrity.md)
    over a recorded drive: the same preparation, initial state and EKF as ``replay_ekf_raim``,
    every tower one source of one operator (P_s ``config.p_sat`` per epoch, P_const
    ``config.p_const``), order 1 of ``config.fault_modes``; ``config.exclusion``: exclusion by
    restart (``araim.filter_monitor.exclusion_restart``)."""
    c = FilterReplayConfig() if config is None else config
    prep, src, args = _filter_bank_setup(rec, c)
    _, out = _fm.run_ekf_monitor(*args)
    out = jax.tree.map(np.asarray, out)
    err2 = None
    if rec.truth is not None:
        truth = _truth_at(rec, prep.t_s)
        err2 = np.hypot(*(out.position_m[:, :2] - truth[:, :2]).T)
    return FilterReplay(prep.t_s, out, err2, np.asarray(prep.tx_ids), src)


class FilterGradientReplay(NamedTuple):
    """What ``replay_filter_gradient`` returns (NumPy arrays)."""

    t_s: np.ndarray
    """(E,) epoch times, s."""
    gradient: _fg.TowerGradient
    """The objective (m), its gradient (L, 3) with respect to the towers' ENU positions (m/m),
    the epochs in it and the bank's per-epoch outputs."""
    tx_ids: np.ndarray
    """(L,) transmitter ids, the rows of the gradient."""
    towers_enu_m: np.ndarray
    """(L, 3) the towers' positions in the recording's ENU frame, m."""


def replay_filter_gradient(rec: recording.Recording, config: FilterReplayConfig | None = None,
                           objective: str = "mean",
                           placement: bool = True) -> FilterGradientReplay:
    """The filter bank of ``replay_filter_monitor`` over a recorded (or synthesized) drive and
    the gradient of its HPL with respect to the tower positions
    (``araim.filter_gradients.hpl_gradient_wrt_towers``; ``objective`` 'mean' or 'last').
    ``placement`` True: the pseudoranges follow the towers about the recording's truth (needs
    a truth table covering every epoch; the measurement errors held); False: the pseudoranges
    held (the sensitivity to the towers' surveyed coordinates)."""
    c = FilterReplayConfig() if config is None else config
    prep, _, args = _filter_bank_setup(rec, c)
    truth = None
    if placement:
        truth = None if rec.truth is None else _truth_at(rec, prep.t_s)
        if truth is None or not np.all(np.isfinite(truth)):
            raise ValueError("placement=True needs the recording's truth at every epoch (a "
                             "truth table covering the drive); pass placement=False for the "
                             "gradient with the pseudoranges held")
    g = _fg.hpl_gradient_wrt_towers(*args, truth, objective)
    return FilterGradientReplay(prep.t_s, jax.tree.map(np.asarray, g),
                                np.asarray(prep.tx_ids), np.asarray(prep.towers))


def trace_summary(tr: ReplayTrace, fault_onset_s: float | None = None,
                  fault_tower: int | None = None) -> dict:
    """Plain numbers of a replay, per filter [without, with exclusion]: RMSE and max 2D error
    (over epochs with truth), first detection (after ``fault_onset_s`` if given), detections
    before the onset (false alarms when the onset is known), exclusions of each tower, HPL max,
    alarms, epochs with 2D error > HPL (misleading information)."""
    out = {}
    for i, name in enumerate(("without_exclusion", "with_exclusion")):
        d = {}
        if tr.err_2d_m is not None:
            e = tr.err_2d_m[i]
            ok = np.isfinite(e)
            d["rmse_2d_m"] = float(np.sqrt(np.mean(e[ok] ** 2))) if ok.any() else None
            d["max_2d_m"] = float(np.max(e[ok])) if ok.any() else None
            d["misleading_epochs"] = int(np.sum(ok & (e > tr.hpl_m[i])))
        det = tr.detected[i].astype(bool)
        after = (tr.t_s >= fault_onset_s) if fault_onset_s is not None else np.ones_like(det)
        hit = det & after
        d["first_detection_s"] = float(tr.t_s[np.argmax(hit)]) if hit.any() else None
        d["detections"] = int(det.sum())
        if fault_onset_s is not None:
            d["detections_before_onset"] = int(np.sum(det & ~after))
        ex = tr.excluded[i]
        d["exclusions_by_tower"] = {str(tr.tx_ids[j]): int(np.sum(ex == j))
                                    for j in range(len(tr.tx_ids))}
        if fault_tower is not None:
            d["correct_exclusions"] = int(np.sum(after & (ex == fault_tower)))
        fin = np.isfinite(tr.hpl_m[i])
        d["hpl_max_m"] = float(np.max(tr.hpl_m[i][fin])) if fin.any() else None
        d["hpl_unavailable_epochs"] = int(np.sum(~fin))
        d["alarms"] = int(np.sum(tr.alarm[i]))
        out[name] = d
    return out
