"""The filter bank augmented with each tower's correlated-error states
(``sim.filter_drive.tower_error_states``, ``araim.filter_monitor.ekf_bank_step_augmented``):
its prior is the calibration's exact covariance, it reduces to the white bank when the world
has no correlated errors, and in the realistic world it removes the false alerts the white
model raises (docs/filter-integrity.md, "Correlated tower errors as states")."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import errors, sim
from oaraim.registry import STUDIES

#: the realistic world of the filter-integrity study: GM multipath, GM tower clocks, the
#: receiver's clock-line calibration; no NLOS (its episodes are faults, not nominal errors)
REALISTIC = dict(sigma_pr_m=2.0, nlos_rate_per_s=0.0, fault_onset_s=np.inf, fault_bias_m=0.0)


@pytest.fixture(scope="module")
def setup20():
    return sim.drive_setup(sim.drive_seed000(), duration_s=20.0)


def test_prior_is_the_covariance_of_the_calibrated_line(setup20):
    """(mp(0), eps(0), a, b) over 2,000 simulated GNSS periods x 5 towers (10,000 samples,
    ``sim.initial_draw``: the world's calibration, the operator's OCXO term switched off as the
    model leaves it to the receiver clock) against the closed form: every covariance entry,
    normalised by sqrt(C_ii C_jj), within 5 standard errors sqrt(2 / 10,000) = 0.014."""
    err = errors.ErrorModel(**REALISTIC, clk_s_wdt_s=0.0, clk_s_wdtdot_per_s=0.0)
    keys = jax.random.split(jax.random.key(11), 2000)
    world = jax.vmap(lambda k: sim.initial_draw(k, setup20, err).world)(keys)
    x = np.stack([np.asarray(world.multipath_m), np.asarray(world.clk_eps_m),
                  np.asarray(world.clk_fit_m[..., 0]), np.asarray(world.clk_fit_m[..., 1])],
                 -1).reshape(-1, 4)
    dt_s = setup20.gyro.shape[1] * setup20.params.dt_s
    es = sim.tower_error_states(err, setup20.calib_t_s, dt_s, err.sigma_pr_m, 5)
    c = np.asarray(es.p0)[:4, :4]
    s = np.cov(x.T)
    d = np.sqrt(np.diag(c))
    assert np.all(np.abs(s - c) / np.outer(d, d) < 5 * np.sqrt(2 / x.shape[0]))
    # the towers are independent, the line's slope is what makes the residual grow
    assert np.allclose(np.asarray(es.p0)[:4, 4:], 0.0)
    assert c[3, 3] > 0 and np.asarray(es.phi)[2, 3] == dt_s


def _traces(setup, err, tower_states, n=2, sigma_f=0.0):
    cfg = sim.FilterDriveConfig(tower_states=tower_states)
    keys = jax.random.split(jax.random.key(3), n)
    fault = jax.tree.map(lambda a: jnp.broadcast_to(a, (n,) + jnp.shape(a)), sim.FaultScenario(
        jnp.asarray(2), jnp.asarray(8.0), jnp.asarray(6.0), jnp.asarray(0.0)))
    return jax.jit(jax.vmap(lambda k, f: sim.simulate_filter_drive(
        k, setup, err, f, cfg, filter_sigma_pr_m=sigma_f, traces=True)[1]))(keys, fault)


def test_without_correlated_errors_the_augmented_bank_is_the_white_bank(setup20):
    """The clean world (white noise, no calibration): the error states have zero prior and
    process noise, so the augmented bank is the white bank: same positions, HPLs, test ratios
    to 1e-6 m (a 6 m step on tower 3 from 8 s: alerts included)."""
    err = errors.ErrorModel.clean(sigma_pr_m=2.0, fault_onset_s=np.inf, fault_bias_m=0.0)
    a = _traces(setup20, err, False, sigma_f=2.0)
    b = _traces(setup20, err, True, sigma_f=2.0)
    np.testing.assert_allclose(b.hpe_m, a.hpe_m, atol=1e-6)
    np.testing.assert_allclose(b.hpl_m, a.hpl_m, atol=1e-6)
    np.testing.assert_allclose(b.test_ratio, a.test_ratio, atol=1e-6)
    assert np.array_equal(b.alert, a.alert) and np.any(a.alert[..., 0])


def test_tower_states_remove_the_realistic_worlds_false_alerts():
    """Fault-free, realistic world, 8 runs of the whole drive (11,624 epochs): the white bank
    (the GM overbound included) alerts at more than 1 % of the epochs — the receiver's
    calibrated clock lines drift away from the towers' clocks, a per-tower bias the white model
    averages down — while the bank with the tower states raises none and its normalised
    separations stay below 5 sigma_ss."""
    setup = sim.drive_setup(sim.drive_seed000())
    err = errors.ErrorModel(**REALISTIC)
    keys = jax.random.split(jax.random.key(5), 8)
    fault = jax.tree.map(lambda a: jnp.broadcast_to(a, (8,) + jnp.shape(a)), sim.no_fault())
    out = {}
    for name, cfg in (("overbound", sim.FilterDriveConfig(gm_inflation=1.0)),
                      ("states", sim.FilterDriveConfig(tower_states=True))):
        out[name] = jax.jit(jax.vmap(lambda k, f, cfg=cfg: sim.simulate_filter_drive(
            k, setup, err, f, cfg)))(keys, fault)
    n_ep = int(np.sum(out["states"].n_epochs))
    assert np.sum(out["overbound"].n_false_alerts[:, 0]) > 0.01 * n_ep
    assert np.sum(out["states"].n_false_alerts[:, 0]) == 0
    assert np.sum(out["states"].n_sep_over[:, 2]) == 0
    assert np.sum(out["states"].n_misleading[:, 0]) == 0
    with pytest.raises(ValueError, match="gm_inflation=0"):
        sim.simulate_filter_drive(keys[0], setup, err, sim.no_fault(),
                                  sim.FilterDriveConfig(gm_inflation=1.0, tower_states=True))


def test_study_options():
    """``tower_states=yes`` with ``gm_overbound=yes`` is refused in one line; the seed drive
    studies accept ``monitor=filter-ss-states``."""
    fi = STUDIES["filter-integrity"]
    with pytest.raises(ValueError, match="set gm_overbound=no"):
        fi.validate({"tower_states": "yes", "gm_overbound": "yes"})
    assert fi.validate({"tower_states": "yes"})["tower_states"] == "yes"
    seed = STUDIES["seed000-ekf-raim"]
    assert seed.validate({"monitor": "filter-ss-states"})["monitor"] == "filter-ss-states"
