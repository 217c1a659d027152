"""Tests of araim.chi2: detection threshold and missed-detection non-centrality (seed 001 sec. 3.1).

Tolerances: these are host-side SciPy computations. The threshold is one call of
``chi2.isf``; the closed forms below agree with it to a few ulps, so 1e-12 relative is loose by
three orders of magnitude. The non-centrality is a root found to ``xtol = 1e-12`` absolute on
values of order 1 to 200; independent solutions (bisection in tests.reference, Brent on the
normal cdf for dof = 1) must agree to 1e-10 relative, which leaves margin for the accuracy of the
non-central cdf at tail probabilities down to 1e-7 (measured agreement is ~1e-14).
"""

import math

import numpy as np
import pytest
from scipy import optimize, special, stats

from oaraim import araim
from oaraim.reference import lambda_det_reference

P_FAS = [1e-2, 1e-3, 1e-5, 1e-7]
P_MDS = [1e-1, 1e-3, 1e-5, 1e-7]


# ------------------------------------------------------------------------ detection_threshold


@pytest.mark.parametrize("p_fa", [0.5, 1e-2, 1e-3, 1e-5, 1e-7, 1e-9])
@pytest.mark.parametrize("dof", [1, 2, 3, 5, 8, 14])
def test_threshold_matches_scipy(p_fa, dof):
    t = araim.detection_threshold(p_fa, dof)
    assert isinstance(t, float)
    assert t == pytest.approx(stats.chi2.isf(p_fa, dof), rel=1e-12)
    # definition: P(chi2_dof > T) = P_FA
    assert stats.chi2.sf(t, dof) == pytest.approx(p_fa, rel=1e-9)


@pytest.mark.parametrize("p_fa", [0.3, 1e-2, 1e-4, 1e-7, 1e-9, 1e-12])
def test_threshold_dof2_is_exponential(p_fa):
    # chi2 with 2 dof is exponential with mean 2: P(X > T) = exp(-T / 2)  =>  T = -2 ln P_FA
    assert araim.detection_threshold(p_fa, 2) == pytest.approx(-2.0 * math.log(p_fa), rel=1e-12)


@pytest.mark.parametrize("p_fa", [0.3, 1e-2, 1e-4, 1e-7, 1e-9, 1e-12])
def test_threshold_dof1_is_squared_normal_quantile(p_fa):
    # chi2 with 1 dof is Z^2: P(Z^2 > T) = 2 Q(sqrt T) = P_FA  =>  T = (Phi^-1(1 - P_FA / 2))^2.
    # Phi^-1(1 - p/2) = -Phi^-1(p/2); the latter avoids forming 1 - p/2 (cancellation for tiny p).
    expected = special.ndtri(0.5 * p_fa) ** 2
    assert araim.detection_threshold(p_fa, 1) == pytest.approx(expected, rel=1e-12)
    if p_fa >= 1e-9:  # 1 - p/2 is still accurate to ~1e-7 relative in p here
        assert araim.detection_threshold(p_fa, 1) == pytest.approx(
            special.ndtri(1.0 - 0.5 * p_fa) ** 2, rel=1e-6
        )


# ------------------------------------------------------------------------------ noncentrality


def _lambda_dof1_closed_form(p_fa, p_md):
    """dof = 1: the statistic is (Z + mu)^2 with mu = sqrt(lambda). Missed detection:
    P(-sqrt T < Z + mu < sqrt T) = Phi(sqrt T - mu) - Phi(-sqrt T - mu) = P_MD."""
    root_t = -special.ndtri(0.5 * p_fa)  # sqrt of the dof-1 threshold, see above

    def excess(mu):
        return special.ndtr(root_t - mu) - special.ndtr(-root_t - mu) - p_md

    mu = optimize.brentq(excess, 0.0, root_t + 40.0, xtol=1e-14, rtol=4 * np.finfo(float).eps)
    return mu**2


@pytest.mark.parametrize("p_fa", P_FAS)
@pytest.mark.parametrize("p_md", P_MDS)
def test_noncentrality_dof1_closed_form(p_fa, p_md):
    lam = araim.noncentrality(p_fa, p_md, 1)
    assert isinstance(lam, float)
    assert lam == pytest.approx(_lambda_dof1_closed_form(p_fa, p_md), rel=1e-10)


def test_noncentrality_dof1_hand_value():
    # P_FA = 0.05 = 2 Q(1.9599640): sqrt T = 1.9599640. P_MD = 1/2 asks for
    # Phi(sqrt T - mu) - Phi(-sqrt T - mu) = 1/2. Writing mu = sqrt T + x:
    # Phi(-x) = 1/2 + Phi(-2 sqrt T - x) ~ 1/2 + Phi(-3.92) = 1/2 + 4.43e-5, so
    # x = -4.43e-5 sqrt(2 pi) = -1.111e-4 and mu = 1.959853 (to ~1e-7: the next term is
    # O(x * 4e-5) and Phi's curvature at 0 vanishes).
    lam = araim.noncentrality(0.05, 0.5, 1)
    assert math.sqrt(lam) == pytest.approx(1.959853, abs=1e-6)


