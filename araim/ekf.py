"""Error-state EKF fusing an IMU with LTE pseudoranges (seed 000 section II).

State (seed 000 section II-B/C): x = [q, r, v, b_g, b_a, x_clk] with q the JPL unit quaternion
(scalar last) of the rotation from the global frame G (a local ENU frame fixed at the start,
DESIGN.md) to the IMU frame I, r and v the position and velocity in G, b_g and b_a the gyroscope
and accelerometer biases, x_clk = [c dt_r, c dt_r_dot] the receiver clock bias and drift (eq. 1).
Error state (17): [theta (3), r~ (3), v~ (3), b_g~ (3), b_a~ (3), x_clk~ (2)], with the attitude
error defined by q = dq (x) q_hat, dq ~ [theta / 2, sqrt(1 - theta^T theta / 4)] (eq. 2) and the
other errors additive (x~ = x - x_hat).

Time update. The nominal state follows the strapdown mechanization at the IMU rate (100 Hz,
``mechanize``); the covariance is propagated once per measurement interval T (10 Hz) with the
transition matrix Phi = exp(A T) and the process noise Q_d = int_0^T exp(A s) Q_c exp(A s)^T ds,
both by their third-order Taylor series in T (``transition_matrix``, ``discrete_process_noise``),
using the interval mean of the continuous error dynamics A (``error_dynamics``) over the IMU
samples. The series is exact for the nilpotent chains of the model (clock bias <- drift, seed 000
eq. 1 including T^3 / 3; position <- velocity <- accelerometer noise); neglected terms are
O(T^4) (a few 1e-5 of the attitude-velocity coupling per step in the sharpest turns). This is the
usual practice of propagating the covariance at a lower rate than the mechanization (Groves 2013,
section 14.2.4).

Error dynamics (Trawny & Roumeliotis 2005, "Indirect Kalman filter for 3D attitude estimation",
JPL convention, their eqs. 187-197; the seed's refs. [33-36]):
    theta'  = -[w_hat x] theta - b_g~ - n_g
    r~'     = v~
    v~'     = -C^T(q_hat) [a_hat x] theta - C^T(q_hat) b_a~ - C^T(q_hat) n_a
    b~'     = -b~ / tau + n_b                    (first-order Gauss-Markov biases, errors.imu)
    x_clk~' = [[0, 1], [0, 0]] x_clk~ + w_clk    (seed 000 eq. 1)
with w_hat = w_m - b_g_hat, a_hat = a_m - b_a_hat. The IMU noises are isotropic, so
C^T n_a has the same covariance as n_a.

Measurement update (seed 000 section II-D/E): pseudoranges z_n = ||r - r_sn|| + c dt_r - c dt_sn
+ v_n (eq. 3) with the tower clocks c dt_sn known; H rows [0_3, 1_sn^T, 0_9, 1, 0]; R =
diag(sigma_n^2); Joseph-form covariance update, valid for any gain (needed when exclusion removes
measurements); the error estimate is injected into the nominal state (attitude by the error
quaternion of eq. 2) and reset to zero. The covariance reset Jacobian (I - [theta/2 x] on the
attitude block) is taken as identity (second order in the correction).

Padding: towers are padded to a static L with a boolean mask; a masked tower gets a zero H row,
a zero innovation and unit R, so it adds nothing to K, S^-1 nu or the NIS (tested).

Everything is pure JAX (float64), jit- and vmap-friendly; ``run_ekf`` is a ``lax.scan``.
"""

from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Array, Bool, Float, Real

from oaraim.constants import C_M_S
from oaraim.geometry.clocks import S_WDT_OCXO_S, S_WDTDOT_OCXO_PER_S, clock_transition

N_ERR = 17
TH, POS, VEL, BG, BA, CLK = (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15),
                             slice(15, 17))


class EkfState(NamedTuple):
    """The filter's nominal state x = [q, r, v, b_g, b_a, x_clk] and the covariance of its
    17-element error state (seed 000 section II-B/C; the module docstring)."""

    q: jnp.ndarray
    """(4,) JPL unit quaternion (scalar last) of the rotation from G (local ENU) to the body."""
    r: jnp.ndarray
    """(3,) position in G (ENU), m."""
    v: jnp.ndarray
    """(3,) velocity in G (ENU), m/s."""
    bg: jnp.ndarray
    """(3,) gyroscope bias, rad/s."""
    ba: jnp.ndarray
    """(3,) accelerometer bias, m/s^2."""
    clk: jnp.ndarray
    """(2,) receiver clock [c dt_r (m), c dt_r_dot (m/s)] (seed 000 eq. 1)."""
    P: jnp.ndarray
    """(17, 17) error-state covariance, order [theta, r, v, b_g, b_a, x_clk]."""


