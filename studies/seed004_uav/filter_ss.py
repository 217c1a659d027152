"""``--set monitor=filter-ss`` of seed004-uav: the solution-separation filter bank
(docs/filter-integrity.md) on the flight's GPS + all-SOP pseudoranges, beside the snapshot MHSS.

A UAV has no IMU here: each filter is a linear Kalman filter with a constant-velocity model in
the flight's ENU frame at its origin, state [E, N, U, v_E, v_N, v_U, one clock per clock group],
white acceleration of PSD ``ACCEL_PSD`` per axis (our choice: a small UAV's manoeuvres) and
clocks as random walks of PSD ``CLOCK_PSD`` (free from epoch to epoch: the towers' clock
residuals are not modelled). Each epoch's pseudoranges are linearised at the epoch's snapshot
all-in-view WNLS solution (``araim.snapshot.replay``), the same point for every filter of the
bank: z' = z - h(x_wls) + G x_wls = G x + clock + (second-order terms, below 1 mm for metre
differences at the towers' kilometre ranges). The fault modes, priors and budget are the
study's (Table I, ``fault_modes``), the PLs come from ``araim.run_linear_monitor``."""

from typing import NamedTuple

import numpy as np

from oaraim import araim, geometry, mc

#: white-acceleration PSD of the constant-velocity model, m^2/s^3 per axis (our choice)
ACCEL_PSD = 1.0
#: random-walk PSD of each clock group, m^2/s (large: the clocks are re-estimated each epoch)
CLOCK_PSD = 1e6
#: the common diffuse prior, m^2 and (m/s)^2
PRIOR_VAR = 1e12


def constant_velocity_model(dt_s, g_enu, cons, n_groups, var_m2):
    """``araim.LinearModel`` (E epochs) of the module docstring: ``dt_s`` (E,), rows ``g_enu``
    (E, L, 3), clock-group labels ``cons`` (L,), variances ``var_m2`` (E, L)."""
    e, l_ = g_enu.shape[:2]
    n = 6 + n_groups
    phi = np.broadcast_to(np.eye(n), (e, n, n)).copy()
    q = np.zeros((e, n, n))
    for a in range(3):
        phi[:, a, 3 + a] = dt_s
        q[:, a, a] = ACCEL_PSD * dt_s**3 / 3.0
        q[:, a, 3 + a] = q[:, 3 + a, a] = ACCEL_PSD * dt_s**2 / 2.0
        q[:, 3 + a, 3 + a] = ACCEL_PSD * dt_s
    for c in range(n_groups):
        q[:, 6 + c, 6 + c] = CLOCK_PSD * dt_s
    h = np.zeros((e, l_, n))
    h[:, :, :3] = g_enu
    h[:, np.arange(l_), 6 + cons] = 1.0
    return araim.LinearModel(phi, q, h, var_m2)


class FlightPseudoranges(NamedTuple):
    """The flight's pseudoranges as the study holds them (E epochs, L sources): ``pr`` (m),
    their corrections ``corr`` (m), variances ``var_int`` (m^2) and the sources ``use``d
    (bool)."""

    pr: np.ndarray
    corr: np.ndarray
    var_int: np.ndarray
    use: np.ndarray


