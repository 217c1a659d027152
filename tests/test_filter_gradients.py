"""Tests of araim.filter_gradients: the EKF filter bank's HPL differentiated with respect to the
tower positions (reverse mode through ``run_ekf_monitor``'s scan and the PL root finder's
implicit derivative).

The drive: the first 5 s of seed 000's drive (50 epochs of 10 IMU samples, 5 towers of one
operator, a bank of 7 EKFs at order 1 of ``add-v4.2``), ideal IMU samples, the initial
estimate 3.7 m off the truth, pseudoranges = the true ranges minus the tower clocks plus a
fixed draw of 2 m white noise (seed 0), the filter told sigma = 2 m.

Oracle: central differences of the same objective. Step h = 0.1 m: the truncation error is
h^2 |f'''| / 6; measured on this drive it scales as h^2 (3e-13 m/m at h = 0.03 m, 3e-12 at
0.1, 3e-11 at 0.3), and rounding is ~1e-15 m / 0.2 m = 5e-15 m/m. The PL root finder returns
its iterate plus a constant margin (1e-6 m), proved within 1e-4 m of the root; both sides of a
difference take the same branch of the finder here, so its error varies smoothly and cancels
to far below the tolerance. Tolerance 1e-9 m/m absolute: 300x the observed error and 1e-5 of
the largest component (~1e-4 m/m; moving a tower 2 km away by 100 m changes the mean HPL by
centimetres), so a dropped term of the chain (the pseudoranges' or the estimate's dependence
on the tower) fails it: without the pseudoranges' dependence the gradient differs by 0.4 of
its largest component.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import araim, sim
from oaraim.araim import Status

DURATION_S = 5.0
H_M = 0.1
ATOL = 1e-9


@functools.lru_cache(maxsize=1)
def _drive():
    setup = sim.drive_setup(sim.drive_seed000(), duration_s=DURATION_S)
    e, n_t = setup.tower_clk_m.shape
    truth = setup.pos[1:e + 1]
    noise = 2.0 * np.random.default_rng(0).standard_normal((e, n_t))
    z = _ranges(truth, setup.towers) - setup.tower_clk_m + noise
    est0 = araim.ekf.ekf_init(setup.quat[0], setup.pos[0] + jnp.array([3.0, -2.0, 1.0]),
                              setup.vel[0], jnp.zeros(3), jnp.zeros(3), jnp.zeros(2), setup.P0)
    inputs = araim.ekf.EkfInputs(setup.gyro, setup.accel, z, jnp.ones((e, n_t), bool),
                                 setup.tower_clk_m, 2.0)
    sources = araim.BankSources(np.zeros(n_t, int), np.full(n_t, 1e-5), np.array([1e-8]))
    options = araim.BankOptions(araim.BUDGET_SEED004_TABLE_I, 1, "add-v4.2")
    return setup, truth, est0, inputs, sources, options


def _ranges(truth, towers):
    return jnp.linalg.norm(truth[:, None, :] - towers[None], axis=-1)


def _objective(tx, inputs, sources, moved, objective="mean"):
    """The objective evaluated plainly (``run_ekf_monitor``), the pseudoranges moved with the
    towers where ``moved``: what the central differences difference."""
    setup, truth, est0, _, _, options = _drive()
    if moved:
        inputs = inputs._replace(z=inputs.z + _ranges(truth, tx) - _ranges(truth, setup.towers))
    out = araim.run_ekf_monitor(est0, inputs, tx, setup.params, sources, options)[1]
    ok = out.status == Status.OK
    if objective == "last":
        return out.hpl_m[-1]
    return jnp.sum(jnp.where(ok, out.hpl_m, 0.0)) / jnp.sum(ok)


def _central_differences(f, tx, components):
    f = jax.jit(f)
    fd = np.zeros(tx.shape)
    for lk in components:
        d = np.zeros(tx.shape)
        d[lk] = H_M
        fd[lk] = (float(f(tx + d)) - float(f(tx - d))) / (2.0 * H_M)
    return fd


def _all(tx):
    return [(l_, k) for l_ in range(tx.shape[0]) for k in range(3)]


@pytest.mark.parametrize("moved, objective", [(True, "mean"), (False, "last")])
def test_gradient_matches_central_differences(moved, objective):
    """Every component of the gradient (5 towers x east, north, up), for the placement
    reading (pseudoranges follow the towers) of the mean HPL and the survey reading
    (pseudoranges held) of the last epoch's HPL."""
    setup, truth, est0, inputs, sources, options = _drive()
    tx = np.asarray(setup.towers, float)
    res = araim.filter_gradients.hpl_gradient_wrt_towers(
        est0, inputs, tx, setup.params, sources, options, truth if moved else None, objective)
    assert int(res.n_epochs) == (inputs.z.shape[0] if objective == "mean" else 1)
    fd = _central_differences(lambda t: _objective(t, inputs, sources, moved, objective), tx,
                              _all(tx))
    g = np.asarray(res.grad_m_per_m)
    assert np.abs(g).max() > 1e-5   # the comparison below is not of zeros
    np.testing.assert_allclose(g, fd, rtol=0.0, atol=ATOL)


