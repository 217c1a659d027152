"""Gradients of the EKF filter bank's HPL with respect to the tower positions
(docs/filter-integrity.md, "Recorded drives and gradients").

``hpl_gradient_wrt_towers`` runs ``araim.filter_monitor.run_ekf_monitor`` (the seed 000 LTE +
IMU error-state EKF bank, one ``lax.scan``) and differentiates its HPL with respect to the
towers' positions ``tx_pos`` (L, 3) in reverse mode: through every epoch's mechanization, update
and covariance, and through the PL root finder's implicit derivative
(``araim.mhss.implicit_root``, docs/gradients.md). Nothing in the bank needed changing: the
fault modes depend on the sources' validity and priors only, and the monitor's square roots of
zero separations sit behind ``where`` that zero their cotangents.

Two readings of "move a tower":

- ``truth_pos_m`` given (the receiver's true positions at the epochs): the pseudoranges follow
  the tower, z(t) = z + ||r_e - t|| - ||r_e - t_0||, with the measurement errors (noise, clocks,
  faults) held: the tower is placed elsewhere and the same drive is made again (placement);
- ``truth_pos_m`` None: the pseudoranges are held and only the filter's knowledge of the tower
  moves (the sensitivity to a survey error of the tower's coordinates).

At the point t = t_0 both give the forward values of ``run_ekf_monitor`` (the correction is
an exact 0.0; the pass under the gradient is compiled apart, seen to differ by one rounding of
the HPL, 4e-16 m). Cost (the whole 145 s drive of seed 000, 1,453 epochs, 7 filters, on a
shared 2-core CPU): the value and the gradient in 0.7-1.3 s, 6.5-9.6x the forward pass, with
163 MiB of residuals (docs/filter-integrity.md); no rematerialisation was needed.
"""

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Float

from oaraim.araim import ekf as _ekf
from oaraim.araim import filter_monitor as _fm
from oaraim.araim.status import Status

__all__ = ["OBJECTIVES", "TowerGradient", "hpl_gradient_wrt_towers"]

#: what is differentiated: 'mean' the mean HPL over the epochs whose status is OK (their count
#: taken at the point: an epoch whose status flips is a jump, not a slope; inf and a zero
#: gradient when no epoch has one), 'last' the last epoch's HPL (inf and a zero gradient where
#: its status is not OK)
OBJECTIVES = ("mean", "last")


class TowerGradient(NamedTuple):
    """What ``hpl_gradient_wrt_towers`` returns."""

    hpl_m: jax.Array
    """() the objective: the mean HPL over the OK epochs, or the last epoch's HPL (m)."""
    grad_m_per_m: jax.Array
    """(L, 3) its derivative with respect to each tower's east, north, up position (m/m)."""
    n_epochs: jax.Array
    """() the epochs in the objective (status OK; 'last': 1 or 0)."""
    monitor: _fm.FilterMonitorEpoch
    """The bank's per-epoch outputs (leading axis E), as ``run_ekf_monitor`` returns them."""


def _objective(tx_pos, state0, inputs, params, sources, options, truth_pos_m, objective):
    if truth_pos_m is not None:
        # the pseudoranges follow the tower; exactly 0.0 added at the point itself
        tx0 = jax.lax.stop_gradient(tx_pos)
        rng = lambda t: jnp.linalg.norm(truth_pos_m[:, None, :] - t[None], axis=-1)  # noqa: E731
        inputs = inputs._replace(z=inputs.z + (rng(tx_pos) - rng(tx0)))
    _, out = _fm.run_ekf_monitor(state0, inputs, tx_pos, params, sources, options)
    ok = out.status == Status.OK
    if objective == "last":
        return out.hpl_m[-1], (ok[-1].astype(jnp.int32), out)
    n = jnp.sum(ok)
    # HPL is inf where the status is not OK: the outer where gives it a zero cotangent
    total = jnp.sum(jnp.where(ok, out.hpl_m, 0.0))
    return jnp.where(n > 0, total / jnp.maximum(n, 1), jnp.inf), (n, out)


@partial(jax.jit, static_argnames=("options", "objective"))
def _value_and_grad(state0, inputs, tx_pos, params, sources, options, truth_pos_m, objective):
    f = jax.value_and_grad(_objective, has_aux=True)
    (value, (n, out)), grad = f(tx_pos, state0, inputs, params, sources, options, truth_pos_m,
                                objective)
    return TowerGradient(value, grad, n, out)


def hpl_gradient_wrt_towers(state0: _ekf.EkfState, inputs: _ekf.EkfInputs,
                            tx_pos: Float[ArrayLike, "L 3"], params: _ekf.EkfParams,
                            sources: _fm.BankSources, options: _fm.BankOptions,
                            truth_pos_m: Float[ArrayLike, "E 3"] | None = None,
                            objective: str = "mean") -> TowerGradient:
    """The EKF bank's HPL over a drive and its gradient with respect to the tower positions.

    ``state0``, ``inputs`` (E epochs), ``tx_pos`` (L, 3) ENU (m), ``params``, ``sources`` and
    ``options`` as ``araim.filter_monitor.run_ekf_monitor``; ``truth_pos_m`` (E, 3) the true
    receiver positions at the epochs (the pseudoranges then follow the towers: placement) or
    None (pseudoranges held: survey sensitivity; module docstring); ``objective`` one of
    ``OBJECTIVES`` (static). Jitted (one compilation per ``options``, ``objective`` and
    shapes). Returns ``TowerGradient`` (objective in m, gradient (L, 3) in m/m, the epochs in
    it, the monitor's outputs)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    tx_pos = jnp.asarray(tx_pos, jnp.float64)
    if tx_pos.ndim != 2 or tx_pos.shape[1] != 3:
        raise ValueError(f"tx_pos must be (L, 3) tower positions in m, got shape {tx_pos.shape}")
    if truth_pos_m is not None:
        truth_pos_m = jnp.asarray(truth_pos_m, jnp.float64)
        if truth_pos_m.shape != (inputs.z.shape[0], 3):
            raise ValueError(f"truth_pos_m must be ({inputs.z.shape[0]}, 3): the receiver's "
                             f"true position at each epoch, got shape {truth_pos_m.shape}")
    return _value_and_grad(state0, inputs, tx_pos, params, sources, options, truth_pos_m,
                           objective)
