"""Why the ``leo-sensitivity`` boundary dips at P_s^LEO = 1e-5 (docs/leo.md): under seed 004's
``grouped`` rule the order-1 unmonitored probability is P(two or more of the three
constellations faulty), P_NM = p_G p_E + p_G p_L + p_E p_L - 2 p_G p_E p_L with
p_c = 1 - (1 - P_const,c) prod_l (1 - P_s,l); the LEO term grows with P_s^LEO and takes
integrity budget from the PLs (P_HMI (1 - P_NM / P_HMI)) until it passes P_THRES, where the
rule (``order_for``) monitors pairs and P_NM drops. The switch is checked here against that
closed form, over a fine P_s^LEO grid, for the study's slot counts."""

import numpy as np
import pytest

from oaraim import araim
from oaraim.studies import leo_sensitivity as ls

P_CONST_LEO = 1e-4


def p_nm_order1(ng, n, p_s):
    """P(two or more constellations faulty): GPS (ng + 1) // 2 and Galileo ng // 2 sources at
    1e-5 (``order_for``'s slots), the LEO constellation n at p_s."""
    gps, gal = ls.GNSS_ISM
    p = [1.0 - (1.0 - gps.p_const) * (1.0 - 1e-5) ** ((ng + 1) // 2),
         1.0 - (1.0 - gal.p_const) * (1.0 - 1e-5) ** (ng // 2),
         1.0 - (1.0 - P_CONST_LEO) * (1.0 - p_s) ** n]
    return p[0] * p[1] + p[0] * p[2] + p[1] * p[2] - 2.0 * p[0] * p[1] * p[2]


@pytest.mark.parametrize("ng, n", [(18, 4), (22, 4), (22, 12)])
def test_order_switches_where_p_nm_passes_p_thresh(ng, n):
    thresh = araim.BUDGET_LPV200.p_thresh
    grid = np.geomspace(1e-7, 1e-3, 25)
    orders = np.array([ls.order_for(ng, n, p, P_CONST_LEO, "grouped") for p in grid])
    p_nm = np.array([p_nm_order1(ng, n, p) for p in grid])
    assert np.all(np.diff(p_nm) > 0)  # more LEO faults, more unmonitored risk at order 1
    np.testing.assert_array_equal(orders, np.where(p_nm > thresh, 2, 1))
    assert orders[0] == 1 and orders[-1] == 2  # the switch lies inside the study's P_s grid


def test_the_study_grid_straddles_the_switch():
    """With 4 LEO satellites and ~20 GNSS slots the switch lies between the study's 1e-5 (order
    1, P_NM already 6e-8 of the 8e-8 with every slot in view) and 1e-4 (order 2): the
    boundary's dip."""
    assert ls.order_for(20, 4, 1e-5, P_CONST_LEO, "grouped") == 1
    assert ls.order_for(20, 4, 1e-4, P_CONST_LEO, "grouped") == 2
    assert 4e-8 < p_nm_order1(20, 4, 1e-5) < araim.BUDGET_LPV200.p_thresh
