"""S^(i) left to the reader that needs it: ``project(lazy_rows=True)`` returns a Projection
without ``s_pos`` but with its pieces (``ModeRows``), and ``position_rows`` builds the array
from them. The MHSS kernel does so under MAAST's position estimator, whose branch alone reads
S^(i) (building it for every chunk was 0.85 of 11.4 us per geometry of the 1 x 1 deg map).
The built array must be the projection's own, bit for bit: at order 1 (the all-in-view mode,
the single-source downdates, the whole constellations) and order 2 (Cholesky modes after
them)."""

import jax
import numpy as np
import pytest

from oaraim import araim
from oaraim.araim.fault_modes import fault_mode_rule
from oaraim.araim.mhss import MHSSOptions, Sources
from oaraim.araim.mhss.entry import batch_last_inputs
from oaraim.araim.mhss.projection import ModeRows, position_rows, project
from oaraim.bench import mhss_bench_inputs

BUDGET = araim.BUDGET_SEED004_TABLE_I


@pytest.mark.parametrize("rule,order", [("add-v4.2", 1), ("grouped", 1), ("grouped", 2)])
def test_rows_built_by_their_reader_are_the_projections(rule, order):
    x = mhss_bench_inputs(64, seed=3)
    args = batch_last_inputs(x["g"], x["constellation"], x["var_int_m2"], x["var_acc_m2"],
                             x["b_nom_m"], x["p_sat"], x["p_const"], x["valid"])
    fm = fault_mode_rule(rule)

    def proj(*a, lazy):
        return project(Sources(*a[:6], a[7]), a[6], BUDGET, MHSSOptions(order, fault_modes=fm),
                       lazy_rows=lazy)

    lazy = proj(*args, lazy=True)
    assert lazy.s_pos is None and isinstance(lazy.rows, ModeRows)
    assert proj(*args, lazy=False).rows is None
    eager = jax.jit(lambda *a: proj(*a, lazy=False).s_pos)(*args)
    built = jax.jit(lambda *a: position_rows(proj(*a, lazy=True)))(*args)
    np.testing.assert_array_equal(np.asarray(built), np.asarray(eager))
    assert np.any(np.asarray(eager)[1:] != 0.0)  # the modes' rows are there, not only zeros