class EkfInputs(NamedTuple):
    """The seed 000 EKF's inputs of one epoch, or stacked over E epochs (a leading axis E on
    every field): the interval's IMU samples ``gyro``, ``accel`` (n, 3) (rad/s, m/s^2), the
    pseudoranges ``z`` (L,) (m), which are ``valid`` (L,) bool, the towers' clocks ``tx_clk_m``
    (L,) = c dt_sn (m) and the pseudorange sigma ``sigma_m`` (scalar or (L,), m)."""

    gyro: jnp.ndarray
    accel: jnp.ndarray
    z: jnp.ndarray
    valid: jnp.ndarray
    tx_clk_m: jnp.ndarray
    sigma_m: jnp.ndarray


class EkfParams(NamedTuple):
    """Model of the filter (all SI). ``gyro_psd``/``accel_psd``: white-noise PSDs (density^2);
    ``*_bias_psd``: GM driving PSDs 2 sigma^2 / tau; ``*_bias_inv_tau``: 1 / tau (0 = random
    walk); clock PSDs of seed 000 eq. 1; ``gravity`` the ENU gravity vector."""

    dt_s: float
    gravity: jnp.ndarray
    gyro_psd: float
    accel_psd: float
    gyro_bias_psd: float
    accel_bias_psd: float
    gyro_bias_inv_tau: float
    accel_bias_inv_tau: float
    s_wdt_s: float = S_WDT_OCXO_S
    s_wdtdot_per_s: float = S_WDTDOT_OCXO_PER_S


def params_from_imu(spec, dt_s, gravity, s_wdt_s=S_WDT_OCXO_S,
                    s_wdtdot_per_s=S_WDTDOT_OCXO_PER_S) -> EkfParams:
    """Filter model matched to an ``errors.ImuSpec`` (the truth model of the synthesis)."""
    return EkfParams(
        dt_s=float(dt_s), gravity=jnp.asarray(gravity, jnp.float64),
        gyro_psd=spec.gyro_noise_rad_s_sqrt_hz**2, accel_psd=spec.accel_noise_m_s2_sqrt_hz**2,
        gyro_bias_psd=2.0 * spec.gyro_bias_sigma_rad_s**2 / spec.gyro_bias_tau_s,
        accel_bias_psd=2.0 * spec.accel_bias_sigma_m_s2**2 / spec.accel_bias_tau_s,
        gyro_bias_inv_tau=1.0 / spec.gyro_bias_tau_s,
        accel_bias_inv_tau=1.0 / spec.accel_bias_tau_s,
        s_wdt_s=s_wdt_s, s_wdtdot_per_s=s_wdtdot_per_s)


# ------------------------------------------------------------------------------------------
# Quaternion algebra (JPL, scalar last; Trawny & Roumeliotis 2005)


def skew(w):
    """[w x], shape (..., 3, 3)."""
    z = jnp.zeros_like(w[..., 0])
    return jnp.stack([jnp.stack([z, -w[..., 2], w[..., 1]], -1),
                      jnp.stack([w[..., 2], z, -w[..., 0]], -1),
                      jnp.stack([-w[..., 1], w[..., 0], z], -1)], -2)


def quat_multiply(q, p):
    """JPL product q (x) p, with C(q (x) p) = C(q) C(p)."""
    qv, qw = q[..., :3], q[..., 3:]
    pv, pw = p[..., :3], p[..., 3:]
    vec = qw * pv + pw * qv - jnp.cross(qv, pv)
    return jnp.concatenate([vec, qw * pw - jnp.sum(qv * pv, -1, keepdims=True)], -1)


def quat_to_dcm(q):
    """C(q) = (2 q_w^2 - 1) I - 2 q_w [q_v x] + 2 q_v q_v^T: maps G coordinates to body ones."""
    qv, qw = q[..., :3], q[..., 3]
    eye = jnp.eye(3)
    return ((2.0 * qw**2 - 1.0)[..., None, None] * eye - 2.0 * qw[..., None, None] * skew(qv)
            + 2.0 * qv[..., :, None] * qv[..., None, :])


