"""IMU error model: white noise plus first-order Gauss-Markov bias instability.

Measured = true + bias + white noise, per axis, for the gyroscope (rad/s) and the accelerometer
(specific force, m/s^2). Each output sample is the mean over its sample interval dt (an
integrating IMU), so the white noise of one sample has standard deviation N / sqrt(dt), with N the
datasheet noise density (angle / velocity random walk).

Bias instability is modelled as a first-order Gauss-Markov (GM) process per axis,
b' = -b / tau + w, with correlation time tau and stationary standard deviation sigma chosen so
that the peak of the process's Allan deviation equals the datasheet in-run bias stability
(``gm_sigma_from_bias_instability``). The discrete step over dt is exact:
b_{k+1} = exp(-dt / tau) b_k + sqrt(sigma^2 (1 - exp(-2 dt / tau))) n_k.

Datasheet values of the consumer/industrial MEMS unit used (VectorNav VN-100, the IMU named in
seed 004 section VII-A; the AsteRx-i V of seed 000 does not publish its IMU grade), from the
VN-100 product datasheet:
  gyroscope      noise density 0.0035 deg/s/sqrt(Hz), in-run bias stability < 10 deg/h
  accelerometer  noise density 0.14 mg/sqrt(Hz),      in-run bias stability < 0.04 mg
The datasheet gives no correlation time: we take tau = 300 s for both (the averaging time at which
Allan-deviation floors of this class of MEMS parts typically sit, a few hundred seconds; the
GM Allan deviation peaks at about 1.9 tau). It is a stated choice, exposed as a parameter.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim.constants import STANDARD_GRAVITY_MPS2

#: standard gravity for the mg <-> m/s^2 conversion of datasheets (``oaraim.constants``)
G0_M_S2 = STANDARD_GRAVITY_MPS2
_DEG = np.pi / 180.0


class ImuSpec(NamedTuple):
    """Per-axis error parameters, SI units.

    gyro_noise_rad_s_sqrt_hz: gyro white-noise density (angle random walk), rad/s/sqrt(Hz)
    accel_noise_m_s2_sqrt_hz: accelerometer white-noise density (velocity random walk)
    gyro_bias_sigma_rad_s, accel_bias_sigma_m_s2: stationary sigma of the GM biases
    gyro_bias_tau_s, accel_bias_tau_s: GM correlation times
    """

    gyro_noise_rad_s_sqrt_hz: float
    accel_noise_m_s2_sqrt_hz: float
    gyro_bias_sigma_rad_s: float
    accel_bias_sigma_m_s2: float
    gyro_bias_tau_s: float
    accel_bias_tau_s: float


def gm_allan_deviation(sigma, tau_c, avg_time):
    """Allan deviation of a first-order GM process with stationary sigma and correlation tau_c.

    sigma_A^2(T) = (2 sigma^2 tau_c / T) [1 - (tau_c / (2 T)) (3 - 4 e^{-T/tau_c} + e^{-2T/tau_c})]
    (the standard closed form for an exponentially correlated process, e.g. IEEE Std 952-1997
    Annex C). NumPy, host side.
    """
    x = np.asarray(avg_time, float) / tau_c
    var = (2.0 * sigma**2 / x) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))
    return np.sqrt(var)


def gm_sigma_from_bias_instability(bias_instability, tau_c):
    """Stationary sigma of the GM process whose Allan-deviation peak equals ``bias_instability``.

    The peak of the normalized curve sigma_A(T) / sigma is a constant (about 0.62 near
    T = 1.9 tau_c), found here on a dense logarithmic grid.
    """
    grid = np.logspace(-2, 3, 20001) * tau_c
    peak = gm_allan_deviation(1.0, tau_c, grid).max()
    return float(bias_instability) / peak


#: VN-100 gyro noise density 0.0035 deg/s/sqrt(Hz) (VN-100 datasheet)
VN100_GYRO_NOISE = 0.0035 * _DEG
#: VN-100 accelerometer noise density 0.14 mg/sqrt(Hz) (VN-100 datasheet)
VN100_ACCEL_NOISE = 0.14e-3 * G0_M_S2
#: VN-100 gyro in-run bias stability 10 deg/h (VN-100 datasheet upper bound)
VN100_GYRO_BIAS_INSTABILITY = 10.0 * _DEG / 3600.0
#: VN-100 accelerometer in-run bias stability 0.04 mg (VN-100 datasheet upper bound)
VN100_ACCEL_BIAS_INSTABILITY = 0.04e-3 * G0_M_S2
#: GM correlation time of both biases, s (our choice; see the module docstring)
VN100_BIAS_TAU_S = 300.0


def vn100(tau_s: float = VN100_BIAS_TAU_S) -> ImuSpec:
    """The VN-100 error parameters with GM correlation time ``tau_s``."""
    return ImuSpec(
        gyro_noise_rad_s_sqrt_hz=VN100_GYRO_NOISE,
        accel_noise_m_s2_sqrt_hz=VN100_ACCEL_NOISE,
        gyro_bias_sigma_rad_s=gm_sigma_from_bias_instability(VN100_GYRO_BIAS_INSTABILITY, tau_s),
        accel_bias_sigma_m_s2=gm_sigma_from_bias_instability(VN100_ACCEL_BIAS_INSTABILITY, tau_s),
        gyro_bias_tau_s=float(tau_s),
        accel_bias_tau_s=float(tau_s),
    )


def gm_step(key, b, sigma, tau_s, dt_s):
    """One exact step of a stationary first-order GM process (any shape)."""
    phi = jnp.exp(-dt_s / tau_s)
    return phi * b + sigma * jnp.sqrt(1.0 - phi**2) * jax.random.normal(key, jnp.shape(b))


def initial_biases(key, spec: ImuSpec, shape=()):
    """Stationary draw of the gyro and accelerometer biases, each ``shape + (3,)``."""
    kg, ka = jax.random.split(key)
    return (spec.gyro_bias_sigma_rad_s * jax.random.normal(kg, shape + (3,)),
            spec.accel_bias_sigma_m_s2 * jax.random.normal(ka, shape + (3,)))


def imu_sample_normals(normals, gyro_true, accel_true, bg, ba, spec: ImuSpec, dt_s):
    """``imu_sample`` with the 12 standard normals given (..., 12): gyro noise, accel noise,
    gyro bias step, accel bias step (3 each). Lets a caller draw many samples in one call."""
    ng, na, nbg, nba = (normals[..., 0:3], normals[..., 3:6], normals[..., 6:9],
                        normals[..., 9:12])
    gyro = gyro_true + bg + spec.gyro_noise_rad_s_sqrt_hz / jnp.sqrt(dt_s) * ng
    accel = accel_true + ba + spec.accel_noise_m_s2_sqrt_hz / jnp.sqrt(dt_s) * na
    pg = jnp.exp(-dt_s / spec.gyro_bias_tau_s)
    pa = jnp.exp(-dt_s / spec.accel_bias_tau_s)
    bg_next = pg * bg + spec.gyro_bias_sigma_rad_s * jnp.sqrt(1.0 - pg**2) * nbg
    ba_next = pa * ba + spec.accel_bias_sigma_m_s2 * jnp.sqrt(1.0 - pa**2) * nba
    return gyro, accel, bg_next, ba_next


def imu_sample(key, gyro_true, accel_true, bg, ba, spec: ImuSpec, dt_s):
    """Measured gyro and accelerometer samples (interval means) and the biases after the step.

    ``gyro_true``, ``accel_true``, ``bg``, ``ba``: (..., 3). The sample uses the bias at the start
    of the interval; the biases then advance one exact GM step.
    Returns ``(gyro_meas, accel_meas, bg_next, ba_next)``.
    """
    normals = jax.random.normal(key, jnp.shape(gyro_true)[:-1] + (12,))
    return imu_sample_normals(normals, gyro_true, accel_true, bg, ba, spec, dt_s)


def simulate_imu(key, gyro_true, accel_true, spec: ImuSpec, dt_s, bg0=None, ba0=None):
    """A whole IMU record: ``gyro_true``, ``accel_true`` of shape (K, 3) -> measured (K, 3) each,
    plus the bias histories (K, 3) (the bias in force during each sample). lax.scan over samples;
    vmap over keys for Monte Carlo runs.
    """
    k0, kscan = jax.random.split(key)
    if bg0 is None or ba0 is None:
        g0, a0 = initial_biases(k0, spec)
        bg0 = g0 if bg0 is None else bg0
        ba0 = a0 if ba0 is None else ba0
    keys = jax.random.split(kscan, gyro_true.shape[0])

    def body(carry, inp):
        bg, ba = carry
        k, w, f = inp
        gm, am, bg1, ba1 = imu_sample(k, w, f, bg, ba, spec, dt_s)
        return (bg1, ba1), (gm, am, bg, ba)

    _, (gm, am, bgs, bas) = jax.lax.scan(body, (jnp.asarray(bg0), jnp.asarray(ba0)),
                                         (keys, gyro_true, accel_true))
    return gm, am, bgs, bas
