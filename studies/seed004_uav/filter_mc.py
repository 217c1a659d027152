"""The filter-integrity study's UAV part: Monte Carlo of the solution-separation filter bank
of ``filter_ss`` (the seed004-uav ``monitor=filter-ss`` option) on the seed 004 flight's
geometry, the filter told the truth (docs/filter-integrity.md, "The UAV flight in the study")."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import araim, geometry, sim
from oaraim.studies.seed004_uav.filter_ss import PRIOR_VAR, constant_velocity_model
from oaraim.studies.seed004_uav.study import Seed004Uav, labels, model_variances, synthesize


class UavBankSetup(NamedTuple):
    """The bank on the seed 004 flight's geometry (E epochs, L sources): the constant-velocity
    ``model`` linearised on the flight's path (rows from the true positions), the sources
    ``used`` (E, L), ``sources`` (labels and priors), ``options`` (budget, the order the
    snapshot MHSS needs, fault modes), the epoch times ``t_s`` (E,), the sources a fault may hit
    ``faultable`` (L,) (in view the whole flight), their priors ``p_s`` (L,) and ``ids`` (L,)
    ("G08", ..., "T1", ...)."""

    model: araim.LinearModel
    used: np.ndarray
    sources: araim.filter_monitor.BankSources
    options: araim.filter_monitor.BankOptions
    t_s: np.ndarray
    faultable: np.ndarray
    p_s: np.ndarray
    ids: np.ndarray


def uav_setup(n_epochs, nav="auto"):
    """``UavBankSetup`` of the seed004-uav study's flight at its defaults (synthesized, GPS + all
    11 SOPs of 3 operators, ``grouped`` fault modes at the order the snapshot MHSS needs) with
    ``n_epochs`` epochs over the 220 s flight and the GPS sky ``nav`` (the study's parameter)."""
    study = Seed004Uav()
    params = study.validate({"n_epochs": n_epochs, "world": "clean", "nav": nav})
    geom, *_ = synthesize(params, 0)
    var_int, _ = model_variances(geom, params)
    cons, names = labels(geom)
    p_const = np.array([params["p_const"]] + [params["p_const_sop"]] * (len(names) - 1))
    p_s = np.where(geom.is_gps, params["p_sat"], params["p_s_sop"])
    used = np.asarray(geom.valid, bool)
    e = used.shape[0]
    order = int(araim.required_order(
        jnp.asarray(used), jnp.asarray(np.broadcast_to(cons, used.shape)),
        jnp.asarray(np.broadcast_to(p_s, used.shape)),
        jnp.asarray(np.broadcast_to(p_const, (e, p_const.size))),
        araim.BUDGET_SEED004_TABLE_I, fault_modes=params["fault_modes"]))
    lat, lon, _ = geometry.ecef_to_geodetic(geom.origin_ecef_m)
    rot = np.asarray(geometry.enu_rotation(lat, lon))
    d = geom.truth_m[:, None, :] - geom.tx_pos_m
    u = d / np.maximum(np.linalg.norm(d, axis=-1), 1e-9)[..., None]
    g = np.where(used[..., None], u @ rot.T, 0.0)
    dt = np.diff(geom.t_s, prepend=geom.t_s[0] - (geom.t_s[1] - geom.t_s[0]))
    model = constant_velocity_model(dt, g, cons, len(names), np.where(used, var_int, 1.0))
    return UavBankSetup(
        model, used, araim.filter_monitor.BankSources(cons, np.broadcast_to(p_s, used.shape),
                                                      p_const),
        araim.filter_monitor.BankOptions(araim.BUDGET_SEED004_TABLE_I, order,
                                         params["fault_modes"]),
        np.asarray(geom.t_s, float), used.all(axis=0), p_s, np.asarray(geom.ids).astype(str))


def _filter_model(setup: UavBankSetup, sigma_scale):
    """The bank's model: the truth's, its pseudorange variances times ``sigma_scale``^2 (< 1:
    the filters believe their measurements better than they are, an injected model error)."""
    m = setup.model
    return m._replace(r_var=jnp.asarray(m.r_var) * jnp.asarray(sigma_scale) ** 2)


def uav_run_detail(key, setup: UavBankSetup, fault, sigma_scale=1.0):
    """One Monte Carlo run on the flight (jit/vmap over ``key`` and ``fault``, a
    ``sim.FaultScenario`` whose source indexes the flight's sources): the vehicle's deviation
    from the flight path follows the bank's own model from zero (white acceleration, clock
    random walks), the pseudoranges its rows plus white noise of the model's variances plus the
    fault; the bank (``araim.run_linear_monitor``, diffuse prior) is the filter told the truth
    (its variances times ``sigma_scale``^2). Returns (the true deviation (E, n), the bank's
    ``FilterMonitorEpoch`` stacked over E epochs, injected bias (E, L))."""
    m = setup.model
    e, n = m.phi.shape[0], m.phi.shape[1]
    k_w, k_v = jax.random.split(key)
    chol = jnp.linalg.cholesky(jnp.asarray(m.q) + 1e-12 * jnp.eye(n))
    w = jnp.einsum("eij,ej->ei", chol, jax.random.normal(k_w, (e, n)))

    def step(x, inp):
        phi, wk = inp
        x = phi @ x + wk
        return x, x

    _, x_true = jax.lax.scan(step, jnp.zeros(n), (jnp.asarray(m.phi), w))
    noise = jnp.sqrt(jnp.asarray(m.r_var)) * jax.random.normal(k_v, m.r_var.shape)
    bias = sim.fault_profile_m(jnp.asarray(setup.t_s), fault, setup.used.shape[1])
    z = jnp.einsum("eln,en->el", jnp.asarray(m.h), x_true) + noise + bias
    z = jnp.where(setup.used, z, 0.0)
    _, out = araim.run_linear_monitor(jnp.zeros(n), PRIOR_VAR * jnp.eye(n),
                                      _filter_model(setup, sigma_scale), z,
                                      jnp.asarray(setup.used), setup.sources, setup.options)
    return x_true, out, bias


def uav_run(key, setup: UavBankSetup, fault):
    """One Monte Carlo run on the flight (``uav_run_detail``, the filter told the truth).
    Returns per-epoch (HPE (E,), HPL (E,), alert (E,), injected bias (E, L))."""
    x_true, out, bias = uav_run_detail(key, setup, fault)
    hpe = jnp.linalg.norm(out.position_m[:, :2] - x_true[:, :2], axis=-1)
    return hpe, out.hpl_m, out.alert, bias


# ------------------------------------------------------------------------------------------
# The conditional risk estimate (docs/filter-integrity.md, "The conditional risk estimate")


def main_covariance(setup: UavBankSetup, sigma_scale=1.0):
    """The main filter's horizontal position covariance P_0,HH (E, 2, 2), m^2, as the bank
    computes it (the filter's model, ``sigma_scale`` as in ``uav_run_detail``; the linear
    bank's covariances do not depend on the measurements)."""
    m = _filter_model(setup, sigma_scale)
    n = m.phi.shape[1]

    def step(p, inp):
        phi, q, h, r_var, used = inp
        p = phi @ p @ phi.T + q
        _, p = araim.filter_monitor.linear_update(jnp.zeros(n), p, h, jnp.zeros(h.shape[0]),
                                                  r_var, used)
        return p, p[:2, :2]

    _, p_h = jax.lax.scan(step, PRIOR_VAR * jnp.eye(n), (
        jnp.asarray(m.phi), jnp.asarray(m.q), jnp.asarray(m.h), jnp.asarray(m.r_var),
        jnp.asarray(setup.used)))
    return p_h


def fault_response(setup: UavBankSetup, fault, sigma_scale=1.0):
    """The bank on ``fault``'s profile alone (no noise, zero prior mean): the deterministic
    part r_i of every filter's error. Returns its ``FilterMonitorEpoch`` over E epochs:
    ``position_m`` (E, 3) is r_0, ``separation_m`` (E, K, 3) is r_i - r_0; the HPL, sigma_ss
    and thresholds are the bank's whatever the measurements."""
    m = _filter_model(setup, sigma_scale)
    n = m.phi.shape[1]
    bias = sim.fault_profile_m(jnp.asarray(setup.t_s), fault, setup.used.shape[1])
    _, out = araim.run_linear_monitor(jnp.zeros(n), PRIOR_VAR * jnp.eye(n), m,
                                      jnp.where(setup.used, bias, 0.0), jnp.asarray(setup.used),
                                      setup.sources, setup.options)
    return out


def epoch_risks(setup: UavBankSetup, fault, p0_h, magnitudes, hpl_fraction=1.0,
                sigma_scale=1.0):
    """P(A_k) of eq. (1) (``araim.filter_risk.epoch_risk_bound``) at every epoch for the
    fault ``fault`` scaled by each of ``magnitudes`` (G,) (the response is linear in the
    magnitude: one bank run), against ``hpl_fraction`` x HPL. ``p0_h`` from
    ``main_covariance``. Returns ``araim.filter_risk.EpochRisk`` of shape (G, E)."""
    return _risks(fault_response(setup, fault, sigma_scale), p0_h, magnitudes, hpl_fraction)


def _risks(out, p0_h, magnitudes, hpl_fraction):
    """``epoch_risks`` from the bank's response ``out`` (``fault_response``)."""
    g = jnp.asarray(magnitudes, jnp.float64)[:, None]
    return araim.filter_risk.epoch_risk_bound(
        p0_h[None], g[..., None] * out.position_m[None, :, :2], hpl_fraction * out.hpl_m[None],
        g[..., None, None] * out.separation_m[None], out.sigma_ss_m[None], out.threshold_m[None])


def _draw_risk(setup, p0_h, nodes, weights, ramp, source, onset):
    """(sum over at-risk epochs of E_m[P(A_k)], at-risk epochs, max over m and k of P(A_k))
    of one drawn source and onset, the magnitude integrated by the quadrature (nodes,
    weights); ``ramp`` 0 a step, 1 a ramp."""
    unit = sim.FaultScenario(source, onset, 1.0 - ramp, ramp)
    r = epoch_risks(setup, unit, p0_h, nodes).p_hmi_bound  # (G, E)
    risk = jnp.asarray(setup.t_s) >= onset
    per_epoch = jnp.sum(weights[:, None] * r, axis=0)
    return (jnp.sum(jnp.where(risk, per_epoch, 0.0)), jnp.sum(risk),
            jnp.max(jnp.where(risk[None], r, 0.0)))


#: runs per compiled call of ``conditional_risk``
DRAW_BATCH = 16
_DRAW_KERNELS = {}


def _draw_kernel(setup: UavBankSetup):
    """The jitted, vmapped ``_draw_risk`` of ``setup`` (one per setup object, kept with it)."""
    entry = _DRAW_KERNELS.get(id(setup))
    if entry is None or entry[0] is not setup:
        fn = jax.jit(jax.vmap(lambda p0, nd, w, rp, s, o: _draw_risk(setup, p0, nd, w, rp, s, o),
                              in_axes=(None, None, None, None, 0, 0)))
        entry = _DRAW_KERNELS[id(setup)] = (setup, fn)
    return entry[1]


class ConditionalRisk(NamedTuple):
    """The conditional estimate of one fault scenario on the flight: per drawn (source,
    onset) the sum over its at-risk epochs of P(A_k) averaged over the magnitude prior
    (``sum_risk`` (n,)), the at-risk epochs (``n_at_risk`` (n,)), the largest P(A_k) over the
    magnitude nodes and epochs (``worst`` (n,)), and the draws' log likelihood ratios
    (``log_weight`` (n,), prior / proposal)."""

    sum_risk: np.ndarray
    n_at_risk: np.ndarray
    worst: np.ndarray
    log_weight: np.ndarray
    source: np.ndarray
    onset_s: np.ndarray


def conditional_risk(setup: UavBankSetup, kind, sources, onsets_s, size_range, log_weight=None,
                     n_nodes=araim.filter_risk.MAGNITUDE_NODES):
    """``ConditionalRisk`` of the drawn ``sources`` (n,) and ``onsets_s`` (n,) of a ``kind``
    ('step': ``size_range`` the step in m; 'ramp': the slope in m/s), the magnitude
    log-uniform in ``size_range`` integrated by ``n_nodes`` Gauss-Legendre nodes in log m
    (``araim.filter_risk.log_uniform_nodes``); ``log_weight`` the draws' log prior / proposal
    (None: drawn from the prior)."""
    nodes, weights = araim.filter_risk.log_uniform_nodes(size_range[0], size_range[1], n_nodes)
    ramp = {"step": 0.0, "ramp": 1.0}[kind]
    p0_h = main_covariance(setup)
    fn = _draw_kernel(setup)
    src = np.asarray(sources, int)
    on = np.asarray(onsets_s, float)
    n, b = src.size, DRAW_BATCH
    pad = -n % b
    src_p, on_p = np.concatenate([src, np.repeat(src[:1], pad)]), np.concatenate(
        [on, np.repeat(on[:1], pad)])
    outs = [np.concatenate(x)[:n] for x in zip(*[
        [np.asarray(a) for a in fn(p0_h, jnp.asarray(nodes), jnp.asarray(weights), ramp,
                                   jnp.asarray(src_p[i:i + b]), jnp.asarray(on_p[i:i + b]))]
        for i in range(0, src_p.size, b)], strict=True)]
    lw = np.zeros(src.size) if log_weight is None else np.asarray(log_weight, float)
    return ConditionalRisk(outs[0], outs[1], outs[2], lw, src, on)


def fault_free_risk(setup: UavBankSetup, hpl_fraction=1.0, sigma_scale=1.0):
    """Eq. (1) without a fault at every epoch (E,): P(|n_0,H| > HPL) times the smallest
    probability of no alert; exact given the model, no sampling."""
    p0_h = main_covariance(setup, sigma_scale)
    return epoch_risks(setup, sim.no_fault(), p0_h, jnp.ones(1), hpl_fraction,
                       sigma_scale).p_hmi_bound[0]


def validation_counts(key, setup: UavBankSetup, fault, hpl_fraction, sigma_scale=1.0):
    """One run checked against eq. (1) where crude Monte Carlo resolves it: the HPL scaled by
    ``hpl_fraction`` < 1. Per at-risk epoch the event B_k = {|e_0,H| > c HPL} and {|Delta_i*,
    q*| <= T_i*,q*} ((i*, q*) the argmin of eq. (1), the event whose probability eq. (1) is,
    exactly, under the model) is counted in the run (``uav_run_detail``) and its probability
    summed; also the event {|e_0,H| > c HPL and no alert}, which eq. (1) bounds, and eq. (1)
    itself (c = 1) summed over the run and its largest value. Returns (observed B, expected B,
    observed HMI at c, at-risk epochs, sum of P(A_k), largest P(A_k))."""
    x_true, out, _ = uav_run_detail(key, setup, fault, sigma_scale)
    p0_h = main_covariance(setup, sigma_scale)
    resp = fault_response(setup, fault, sigma_scale)
    er = jax.tree.map(lambda a: a[0], _risks(resp, p0_h, jnp.ones(1), hpl_fraction))
    e0 = jnp.linalg.norm(out.position_m[:, :2] - x_true[:, :2], axis=-1)
    outside = e0 > hpl_fraction * out.hpl_m
    idx = jnp.arange(e0.shape[0])
    d = out.separation_m[idx, er.mode, er.direction]
    t = out.threshold_m[idx, er.mode, er.direction]
    quiet = jnp.where(t > 0.0, jnp.abs(d) <= t, True)
    risk = jnp.asarray(setup.t_s) >= jnp.where(fault.source >= 0, fault.onset_s, -jnp.inf)
    p1 = jnp.where(risk, _risks(resp, p0_h, jnp.ones(1), 1.0).p_hmi_bound[0], 0.0)
    return (jnp.sum(outside & quiet & risk), jnp.sum(jnp.where(risk, er.p_hmi_bound, 0.0)),
            jnp.sum(outside & ~out.alert & risk), jnp.sum(risk), jnp.sum(p1), jnp.max(p1))


def onset_nodes(t_s, onset_range_s, n=4096):
    """E over the uniform onset prior of the at-risk epochs (those with t >= onset): the mean
    over ``n`` midpoints of the window (exact to 1 / n of an epoch's share)."""
    on = onset_range_s[0] + (np.arange(n) + 0.5) / n * (onset_range_s[1] - onset_range_s[0])
    return float(np.mean(np.sum(np.asarray(t_s)[None] >= on[:, None], axis=1)))


def importance_risk(setup: UavBankSetup, kind, onset_range_s, size_range, n_draws, key):
    """The scenario's P(A) per at-risk epoch, importance sampled (docs/filter-integrity.md,
    "The conditional risk estimate"): the magnitude integrated by quadrature
    (``conditional_risk``), a pilot at the window's middle onset for every faultable source,
    then ``n_draws`` draws of (source, onset): the source from the pilot's shares mixed with
    ``araim.filter_risk.DEFENSIVE`` of the uniform prior (``source_proposal``), the onset
    from its uniform prior. Returns a JSON-able dict: ``rate`` E[sum_k P(A_k)] / E[at-risk
    epochs], ``std_error``, ``ci_low``/``ci_high`` (normal, 95 %), ``ess``, ``worst`` (the
    largest P(A_k) over every magnitude node and epoch drawn), ``draws``, ``pilot`` (per
    source)."""
    cand = np.flatnonzero(setup.faultable)
    mid = 0.5 * (onset_range_s[0] + onset_range_s[1])
    pilot = conditional_risk(setup, kind, cand, np.full(cand.size, mid), size_range)
    q = araim.filter_risk.source_proposal(pilot.sum_risk)
    k_s, k_o = jax.random.split(key)
    pick = np.asarray(jax.random.choice(k_s, cand.size, (n_draws,), p=jnp.asarray(q)))
    onset = np.asarray(jax.random.uniform(k_o, (n_draws,), minval=onset_range_s[0],
                                          maxval=onset_range_s[1]))
    lw = np.log(1.0 / cand.size) - np.log(q[pick])
    cr = conditional_risk(setup, kind, cand[pick], onset, size_range, lw)
    est = araim.filter_risk.weighted_mean(cr.sum_risk, cr.log_weight)
    n_risk = onset_nodes(setup.t_s, onset_range_s)
    rate, se = est.mean / n_risk, est.std_error / n_risk
    return {"rate": rate, "std_error": se, "ci_low": max(rate - 1.96 * se, 0.0),
            "ci_high": rate + 1.96 * se, "ess": est.ess, "draws": int(n_draws),
            "worst": float(max(cr.worst.max(), pilot.worst.max())),
            "mean_at_risk_epochs": n_risk,
            "pilot": {str(setup.ids[c]): float(s / max(n, 1)) for c, s, n in
                      zip(cand, pilot.sum_risk, pilot.n_at_risk, strict=True)}}