def rotation_quat(phi):
    """Exact quaternion of a rotation vector phi (body frame), safe at phi = 0."""
    a2 = jnp.sum(phi * phi, -1, keepdims=True)
    a = jnp.sqrt(a2 + 1e-300)
    small = a2 < 1e-12
    s = jnp.where(small, 0.5 - a2 / 48.0, jnp.sin(a / 2.0) / a)
    c = jnp.where(small, 1.0 - a2 / 8.0, jnp.cos(a / 2.0))
    return jnp.concatenate([s * phi, c], -1)


def error_quat(theta):
    """Error quaternion of seed 000 eq. 2, [theta / 2, sqrt(1 - theta^T theta / 4)], normalized
    (the square root is clamped at 0 for |theta| > 2, far outside the filter's use)."""
    w = jnp.sqrt(jnp.maximum(1.0 - jnp.sum(theta * theta, -1, keepdims=True) / 4.0, 0.0))
    dq = jnp.concatenate([theta / 2.0, w], -1)
    return dq / jnp.linalg.norm(dq, axis=-1, keepdims=True)


def attitude_error(q_true, q_est):
    """theta with q_true = dq(theta) (x) q_est: theta = 2 vec(q_true (x) q_est^-1), sign fixed."""
    inv = jnp.concatenate([-q_est[..., :3], q_est[..., 3:]], -1)
    dq = quat_multiply(q_true, inv)
    return 2.0 * jnp.where(dq[..., 3:] < 0.0, -dq[..., :3], dq[..., :3])


# ------------------------------------------------------------------------------------------
# Time update


def mechanize(q, r, v, bg, ba, gyro, accel, params: EkfParams):
    """One strapdown step over dt with interval-mean IMU samples (flat non-rotating ENU frame).

    q+ = dq(w_hat dt) (x) q; v+ = v + C^T(q_mid) a_hat dt + g dt with q_mid the mid-interval
    attitude; r+ = r + (v + v+) dt / 2 (exact for constant acceleration); biases decay as their
    GM mean. Returns the new nominal values and (w_hat, C^T(q_mid), C^T(q_mid) [a_hat x]), the
    ingredients of the error dynamics A over this step.
    """
    dt = params.dt_s
    w_hat = gyro - bg
    a_hat = accel - ba
    phi = w_hat * dt
    q_new = quat_multiply(rotation_quat(phi), q)
    q_new = q_new / jnp.linalg.norm(q_new, axis=-1, keepdims=True)
    ct_mid = jnp.swapaxes(quat_to_dcm(quat_multiply(rotation_quat(phi / 2.0), q)), -1, -2)
    v_new = v + (ct_mid @ a_hat[..., None])[..., 0] * dt + params.gravity * dt
    r_new = r + 0.5 * (v + v_new) * dt
    bg_new = bg * jnp.exp(-dt * params.gyro_bias_inv_tau)
    ba_new = ba * jnp.exp(-dt * params.accel_bias_inv_tau)
    return (q_new, r_new, v_new, bg_new, ba_new), (w_hat, ct_mid, ct_mid @ skew(a_hat))


def _qmul_c(q, p):
    """``quat_multiply`` on lists of scalar components (see ``_mechanize_c``)."""
    qx, qy, qz, qw = q
    px, py, pz, pw = p
    return [qw * px + pw * qx - (qy * pz - qz * py),
            qw * py + pw * qy - (qz * px - qx * pz),
            qw * pz + pw * qz - (qx * py - qy * px),
            qw * pw - (qx * px + qy * py + qz * pz)]


def _rotq_c(phi):
    """``rotation_quat`` on scalar components."""
    a2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    a = jnp.sqrt(a2 + 1e-300)
    small = a2 < 1e-12
    s = jnp.where(small, 0.5 - a2 / 48.0, jnp.sin(a / 2.0) / a)
    c = jnp.where(small, 1.0 - a2 / 8.0, jnp.cos(a / 2.0))
    return [s * phi[0], s * phi[1], s * phi[2], c]


