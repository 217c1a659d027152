"""The one measurement model of the simulated world: what a receiver on a drive or flight
measures, and the errors it measures with.

Every simulated drive (``sim.drive``), flight (``sim.gnss``) and synthesized recording
(``sim.recordings``) draws its measurements here, so a change of the error world is made once.

Pseudoranges (seed 000 eq. 3): ``z = |r_rx - r_tx| + c dt_rx - c dt_tx + b + sigma eps``, the
transmitter clocks c dt_tx the polynomials the receiver calibrated (``geometry.clocks``), the
receiver clock the double integrator of seed 000 section II-B with the OCXO PSDs, ``b`` the sum
of the bias terms of the ``ErrorModel`` world (``errors.world``): short-delay multipath
(first-order Gauss-Markov per tower), NLOS episodes (a two-state Markov chain per tower with
exponential excess delays), each tower's own clock deviation epsilon_n (Gauss-Markov) and its
operator's common clock term (double integrator; seed 004 eq. 3), minus the line the receiver
fitted to them by least squares during the GNSS period (seed 000 II-D; ``calibrate``), plus the
injected fault; eps is standard normal. docs/error-world.md gives every parameter with its
source.

IMU (``errors.imu``): interval-mean samples, white noise plus first-order Gauss-Markov
biases of the ``ImuSpec``.

Draws: a drive epoch's key gives one normal vector (IMU, receiver clock, multipath, white
noise: the layout of ``n_epoch_normals``, unchanged since the clean world) and the named streams
``world_sop`` and ``world_nlos`` (``mc.STREAMS``); the GNSS period draws from the run key's
``world_calibration`` stream.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from oaraim.errors import ErrorModel, imu
from oaraim.geometry import clocks
from oaraim.mc import stream


class WorldState(NamedTuple):
    """The simulated world's error state carried from epoch to epoch: gyro and accelerometer
    biases (3,) each, the receiver clock [c dt, c dt'] (m, m/s), and per tower (L,): the
    multipath, the NLOS bias (0: line of sight), the own clock deviation epsilon_n, the common
    clock term of the tower's operator [c dt, c dt'] (L, 2) (row n: operator n), and the
    receiver's least-squares clock fit [intercept at t = 0 (m), slope (m/s)] (L, 2)."""

    gyro_bias_rad_s: jnp.ndarray
    accel_bias_m_s2: jnp.ndarray
    rx_clock_m: jnp.ndarray
    multipath_m: jnp.ndarray
    nlos_m: jnp.ndarray = 0.0
    clk_eps_m: jnp.ndarray = 0.0
    clk_common_m: jnp.ndarray = 0.0
    clk_fit_m: jnp.ndarray = 0.0


class EpochMeasurements(NamedTuple):
    """What one pseudorange epoch of a drive measures: the IMU samples of the epoch's interval
    (n, 3) each, the pseudoranges (L,) m and the total bias in them (L,) m (multipath + fault:
    what the white noise does not explain)."""

    gyro_rad_s: jnp.ndarray
    accel_m_s2: jnp.ndarray
    pseudorange_m: jnp.ndarray
    bias_m: jnp.ndarray


def pseudorange_from_range(range_m, rx_clock_m, tx_clock_m):
    """Error-free pseudorange from the geometric range: range + c dt_rx - c dt_tx (seed 000
    eq. 3), shape (..., L); ``rx_clock_m`` (...) and ``tx_clock_m`` (..., L) in metres. NumPy in,
    NumPy out; JAX in, JAX out."""
    return range_m + rx_clock_m[..., None] - tx_clock_m


def pseudorange_true(pos_m, towers_m, rx_clk_bias_m, tower_clk_m):
    """Error-free pseudorange ||r - r_s|| + c (dt_r - dt_s) (seed 000 eq. 3), shape (..., L).

    ``pos_m`` (..., 3), ``towers_m`` (..., L, 3), ``rx_clk_bias_m`` (...), ``tower_clk_m`` (..., L).
    """
    rng = jnp.linalg.norm(pos_m[..., None, :] - towers_m, axis=-1)
    return pseudorange_from_range(rng, jnp.asarray(rx_clk_bias_m), tower_clk_m)


