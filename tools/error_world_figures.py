"""Figures of the simulated error world (docs/error-world.md): the multipath autocorrelation
against its Gauss-Markov closed form, NLOS episodes of one drive, and the tower-clock residual
after the GNSS period. Run from the repository root:

    python tools/error_world_figures.py [OUT_DIR]     # default docs/img

Every curve is drawn from ``oaraim.sim`` at the ``sim.ErrorModel()`` defaults (fixed keys), so
the figures change only when the world does.
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

from oaraim import errors, sim
from oaraim.sim import measurement as m

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def multipath_acf(ax, err):
    """Sample autocorrelation of the multipath (2,000 chains x 600 s at 10 Hz) vs
    sigma^2 exp(-lag / tau)."""
    n, dt, steps = 2000, 0.1, 6000
    key = jax.random.key(1)
    x0 = err.mp_sigma_m * jax.random.normal(key, (n,))

    def body(x, k):
        x = m.multipath_step(x, jax.random.normal(k, (n,)), err, dt)
        return x, x

    _, xs = jax.lax.scan(body, x0, jax.random.split(jax.random.fold_in(key, 1), steps))
    xs = np.asarray(xs)
    lags = np.arange(0, 400, 10)
    acf = [np.mean(xs[:steps - lag] * xs[lag:]) for lag in lags]
    ax.plot(lags * dt, acf, "o", ms=3, label="simulated (2,000 towers x 600 s)")
    tt = np.linspace(0, lags[-1] * dt, 200)
    ax.plot(tt, err.mp_sigma_m**2 * np.exp(-tt / err.mp_tau_s), "k-", lw=1,
            label=f"sigma^2 exp(-lag/tau), sigma {err.mp_sigma_m:g} m, tau {err.mp_tau_s:g} s")
    ax.set_xlabel("lag (s)")
    ax.set_ylabel("autocovariance (m^2)")
    ax.set_title("short-delay multipath (Gauss-Markov)", fontsize=9)
    ax.legend(fontsize=7)


def nlos_episodes(ax, err):
    """The SOP error of 5 towers over 1,200 s at 10 Hz (``sim.sop_errors``), NLOS marked."""
    t = jnp.arange(1, 12001) * 0.1
    t_cal = -jnp.arange(300)[::-1] * 1.0
    errs, _ = sim.sop_errors(jax.random.key(6), err._replace(fault_onset_s=np.inf), t, 5, t_cal)
    e = np.asarray(errs)
    for j in range(5):
        ax.plot(np.asarray(t), e[:, j] + 25 * j, lw=0.4)
    ax.set_xlabel("time after the GNSS period (s)")
    ax.set_ylabel("SOP error + 25 m x tower (m)")
    ax.set_title(f"pseudorange errors of 5 towers: NLOS episodes (rate 1/"
                 f"{1 / err.nlos_rate_per_s:.0f} s, {err.nlos_duration_s:g} s, mean "
                 f"{err.nlos_bias_m:g} m) on multipath, clock and noise", fontsize=8)


def clock_residual(ax, err):
    """Tower-clock residual after the least-squares fit over the GNSS period: the clock part
    (epsilon_n + common term - fit) of 500 runs, its 5-95 % band over time."""
    setup = sim.drive_setup(sim.drive_seed000(), duration_s=20.0)
    keys = jax.random.split(jax.random.key(9), 500)
    d = jax.vmap(lambda k: sim.initial_draw(k, setup, err))(keys)
    t = np.linspace(0, 600, 121)
    fit = np.asarray(d.world.clk_fit_m)[:, 0, :]  # tower 1: [value at 0, slope]
    res = -(fit[:, 0][:, None] + fit[:, 1][:, None] * t[None])
    lo, med, hi = np.percentile(res, [5, 50, 95], axis=0)
    ax.fill_between(t, lo, hi, color="0.8", label="5-95 % of 500 runs")
    ax.plot(t, med, "k-", lw=1, label="median")
    ax.set_xlabel("time after the GNSS period (s)")
    ax.set_ylabel("- fitted line (m)")
    ax.set_title(f"tower-clock fit error extrapolated (GNSS period {err.calib_window_s:g} s)",
                 fontsize=9)
    ax.legend(fontsize=7)


def main(out_dir="docs/img"):
    """Write the three PNGs into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    err = errors.ErrorModel()
    paths = []
    for name, fn, size in (("multipath-acf", multipath_acf, (5, 3)),
                           ("nlos-episodes", nlos_episodes, (8, 3.6)),
                           ("clock-residual", clock_residual, (5, 3))):
        fig, ax = plt.subplots(figsize=size)
        fn(ax, err)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        paths.append(out / f"error-world-{name}.png")
        fig.savefig(paths[-1], dpi=90)
        plt.close(fig)
    return paths


if __name__ == "__main__":
    print(*main(*sys.argv[1:]), sep="\n")