def test_the_two_readings_differ_and_the_values_are_the_banks():
    """At the point both readings give the bank's own outputs (``run_ekf_monitor`` under jit,
    to one rounding of the HPL) and the same objective; their gradients differ (the estimate
    moves with held pseudoranges), by far more than the tolerance of the test above."""
    setup, truth, est0, inputs, sources, options = _drive()
    tx = jnp.asarray(setup.towers)
    ref = jax.jit(lambda: araim.run_ekf_monitor(est0, inputs, tx, setup.params, sources,
                                                options)[1])()
    moved = araim.filter_gradients.hpl_gradient_wrt_towers(
        est0, inputs, tx, setup.params, sources, options, truth)
    held = araim.filter_gradients.hpl_gradient_wrt_towers(
        est0, inputs, tx, setup.params, sources, options)
    for r in (moved, held):
        np.testing.assert_allclose(r.monitor.hpl_m, ref.hpl_m, rtol=0.0, atol=1e-14)
        np.testing.assert_allclose(r.monitor.position_m, ref.position_m, rtol=0.0, atol=1e-12)
        assert float(r.hpl_m) == pytest.approx(float(jnp.mean(ref.hpl_m)), rel=1e-15)
    diff = np.abs(np.asarray(moved.grad_m_per_m) - np.asarray(held.grad_m_per_m)).max()
    assert diff > 0.1 * np.abs(np.asarray(moved.grad_m_per_m)).max()


def test_epochs_without_a_pl_and_an_unused_tower_give_a_finite_gradient():
    """A sixth tower that is never valid and a P_s of 1e-2 at epochs 20-29 (P_NM above
    P_thresh there: UNMONITORED_RISK, HPL inf): the mean runs over the 40 other epochs, the
    gradient is finite, exactly 0 for the unused tower, and equals central differences; with
    P_s = 1e-2 at every epoch the objective is inf and its gradient 0."""
    setup, truth, est0, inputs, sources, options = _drive()
    e, n_t = inputs.z.shape
    tx = np.concatenate([np.asarray(setup.towers), [[500.0, 2500.0, 30.0]]])
    p_sat = np.full((e, n_t + 1), 1e-5)
    p_sat[20:30] = 1e-2
    src6 = araim.BankSources(np.zeros(n_t + 1, int), p_sat, np.array([1e-8]))
    valid = np.ones((e, n_t + 1), bool)
    valid[:, -1] = False
    pad = lambda a, v: jnp.concatenate([a, jnp.full((e, 1), v)], 1)  # noqa: E731
    in6 = inputs._replace(z=pad(inputs.z, 1e7), valid=valid,
                          tx_clk_m=pad(inputs.tx_clk_m, 0.0))
    res = araim.filter_gradients.hpl_gradient_wrt_towers(est0, in6, tx, setup.params, src6,
                                                         options)
    st = np.asarray(res.monitor.status)
    assert np.all(st[20:30] == Status.UNMONITORED_RISK) and np.all(np.delete(st, range(20, 30))
                                                                  == Status.OK)
    assert int(res.n_epochs) == e - 10 and np.isfinite(float(res.hpl_m))
    g = np.asarray(res.grad_m_per_m)
    assert np.all(np.isfinite(g)) and np.all(g[-1] == 0.0)
    comps = [(0, 0), (2, 1), (4, 2)]
    fd = _central_differences(lambda t: _objective(t, in6, src6, False), tx, comps)
    for lk in comps:
        assert g[lk] == pytest.approx(fd[lk], rel=0.0, abs=ATOL)
    # no epoch with a PL: the objective is inf, its gradient 0 (not NaN)
    none = araim.filter_gradients.hpl_gradient_wrt_towers(
        est0, in6, tx, setup.params, src6._replace(p_sat=np.full((e, n_t + 1), 1e-2)), options)
    assert int(none.n_epochs) == 0 and float(none.hpl_m) == np.inf
    assert np.all(np.asarray(none.grad_m_per_m) == 0.0)


def test_a_gradient_step_lowers_the_mean_hpl_as_predicted():
    """Moving every tower along minus the gradient (the largest move 50 m) lowers the mean HPL
    by the first-order prediction s |g|^2 to within 5 % (measured 1.2 %: the curvature of the
    HPL over 50 m at 2 km is small), placement reading."""
    setup, truth, est0, inputs, sources, options = _drive()
    tx = np.asarray(setup.towers, float)
    res = araim.filter_gradients.hpl_gradient_wrt_towers(est0, inputs, tx, setup.params,
                                                         sources, options, truth)
    g = np.asarray(res.grad_m_per_m)
    s = 50.0 / np.linalg.norm(g, axis=1).max()
    predicted = s * np.sum(g * g)
    after = float(jax.jit(lambda t: _objective(t, inputs, sources, True))(tx - s * g))
    drop = float(res.hpl_m) - after
    assert drop > 0.0
    assert drop == pytest.approx(predicted, rel=0.05)


