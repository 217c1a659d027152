"""Receiver and transmitter clocks of the LTE + IMU drives (seed 000 sections II-A and II-D).

Receiver clock: the state x_clk = [c dt_r, c dt_r_dot] is a double integrator driven by two
independent white noises with power spectral densities S_wdt (bias, seconds) and S_wdtdot
(drift, 1/s) (seed 000 eq. 1, after Barnes et al. 1971). Its exact discretization over a step T
is F_clk = [[1, T], [0, 1]] and

    Q_clk = c^2 [[S_wdt T + S_wdtdot T^3 / 3, S_wdtdot T^2 / 2],
                 [S_wdtdot T^2 / 2,           S_wdtdot T      ]].

The seed prints S_wdt T^2 / 2 in the upper-right corner; the integral is symmetric and both
off-diagonal terms are S_wdtdot T^2 / 2 (DESIGN.md, "Where the seeds are wrong").

Tower clocks: first-order polynomials dt_s(t) = dt_s0 + dt_s_dot t (seed 000 after eq. 3), whose
coefficients the receiver calibrated while GNSS was available, so they are known to the filter.

All functions are pure JAX, float64, and broadcast over leading batch axes.
"""

import jax
import jax.numpy as jnp

from oaraim.constants import C_M_S

#: OCXO of the NI USRP-2954R of seed 000 section IV-A: clock-bias process-noise PSD, seconds
S_WDT_OCXO_S = 1.3e-22
#: OCXO of seed 000 section IV-A: clock-drift process-noise PSD, 1/s
S_WDTDOT_OCXO_PER_S = 7.89e-25


def clock_transition(t_s):
    """F_clk of seed 000 eq. (1), shape ``(..., 2, 2)``."""
    t_s = jnp.asarray(t_s, jnp.float64)
    one, zero = jnp.ones_like(t_s), jnp.zeros_like(t_s)
    return jnp.stack([jnp.stack([one, t_s], -1), jnp.stack([zero, one], -1)], -2)


def clock_process_noise(t_s, s_wdt_s=S_WDT_OCXO_S, s_wdtdot_per_s=S_WDTDOT_OCXO_PER_S):
    """Q_clk of seed 000 eq. (1) in m^2 and (m/s)^2, exact and symmetric, shape ``(..., 2, 2)``."""
    t = jnp.asarray(t_s, jnp.float64)
    c2 = C_M_S**2
    q00 = c2 * (s_wdt_s * t + s_wdtdot_per_s * t**3 / 3.0)
    q01 = c2 * s_wdtdot_per_s * t**2 / 2.0
    q11 = c2 * s_wdtdot_per_s * t
    return jnp.stack([jnp.stack([q00, q01], -1), jnp.stack([q01, q11], -1)], -2)


def clock_step_normals(normals, x_clk_m, t_s, s_wdt_s=S_WDT_OCXO_S,
                       s_wdtdot_per_s=S_WDTDOT_OCXO_PER_S):
    """``clock_step`` with two standard normals given (..., 2): x <- F_clk x + chol(Q_clk) n,
    with the 2 x 2 Cholesky factor written out."""
    q = clock_process_noise(t_s, s_wdt_s, s_wdtdot_per_s)
    l00 = jnp.sqrt(q[..., 0, 0])
    l10 = q[..., 1, 0] / l00
    l11 = jnp.sqrt(q[..., 1, 1] - l10**2)
    w0 = l00 * normals[..., 0]
    w1 = l10 * normals[..., 0] + l11 * normals[..., 1]
    t = jnp.asarray(t_s, jnp.float64)
    return jnp.stack([x_clk_m[..., 0] + t * x_clk_m[..., 1] + w0, x_clk_m[..., 1] + w1], -1)


def clock_step(key, x_clk_m, t_s, s_wdt_s=S_WDT_OCXO_S, s_wdtdot_per_s=S_WDTDOT_OCXO_PER_S):
    """One exact receiver-clock step x <- F_clk x + w, w ~ N(0, Q_clk); ``x`` is (..., 2)."""
    normals = jax.random.normal(key, jnp.shape(x_clk_m), jnp.float64)
    return clock_step_normals(normals, x_clk_m, t_s, s_wdt_s, s_wdtdot_per_s)


def tower_clock_m(t_s, bias0_s, drift):
    """c dt_s(t) of the towers: first-order polynomial (seed 000 after eq. 3), in metres.

    ``bias0_s`` (s) and ``drift`` (s/s) have shape ``(..., L)``; ``t_s`` broadcasts against them.
    """
    return C_M_S * (jnp.asarray(bias0_s) + jnp.asarray(drift) * jnp.asarray(t_s))