def _mechanize_interval(state: EkfState, gyro, accel, params: EkfParams):
    """``mechanize`` applied to the n samples of one interval (same formulas), staged for XLA.

    Written on scalar components: under vmap each is a (batch, n) or (batch,) array, so XLA's
    fused loops run over the batch instead of trailing 3 x 3 dimensions. Only the attitude is
    truly sequential; the rest is vectorized over the n samples: the rotation increments (sin,
    cos) before the attitude loop, the mid-interval DCMs, velocity increments and A's
    ingredients after it. In one 100 Hz loop XLA fused the shared sin/cos/quaternion chain into
    each of its ~40 outputs and recomputed it (~20 % of a Monte Carlo drive). Returns the new
    (q, r, v, b_g, b_a) and the interval sums of (w_hat, C^T(q_mid), C^T(q_mid) [a_hat x])."""
    n = gyro.shape[0]
    dt = params.dt_s
    eg = jnp.exp(-dt * params.gyro_bias_inv_tau)
    ea = jnp.exp(-dt * params.accel_bias_inv_tau)
    bgs, bas = [state.bg], [state.ba]
    for _ in range(n):              # the biases' GM mean decay, step by step as in mechanize
        bgs.append(bgs[-1] * eg)
        bas.append(bas[-1] * ea)
    w_hat = gyro - jnp.stack(bgs[:n])
    a_hat = accel - jnp.stack(bas[:n])
    w_c = [w_hat[:, i] for i in range(3)]
    a_c = [a_hat[:, i] for i in range(3)]
    phi = [w * dt for w in w_c]
    dq = _rotq_c(phi)
    dqm = _rotq_c([x / 2.0 for x in phi])

    def att(qc, d):
        # the mid-interval attitude leaves the loop as an output (materialized once)
        qn = _qmul_c(list(d[0]), qc)
        nrm = jnp.sqrt(qn[0] * qn[0] + qn[1] * qn[1] + qn[2] * qn[2] + qn[3] * qn[3])
        return [x / nrm for x in qn], _qmul_c(list(d[1]), qc)

    q_end, (qx, qy, qz, qw) = jax.lax.scan(att, [state.q[i] for i in range(4)], (dq, dqm))
    qv = (qx, qy, qz)
    d = 2.0 * qw**2 - 1.0
    sk = ((None, -qz, qy), (qz, None, -qx), (-qy, qx, None))   # [q_v x]
    # C = d I - 2 q_w [q_v x] + 2 q_v q_v^T; ct = C^T
    cmat = [[(d if i == j else 0.0) - (0.0 if i == j else 2.0 * qw * sk[i][j])
             + 2.0 * qv[i] * qv[j] for j in range(3)] for i in range(3)]
    ct = [[cmat[j][i] for j in range(3)] for i in range(3)]
    dv = jnp.stack([(ct[i][0] * a_c[0] + ct[i][1] * a_c[1] + ct[i][2] * a_c[2]) * dt
                    for i in range(3)], -1)
    g_dt = params.gravity * dt
    v, r = state.v, state.r
    for j in range(n):
        v_new = v + dv[j] + g_dt
        r = r + 0.5 * (v + v_new) * dt
        v = v_new
    ska = ((0.0, -a_c[2], a_c[1]), (a_c[2], 0.0, -a_c[0]), (-a_c[1], a_c[0], 0.0))
    cta = [[sum(ct[i][k] * ska[k][j] for k in range(3) if k != j) for j in range(3)]
           for i in range(3)]
    msum = lambda m: jnp.stack([jnp.stack([x.sum(0) for x in row]) for row in m])  # noqa: E731
    return ((jnp.stack(q_end), r, v, bgs[n], bas[n]),
            (w_hat.sum(0), msum(ct), msum(cta)))


def error_dynamics(w_hat, ct, ct_askew, params: EkfParams):
    """Continuous error-state matrix A (17 x 17) of the module docstring."""
    eye = jnp.eye(3)
    a = jnp.zeros((N_ERR, N_ERR))
    a = a.at[TH, TH].set(-skew(w_hat))
    a = a.at[TH, BG].set(-eye)
    a = a.at[POS, VEL].set(eye)
    a = a.at[VEL, TH].set(-ct_askew)
    a = a.at[VEL, BA].set(-ct)
    a = a.at[BG, BG].set(-params.gyro_bias_inv_tau * eye)
    a = a.at[BA, BA].set(-params.accel_bias_inv_tau * eye)
    a = a.at[15, 16].set(1.0)
    return a