def test_wrong_arguments_are_refused_with_one_line():
    setup, truth, est0, inputs, sources, options = _drive()
    f = araim.filter_gradients.hpl_gradient_wrt_towers
    with pytest.raises(ValueError, match="objective must be one of"):
        f(est0, inputs, setup.towers, setup.params, sources, options, objective="max")
    with pytest.raises(ValueError, match=r"tx_pos must be \(L, 3\)"):
        f(est0, inputs, setup.towers[:, :2], setup.params, sources, options)
    with pytest.raises(ValueError, match="truth_pos_m must be"):
        f(est0, inputs, setup.towers, setup.params, sources, options, truth[:-1])


def test_gradient_through_an_exclusion_restart():
    """``exclusion=True`` with a 30 m step on tower 1 from 2 s: the bank restarts from the
    sub-filter without it (a select over the bank by an argmax: piecewise, differentiated on
    the branch taken), and the gradient still equals central differences (placement reading;
    the restart happens at the same epoch at t +- h)."""
    setup, truth, est0, inputs, sources, options = _drive()
    opt = options._replace(exclusion=True)
    inp = inputs._replace(z=inputs.z.at[20:, 0].add(30.0))
    tx = np.asarray(setup.towers, float)
    res = araim.filter_gradients.hpl_gradient_wrt_towers(est0, inp, tx, setup.params, sources,
                                                         opt, truth)
    gone = np.asarray(res.monitor.excluded_sources)
    assert gone[-1].tolist() == [True, False, False, False, False] and not gone[:20].any()

    def f(t):
        i = inp._replace(z=inp.z + _ranges(truth, t) - _ranges(truth, setup.towers))
        out = araim.run_ekf_monitor(est0, i, t, setup.params, sources, opt)[1]
        return jnp.mean(out.hpl_m)

    comps = [(0, 0), (1, 1), (3, 2)]
    fd = _central_differences(f, tx, comps)
    g = np.asarray(res.grad_m_per_m)
    for lk in comps:
        assert g[lk] == pytest.approx(fd[lk], rel=0.0, abs=ATOL)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A synthesized 5 s seed 000 drive (clean world), written and loaded as a recording."""
    from oaraim import errors, mc, readers

    rec = sim.synthesize_recording(sim.drive_seed000(), mc.realization_keys(0, 0, 0, 1)[0],
                                   err=errors.ErrorModel.clean(), duration_s=DURATION_S)
    folder = tmp_path_factory.mktemp("drive")
    readers.write_recording(folder, rec)
    return readers.load_recording(folder)


def test_replay_gradient_matches_moving_the_recorded_towers(recorded):
    """``ekf_replay.replay_filter_gradient`` on a recording: its bank is
    ``replay_filter_monitor``'s (1e-12 m), and its held-pseudorange gradient equals central
    differences of ``replay_filter_monitor``'s mean HPL with a tower moved in the recording's
    transmitters table (ECEF, moved by R^T d for an ENU step d: the ENU position moves by d to
    ~1e-9 m of rounding at ECEF magnitudes, 1e-9 x 1e-3 m/m / 0.2 m: nothing); the placement
    reading (pseudoranges about the truth) is finite and differs from it."""
    import dataclasses

    from oaraim import geometry

    rp = araim.ekf_replay
    held = rp.replay_filter_gradient(recorded, placement=False)
    mon = rp.replay_filter_monitor(recorded)
    np.testing.assert_allclose(held.gradient.monitor.hpl_m, mon.monitor.hpl_m, rtol=0.0,
                               atol=1e-12)
    assert float(held.gradient.hpl_m) == pytest.approx(float(np.mean(mon.monitor.hpl_m)),
                                                       rel=1e-14)
    o = recorded.meta["origin"]
    rot = np.asarray(geometry.enu_rotation(np.deg2rad(o["lat_deg"]), np.deg2rad(o["lon_deg"])))
    tx = recorded.transmitters
    g = held.gradient.grad_m_per_m
    assert g.shape == (len(tx), 3) and list(held.tx_ids) == list(tx["tx_id"].astype(str))

    def mean_hpl(row, k, h):
        moved = tx.copy()
        moved.loc[row, ["x_m", "y_m", "z_m"]] += rot.T @ (h * np.eye(3)[k])
        r = dataclasses.replace(recorded, transmitters=moved)
        return float(np.mean(rp.replay_filter_monitor(r).monitor.hpl_m))

    for row, k in ((3, 1), (2, 2)):
        fd = (mean_hpl(row, k, H_M) - mean_hpl(row, k, -H_M)) / (2.0 * H_M)
        assert g[row, k] == pytest.approx(fd, rel=0.0, abs=ATOL)
    placed = rp.replay_filter_gradient(recorded)
    gp = placed.gradient.grad_m_per_m
    assert np.all(np.isfinite(gp)) and np.abs(gp - g).max() > 0.1 * np.abs(g).max()
    with pytest.raises(ValueError, match="placement=True needs the recording's truth"):
        rp.replay_filter_gradient(dataclasses.replace(recorded, truth=None))