def fault_bias_m(t_s, onset_s, magnitude_m, tower_index, n_towers):
    """Injected fault: a constant bias on one tower from ``onset_s`` on, shape (..., L)."""
    on = (jnp.asarray(t_s) >= onset_s)[..., None]
    sel = jnp.arange(n_towers) == tower_index
    return jnp.where(on & sel, magnitude_m, 0.0)


def pseudorange_sample(key, pos_m, towers_m, rx_clk_bias_m, tower_clk_m, sigma_m,
                       bias_m=0.0):
    """Measured pseudoranges: truth + N(0, sigma^2) white noise + ``bias_m`` (multipath/NLOS and
    faults, (..., L))."""
    z0 = pseudorange_true(pos_m, towers_m, rx_clk_bias_m, tower_clk_m)
    return z0 + bias_m + sigma_m * jax.random.normal(key, z0.shape)


def gauss_markov_step(x, normals, sigma, tau_s, dt_s):
    """One exact step of a first-order Gauss-Markov process of stationary 1-sigma ``sigma`` and
    correlation time ``tau_s``: x <- phi x + sigma sqrt(1 - phi^2) n, phi = exp(-dt / tau).
    Its autocovariance at lag tau is sigma^2 exp(-tau / tau_s)."""
    phi = jnp.exp(-dt_s / tau_s)
    return phi * x + sigma * jnp.sqrt(1.0 - phi**2) * normals


def multipath_step(mp_m, normals, err: ErrorModel, dt_s):
    """One exact step of the per-tower first-order Gauss-Markov multipath bias (L,)."""
    return gauss_markov_step(mp_m, normals, err.mp_sigma_m, err.mp_tau_s, dt_s)


def nlos_probabilities(err: ErrorModel, dt_s):
    """(p_on, p_off): the per-step probabilities that a line-of-sight tower turns NLOS
    (1 - exp(-rate dt)) and that an NLOS episode ends (1 - exp(-dt / duration)). The chain's
    stationary NLOS share is p_on / (p_on + p_off); an episode lasts 1 / p_off steps on mean."""
    p_on = 1.0 - jnp.exp(-err.nlos_rate_per_s * dt_s)
    p_off = 1.0 - jnp.exp(-dt_s / err.nlos_duration_s)
    return p_on, p_off


def nlos_step(nlos_m, uniforms, exponentials, err: ErrorModel, dt_s):
    """One step of the per-tower NLOS episodes (L,): an episode (bias > 0) ends with
    probability p_off, a line-of-sight tower starts one with probability p_on, whose constant
    bias is ``nlos_bias_m`` times a standard exponential draw. ``uniforms`` (2, L) and
    ``exponentials`` (L,) are the step's draws."""
    p_on, p_off = nlos_probabilities(err, dt_s)
    start = jnp.where(uniforms[1] < p_on, err.nlos_bias_m * exponentials, 0.0)
    return jnp.where(nlos_m > 0.0, jnp.where(uniforms[0] < p_off, 0.0, nlos_m), start)


def common_clock_step(x_m, normals, err: ErrorModel, dt_s):
    """One exact step of the operators' common tower-clock terms [c dt, c dt'] (L, 2) (seed 004
    eq. 3), the double integrator of ``geometry.clocks`` with the ``clk_s_*`` PSDs; zero PSDs
    keep the term at its value (no 0/0 in the Cholesky factor)."""
    q = clocks.clock_process_noise(dt_s, err.clk_s_wdt_s, err.clk_s_wdtdot_per_s)
    l00 = jnp.sqrt(q[..., 0, 0])
    l10 = jnp.where(l00 > 0.0, q[..., 1, 0] / jnp.where(l00 > 0.0, l00, 1.0), 0.0)
    l11 = jnp.sqrt(jnp.maximum(q[..., 1, 1] - l10**2, 0.0))
    w0 = l00 * normals[..., 0]
    w1 = l10 * normals[..., 0] + l11 * normals[..., 1]
    return jnp.stack([x_m[..., 0] + dt_s * x_m[..., 1] + w0, x_m[..., 1] + w1], -1)