def continuous_noise(params: EkfParams):
    """Diagonal of Q_c = G Q G^T (17,): gyro and accelerometer white noise, GM bias driving
    noise, clock PSDs c^2 S (seed 000 eq. 1); zero for the position."""
    z3, o3 = jnp.zeros(3), jnp.ones(3)
    return jnp.concatenate([
        params.gyro_psd * o3, z3, params.accel_psd * o3, params.gyro_bias_psd * o3,
        params.accel_bias_psd * o3,
        jnp.stack([C_M_S**2 * params.s_wdt_s, C_M_S**2 * params.s_wdtdot_per_s])])


def transition_matrix(a, t_s):
    """Phi = exp(A T) by its Taylor series to third order (exact for nilpotent chains of
    length <= 3)."""
    return _transition(a, a @ a, t_s)


def _transition(a, a2, t_s):
    return jnp.eye(a.shape[-1]) + a * t_s + a2 * (t_s**2 / 2.0) + (a2 @ a) * (t_s**3 / 6.0)


def discrete_process_noise(a, qc_diag, t_s, a2=None):
    """Q_d = int_0^T e^{As} Q_c e^{A^T s} ds to third order in T:
    Q_c T + (A Q_c + Q_c A^T) T^2 / 2 + (A^2 Q_c + 2 A Q_c A^T + Q_c A^T^2) T^3 / 6.
    For the clock block this is exactly seed 000 eq. 1 (symmetric form). ``a2`` = A A if known."""
    a2 = a @ a if a2 is None else a2
    aq = a * qc_diag[None, :]
    a2q = a2 * qc_diag[None, :]
    aqa = aq @ a.T
    q = (jnp.diag(qc_diag) * t_s + (aq + aq.T) * t_s**2 / 2.0
         + (a2q + 2.0 * aqa + a2q.T) * t_s**3 / 6.0)
    return 0.5 * (q + q.T)


_BLOCK_SIZES = (3, 3, 3, 3, 3, 2)  # theta, r, v, b_g, b_a, clock


def _error_blocks(w_hat, ct, ct_askew, params: EkfParams):
    """The nonzero 3 x 3 (2 x 2) blocks of A, keyed by (block row, block column)."""
    eye = jnp.eye(3)
    return {(0, 0): -skew(w_hat), (0, 3): -eye, (1, 2): eye, (2, 0): -ct_askew, (2, 4): -ct,
            (3, 3): -params.gyro_bias_inv_tau * eye, (4, 4): -params.accel_bias_inv_tau * eye,
            (5, 5): jnp.array([[0.0, 1.0], [0.0, 0.0]])}


def _bmul(x, y):
    """Product of two block-sparse matrices (dicts of blocks); only existing blocks multiply."""
    out = {}
    for (i, j), xb in x.items():
        for (j2, k), yb in y.items():
            if j == j2:
                out[(i, k)] = out[(i, k)] + xb @ yb if (i, k) in out else xb @ yb
    return out


def _assemble(terms):
    """Dense 17 x 17 matrix from a list of (coefficient, block dict) terms."""
    rows = []
    for i, ni in enumerate(_BLOCK_SIZES):
        row = []
        for j, nj in enumerate(_BLOCK_SIZES):
            blk = jnp.zeros((ni, nj))
            for c, d in terms:
                if (i, j) in d:
                    blk = blk + c * d[(i, j)]
            row.append(blk)
        rows.append(jnp.concatenate(row, 1))
    return jnp.concatenate(rows, 0)