def filter_monitor(geom, meas: FlightPseudoranges, sources: araim.filter_monitor.BankSources,
                   x0, options: araim.filter_monitor.BankOptions, hal_m):
    """The bank over the flight (GPS + the SOPs of ``meas.use``; ``sources`` the clock-group
    labels and priors, ``options`` the budget, fault-mode convention and the order the snapshot
    MHSS needed): per-epoch HPE, HPL and alert of the filter, and the summary (JSON values)."""
    pr, corr, var_int, use = meas
    cons, p_sat, p_const = sources
    max_order = options.max_order
    r = araim.snapshot.replay(pr, geom.tx_pos_m, araim.snapshot.ReplaySources(
                                  var_int, var_int, use, constellation=cons), geom.truth_m,
                              p_const=p_const, correction_m=corr, x0_m=x0,
                              config=araim.snapshot.ReplayConfig(monitors=("slope",)))
    pos = np.asarray(r.wnls.position_m)
    ok = np.asarray(r.wnls.status) == 0
    used = np.asarray(r.used) & ok[:, None]
    lat, lon, _ = geometry.ecef_to_geodetic(geom.origin_ecef_m)
    rot = np.asarray(geometry.enu_rotation(lat, lon))
    d = pos[:, None, :] - geom.tx_pos_m
    u = d / np.maximum(np.linalg.norm(d, axis=-1), 1e-9)[..., None]
    g = u @ rot.T                                   # rows in the origin's ENU frame
    x_enu = (pos - geom.origin_ecef_m) @ rot.T
    truth_enu = (geom.truth_m - geom.origin_ecef_m) @ rot.T
    clk = np.asarray(r.wnls.clock_m)
    z = (np.where(used, np.asarray(r.wnls.residual_m), 0.0) + np.sum(g * x_enu[:, None], -1)
         + np.take_along_axis(clk, np.broadcast_to(cons, used.shape), 1))
    z = np.where(used, z, 0.0)
    dt = np.diff(geom.t_s, prepend=geom.t_s[0] - (geom.t_s[1] - geom.t_s[0]))
    n_c = p_const.size
    model = constant_velocity_model(dt, np.where(used[..., None], g, 0.0), cons, n_c,
                                    np.where(used, var_int, 1.0))
    n = 6 + n_c
    _, out = araim.run_linear_monitor(
        np.zeros(n), PRIOR_VAR * np.eye(n), model, z, used,
        araim.filter_monitor.BankSources(cons, np.broadcast_to(p_sat, used.shape), p_const),
        options)
    hpl = np.asarray(out.hpl_m)
    hpe = np.linalg.norm(np.asarray(out.position_m)[:, :2] - truth_enu[:, :2], axis=1)
    alert = np.asarray(out.alert)
    fin = np.isfinite(hpl)
    mi = int(np.sum(fin & (hpe > hpl) & ~alert))
    return hpl, hpe, alert, {
        "epochs": int(hpl.size), "finite_hpl_epochs": int(fin.sum()),
        "mean_hpl_m": float(np.mean(hpl[fin])) if fin.any() else float("inf"),
        "median_hpe_m": float(np.median(hpe)),
        "misleading_epochs": mc.rate_with_interval(mi, int(fin.sum())),
        "alerts": int(alert.sum()), "max_order": int(max_order),
        "status_counts": dict(zip(*(x.tolist() for x in np.unique(
            np.asarray(out.status).astype(int), return_counts=True)), strict=True)),
        "available_pct": 100.0 * float(np.mean(hpl <= hal_m)),
        "accel_psd_m2_s3": ACCEL_PSD, "clock_psd_m2_s": CLOCK_PSD}


def filter_rows(fs, hpl_snapshot, hal_m):
    """Summary rows of the filter bank beside the snapshot MHSS of the same configuration."""
    fin = np.isfinite(hpl_snapshot)
    snap = float(np.mean(hpl_snapshot[fin])) if fin.any() else float("inf")
    m = fs["misleading_epochs"]
    return [
        {"quantity": "mean HPL, filter solution separation, GPS + all SOPs", "unit": "m",
         "published": None, "reproduced": fs["mean_hpl_m"],
         "note": f"constant-velocity filter bank (docs/filter-integrity.md); snapshot MHSS of "
                 f"the same sources {snap:.3g} m; available at HAL {hal_m:g} m: "
                 f"{fs['available_pct']:.3g} %"},
        {"quantity": "HPE > HPL without alert, filter solution separation, GPS + all SOPs",
         "unit": "-", "published": None, "reproduced": m["rate"],
         "note": f"{m['count']} of {m['trials']} epochs, 95 % CI [{m['ci_low']:.2g}, "
                 f"{m['ci_high']:.2g}]; alerts {fs['alerts']}; median HPE "
                 f"{fs['median_hpe_m']:.3g} m"}]
