"""The replay's monitor table (``araim.snapshot.MONITORS``), following the recipe "A new
monitor" of docs/contributing.md: a toy monitor registered and replayed beside the built-in
ones, on the synthetic skies of tests/test_snapshot.py (no shared files needed)."""

from typing import NamedTuple

import numpy as np
import pytest

from oaraim import araim
from oaraim.araim import snapshot
from tests.test_snapshot import _sky

#: the toy's PL multiplier on the 1-sigma horizontal (DRMS) and vertical errors
K_TOY = 6.0


class CovarianceMonitor(NamedTuple):
    """A toy monitor: PLs from the all-in-view solution's covariance alone, K_TOY x DRMS
    horizontally and K_TOY x sigma_U vertically, one clock per group; it never detects nor
    excludes, so a fault outside its model shows up as misleading information."""

    name: str = "toy-covariance"
    needs_order: bool = False

    def run(self, inputs, config):
        """PLs per epoch from (H^T C_int^-1 H)^-1 of the used sources (H: ENU rows and one
        clock column per group)."""
        g = np.asarray(inputs.g_enu)
        used = np.asarray(inputs.used)
        n_c = int(inputs.p_const.shape[-1])
        clocks = (inputs.constellation[..., None] == np.arange(n_c)) & used[..., None]
        h = np.concatenate([g, clocks.astype(float)], -1)  # (T, L, 3 + C)
        w = np.where(used, 1.0 / inputs.var_int_m2, 0.0)
        # every clock group has a source in these skies (a real monitor drops an empty
        # group's column, as araim.wnls does)
        cov = np.linalg.inv(np.einsum("tli,tl,tlj->tij", h, w, h))
        ok = np.asarray(inputs.used_epoch)
        hpl = np.where(ok, K_TOY * np.sqrt(cov[:, 0, 0] + cov[:, 1, 1]), np.inf)
        vpl = np.where(ok, K_TOY * np.sqrt(cov[:, 2, 2]), np.inf)
        t = hpl.shape[0]
        return snapshot.MonitorReplay(
            hpl, vpl, np.zeros(t, bool), np.zeros(t), np.zeros(used.shape, bool), hpl, vpl,
            np.asarray(inputs.sol.position_m), np.asarray(inputs.error_enu_m),
            np.asarray(inputs.hpe_m), np.asarray(inputs.vpe_m),
            np.where(ok, araim.Status.OK, araim.Status.TOO_FEW_SOURCES).astype(np.int8))


@pytest.fixture
def toy():
    """The toy registered for one test and removed after it."""
    monitor = snapshot.register_monitor(CovarianceMonitor())
    yield monitor
    snapshot.MONITORS.pop(monitor.name)


def test_slope_and_mhss_are_the_first_two_entries():
    assert list(snapshot.MONITORS)[:2] == ["slope", "mhss"]
    assert snapshot.MONITORS["mhss"].needs_order and not snapshot.MONITORS["slope"].needs_order


def test_a_registered_monitor_is_replayed_and_reported(toy):
    """Replayed alone and beside slope RAIM: its PLs bound the fault-free errors (K = 6 on 1 m
    noise: a 6-DRMS excursion in 60 epochs has probability ~1e-7), its metrics carry its name,
    slope RAIM's result does not change because another monitor ran beside it."""
    x, tx, pr, valid = _sky(1)
    var = np.ones(valid.shape)
    alone = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                            config=snapshot.ReplayConfig(monitors=(toy.name,)))
    assert alone.slope is None and alone.mhss is None and alone.max_order == 0
    m = alone.monitors[toy.name]
    assert np.all(np.isfinite(m.hpl_m)) and np.all(m.hpe_m < m.hpl_m)
    # one clock: the toy's VPL / K is the all-in-view vertical sigma, which the slope RAIM
    # statistic does not give; compare with the MHSS accuracy sigma instead (C_acc = C_int)
    both = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                           config=snapshot.ReplayConfig(monitors=("slope", "mhss", toy.name)))
    np.testing.assert_allclose(both.monitors[toy.name].vpl_m / K_TOY, both.mhss.sigma_acc_u_m,
                               rtol=1e-9)
    slope_only = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                                 config=snapshot.ReplayConfig(monitors=("slope",)))
    np.testing.assert_array_equal(both.slope.hpl_m, slope_only.slope.hpl_m)
    metrics = snapshot.replay_metrics(both)
    assert metrics[f"misleading_information_epochs_{toy.name}"] == 0
    assert metrics[f"hpl_{toy.name}_median_m"] == pytest.approx(float(np.median(m.hpl_m)))
    assert metrics["hpl_median_m"] == metrics["hpl_mhss_median_m"]  # the MHSS stays the main


def test_a_monitor_without_detection_misleads_under_a_fault(toy):
    """A 150 m step on one satellite in 10 epochs: slope RAIM excludes it, the toy (no
    detection) reports the pulled-off solution under its covariance PL: misleading
    information in those epochs, counted under its name."""
    x, tx, pr, valid = _sky(3)
    pr = pr.copy()
    pr[:10, 4] += 150.0
    var = np.ones(valid.shape)
    r = snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                        config=snapshot.ReplayConfig(monitors=("slope", toy.name)))
    metrics = snapshot.replay_metrics(r)
    assert metrics[f"misleading_information_epochs_{toy.name}"] >= 5
    assert metrics["misleading_information_epochs_slope"] == 0
    assert metrics["misleading_information_epochs"] == 0  # slope is the main without MHSS


def test_unknown_or_duplicate_monitors_are_refused_with_one_line(toy):
    x, tx, pr, valid = _sky(7)
    var = np.ones(valid.shape)
    with pytest.raises(ValueError, match="toy-covariance.*register_monitor"):
        snapshot.replay(pr, tx, snapshot.ReplaySources(var, var, valid), x,
                        config=snapshot.ReplayConfig(monitors=("filter",)))
    with pytest.raises(ValueError, match="registered already"):
        snapshot.register_monitor(CovarianceMonitor())
    with pytest.raises(ValueError, match="needs_order"):
        snapshot.register_monitor(CovarianceMonitor(name="other", needs_order=None))
