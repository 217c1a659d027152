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


def uav_run(key, setup: UavBankSetup, fault):
    """One Monte Carlo run on the flight (jit/vmap over ``key`` and ``fault``, a
    ``sim.FaultScenario`` whose source indexes the flight's sources): the vehicle's deviation
    from the flight path follows the bank's own model from zero (white acceleration, clock
    random walks), the pseudoranges its rows plus white noise of the model's variances plus the
    fault; the bank (``araim.run_linear_monitor``, diffuse prior) is the filter told the truth.
    Returns per-epoch (HPE (E,), HPL (E,), alert (E,), injected bias (E, L))."""
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
    _, out = araim.run_linear_monitor(jnp.zeros(n), PRIOR_VAR * jnp.eye(n), m, z,
                                      jnp.asarray(setup.used), setup.sources, setup.options)
    hpe = jnp.linalg.norm(out.position_m[:, :2] - x_true[:, :2], axis=-1)
    return hpe, out.hpl_m, out.alert, bias
