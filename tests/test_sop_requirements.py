"""The sop-requirements study: its root finder on closed-form functions, the grid-step check by
hand, and (in tests/test_studies.py) a small run against Fig. 4's grid on the same draws."""

import numpy as np
import pytest

from oaraim.studies import sop_requirements as sr
from oaraim.studies.sop_requirements_report import within_one_step


class _Closed:
    """f(sigma) given in closed form, with its derivative (the study's Cell interface)."""

    def __init__(self, f, df):
        self.f, self.df, self.evaluations = f, df, 0

    def value(self, s):
        self.evaluations += 1
        return self.f(s)

    def value_and_slope(self, s):
        self.evaluations += 1
        return self.f(s), self.df(s)


def test_largest_root_of_a_line_and_of_a_log():
    """f = 1 - s / 5.3 has its root at 5.3 m; f = -log(s / 7.7) at 7.7 m, where Newton in
    log sigma is exact in one step once bracketed."""
    r, steps = sr.largest_root(_Closed(lambda s: 1 - s / 5.3, lambda s: -1 / 5.3))
    assert r == pytest.approx(5.3, rel=1e-6) and steps <= sr.MAX_STEPS
    c = _Closed(lambda s: -np.log(s / 7.7), lambda s: -1 / s)
    r, steps = sr.largest_root(c)
    assert r == pytest.approx(7.7, rel=1e-9) and steps <= 3
    assert c.evaluations == len(sr.PROBES_M) + steps


def test_largest_of_two_roots_none_and_beyond():
    """(s - 1)(4 - s) > 0 between 1 and 4 m: the largest root is 4 m (the probe at 2 m is
    positive, the one at 8 m negative); never positive: NaN; positive at 25 m: inf."""
    f = lambda s: (s - 1.0) * (4.0 - s)  # noqa: E731
    df = lambda s: 5.0 - 2.0 * s  # noqa: E731
    assert sr.largest_root(_Closed(f, df))[0] == pytest.approx(4.0, rel=1e-6)
    assert np.isnan(sr.largest_root(_Closed(lambda s: -1.0, lambda s: 0.0))[0])
    assert sr.largest_root(_Closed(lambda s: 1.0, lambda s: 0.0))[0] == np.inf


def test_within_one_grid_step_by_hand():
    """Fig. 4's grid is 0.5, 1, 2, ..., 25 m: a boundary of 4 m takes roots in [4, 5)."""
    assert within_one_step(np.array([4.0, 4.99, 5.0, 3.9]), np.array([4.0, 4.0, 4.0, 4.0])) \
        .tolist() == [True, True, False, False]
    assert within_one_step(np.array([0.3, np.nan, 30.0]), np.array([np.nan, np.nan, 25.0])) \
        .tolist() == [True, True, True]