def sop_step(key, mp_normals, state: WorldState, err: ErrorModel, dt_s):
    """One step of every time-correlated SOP error of the world (multipath, NLOS, epsilon_n,
    the operators' common clock terms); ``mp_normals`` (L,) drive the multipath, the rest is
    drawn from the named streams ``world_sop`` (normals) and ``world_nlos`` (uniforms) of
    ``key``. Returns the state with those four fields stepped."""
    n_t = mp_normals.shape[0]
    w = jax.random.normal(stream(key, "world_sop"), (3, n_t))
    u = jax.random.uniform(stream(key, "world_nlos"), (3, n_t))
    mp = multipath_step(state.multipath_m, mp_normals, err, dt_s)
    nlos = nlos_step(state.nlos_m, u[:2], -jnp.log1p(-u[2]), err, dt_s)
    eps = gauss_markov_step(state.clk_eps_m, w[0], err.clk_eps_sigma_m, err.clk_eps_tau_s, dt_s)
    com = common_clock_step(state.clk_common_m, w[1:].T, err, dt_s)
    return state._replace(multipath_m=mp, nlos_m=nlos, clk_eps_m=eps, clk_common_m=com)


def sop_error_m(state: WorldState, t_s, operator):
    """The SOP part of the pseudorange errors at time ``t_s`` (L,): multipath + NLOS +
    epsilon_n + the common clock term of each tower's operator - the receiver's clock fit."""
    fit = state.clk_fit_m[..., 0] + state.clk_fit_m[..., 1] * t_s
    return (state.multipath_m + state.nlos_m + state.clk_eps_m
            + state.clk_common_m[operator, 0] - fit)


def clock_fit(y_m, t_s, mask):
    """Least-squares line through each column of ``y_m`` (N, L) over the masked samples
    (``mask`` (N,)): returns ``(fit (L, 2) [value at t = 0, slope], residual variance (L,))``,
    the variance with N - 2 degrees of freedom (seed 000 II-D: tower clock bias and drift by
    least squares while GNSS is available). Fewer than 3 samples: fit 0, variance nan."""
    m = mask.astype(y_m.dtype)
    n = jnp.sum(m)
    nn = jnp.maximum(n, 1.0)
    tb = jnp.sum(m * t_s) / nn
    yb = jnp.sum(m[:, None] * y_m, 0) / nn
    x = (t_s - tb) * m
    sxx = jnp.sum(x**2)
    ok = n > 2
    b = jnp.where(ok, jnp.sum(x[:, None] * (y_m - yb), 0) / jnp.where(ok, sxx, 1.0), 0.0)
    a = jnp.where(ok, yb - b * tb, 0.0)
    r = (y_m - a - b * t_s[:, None]) * m[:, None]
    var = jnp.where(ok, jnp.sum(r**2, 0) / jnp.maximum(n - 2.0, 1.0), jnp.nan)
    return jnp.stack([a, b], -1), var