def transition_and_noise(w_hat, ct, ct_askew, params: EkfParams, t_s):
    """Phi and Q_d of ``transition_matrix`` / ``discrete_process_noise`` (the same third-order
    series) computed on the nonzero blocks of A only; equal to the dense forms to rounding
    (tested) at a fraction of the cost of 17 x 17 matmuls."""
    a = _error_blocks(w_hat, ct, ct_askew, params)
    a2 = _bmul(a, a)
    a3 = _bmul(a2, a)
    eye = {(i, i): jnp.eye(n) for i, n in enumerate(_BLOCK_SIZES)}
    phi = _assemble([(1.0, eye), (t_s, a), (t_s**2 / 2.0, a2), (t_s**3 / 6.0, a3)])
    qc = continuous_noise(params)
    qc_blocks = {}
    off = 0
    for i, n in enumerate(_BLOCK_SIZES):
        qc_blocks[(i, i)] = jnp.diag(qc[off:off + n])
        off += n
    aq = _bmul(a, qc_blocks)
    a2q = _bmul(a2, qc_blocks)
    aqa = _bmul(aq, {(j, i): b.T for (i, j), b in a.items()})
    tr = lambda d: {(j, i): b.T for (i, j), b in d.items()}  # noqa: E731
    qd = _assemble([(t_s, qc_blocks), (t_s**2 / 2.0, aq), (t_s**2 / 2.0, tr(aq)),
                    (t_s**3 / 6.0, a2q), (t_s**3 / 3.0, aqa), (t_s**3 / 6.0, tr(a2q))])
    return phi, 0.5 * (qd + qd.T)


def ekf_predict(state: EkfState, gyro: Float[ArrayLike, "n 3"], accel: Float[ArrayLike, "n 3"],
                params: EkfParams) -> tuple[EkfState, Float[Array, "17 17"]]:
    """Propagate over one measurement interval of n IMU samples (``gyro``, ``accel``: (n, 3)).

    Mechanization at the IMU rate (``_mechanize_interval``), then P <- Phi P Phi^T + Q_d with
    the interval-mean A. Returns ``(state, phi)``; ``phi`` is also what the Xi recursion of
    seed 000 section III-B needs.
    """
    state, phi, _ = ekf_propagate(state, gyro, accel, params)
    return state, phi


def ekf_propagate(state: EkfState, gyro: Float[ArrayLike, "n 3"],
                  accel: Float[ArrayLike, "n 3"], params: EkfParams
                  ) -> tuple[EkfState, Float[Array, "17 17"], Float[Array, "17 17"]]:
    """``ekf_predict`` that also returns the interval's process noise Q_d (17, 17): (state,
    Phi, Q_d). A bank of error-state filters linearised about this state's trajectory
    propagates each member's covariance with the same Phi and Q_d (``araim.filter_monitor``)."""
    n = gyro.shape[0]
    t_int = n * params.dt_s

    (q, r, v, bg, ba), (w_sum, ct_sum, cta_sum) = _mechanize_interval(state, gyro, accel,
                                                                      params)
    phi, qd = transition_and_noise(w_sum / n, ct_sum / n, cta_sum / n, params, t_int)
    p = phi @ state.P @ phi.T + qd
    clk = clock_transition(t_int) @ state.clk
    return EkfState(q, r, v, bg, ba, clk, 0.5 * (p + p.T)), phi, qd


# ------------------------------------------------------------------------------------------
# Measurement update


class UpdateInfo(NamedTuple):
    """What the integrity monitor needs from one update: innovation nu (L,), H (L, 17),
    S^-1 (L, L), gain K (17, L), NIS nu^T S^-1 nu, number of used measurements."""

    nu: jnp.ndarray
    H: jnp.ndarray
    S_inv: jnp.ndarray
    K: jnp.ndarray
    nis: jnp.ndarray
    n_used: jnp.ndarray


def pseudorange_model(r, clk, tx_pos, tx_clk_m):
    """Predicted pseudoranges (seed 000 eq. 3 without noise) and the unit vectors 1_sn.

    ``tx_pos`` (L, 3), ``tx_clk_m`` (L,) = c dt_sn. The Jacobian of section II-E has rows
    [0_3, 1_sn^T, 0_9, 1, 0] with 1_sn = (r_hat - r_sn) / ||r_hat - r_sn|| (``jacobian_rows``).
    """
    d = r - tx_pos
    rng = jnp.linalg.norm(d, axis=-1)
    return rng + clk[0] - tx_clk_m, d / rng[:, None]


def jacobian_rows(u):
    """Dense H (L, 17) of seed 000 section II-E from the unit vectors ``u`` (L, 3)."""
    return jnp.zeros((u.shape[0], N_ERR)).at[:, POS].set(u).at[:, 15].set(1.0)


