"""Injected faults with random onset, source and size: steps and ramps (docs/filter-integrity.md).

A ``FaultScenario`` is one fault on one source: a bias ``step_m + slope_m_s (t - onset_s)``
from ``onset_s`` on (a step has slope 0, a ramp step 0: a tower's clock or a multipath bias
growing slowly, the case an innovation test misses while the estimate drifts). It is a pytree
of scalars, so one compiled drive serves every scenario, and it adds to the world's other
errors (``sim.ErrorModel``, whose own constant fault is left at its fields: set its
``fault_onset_s`` to inf to use these alone). ``draw_faults`` draws scenarios from one key:
the source uniform over the towers, the onset uniform in a window, the step's size or the
ramp's slope log-uniform in a range (the ranges are the study's parameters; the seeds give
none)."""

from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["FaultScenario", "draw_faults", "fault_profile_m", "no_fault"]


class FaultScenario(NamedTuple):
    """One injected fault (scalars, or arrays of scenarios with a leading axis)."""

    source: jax.Array
    """0-based index of the faulty source; -1: no fault."""
    onset_s: jax.Array
    """time from which the fault is on, s."""
    step_m: jax.Array
    """bias at the onset, m (a step)."""
    slope_m_s: jax.Array
    """growth of the bias after the onset, m/s (a ramp)."""


def no_fault() -> FaultScenario:
    """The fault-free scenario."""
    return FaultScenario(jnp.asarray(-1), jnp.asarray(jnp.inf), jnp.asarray(0.0),
                         jnp.asarray(0.0))


def fault_profile_m(t_s, fault: FaultScenario, n_sources: int):
    """The bias of ``fault`` on each of ``n_sources`` sources at time ``t_s`` (...,), shape
    (..., n_sources): step + slope (t - onset) on the faulty source from the onset on."""
    t = jnp.asarray(t_s)[..., None]
    on = (t >= fault.onset_s) & (jnp.arange(n_sources) == fault.source)
    return jnp.where(on, fault.step_m + fault.slope_m_s * (t - fault.onset_s), 0.0)


def draw_faults(key, n: int, n_sources: int, kind: str, onset_range_s, size_range):
    """``n`` scenarios of ``kind`` 'step' (``size_range`` the step in m) or 'ramp' (the slope
    in m/s): the source uniform over ``n_sources``, the onset uniform in ``onset_range_s``,
    the size log-uniform in ``size_range`` (a positive sign: the range error grows)."""
    if kind not in ("step", "ramp"):
        raise ValueError(f"fault kind must be 'step' or 'ramp', got {kind!r}")
    k_s, k_o, k_m = jax.random.split(key, 3)
    src = jax.random.randint(k_s, (n,), 0, n_sources)
    onset = jax.random.uniform(k_o, (n,), minval=onset_range_s[0], maxval=onset_range_s[1])
    lo, hi = jnp.log(size_range[0]), jnp.log(size_range[1])
    size = jnp.exp(jax.random.uniform(k_m, (n,), minval=lo, maxval=hi))
    zero = jnp.zeros(n)
    if kind == "step":
        return FaultScenario(src, onset, size, zero)
    return FaultScenario(src, onset, zero, size)