def calibrate(key, state: WorldState, err: ErrorModel, operator, t_cal_s):
    """The GNSS period before t = 0 at the epochs ``t_cal_s`` (n_cal,) (uniformly spaced, the
    last at t = 0; static length), of which those within ``err.calib_window_s`` before t = 0 are
    the receiver's calibration data. The world's SOP errors start from their stationary laws
    (NLOS from the chain's stationary share), run through the period, and the receiver fits
    each tower's clock (``clock_fit``) to z - range - c dt_rx + c dt_poly = the SOP error +
    white noise. Draws: stream ``world_calibration`` of the run's ``key``, ``fold_in`` by
    calibration epoch (n_cal and n_cal + 1: the initial state).

    Returns ``(state at t = 0 with clk_fit_m set, empirical sigma (m): the square root of the
    towers' mean residual variance, nan without data)``."""
    n_t = state.multipath_m.shape[0]
    n_cal = t_cal_s.shape[0]
    dt_s = t_cal_s[1] - t_cal_s[0]
    k0 = stream(key, "world_calibration")
    w0 = jax.random.normal(jax.random.fold_in(k0, n_cal), (3, n_t))
    p_on, p_off = nlos_probabilities(err, dt_s)
    share = p_on / jnp.maximum(p_on + p_off, 1e-300)
    u0 = jax.random.uniform(jax.random.fold_in(k0, n_cal + 1), (2, n_t))
    state = state._replace(
        multipath_m=err.mp_sigma_m * w0[0], clk_eps_m=err.clk_eps_sigma_m * w0[1],
        nlos_m=jnp.where(u0[0] < share, err.nlos_bias_m * -jnp.log1p(-u0[1]), 0.0),
        clk_common_m=jnp.zeros((n_t, 2)), clk_fit_m=jnp.zeros((n_t, 2)))

    def body(st, k):
        kk = jax.random.fold_in(k0, k)
        w = jax.random.normal(kk, (2, n_t))
        st = sop_step(kk, w[0], st, err, dt_s)
        return st, sop_error_m(st, t_cal_s[k], operator) + err.sigma_pr_m * w[1]

    state, y = jax.lax.scan(body, state, jnp.arange(n_cal))
    fit, var = clock_fit(y, t_cal_s, t_cal_s > -err.calib_window_s)
    return state._replace(clk_fit_m=fit), jnp.sqrt(jnp.mean(var))


def n_epoch_normals(n_imu: int, n_towers: int) -> int:
    """Standard normals one drive epoch draws (one vector per epoch key): 12 per IMU sample,
    2 for the receiver clock, one per tower for multipath and one per tower for the noise."""
    return n_imu * 12 + 2 + 2 * n_towers


class EpochTruth(NamedTuple):
    """The truth of one drive epoch (``drive_epoch``)."""

    gyro_rad_s: jax.Array
    """(n, 3) rad/s: the ideal interval-mean body rates of the epoch's n IMU intervals."""
    accel_m_s2: jax.Array
    """(n, 3) m/s^2: the ideal interval-mean specific forces."""
    t_s: jax.Array
    """() s: the epoch's time."""
    pos_m: jax.Array
    """(3,) m: the receiver's position at the epoch (the towers' frame)."""


class EpochTowers(NamedTuple):
    """The towers one drive epoch ranges to (``drive_epoch``)."""

    pos_m: jax.Array
    """(L, 3) m: the towers' positions."""
    clock_m: jax.Array
    """(L,) m: the towers' calibrated clock polynomials at the epoch."""
    operator: jax.Array | None = None
    """(L,) int: each tower's operator 0..L-1 (its common clock term); None: all one."""


class ReceiverSensors(NamedTuple):
    """The receiver's IMU and clock in the simulated world (``drive_epoch``)."""

    spec: imu.ImuSpec
    """The IMU's error specification."""
    dt_imu_s: float
    """s: the IMU step."""
    s_wdt_s: float
    """The receiver clock's bias PSD (``geometry.clocks``)."""
    s_wdtdot_per_s: float
    """The receiver clock's drift PSD."""