def spd_inverse(s):
    """Inverse of a small symmetric positive-definite matrix (..., n, n) by the sweep operator
    (Gauss-Jordan without pivoting, stable for SPD), unrolled over the n pivots: elementwise
    batched arithmetic, much cheaper than per-matrix LAPACK calls for n <= 17 on CPU."""
    n = s.shape[-1]
    a = s
    idx = jnp.arange(n)
    for k in range(n):
        d = a[..., k, k][..., None, None]
        col = a[..., :, k][..., :, None]
        row = a[..., k, :][..., None, :]
        upd = a - col * row / d
        is_r = (idx == k)[:, None]
        is_c = (idx == k)[None, :]
        a = jnp.where(is_r & is_c, -1.0 / d,
                      jnp.where(is_r, row / d, jnp.where(is_c, col / d, upd)))
    a = -a
    return 0.5 * (a + jnp.swapaxes(a, -1, -2))


def pr_rows_times(x, u, used):
    """H X for pseudorange rows H = [0_3, u_n^T, 0_9, 1, 0] (masked): u X[r] + X[clock bias],
    shape (L, m) for X (17, m). The seed's H touches only 4 of the 17 columns."""
    return (u @ x[POS] + x[15][None, :]) * used[:, None]


def innovation_covariance(P, u, r_var, used):
    """P H^T (17, L) and S^-1 (L, L) with S = H P H^T + R for pseudorange rows with unit
    vectors ``u`` (L, 3), padding-safe (an unused tower has a zero row and unit R)."""
    pht = pr_rows_times(P, u, used).T
    ru = jnp.where(used, r_var, 1.0)
    s = pr_rows_times(pht, u, used) + jnp.diag(ru)
    return pht, spd_inverse(0.5 * (s + s.T))


def remove_from_inverse(s_inv, i):
    """S^-1 of S with row/column i replaced by the unit vector, from S^-1 (rank-one downdate):
    (S_{-i})^-1 = S^-1 - S^-1 e_i e_i^T S^-1 / (S^-1)_ii on the remaining block. i < 0: no-op."""
    n = s_inv.shape[-1]
    ii = jnp.clip(i, 0, n - 1)
    c = s_inv[:, ii]
    down = s_inv - jnp.outer(c, c) / c[ii]
    e = jnp.arange(n) == ii
    down = jnp.where(e[:, None] | e[None, :], 0.0, down) + jnp.diag(e.astype(s_inv.dtype))
    return jnp.where(i >= 0, down, s_inv)


def inject(state: EkfState, dx, P) -> EkfState:
    """Add the estimated error to the nominal state (attitude by eq. 2's error quaternion)."""
    q = quat_multiply(error_quat(dx[TH]), state.q)
    q = q / jnp.linalg.norm(q)
    return EkfState(q, state.r + dx[POS], state.v + dx[VEL], state.bg + dx[BG],
                    state.ba + dx[BA], state.clk + dx[CLK], P)


def kalman_update(state: EkfState, nu, u, r_var, used, s_inv=None):
    """Kalman update of the error state with pseudorange-type rows and a Joseph-form covariance.

    ``nu`` (L,) innovations z - h(x_hat); ``u`` (L, 3) the position part of each H row (the
    unit vector 1_sn of seed 000 section II-E; any vector for a linear model), the clock-bias
    entry being 1: H = [0_3, u^T, 0_9, 1, 0]; ``r_var`` (L,) variances; ``used`` (L,) bool;
    ``s_inv`` the padded S^-1 of the used set if already known.

    Joseph form P+ = (I - K H) P (I - K H)^T + K R K^T, expanded exactly (for any gain K) as
    P - K (P H^T)^T - (P H^T) K^T + K S K^T = P + [K S - P H^T, -K] [K, P H^T]^T: one rank-2L
    product instead of two 17 x 17 x 17 matmuls (on CPU the cost is writing 17 x 17 outputs).
    It stays valid for the suboptimal gains exclusion produces (tested against the product form).
    Returns ``(state, UpdateInfo)``.
    """
    dx, p, info = error_state_update(state.P, nu, u, r_var, used, s_inv)
    return inject(state, dx, p), info


