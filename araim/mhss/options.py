"""The static options of every MHSS entry point as one frozen object, ``MHSSOptions``: the
fault-mode convention, the template order, the all-in-view weighting, the all-in-view
estimator and the PL solver's iteration bound. The host functions
(``araim.protection_levels``, ``solution_separation``, ``detect_and_exclude``,
``integrity_risk.monitor_maps``) and the kernels (``protection_levels_kernel``,
``separation_kernel``, ...) take it beside the ``Sources`` pytree, P_const and the
``IntegrityBudget`` (kept apart: the budget is the operation's requirement, the options how
the receiver meets it). It is a hashable NamedTuple, so a jitted kernel takes it as one static
argument; ``checked`` turns it into the canonical form the compiled programs are keyed on."""

from typing import NamedTuple

from oaraim.araim.fault_modes import FaultModeRule, check_order, fault_mode_rule
from oaraim.araim.mhss.root import PL_ITERATIONS
from oaraim.araim.position_opt import PositionOptimization, check_position_optimization
from oaraim.araim.validate import check_int

__all__ = ["MHSSOptions", "as_options"]

#: the weightings of the all-in-view solution S^(0): C_int^-1 (ADD, MAAST) or C_acc^-1 (seed
#: 004 after eq. 5)
WEIGHTINGS = ("int", "acc")


class MHSSOptions(NamedTuple):
    """How the MHSS receiver computes its protection levels (static: part of the compiled
    program). ``MHSSOptions()`` is the ADD baseline: ``add-v4.2`` fault modes, the order the
    batch needs, C_int^-1 weighting, the weighted least-squares all-in-view estimate."""

    max_order: int | None = None
    """The template order: most simultaneous events (event conventions, up to 2) or faulty
    constellations (``grouped``, up to 3) a monitored mode stands for. None (host functions
    only): the smallest the convention needs over the batch given; the kernels need an int.
    Geometries needing more get status UNMONITORED_RISK (their priors stay in P_NM)."""
    all_in_view_weighting: str = "int"
    """"int" (C_int^-1, ADD and MAAST, default) or "acc" (seed 004 after eq. 5)."""
    fault_modes: str | FaultModeRule | None = None
    """The fault-mode convention, a name or ``araim.FaultModeRule``: ``add-v4.2`` (None, the
    default), ``add-v3``, ``add-v3-consolidated``, ``blanch-2012``, ``grouped``
    (docs/conformance.md)."""
    position_optimization: PositionOptimization | None = None
    """None (the weighted least-squares all-in-view estimate) or an
    ``araim.PositionOptimization``: MAAST's use of the Blanch et al. (2015) estimator where the
    baseline misses a target (``protection_levels`` and its kernel only)."""
    iterations: int = PL_ITERATIONS
    """The iteration bound of the bracketed PL solver."""

    def checked(self, need_order: bool = False) -> "MHSSOptions":
        """The options in canonical form (``fault_modes`` a ``FaultModeRule``, numbers as
        ints, the estimator's limits as floats), each checked: a ValueError of one line naming
        the field otherwise. ``need_order``: ``max_order`` must be an int (the kernels)."""
        rule = fault_mode_rule(self.fault_modes)
        if self.all_in_view_weighting not in WEIGHTINGS:
            raise ValueError("all_in_view_weighting must be 'int' or 'acc', "
                             f"got {self.all_in_view_weighting!r}")
        order = self.max_order
        if order is None and need_order:
            raise ValueError("a kernel needs a static order: MHSSOptions(max_order=1) (or "
                             "araim.required_order on concrete probabilities)")
        if order is not None:
            order = check_order(rule, check_int("max_order", order, 1))
        return MHSSOptions(order, self.all_in_view_weighting, rule,
                           check_position_optimization(self.position_optimization),
                           check_int("iterations", self.iterations, 1))


def as_options(options: MHSSOptions | None) -> MHSSOptions:
    """``options`` itself, ``MHSSOptions()`` for None; a ValueError for anything else."""
    if options is None:
        return MHSSOptions()
    if not isinstance(options, MHSSOptions):
        raise ValueError("options must be an araim.MHSSOptions, e.g. "
                         f"araim.MHSSOptions(max_order=1), got {type(options).__name__}")
    return options