def drive_epoch(key, state: WorldState, truth: EpochTruth, towers: EpochTowers,
                err: ErrorModel, sensors: ReceiverSensors, unrolled_imu=False):
    """One pseudorange epoch of a simulated drive: the IMU samples of its n intervals, the
    receiver clock and SOP error steps (``sop_step``), and the pseudoranges at the epoch's end.

    ``key`` is the epoch's key (one normal vector of ``n_epoch_normals`` is drawn from it, the
    other SOP errors from its named streams); ``truth`` the ideal IMU interval means and the
    position at the epoch (``EpochTruth``); ``towers`` their positions, calibrated clock
    polynomials and operators (``EpochTowers``); ``sensors`` the IMU spec and step and the
    receiver clock's PSDs (``ReceiverSensors``). ``unrolled_imu`` (static) writes the IMU
    chain as a Python loop instead of a ``lax.scan``: the same equations; XLA may round the two
    forms differently in the last bit, and the one-run synthesis keeps the loop so that
    synthesized recordings stay bit-identical to earlier versions. Returns
    ``(WorldState, EpochMeasurements)``."""
    gyro_true, accel_true, t_s, pos_m = truth
    towers_m, tower_clk_m, operator = towers
    spec, dt_imu_s, s_wdt_s, s_wdtdot_per_s = sensors
    n_sub = gyro_true.shape[0]
    n_t = towers_m.shape[0]
    operator = jnp.zeros(n_t, int) if operator is None else operator
    dt_meas = n_sub * dt_imu_s
    w = jax.random.normal(key, (n_epoch_normals(n_sub, n_t),))
    w_imu = w[:n_sub * 12].reshape(n_sub, 12)
    w_clk = w[n_sub * 12:n_sub * 12 + 2]
    w_mp = w[n_sub * 12 + 2:n_sub * 12 + 2 + n_t]
    w_pr = w[n_sub * 12 + 2 + n_t:]

    bg, ba = state.gyro_bias_rad_s, state.accel_bias_m_s2
    if unrolled_imu:
        gl, al = [], []
        for j in range(n_sub):
            gj, aj, bg, ba = imu.imu_sample_normals(w_imu[j], gyro_true[j], accel_true[j], bg,
                                                    ba, spec, dt_imu_s)
            gl.append(gj)
            al.append(aj)
        gm, am = jnp.stack(gl), jnp.stack(al)
    else:
        def imu_step(b, x):
            # a scan, not an unrolled loop: unrolled inside the Monte Carlo scan, XLA fused the
            # whole bias chain into every sample's fusion (quadratic recomputation)
            wj, gt, at = x
            gj, aj, bgj, baj = imu.imu_sample_normals(wj, gt, at, b[0], b[1], spec, dt_imu_s)
            return (bgj, baj), (gj, aj)

        (bg, ba), (gm, am) = jax.lax.scan(imu_step, (bg, ba), (w_imu, gyro_true, accel_true))
    clk = clocks.clock_step_normals(w_clk, state.rx_clock_m, dt_meas, s_wdt_s, s_wdtdot_per_s)
    state = sop_step(key, w_mp, state._replace(gyro_bias_rad_s=bg, accel_bias_m_s2=ba,
                                               rx_clock_m=clk), err, dt_meas)
    bias = (sop_error_m(state, t_s, operator)
            + fault_bias_m(t_s, err.fault_onset_s, err.fault_bias_m, err.fault_tower, n_t))
    z = pseudorange_true(pos_m, towers_m, clk[0], tower_clk_m) + bias + err.sigma_pr_m * w_pr
    return state, EpochMeasurements(gm, am, z, bias)


def sop_errors(key, err: ErrorModel, t_s, n_towers: int, t_cal_s, operator=None):
    """The SOP pseudorange errors of ``n_towers`` towers at the epochs ``t_s`` (T,) (s from the
    end of the GNSS period, increasing, > 0) in the world ``err``, without the receiver: the
    GNSS period (``calibrate`` at ``t_cal_s``), then ``sop_step`` epoch by epoch plus the white
    noise and the injected fault, from ``fold_in(stream(key, "world_sop_epochs"), e)``. For the
    snapshot studies (``sim.gnss``). Returns ``(errors (T, L) m, empirical sigma m)``."""
    operator = jnp.zeros(n_towers, int) if operator is None else operator
    z = jnp.zeros(n_towers)
    st = WorldState(jnp.zeros(3), jnp.zeros(3), jnp.zeros(2), z, z, z,
                    jnp.zeros((n_towers, 2)), jnp.zeros((n_towers, 2)))
    st, sig = calibrate(key, st, err, operator, t_cal_s)
    k0 = stream(key, "world_sop_epochs")
    dts = jnp.diff(t_s, prepend=0.0)

    def body(s, x):
        e, t, dt = x
        k = jax.random.fold_in(k0, e)
        w = jax.random.normal(k, (2, n_towers))
        s = sop_step(k, w[0], s, err, dt)
        out = (sop_error_m(s, t, operator) + err.sigma_pr_m * w[1]
               + fault_bias_m(t, err.fault_onset_s, err.fault_bias_m, err.fault_tower, n_towers))
        return s, out

    _, y = jax.lax.scan(body, st, (jnp.arange(t_s.shape[0]), t_s, dts))
    return y, sig