def error_state_update(P, nu, u, r_var, used, s_inv=None):
    """The error-state part of ``kalman_update`` (same arguments, the covariance ``P`` (17, 17)
    for the state): the correction dx = K nu (17,), the Joseph-form P+ and the ``UpdateInfo``,
    nothing injected. Returns ``(dx, P+, UpdateInfo)``."""
    pht = pr_rows_times(P, u, used).T
    ru = jnp.where(used, r_var, 1.0)
    if s_inv is None:
        _, s_inv = innovation_covariance(P, u, r_var, used)
    s = pr_rows_times(pht, u, used) + jnp.diag(ru)
    nu_u = jnp.where(used, nu, 0.0)
    k = pht @ s_inv
    dx = k @ nu_u
    left = jnp.concatenate([k @ s - pht, -k], 1)
    right = jnp.concatenate([k, pht], 1)
    p = P + left @ right.T
    p = 0.5 * (p + p.T)
    nis = nu_u @ s_inv @ nu_u
    hu = jacobian_rows(u) * used[:, None]
    info = UpdateInfo(nu_u, hu, s_inv, k, nis, jnp.sum(used))
    return dx, p, info


def ekf_update(state: EkfState, z: Float[ArrayLike, " L"], used: Bool[ArrayLike, " L"],
               tx_pos: Float[ArrayLike, "L 3"], tx_clk_m: Float[ArrayLike, " L"],
               sigma_m: Real[ArrayLike, "#L"] | Real[ArrayLike, ""]
               ) -> tuple[EkfState, UpdateInfo]:
    """Pseudorange update (seed 000 section II-E). ``sigma_m`` scalar or (L,)."""
    z_hat, u = pseudorange_model(state.r, state.clk, tx_pos, tx_clk_m)
    r_var = jnp.broadcast_to(jnp.asarray(sigma_m, jnp.float64) ** 2, z_hat.shape)
    return kalman_update(state, z - z_hat, u, r_var, used)


def ekf_step(state: EkfState, inputs: EkfInputs, tx_pos: Float[ArrayLike, "L 3"],
             params: EkfParams) -> tuple[EkfState, UpdateInfo]:
    """Predict over one interval of IMU samples, then update with that epoch's pseudoranges
    (``inputs`` one epoch's ``EkfInputs``: gyro, accel (n, 3); z, valid (the towers used),
    tx_clk_m (L,); sigma_m scalar or (L,))."""
    state, _ = ekf_predict(state, inputs.gyro, inputs.accel, params)
    return ekf_update(state, inputs.z, inputs.valid, tx_pos, inputs.tx_clk_m, inputs.sigma_m)


def ekf_init(q: Real[ArrayLike, "4"] | Sequence[float],
             r: Real[ArrayLike, "3"] | Sequence[float],
             v: Real[ArrayLike, "3"] | Sequence[float],
             bg: Real[ArrayLike, "3"] | Sequence[float],
             ba: Real[ArrayLike, "3"] | Sequence[float],
             clk: Real[ArrayLike, "2"] | Sequence[float],
             P: Real[ArrayLike, "17 17"]) -> EkfState:
    """Initial state (arrays coerced to float64)."""
    f = lambda x: jnp.asarray(x, jnp.float64)  # noqa: E731
    return EkfState(f(q), f(r), f(v), f(bg), f(ba), f(clk), f(P))


class EkfOutput(NamedTuple):
    """Per-epoch outputs of ``run_ekf``: the posterior nominal state, covariance, NIS."""

    q: jnp.ndarray
    r: jnp.ndarray
    v: jnp.ndarray
    bg: jnp.ndarray
    ba: jnp.ndarray
    clk: jnp.ndarray
    P: jnp.ndarray
    nis: jnp.ndarray
    n_used: jnp.ndarray


def run_ekf(state0: EkfState, inputs: EkfInputs, tx_pos: Float[ArrayLike, "L 3"],
            params: EkfParams) -> tuple[EkfState, EkfOutput]:
    """Run the EKF over E epochs with ``lax.scan``.

    ``inputs``: ``EkfInputs`` stacked over E epochs: ``gyro``, ``accel`` (E, n, 3) IMU samples
    of each interval (n per pseudorange epoch); ``z``, ``valid``, ``tx_clk_m`` (E, L);
    ``sigma_m`` scalar, (L,) or (E, L). ``tx_pos``: (L, 3). Returns (final state, EkfOutput
    stacked over epochs).
    """
    sigma = jnp.broadcast_to(jnp.asarray(inputs.sigma_m, jnp.float64), inputs.z.shape)

    def body(state, inp):
        state, info = ekf_step(state, inp, tx_pos, params)
        return state, EkfOutput(*state, info.nis, info.n_used)

    return jax.lax.scan(body, state0, inputs._replace(sigma_m=sigma))
