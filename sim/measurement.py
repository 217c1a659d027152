"""The one measurement model of the simulated world: what a receiver on a drive or flight
measures, and the errors it measures with.

Every simulated drive (``sim.drive``), flight (``sim.gnss``) and synthesized recording
(``sim.recordings``) draws its measurements here, so a change of the error world is made once.

Pseudoranges (seed 000 eq. 3): ``z = |r_rx - r_tx| + c dt_rx - c dt_tx + b + sigma eps``, the
transmitter clocks c dt_tx known polynomials (``geometry.clocks.tower_clock_m``), the receiver
clock the double integrator of seed 000 section II-B (``geometry.clocks``), ``b`` the sum of
the bias terms of the ``ErrorModel`` (multipath as a first-order Gauss-Markov process per
tower, the injected fault) and eps standard normal.

IMU (``geometry.imu``): interval-mean samples, white noise plus first-order Gauss-Markov
biases of the ``ImuSpec``.

The error world's parameters are one ``ErrorModel`` pytree: a new error term (issue 25's
NLOS episodes, tower-clock residuals, elevation-dependent GNSS multipath) is a new field there
and a new term in ``drive_epoch``, and reaches every simulated drive and recording at once.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from oaraim.geometry import clocks, imu


class ErrorModel(NamedTuple):
    """Parameters of the simulated pseudorange errors of a drive or flight (a pytree: every
    field may be traced, so one compilation serves a sweep over them).

    Defaults are the drive scenarios' (``sim.trajectory``: each with its reasoning there).
    """

    #: 1-sigma white noise of each pseudorange, m ("meter-level" LTE ranging, seed 000 sec. I)
    sigma_pr_m: float = 2.0
    #: stationary 1-sigma of the per-tower first-order Gauss-Markov multipath bias, m (0: off)
    mp_sigma_m: float = 0.0
    #: correlation time of that multipath process, s
    mp_tau_s: float = 5.0
    #: 0-based index of the tower that carries the injected fault
    fault_tower: int = 0
    #: time from which the fault is on, s (inf: no fault)
    fault_onset_s: float = 25.0
    #: magnitude of the injected constant fault bias, m
    fault_bias_m: float = 30.0


class WorldState(NamedTuple):
    """The simulated world's error state carried from epoch to epoch: gyro and accelerometer
    biases (3,) each, the receiver clock [c dt, c dt'] (m, m/s) and the multipath bias (L,) m."""

    gyro_bias_rad_s: jnp.ndarray
    accel_bias_m_s2: jnp.ndarray
    rx_clock_m: jnp.ndarray
    multipath_m: jnp.ndarray


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


def multipath_step(mp_m, normals, err: ErrorModel, dt_s):
    """One exact step of the per-tower first-order Gauss-Markov multipath bias (L,)."""
    phi = jnp.exp(-dt_s / err.mp_tau_s)
    return phi * mp_m + err.mp_sigma_m * jnp.sqrt(1.0 - phi**2) * normals


def n_epoch_normals(n_imu: int, n_towers: int) -> int:
    """Standard normals one drive epoch draws (one vector per epoch key): 12 per IMU sample,
    2 for the receiver clock, one per tower for multipath and one per tower for the noise."""
    return n_imu * 12 + 2 + 2 * n_towers


def drive_epoch(key, state: WorldState, gyro_true, accel_true, t_s, pos_m, towers_m,
                tower_clk_m, err: ErrorModel, spec: imu.ImuSpec, dt_imu_s, s_wdt_s,
                s_wdtdot_per_s, unrolled_imu=False):
    """One pseudorange epoch of a simulated drive: the IMU samples of its n intervals, the
    receiver clock and multipath steps, and the pseudoranges at the epoch's end.

    ``key`` is the epoch's key (one normal vector of ``n_epoch_normals`` is drawn from it);
    ``gyro_true``/``accel_true`` (n, 3) the ideal interval means; ``pos_m`` (3,) the truth at
    the epoch; ``towers_m`` (L, 3); ``tower_clk_m`` (L,); ``dt_imu_s`` the IMU step and
    ``s_wdt_s``, ``s_wdtdot_per_s`` the receiver clock's PSDs. ``unrolled_imu`` (static)
    writes the IMU chain as a Python loop instead of a ``lax.scan``: the same equations; XLA
    may round the two forms differently in the last bit, and the one-run synthesis keeps the
    loop so that synthesized recordings stay bit-identical to earlier versions. Returns
    ``(WorldState, EpochMeasurements)``."""
    n_sub = gyro_true.shape[0]
    n_t = towers_m.shape[0]
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
    mp = multipath_step(state.multipath_m, w_mp, err, dt_meas)
    bias = mp + fault_bias_m(t_s, err.fault_onset_s, err.fault_bias_m, err.fault_tower, n_t)
    z = pseudorange_true(pos_m, towers_m, clk[0], tower_clk_m) + bias + err.sigma_pr_m * w_pr
    return WorldState(bg, ba, clk, mp), EpochMeasurements(gm, am, z, bias)
