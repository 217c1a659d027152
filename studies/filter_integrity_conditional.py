"""The ``filter-integrity`` study's conditional estimate on the seed 000 drive
(docs/filter-integrity.md, "The conditional risk estimate"): eq. (1) of ``araim.filter_risk``
per drawn run, source and onset (``sim.filter_risk``), the magnitude by quadrature about one
faulted run at a reference magnitude, the source importance sampled from a pilot; and the
crude check at c HPL on the study's own runs.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import araim, errors, mc, sim

MAGNITUDE_NODES = araim.filter_risk.MAGNITUDE_NODES
#: the crude check's HPL fraction c: P(|e_0,H| > c HPL) ~1e-2 per epoch on both platforms,
#: tens of epochs in a quick run's 16 runs
HPL_FRACTION = 0.3
#: runs per compiled call
BATCH = 16
#: at most this many importance draws, and this many of the study's runs checked crudely
#: (each costs two drives: the full-size study's 160 would more than double its time)
MAX_RUNS = 64
#: cells of the importance draws' keys (``mc.realization_keys``), apart from the study's runs
#: and fault draws (cells 0-2, 100-102, 200-202, 300-302)
COND_CELL = 400


class DriveCase(NamedTuple):
    """The drive's inputs of ``sim.simulate_filter_drive``: ``setup``, the world ``err``, the
    bank's ``cfg`` and the filters' sigma ``sigma_f`` (m, 0: the world's)."""

    setup: sim.DriveSetup
    err: errors.ErrorModel
    cfg: sim.FilterDriveConfig
    sigma_f: float


@functools.cache
def _risk_kernel(cfg):
    """Jitted, vmapped over (key, source, onset, m_ref): per magnitude node (``nodes`` (G,),
    m) the sum over the at-risk epochs of P(A_k) (G,), the response of a step (``ramp`` 0) or
    ramp (1) of m_ref scaled to each node; the at-risk epochs; the largest P(A_k). One
    compiled kernel for both kinds."""
    def one(key, source, onset, m_ref, nodes, ramp, setup, err, sigma_f):
        f = sim.FaultScenario(source, onset, m_ref * (1.0 - ramp), m_ref * ramp)
        resp = sim.filter_risk.drive_response(key, setup, err, f, cfg, sigma_f)
        r = sim.filter_risk.drive_epoch_risks(resp, nodes / m_ref).p_hmi_bound
        risk = setup.t_s >= onset
        return (jnp.sum(jnp.where(risk[None], r, 0.0), axis=1), jnp.sum(risk),
                jnp.max(jnp.where(risk[None], r, 0.0)))

    return jax.jit(jax.vmap(one, in_axes=(0, 0, 0, 0, None, None, None, None, None)))


def _pad(a, i, m):
    """Rows i..i+m of ``a`` padded to BATCH with copies of row i (one compiled shape)."""
    a = a if isinstance(a, jax.Array) else jnp.asarray(a)
    return jnp.concatenate([a[i:i + m], jnp.repeat(a[i:i + 1], BATCH - m, 0)])


def _batched(fn, case, per_run, shared=()):
    """``fn`` over the runs (``per_run`` arrays, one row per run) in BATCH-sized calls, with
    the ``shared`` arguments; its outputs concatenated."""
    outs = []
    n = len(per_run[0])
    for i in range(0, n, BATCH):
        m = min(BATCH, n - i)
        o = fn(*(_pad(a, i, m) for a in per_run), *shared, case.setup, case.err, case.sigma_f)
        outs.append([np.asarray(x)[:m] for x in o])
    return [np.concatenate(x) for x in zip(*outs, strict=True)]


def drive_importance_risk(case: DriveCase, kind, onset_s, size_range, n_draws, key):
    """P(A) per at-risk epoch of a faulted scenario on the drive (the UAV flight's
    ``importance_risk``): a pilot per tower at the window's middle onset, then ``n_draws``
    draws of (run key, tower, onset), the tower from the pilot's shares mixed with
    ``araim.filter_risk.DEFENSIVE`` of the uniform prior, the onset uniform; the magnitude
    log-uniform in ``size_range`` by quadrature, the response of one faulted run scaled to
    every node. The EKF bank is linear to first order only, so that run is taken where the
    magnitude matters: the pilot runs at the range's geometric mean, which finds each tower's
    peak node m*, and the draws run at their tower's m*. The pilot also runs at a second
    reference magnitude (a quarter of the way up the range in ln m); the two pilot estimates
    of the dominant tower differ by ``pilot_rerun_change`` (relative): the linearisation's
    effect. JSON-able dict (``rate``, ``std_error``, ``ci_low``, ``ci_high``, ``ess``,
    ``worst``, ``draws``, ``pilot``, ``pilot_rerun_change``)."""
    n_t = int(case.setup.towers.shape[0])
    lo, hi = float(size_range[0]), float(size_range[1])
    nodes, weights = araim.filter_risk.log_uniform_nodes(lo, hi, MAGNITUDE_NODES)
    fn = _risk_kernel(case.cfg)
    shared = (jnp.asarray(nodes), {"step": 0.0, "ramp": 1.0}[kind])
    k_p, k_r, k_s, k_o = jax.random.split(key, 4)
    mid = np.full(2 * n_t, 0.5 * (onset_s[0] + onset_s[1]))
    pk = jax.random.split(k_p, n_t)
    pk = jnp.concatenate([pk, pk])
    m_a, m_b = np.sqrt(lo * hi), lo ** 0.75 * hi ** 0.25
    per_node, n_pilot, worst_p = _batched(
        fn, case, (pk, np.tile(np.arange(n_t), 2), mid, np.repeat([m_a, m_b], n_t)), shared)
    s1, s2 = per_node[n_t:] @ weights, per_node[:n_t] @ weights
    m_star = np.where(per_node[:n_t].max(1) > 0, nodes[np.argmax(per_node[:n_t], axis=1)], m_a)
    q = araim.filter_risk.source_proposal(s2)
    pick = np.asarray(jax.random.choice(k_s, n_t, (n_draws,), p=jnp.asarray(q)))
    onset = np.asarray(jax.random.uniform(k_o, (n_draws,), minval=onset_s[0],
                                          maxval=onset_s[1]))
    keys = jax.random.split(k_r, n_draws)
    per_draw, _, worst = _batched(fn, case, (keys, pick, onset, m_star[pick]), shared)
    est = araim.filter_risk.weighted_mean(per_draw @ weights, np.log(1.0 / n_t) - np.log(q[pick]))
    t = np.asarray(case.setup.t_s)
    grid = onset_s[0] + (np.arange(4096) + 0.5) / 4096 * (onset_s[1] - onset_s[0])
    n_risk = float(np.mean(np.sum(t[None] >= grid[:, None], axis=1)))
    rate, se = est.mean / n_risk, est.std_error / n_risk
    top = int(np.argmax(s2))
    change = float(abs(s1[top] - s2[top]) / s2[top]) if s2[top] > 0 else 0.0
    return {"rate": rate, "std_error": se, "ci_low": max(rate - 1.96 * se, 0.0),
            "ci_high": rate + 1.96 * se, "ess": est.ess, "draws": int(n_draws),
            "worst": float(max(worst.max(), worst_p.max())), "pilot_rerun_change": change,
            "pilot": {f"tower {j + 1}": {"rate": float(s2[j] / max(n_pilot[j], 1)),
                                         "m_star": float(m_star[j])} for j in range(n_t)}}


@functools.cache
def _validation_kernel(cfg):
    """Jitted, vmapped over (key, fault): ``sim.filter_risk.drive_validation_counts`` at
    ``HPL_FRACTION`` (a fault-free batch too: its response is exactly 0; one compiled kernel
    for every scenario)."""
    def one(key, fault, setup, err, sigma_f):
        resp = sim.filter_risk.drive_response(key, setup, err, fault, cfg, sigma_f)
        return sim.filter_risk.drive_validation_counts(resp, setup.t_s, fault, HPL_FRACTION)
    return jax.jit(jax.vmap(one, in_axes=(0, 0, None, None, None)))


def drive_validation(case: DriveCase, keys, faults):
    """``sim.filter_risk.drive_validation_counts`` of the study's own runs (``keys`` (B, ...)
    and ``faults`` a ``sim.FaultScenario`` batch of B): (observed, expected, HMI at c, at-risk
    epochs, sum of P(A_k), largest P(A_k)) (B,) each."""
    out = _validation_kernel(case.cfg)(keys, faults, case.setup, case.err, case.sigma_f)
    return tuple(np.asarray(x) for x in out)


def on_runs(parts):
    """The conditional estimate on the study's own runs (plain Monte Carlo over the fault
    prior, no scaling of the response) from the batches' ``drive_validation`` (or the UAV
    flight's ``validation_counts``) outputs: (crude check dict, estimate dict)."""
    cols = [np.concatenate(x) for x in zip(*parts, strict=True)]
    ob, ex, hm, n_risk, s, worst = cols
    check = araim.filter_risk.crude_check(ob, ex, hm, HPL_FRACTION)
    n = float(max(n_risk.sum(), 1))
    est = araim.filter_risk.weighted_mean(s) if s.size > 1 else None
    rate = float(s.sum() / n)
    se = est.std_error * s.size / n if est else 0.0
    return check, {"rate": rate, "std_error": se, "ci_low": max(rate - 1.96 * se, 0.0),
                   "ci_high": rate + 1.96 * se, "ess": None, "draws": int(s.size),
                   "worst": float(worst.max())}


def fault_size_range(p, scen):
    """(lo, hi) of a faulted scenario's log-uniform size: the study's ``step_m`` (m) for
    'step', ``ramp_m_s`` (m/s) for 'ramp' (validated 'lo,hi' strings)."""
    return tuple(float(x) for x in (p["step_m"] if scen == "step" else p["ramp_m_s"]).split(","))


def _importance_how(n, drawn, est, plain):
    """The note's words for an importance-sampled estimate ``est`` over ``n`` draws of
    ``drawn`` (which tuple, which member importance sampled), beside the plain estimate
    ``plain`` on the study's runs (stored in ``est['on_runs']``)."""
    est["on_runs"] = plain
    return (f"{n} draws of {drawn} importance sampled (ESS {est['ess']:.3g}), the magnitude "
            f"by {MAGNITUDE_NODES}-node quadrature; on the study's {plain['draws']} runs "
            f"{plain['rate']:.2g} (+- {plain['std_error']:.2g})")


def _rows_result(rows, per):
    """(rows, metrics) of one platform: the scenarios' entries, ``passed`` when none failed."""
    return rows, {"scenarios": per, "passed": not any(d["failed"] for d in per.values()),
                  "hpl_fraction": HPL_FRACTION}


def summary_row(scen, platform, est, alloc, validation, how):
    """(row, metrics entry) of one scenario's conditional estimate beside the crude check:
    ``est`` the estimate's dict, ``validation`` the ``araim.filter_risk.crude_check`` of the
    study's runs, ``how`` the sampling in words. A flagged check fails the scenario whatever
    the estimate."""
    v = validation
    fails = est["ci_low"] > alloc or v["flagged"]
    verdict = ("model flagged by the crude check" if v["flagged"] else
               "exceeds the allocation" if est["ci_low"] > alloc else
               "within the allocation" if est["ci_high"] <= alloc else "not resolved")
    row = {"quantity": f"P(HMI) bound per at-risk epoch, {scen}, {platform}, filter solution "
                       "separation, conditional estimate (eq. 1)",
           "unit": "-", "published": None, "reproduced": est["rate"],
           "note": f"{how}; 95 % CI [{est['ci_low']:.2g}, {est['ci_high']:.2g}]; largest "
                   f"epoch value {est['worst']:.2g}; allocation {alloc:.2g}: {verdict}; crude "
                   f"check at {v['hpl_fraction']:g} HPL: {v['observed']} epochs seen, "
                   f"{v['expected']:.1f} expected (z = {v['z']:.2f}, {v['runs']} runs)"}
    return row, {**est, "allocation": alloc, "verdict": verdict, "validation": v,
                 "failed": bool(fails)}


def drive_rows(case: DriveCase, validation, p, n, seed, onset_s, budget):
    """The drive's rows of the conditional estimate (one per scenario) and their metrics:
    ``validation`` {scenario: list of ``drive_validation`` outputs of the study's batches},
    ``p`` the study's parameters (``step_m``, ``ramp_m_s``, ``p_s``), ``n`` the importance
    draws after the pilot, ``seed``, the onset window ``onset_s`` and the ``budget``. The
    fault-free estimate is eq. (1) on the study's own runs; a faulted one is importance
    sampled, the plain estimate on the runs reported beside it. Returns (rows, metrics with
    ``passed``)."""
    rows, per = [], {}
    for si, scen in enumerate(("fault-free", "step", "ramp")):
        v, plain = on_runs(validation[scen])
        if scen == "fault-free":
            alloc = budget.phmi_h
            est = plain
            how = f"exact given each run's covariances, over {plain['draws']} runs"
        else:
            alloc = budget.phmi_h / p["p_s"]
            est = drive_importance_risk(case, scen, onset_s, fault_size_range(p, scen), n,
                                        mc.realization_keys(seed, COND_CELL + si, 0, 1)[0])
            how = _importance_how(n, "(run, tower, onset), the tower", est, plain)
        row, per[scen] = summary_row(scen, "seed 000 drive", est, alloc, v, how)
        rows.append(row)
    return _rows_result(rows, per)


@functools.cache
def uav_validation_kernel(setup_key):
    """Jitted, vmapped over (key, fault): the UAV flight's ``validation_counts`` at
    ``HPL_FRACTION`` on the flight ``setup_key`` = (epochs, nav) (its setup cached)."""
    from oaraim.studies.seed004_uav import filter_mc
    st = filter_mc.uav_setup(*setup_key)
    return jax.jit(jax.vmap(lambda k, f: filter_mc.validation_counts(k, st, f, HPL_FRACTION)))


def uav_rows(setup, validation, p, n, seed, onset_s, budget):
    """The UAV flight's rows as ``drive_rows`` (``setup`` the flight's ``UavBankSetup``,
    ``validation`` {scenario: list of ``uav_validation_kernel`` outputs}); the allocation
    under a fault PHMI_H / P_s of a SOP, as the crude rows'."""
    from oaraim.studies.seed004_uav import filter_mc
    cand = np.flatnonzero(setup.faultable)
    rows, per = [], {}
    for si, scen in enumerate(("fault-free", "step", "ramp")):
        v, plain = on_runs(validation[scen])
        if scen == "fault-free":
            alloc = budget.phmi_h
            ff = np.asarray(filter_mc.fault_free_risk(setup))
            est = {"rate": float(ff.mean()), "std_error": 0.0, "ci_low": float(ff.mean()),
                   "ci_high": float(ff.mean()), "worst": float(ff.max()), "ess": None,
                   "draws": 0}
            how = "exact given the model (the linear bank's covariances are the same every run)"
        else:
            alloc = budget.phmi_h / float(np.max(setup.p_s[cand]))
            est = filter_mc.importance_risk(setup, scen, onset_s, fault_size_range(p, scen), n,
                                            mc.realization_keys(seed, COND_CELL + 10 + si, 0,
                                                                1)[0])
            how = _importance_how(n, "(source, onset), the source", est, plain)
        row, per[scen] = summary_row(scen, "UAV flight (seed 004)", est, alloc, v, how)
        rows.append(row)
    return _rows_result(rows, per)


def check_row(passed):
    """The conditional estimate's check row: every scenario's crude check at c HPL left the
    model unflagged and no estimate's interval lies above its allocation."""
    return {"quantity": "conditional check: the model passes the crude check at "
                        f"{HPL_FRACTION:g} HPL and no conditional estimate exceeds its "
                        "allocation", "unit": "pass", "published": None,
            "reproduced": float(passed),
            "note": "1 pass, 0 fail; sigma_scale < 1 (an injected model error) must fail it, "
                    "through the crude check"}


def dataset_vars(metrics, prefix):
    """The conditional estimate's numbers as dataset variables over the scenarios
    (``prefix``_rate, _ci_low, _ci_high, _worst, _allocation, _check_z) from ``drive_rows``'
    or ``uav_rows``' metrics."""
    per = metrics["scenarios"]
    scen = ("fault-free", "step", "ramp")
    cols = {"rate": lambda d: d["rate"], "ci_low": lambda d: d["ci_low"],
            "ci_high": lambda d: d["ci_high"], "worst": lambda d: d["worst"],
            "allocation": lambda d: d["allocation"], "check_z": lambda d: d["validation"]["z"]}
    return {f"{prefix}_{k}": ("scenario", np.array([f(per[s]) for s in scen], float))
            for k, f in cols.items()}


def plot_conditional(ds, out_dir, plt):
    """conditional.png: per scenario and platform the conditional estimate with its 95 %
    interval and its largest epoch value, the crude count's 95 % upper bound and the
    allocation, on one log scale. Returns the file's path."""
    from oaraim.mc import clopper_pearson

    scen = list(ds["scenario"].values)
    fig, ax = plt.subplots(figsize=(8.0, 4.4))
    plats = [("cond", "seed 000 drive", "n_misleading", "n_at_risk", "C0")]
    if "uav_cond_rate" in ds:
        plats.append(("uav_cond", "UAV flight (seed 004)", "uav_n_misleading", "uav_n_at_risk",
                      "C1"))
    for pi, (pre, label, k_name, n_name, color) in enumerate(plats):
        for si in range(len(scen)):
            x = si + (pi - 0.5 * (len(plats) - 1)) * 0.3
            rate = float(ds[f"{pre}_rate"].values[si])
            lo, hi = (float(ds[f"{pre}_ci_{s}"].values[si]) for s in ("low", "high"))
            ax.plot([x, x], [max(lo, 1e-30), hi], color=color, lw=3)
            ax.plot(x, rate, "D", color=color, ms=5,
                    label=f"{label}: conditional estimate (eq. 1), 95 % CI" if si == 0 else None)
            ax.plot(x + 0.06, float(ds[f"{pre}_worst"].values[si]), "_", color=color, ms=9,
                    mew=2, label="largest epoch value (its platform's colour)"
                    if si == 0 and pi == 0 else None)
            k = ds[k_name].values[si]
            k = int(k[:, 0].sum()) if k.ndim == 2 else int(k.sum())
            _, up = clopper_pearson(k, int(ds[n_name].values[si].sum()))
            ax.plot(x - 0.06, up, "v", color=color, mfc="none", ms=6,
                    label=f"{label}: crude count, 95 % upper bound" if si == 0 else None)
            alloc = float(ds[f"{pre}_allocation"].values[si])
            ax.plot([x - 0.12, x + 0.12], [alloc, alloc], "k--", lw=1,
                    label="allocation (PHMI_H; PHMI_H / P_s under a fault)"
                    if si == 0 and pi == 0 else None)
    ax.set_yscale("log")
    ax.set_ylim(1e-22, 1.0)
    ax.set_xlim(-0.6, len(scen) - 0.4)
    ax.set_xticks(range(len(scen)), scen)
    ax.set_ylabel("P(HPE > HPL, no alert) per at-risk epoch")
    ax.set_title("Filter bank: conditional estimate (an upper bound, eq. 1) vs crude count",
                 fontsize=9)
    ax.grid(alpha=0.3, which="major")
    ax.legend(fontsize=6.5, loc="lower right")
    fig.tight_layout()
    path = f"{out_dir}/conditional.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
