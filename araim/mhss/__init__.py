"""Multiple-hypothesis solution separation (MHSS) protection levels, seed 004 eqs. (8)-(16).

A small package, one concern per module:

- ``inputs``: the ``Sources`` pytree (with ``concat``, ``pad`` and ``select`` for the
  studies), the host's argument checks and the kernel's own (``Status.INVALID_INPUT``);
- ``options``: ``MHSSOptions``, the static options every entry point takes as one object;
- ``orders``: the fault-mode order a batch needs (``required_order``);
- ``projection``: every fault mode's fault-tolerant solution, sigmas, biases, separations and
  thresholds (eqs. 8-12, ``project``);
- ``root``: the PL equations and their root finder (eqs. 14-16, ``pls_from_projection``,
  ``solve_pl``);
- ``entry``: the jit-safe kernel ``protection_levels_kernel`` (and
  ``protection_levels_priors_kernel``: several prior sets over the same geometries) and the
  host function ``protection_levels`` over it;
- ``implicit``: the derivatives of the PL roots by the implicit function theorem
  (``implicit_root``, a ``jax.custom_jvp`` on the root finder; docs/gradients.md);
- ``switches``: where those derivatives are not defined (``switch_flags_kernel``).

The names below are this package's public face; ``araim.fde`` builds the solution-separation
test and exclusion on ``project`` and ``pls_from_projection``.
"""

from oaraim.araim.mhss.entry import (
    MHSSResult,
    batch_last_inputs,
    kernel_cache_size,
    kernel_options,
    protection_levels,
    protection_levels_kernel,
    protection_levels_priors_kernel,
    protection_levels_threaded,
)
from oaraim.araim.mhss.implicit import implicit_root, risk_partials
from oaraim.araim.mhss.inputs import (
    UNIT_ROW_TOLERANCE,
    Sources,
    check_inputs,
    check_options,
    host_inputs,
    prepare_inputs,
)
from oaraim.araim.mhss.options import MHSSOptions, as_options
from oaraim.araim.mhss.orders import MAX_AUTO_ORDER, higher_order_flags, required_order
from oaraim.araim.mhss.projection import (
    SINGLE_REDUNDANCY_TOLERANCE,
    ZERO_SEPARATION_RTOL,
    Projection,
    project,
)
from oaraim.araim.mhss.root import (
    FAST_EXTRA_ROUNDS,
    FAST_PROOF_TOL_M,
    NEWTON_STEP_TOL_M,
    PL_ITERATIONS,
    PL_MARGIN_M,
    PL_TOLERANCE_M,
    Q_INVERSE_APPROX_MARGIN,
    pls_from_projection,
    q_function,
    q_inverse,
    q_inverse_approx,
    solve_pl,
    solve_pl_bracketed,
)
from oaraim.araim.mhss.switches import (
    SINGULAR_BAND,
    SWITCH_EMT,
    SWITCH_MODE_SET,
    SWITCH_RTOL,
    SWITCH_SINGULAR,
    SWITCH_UNMONITORED,
    switch_flags_kernel,
)

__all__ = [
    "FAST_EXTRA_ROUNDS",
    "FAST_PROOF_TOL_M",
    "MAX_AUTO_ORDER",
    "MHSSOptions",
    "MHSSResult",
    "NEWTON_STEP_TOL_M",
    "PL_ITERATIONS",
    "PL_MARGIN_M",
    "PL_TOLERANCE_M",
    "Projection",
    "Q_INVERSE_APPROX_MARGIN",
    "SINGLE_REDUNDANCY_TOLERANCE",
    "SINGULAR_BAND",
    "SWITCH_EMT",
    "SWITCH_MODE_SET",
    "SWITCH_RTOL",
    "SWITCH_SINGULAR",
    "SWITCH_UNMONITORED",
    "Sources",
    "UNIT_ROW_TOLERANCE",
    "ZERO_SEPARATION_RTOL",
    "as_options",
    "batch_last_inputs",
    "check_inputs",
    "check_options",
    "higher_order_flags",
    "host_inputs",
    "implicit_root",
    "kernel_cache_size",
    "kernel_options",
    "pls_from_projection",
    "prepare_inputs",
    "project",
    "protection_levels",
    "protection_levels_kernel",
    "protection_levels_priors_kernel",
    "protection_levels_threaded",
    "q_function",
    "q_inverse",
    "q_inverse_approx",
    "required_order",
    "risk_partials",
    "solve_pl",
    "solve_pl_bracketed",
    "switch_flags_kernel",
]