@pytest.mark.parametrize("dof", range(1, 11))
def test_noncentrality_matches_reference(dof):
    for p_fa, p_md in [(1e-2, 1e-1), (1e-3, 1e-3), (1e-5, 1e-3), (1e-7, 1e-7), (0.2, 0.3)]:
        lam = araim.noncentrality(p_fa, p_md, dof)
        ref = lambda_det_reference(p_fa, p_md, dof)
        assert lam == pytest.approx(ref, rel=1e-10), (p_fa, p_md, dof)
        # definition: P(ncx2_dof(lambda) < T) = P_MD
        t = araim.detection_threshold(p_fa, dof)
        assert stats.ncx2.cdf(t, dof, lam) == pytest.approx(p_md, rel=1e-8)


def test_noncentrality_monotonic():
    dofs = range(1, 15)
    for p_fa in P_FAS:
        for p_md in P_MDS:
            lams = [araim.noncentrality(p_fa, p_md, d) for d in dofs]
            # more degrees of freedom dilute the bias: a larger non-centrality is needed
            assert np.all(np.diff(lams) > 0), (p_fa, p_md, lams)
    for dof in (1, 4, 9):
        # smaller P_FA -> higher threshold -> larger lambda; smaller P_MD -> larger lambda
        by_fa = [araim.noncentrality(p, 1e-3, dof) for p in P_FAS]
        by_md = [araim.noncentrality(1e-3, p, dof) for p in P_MDS]
        assert np.all(np.diff(by_fa) > 0), by_fa
        assert np.all(np.diff(by_md) > 0), by_md


def test_noncentrality_zero_when_no_bias_needed():
    # 1 - P_FA <= P_MD: the fault-free statistic already misses with probability >= P_MD
    assert araim.noncentrality(0.6, 0.5, 3) == 0.0


# ---------------------------------------------------------------------------- bad user input


@pytest.mark.parametrize(
    ("kwargs", "field", "shown"),
    [
        ({"p_fa": 1e-3, "p_md": 2}, "p_md", "2"),
        ({"p_fa": 0, "p_md": 1e-3}, "p_fa", "0"),
        ({"p_fa": 0.0, "p_md": 1e-3}, "p_fa", "0.0"),
        ({"p_fa": -1, "p_md": 1e-3}, "p_fa", "-1"),
        ({"p_fa": 1e-3, "p_md": 1.0}, "p_md", "1.0"),
        ({"p_fa": "x", "p_md": 1e-3}, "p_fa", "'x'"),
        ({"p_fa": None, "p_md": 1e-3}, "p_fa", "None"),
        ({"p_fa": float("nan"), "p_md": 1e-3}, "p_fa", "nan"),
    ],
)
def test_bad_probabilities_raise_naming_field(kwargs, field, shown):
    with pytest.raises(ValueError) as exc:
        araim.noncentrality(dof=3, **kwargs)
    msg = str(exc.value)
    assert field in msg and shown in msg, msg
    if field == "p_fa":
        with pytest.raises(ValueError, match=field) as exc:
            araim.detection_threshold(kwargs["p_fa"], 3)
        assert shown in str(exc.value)
    with pytest.raises(ValueError, match=field):
        araim.lambda_det_table(kwargs["p_fa"], kwargs["p_md"], 4)


@pytest.mark.parametrize("dof", [0, -1, 2.5, "three"])
def test_bad_dof_raises(dof):
    with pytest.raises(ValueError, match="dof"):
        araim.detection_threshold(1e-3, dof)
    with pytest.raises(ValueError, match="dof"):
        araim.noncentrality(1e-3, 1e-3, dof)


# --------------------------------------------------------------------------- lambda_det_table


def test_lambda_det_table():
    table = araim.lambda_det_table(1e-5, 1e-3, 12)
    assert isinstance(table, np.ndarray)
    assert table.shape == (13,)
    assert table.dtype == np.float64
    assert table[0] == np.inf
    for dof in range(1, 13):
        assert table[dof] == araim.noncentrality(1e-5, 1e-3, dof)
    assert not table.flags.writeable
    with pytest.raises(ValueError):
        table[3] = 0.0
    # the cached table cannot be corrupted through the returned object either
    assert araim.lambda_det_table(1e-5, 1e-3, 12)[3] == araim.noncentrality(1e-5, 1e-3, 3)
