"""``leo-sensitivity``: the Newton boundary on a closed form, the exact derivative against
finite differences, and a small run whose boundary lies where its grid changes sign."""

import jax.numpy as jnp
import numpy as np
import pytest

from oaraim import errors
from oaraim.registry import STUDIES
from oaraim.studies import leo_sensitivity as ls

STUDY = STUDIES["leo-sensitivity"]
SMALL = {"constellations": "starlink", "n_leo": "4", "sigma_ura_leo_m": "0.5,1,2,4,8",
         "p_s_leo": "1e-5"}


def test_boundary_closed_form():
    """Mean VPL change v(s) = s - 3 (m): LEO helps below 3 m; the boundary is where
    -v - TOL_M = 0, s = 3 - 0.002, found by Newton from the probes' bracket in a few steps."""
    root, n = ls.boundary(lambda s: (s - 3.0, 1.0))
    assert root == pytest.approx(3.0 - ls.TOL_M, rel=1e-3)
    assert n <= len(ls.PROBES_M) + 8
    assert np.isnan(ls.boundary(lambda s: (1.0 + s, 1.0))[0])  # never helps
    assert ls.boundary(lambda s: (-1.0, 0.0))[0] == np.inf  # helps at every probe


@pytest.fixture(scope="module")
def small(shared_data):
    p = STUDY.validate(SMALL)
    return p, STUDY.run(p, 96, 0)


def test_boundary_lies_where_the_grid_changes_sign(small):
    _, res = small
    ds = res.dataset
    dv = ds.vpl_change_m.values[0, 0, 0]  # (sigma,)
    sig = ds.sigma_ura_leo_m.values
    root = float(ds.sigma_boundary_m.values[0, 0, 0])
    helps = dv < -ls.TOL_M
    assert helps[0] and not helps[-1]  # 0.5 m LEO helps, 8 m does not (measured)
    k = int(np.flatnonzero(~helps)[0])
    assert sig[k - 1] <= root <= sig[k]
    assert float(ds.share_n_in_view.values[0, 0]) > 0.9


def test_exact_derivative_matches_finite_differences(small):
    p, _ = small
    d = {k: jnp.asarray(v) for k, v in ls.draws(p, 32, 0, "starlink").items()}
    sig = errors.LEO_SIGNALS["starlink"]
    pc = jnp.float64(1e-4)
    v0, h0 = ls.gnss_only(d, pc, signal=sig, fault_modes="grouped")
    keep = d["n_in_view"] >= 4
    f = lambda s: ls.cell(d, keep, 4, jnp.float64(s), (jnp.float64(-5.0), pc),  # noqa: E731
                          (v0, h0), setup=(1, sig, "grouped"))
    (v, dv) = (np.asarray(x) for x in f(3.0))
    e = 1e-4
    fd = (np.asarray(f(3.0 + e)[0]) - np.asarray(f(3.0 - e)[0])) / (2 * e)
    # central difference of a smooth function: error ~ e^2 f''' ~ 1e-8 m/m; 1e-5 leaves room
    # for the PL roots' solver tolerance (the derivative is exact, the values are roots)
    np.testing.assert_allclose(dv[:2], fd[:2], atol=1e-5, rtol=1e-4)
    assert v[0] > 0.0  # 3 m LEO ranging raises the mean VPL (the boundary is lower)
