"""Tests of araim.slopes / araim.slope_hpl: chi-square snapshot RAIM, seed 001 section 3.1.

    slope_i = sqrt(B_1i^2 + B_2i^2) sqrt(R_ii) / sqrt(S_ii),   HPL = slope_max sqrt(lambda_det)

Compiled shapes are kept few (DESIGN.md): the random oracle runs at a padded L = 18, the small
cases at L = 8 (batched) or L = 12 / 7 (padding property).
"""

import functools
from fractions import Fraction

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from oaraim import araim, geometry
from oaraim.araim import Status
from oaraim.reference import lambda_det_reference, slope_hpl_reference, slopes_reference

L_BIG = 18  # 12 satellites + 6 towers at most
L_SMALL = 8
MASK = np.deg2rad(10.0)
PAIRS = [(1e-3, 1e-3), (1e-5, 1e-3), (1e-7, 1e-7), (3.33e-7, 1e-4)]  # (P_FA, P_MD)
PER_PAIR = 300  # geometries per (P_FA, P_MD) pair: 1200 in all

_sky = jax.jit(geometry.random_sky, static_argnums=(1, 3))
_bpp = jax.jit(geometry.bpp_towers, static_argnums=(1, 6))


def _rows(az_rad, el_rad):
    """geometry_rows in NumPy for the small hand-built cases (geometry_rows itself is tested in
    test_geometry_random.py; this avoids compiling it for every small shape)."""
    az, el = np.broadcast_arrays(np.asarray(az_rad, float), np.asarray(el_rad, float))
    return np.stack([-np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), -np.sin(el)], axis=-1)


@functools.cache
def _lambda_ref(p_fa, p_md, dof):
    return lambda_det_reference(p_fa, p_md, dof)


def _random_geometries(seed, n):
    """n geometries of 5..12 random-sky satellites and 0..6 BPP towers (half of the geometries
    with towers on the horizon, half with heights 0..150 m), per-source sigma ~ U[0.3, 8] m,
    the valid rows scattered over L = 18 (each geometry's rows shuffled), padding rows holding
    finite junk with sigma = 1."""
    k_sky, k_tow0, k_towh = jax.random.split(jax.random.key(seed), 3)
    az_s, el_s = _sky(k_sky, 12, MASK, (n,))
    flat = _bpp(k_tow0, 6, 5.0, 3000.0, 0.0, 0.0, (n,))
    high = _bpp(k_towh, 6, 5.0, 3000.0, 0.0, 150.0, (n,))
    assert np.all(np.asarray(flat.el_rad) == 0.0)
    rng = np.random.default_rng(seed)
    with_height = rng.random(n) < 0.5
    az_t = np.where(with_height[:, None], high.az_rad, flat.az_rad)
    el_t = np.where(with_height[:, None], high.el_rad, flat.el_rad)
    az = np.concatenate([np.asarray(az_s), az_t], axis=1)
    el = np.concatenate([np.asarray(el_s), el_t], axis=1)
    n_sat = rng.integers(5, 13, n)
    n_tow = rng.integers(0, 7, n)
    idx = np.arange(L_BIG)
    valid = (idx < n_sat[:, None]) | ((idx >= 12) & (idx < 12 + n_tow[:, None]))
    sigma = rng.uniform(0.3, 8.0, (n, L_BIG))
    g = np.array(geometry.geometry_rows(az, el))
    g[~valid] = rng.normal(0.0, 50.0, (np.sum(~valid), 3))  # junk padding
    sigma[~valid] = 1.0
    perm = np.argsort(rng.random((n, L_BIG)), axis=1)
    take = np.take_along_axis
    return take(g, perm[..., None], 1), take(sigma, perm, 1), take(valid, perm, 1)


@pytest.fixture(scope="module")
def oracle_cases():
    g, sigma, valid = _random_geometries(20240601, len(PAIRS) * PER_PAIR)
    results = []
    for k, (p_fa, p_md) in enumerate(PAIRS):
        sl = slice(k * PER_PAIR, (k + 1) * PER_PAIR)
        results.append(araim.slope_hpl(g[sl], sigma[sl], p_fa=p_fa, p_md=p_md, valid=valid[sl]))
    return g, sigma, valid, results


# ---------------------------------------------------------------------------------- oracle


def _slopes_exact(g, sigma_m):
    """Seed 001 slopes in exact rational arithmetic (the float64 inputs are exact rationals),
    with only the final square root rounded: the arbiter where float64 codes disagree."""
    h = [[Fraction(float(x)) for x in row] + [Fraction(1)] for row in g]
    w = [1 / Fraction(float(s)) ** 2 for s in sigma_m]
    n = [
        [sum(wl * hl[a] * hl[b] for wl, hl in zip(w, h, strict=True)) for b in range(4)]
        for a in range(4)
    ]
    aug = [row + [Fraction(int(i == j)) for j in range(4)] for i, row in enumerate(n)]
    for c in range(4):  # Gauss-Jordan inverse of the normal matrix
        p = next(r for r in range(c, 4) if aug[r][c] != 0)
        aug[c], aug[p] = aug[p], aug[c]
        aug[c] = [x / aug[c][c] for x in aug[c]]
        for r in range(4):
            if r != c:
                aug[r] = [x - aug[r][c] * y for x, y in zip(aug[r], aug[c], strict=True)]
    p_mat = [row[4:] for row in aug]
    out = []
    for wl, hl in zip(w, h, strict=True):
        ph = [sum(p_mat[a][b] * hl[b] for b in range(4)) for a in range(4)]
        s_ii = 1 - wl * sum(x * y for x, y in zip(hl, ph, strict=True))
        out.append(np.sqrt(float(wl * (ph[0] ** 2 + ph[1] ** 2) / s_ii)))
    return np.array(out)


def _close(x, ref, rel):
    """Relative agreement; a slope near zero (a source near the zenith) is compared against the
    geometry's largest slope, since its own relative error is not defined by the data."""
    return np.all(np.abs(np.asarray(x) - ref) <= rel * np.abs(ref) + rel * np.max(ref))


def _assert_rows_close(actual, desired, rel):
    """Per geometry (last axis = sources), relative agreement with the same near-zero rule."""
    actual, desired = np.asarray(actual), np.asarray(desired)
    scale = np.max(np.abs(desired), axis=-1, keepdims=True)
    err = np.abs(actual - desired) - rel * np.abs(desired) - rel * scale
    assert np.all(err <= 0), np.max(err)


def test_oracle_slopes_and_hpl(oracle_cases):
    """1200 random geometries against tests.reference, relative agreement 1e-9.

    Both solve the same small weighted normal equations in float64; for well-conditioned
    geometries they agree to ~1e-12. Near an undetectable fault (S_ii ~ 1e-5, dof = 1) the
    reference, which forms explicit inverses and S = I - H B densely, loses accuracy like
    eps / S_ii times the condition number (measured: 6e-9 off at S_ii = 3e-5, against 3e-10
    for araim). Where the two disagree by more than 1e-9, exact rational arithmetic decides and
    araim must be within 1e-9 of it; such arbitrations must stay rare.
    """
    g, sigma, valid, results = oracle_cases
    n_checked = n_arbitrated = 0
    for k, (p_fa, p_md) in enumerate(PAIRS):
        res = results[k]
        hpl = np.asarray(res.hpl_m)
        slopes = np.asarray(res.slopes)
        assert np.all(np.asarray(res.status) == Status.OK)
        for b in range(PER_PAIR):
            i = k * PER_PAIR + b
            v = valid[i]
            ref = slopes_reference(g[i][v], sigma[i][v])
            if not _close(slopes[b][v], ref, 1e-9):
                n_arbitrated += 1
                ref = _slopes_exact(g[i][v], sigma[i][v])
            assert _close(slopes[b][v], ref, 1e-9), (i, slopes[b][v], ref)
            np.testing.assert_array_equal(slopes[b][~v], 0.0)
            dof = int(v.sum()) - 4
            assert int(res.dof[b]) == dof
            lam = _lambda_ref(p_fa, p_md, dof)
            assert float(res.slope_max[b]) == pytest.approx(ref.max(), rel=1e-9)
            assert float(res.lambda_det[b]) == pytest.approx(lam, rel=1e-9)
            assert hpl[b] == pytest.approx(ref.max() * np.sqrt(lam), rel=1e-9), i
            n_checked += 1
        # the reference's own HPL function, literally, on a few geometries per pair
        for b in range(0, PER_PAIR, 60):
            i = k * PER_PAIR + b
            v = valid[i]
            assert hpl[b] == pytest.approx(
                slope_hpl_reference(g[i][v], sigma[i][v], p_fa, p_md), rel=1e-9
            )
    assert n_checked >= 1000
    assert n_arbitrated <= n_checked // 100, n_arbitrated


def test_exact_arbiter_agrees_with_reference(oracle_cases):
    """The rational arbiter above is itself checked against the reference (well-conditioned
    geometries: 1e-11 relative)."""
    g, sigma, valid, _ = oracle_cases
    for i in range(0, 1200, 150):
        v = valid[i]
        ref = slopes_reference(g[i][v], sigma[i][v])
        assert _close(_slopes_exact(g[i][v], sigma[i][v]), ref, 1e-11)


def test_oracle_cases_cover_the_ranges(oracle_cases):
    """The oracle set really holds what it claims (guards the generator above)."""
    g, sigma, valid, _ = oracle_cases
    n_valid = valid.sum(axis=1)
    assert n_valid.min() == 5 and n_valid.max() == 18
    el = -np.arcsin(np.clip(g[..., 2], -1, 1))
    horizon = valid & (el == 0.0)
    assert horizon.sum() > 500  # towers exactly on the horizon
    assert np.sum(valid & (el > 0) & (el < MASK)) > 200  # towers with heights
    assert sigma[valid].min() >= 0.3 and sigma[valid].max() <= 8.0


def test_slopes_function_equals_slope_hpl(oracle_cases):
    g, sigma, valid, results = oracle_cases
    s = araim.slopes(g, sigma, valid)
    for k in range(len(PAIRS)):
        sl = slice(k * PER_PAIR, (k + 1) * PER_PAIR)
        np.testing.assert_array_equal(s.slopes[sl], results[k].slopes)
        np.testing.assert_array_equal(s.slope_max[sl], results[k].slope_max)
        np.testing.assert_array_equal(s.status[sl], results[k].status)
        np.testing.assert_array_equal(s.dof[sl], results[k].dof)


def test_batch_shape_invariance(oracle_cases):
    g, sigma, valid, results = oracle_cases
    p_fa, p_md = PAIRS[0]
    n = PER_PAIR
    flat = results[0]
    nested = araim.slope_hpl(
        g[:n].reshape(20, 15, L_BIG, 3),
        sigma[:n].reshape(20, 15, L_BIG),
        p_fa=p_fa,
        p_md=p_md,
        valid=valid[:n].reshape(20, 15, L_BIG),
    )
    for name in flat._fields:
        a = np.asarray(getattr(flat, name))
        b = np.asarray(getattr(nested, name)).reshape(a.shape)
        # per-geometry arithmetic does not depend on the batch layout: 1e-15 relative allows
        # only for a different vectorisation of the same operations
        np.testing.assert_allclose(b, a, rtol=1e-15, atol=0, err_msg=name)


def test_tiled_batch_equals_the_untiled_kernel():
    """``slope_hpl`` evaluates batches larger than ``SLOPE_TILE`` in tiles (padding the last
    with a real geometry): every output equals the untiled kernel's within 1e-12 relative,
    failures included, and a nested batch shape comes back."""
    import importlib

    slopes_mod = importlib.import_module("oaraim.araim.slopes")
    n = 2 * slopes_mod.SLOPE_TILE + 5
    g, sigma, valid = _random_geometries(11, n)
    valid[::97] = False  # too few sources: inf with a status
    table = np.asarray(araim.lambda_det_table(1e-5, 1e-3, L_BIG - 4))
    got = araim.slope_hpl(g, sigma, p_fa=1e-5, p_md=1e-3, valid=valid)
    want = araim.slope_hpl_kernel(g, sigma, valid, table)
    assert got.hpl_m.shape == (n,)
    assert np.any(np.asarray(want.status) != 0) and np.any(np.asarray(want.status) == 0)
    for name in got._fields:
        a, b = np.asarray(getattr(got, name)), np.asarray(getattr(want, name))
        fin = np.isfinite(b)
        np.testing.assert_array_equal(np.isfinite(a), fin, err_msg=name)
        np.testing.assert_allclose(a[fin], b[fin], rtol=1e-12, atol=0, err_msg=name)
        np.testing.assert_array_equal(a[~fin], b[~fin], err_msg=name)
    s = araim.slopes(g[:-5].reshape(2, -1, L_BIG, 3), sigma[:-5].reshape(2, -1, L_BIG),
                     valid[:-5].reshape(2, -1, L_BIG))
    np.testing.assert_array_equal(np.asarray(s.slope_max).ravel(),
                                  np.asarray(got.slope_max)[:-5])


def _min_redundancy(g, sigma, valid):
    """min_i S_ii per geometry (NumPy): how close the geometry is to an undetectable fault."""
    out = np.empty(len(g))
    for b in range(len(g)):
        v = valid[b]
        h = np.hstack([g[b][v], np.ones((v.sum(), 1))])
        w = 1.0 / sigma[b][v] ** 2
        p = np.linalg.inv(h.T @ (w[:, None] * h))
        out[b] = np.min(1.0 - w * np.einsum("li,ij,lj->l", h, p, h))
    return out


def _assert_invariant(new, base, g, sigma, valid):
    """Exact-in-theory invariances only change rounding. A rounding perturbation is amplified
    by ~1 / S_ii: 1e-12 relative where every S_ii > 0.01 (~90 % of the random set), 1e-10 on
    the near-undetectable rest (measured worst: 3e-11 at S_ii = 2e-3)."""
    well = _min_redundancy(g, sigma, valid) > 0.01
    assert well.mean() > 0.8
    _assert_rows_close(np.asarray(new.slopes)[well], np.asarray(base.slopes)[well], 1e-12)
    _assert_rows_close(new.slopes, base.slopes, 1e-10)
    np.testing.assert_allclose(
        np.asarray(new.hpl_m)[well], np.asarray(base.hpl_m)[well], rtol=1e-12, atol=0
    )
    np.testing.assert_allclose(new.hpl_m, base.hpl_m, rtol=1e-10, atol=0)
    np.testing.assert_array_equal(new.status, base.status)


def test_sigma_scaling_law(oracle_cases):
    # R -> k^2 R leaves B = (H^T R^-1 H)^-1 H^T R^-1 and S = I - H B unchanged (the k^-2
    # cancels) and multiplies sqrt(R_ii) by k: every slope, and the HPL, scale by k.
    g, sigma, valid, results = oracle_cases
    p_fa, p_md = PAIRS[0]
    k = 3.7
    scaled = araim.slope_hpl(
        g[:PER_PAIR], k * sigma[:PER_PAIR], p_fa=p_fa, p_md=p_md, valid=valid[:PER_PAIR]
    )
    base = results[0]
    expected = base._replace(slopes=k * np.asarray(base.slopes), hpl_m=k * np.asarray(base.hpl_m))
    sl = slice(0, PER_PAIR)
    _assert_invariant(scaled, expected, g[sl], sigma[sl], valid[sl])


def test_rotation_of_azimuths_leaves_slopes_unchanged(oracle_cases):
    # Rotating every azimuth by alpha multiplies H by D = blockdiag(Rot(alpha), 1, 1) on the
    # right: P -> D^-1 P D^-T, B -> D^-1 B, S unchanged; the horizontal column of B is rotated,
    # its norm (the slope) is not.
    g, sigma, valid, results = oracle_cases
    p_fa, p_md = PAIRS[0]
    alpha = 1.234
    c, s = np.cos(alpha), np.sin(alpha)
    # rotating (east, north) = (-cos el sin az, -cos el cos az) by az -> az + alpha
    gr = g[:PER_PAIR].copy()
    e, n = gr[..., 0].copy(), gr[..., 1].copy()
    gr[..., 0] = c * e + s * n
    gr[..., 1] = -s * e + c * n
    rot = araim.slope_hpl(gr, sigma[:PER_PAIR], p_fa=p_fa, p_md=p_md, valid=valid[:PER_PAIR])
    sl = slice(0, PER_PAIR)
    _assert_invariant(rot, results[0], g[sl], sigma[sl], valid[sl])
    # the rotated rows are those of the azimuths + alpha (checks the construction above)
    v = valid[0]
    az = np.arctan2(-g[0][v][:, 0], -g[0][v][:, 1])
    el = -np.arcsin(g[0][v][:, 2])
    np.testing.assert_allclose(gr[0][v], _rows(az + alpha, el), rtol=0, atol=1e-15)


# ----------------------------------------------------------------------- hand-derived cases

# Ring-and-zenith geometry. Four sources at elevation e, azimuths 0, 90, 180, 270 deg, standard
# deviation sigma_a (weight a = 1 / sigma_a^2), plus k sources at the zenith with weight z each
# (Z = k z). With c = cos e, s = sin e the rows h = [g, 1] are
#     [0, -c, -s, 1], [-c, 0, -s, 1], [0, c, -s, 1], [c, 0, -s, 1]   and k x [0, 0, -1, 1].
# The normal matrix N = H^T W H is block diagonal:
#     N_EE = N_NN = 2 a c^2, N_EN = 0, and no E/N coupling to (up, clock) since the ring's
#     east and north components cancel in pairs;
#     (up, clock) block M = [[4 a s^2 + Z, -(4 a s + Z)], [-(4 a s + Z), 4 a + Z]],
#     det M = 4 a Z (1 - s)^2,  M^-1 = [[4 a + Z, 4 a s + Z], [4 a s + Z, 4 a s^2 + Z]] / det M.
# For a ring source, the (up, clock) part [-s, 1] gives
#     [-s, 1] M^-1 [-s, 1]^T = Z (s^2 - 2 s + 1) / (4 a Z (1 - s)^2) = 1 / (4 a),
# and the horizontal part (norm c) gives c^2 / (2 a c^2) = 1 / (2 a); so h^T P h = 3 / (4 a) and
#     S_ii = 1 - a h^T P h = 1/4,     |(P h)_EN| = c / (2 a c^2) = 1 / (2 a c),
#     slope^2 = a |(P h)_EN|^2 / S_ii = 1 / (a c^2)   =>   slope = sigma_a / cos(e),
# independent of k and of the zenith sigma. For a zenith source [-1, 1] M^-1 [-1, 1]^T
# = 4 a (1 - s)^2 / det M = 1 / Z, so S_ii = 1 - z / Z = 1 - 1/k, and its slope is 0 (no
# horizontal component). Check: trace S = 4/4 + k (1 - 1/k) = k = n - 4 = dof.
# Hence HPL = sigma_a / cos(e) sqrt(lambda_det(dof = k)) for k >= 2, while k = 1 leaves the
# zenith source with S_ii = 0: its fault is undetectable (the four ring sources alone cannot
# separate up from the clock), so HPL = inf with UNDETECTABLE_FAULT.

HAND_CASES = [  # (e_deg, sigma_ring, sigma_zenith, k_zenith)
    (0.0, 1.0, 1.0, 2),
    (20.0, 1.0, 1.0, 2),
    (35.0, 2.5, 0.7, 2),
    (60.0, 0.4, 3.0, 3),
    (15.0, 6.0, 6.0, 4),
    (45.0, 1.0, 1.0, 1),  # no redundancy for the zenith source
    (10.0, 3.0, 0.5, 1),
    (80.0, 1.0, 2.0, 2),
]


def _ring_zenith_batch(rotation_rad=0.0):
    g = np.zeros((len(HAND_CASES), L_SMALL, 3))
    sigma = np.ones((len(HAND_CASES), L_SMALL))
    valid = np.zeros((len(HAND_CASES), L_SMALL), bool)
    for b, (e_deg, s_a, s_z, k) in enumerate(HAND_CASES):
        az = np.deg2rad([0.0, 90.0, 180.0, 270.0] + [0.0] * k) + rotation_rad
        el = np.deg2rad([e_deg] * 4 + [90.0] * k)
        g[b, : 4 + k] = _rows(az, el)
        sigma[b, : 4 + k] = [s_a] * 4 + [s_z] * k
        valid[b, : 4 + k] = True
    return g, sigma, valid


@pytest.mark.parametrize("rotation_deg", [0.0, 17.0])
def test_ring_and_zenith_closed_form(rotation_deg):
    p_fa, p_md = 1e-5, 1e-3
    g, sigma, valid = _ring_zenith_batch(np.deg2rad(rotation_deg))
    res = araim.slope_hpl(g, sigma, p_fa=p_fa, p_md=p_md, valid=valid)
    for b, (e_deg, s_a, _s_z, k) in enumerate(HAND_CASES):
        assert int(res.dof[b]) == k
        if k == 1:
            assert int(res.status[b]) == Status.UNDETECTABLE_FAULT
            assert res.hpl_m[b] == np.inf
            assert res.slope_max[b] == np.inf
            assert res.lambda_det[b] == np.inf
            continue
        expected = s_a / np.cos(np.deg2rad(e_deg))
        assert int(res.status[b]) == Status.OK
        np.testing.assert_allclose(res.slopes[b, :4], expected, rtol=1e-12)
        # zenith rows: horizontal component cos(pi/2) = 6e-17, so slopes ~1e-16 m
        np.testing.assert_array_less(np.asarray(res.slopes[b, 4 : 4 + k]), 1e-12 * s_a)
        np.testing.assert_array_equal(res.slopes[b, 4 + k :], 0.0)
        lam = araim.noncentrality(p_fa, p_md, k)
        assert float(res.hpl_m[b]) == pytest.approx(expected * np.sqrt(lam), rel=1e-12)


# ---------------------------------------------------------------------------------- padding


def _small_geometry(seed, n):
    rng = np.random.default_rng(seed)
    n_tow = n // 3
    az = rng.uniform(0, 2 * np.pi, n)
    el = np.concatenate([rng.uniform(MASK, 0.5 * np.pi, n - n_tow), np.zeros(n_tow)])
    return _rows(az, el), rng.uniform(0.3, 8.0, n)


N_PAD_VALID, N_PAD = 7, 12
N_JUNK = N_PAD - N_PAD_VALID
_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def _compare_padded(base, padded, pos, rel=1e-12):
    assert int(padded.status) == int(base.status)
    assert int(padded.dof) == int(base.dof)
    assert float(padded.hpl_m) == pytest.approx(float(base.hpl_m), rel=rel)
    assert float(padded.lambda_det) == float(base.lambda_det)
    smax = float(base.slope_max)
    np.testing.assert_allclose(padded.slopes[pos], base.slopes, rtol=rel, atol=rel * smax)
    invalid = np.ones(N_PAD, bool)
    invalid[pos] = False
    np.testing.assert_array_equal(padded.slopes[invalid], 0.0)


@settings(max_examples=30, deadline=None, derandomize=True, database=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    perm=st.permutations(range(N_PAD)),
    junk_g=st.lists(_finite, min_size=3 * N_JUNK, max_size=3 * N_JUNK),
    junk_sigma=st.lists(st.floats(1e-3, 1e3), min_size=N_JUNK, max_size=N_JUNK),
)
def test_padding_invariance_property(seed, perm, junk_g, junk_sigma):
    """Invalid rows anywhere, holding any finite geometry, never change a result."""
    p_fa, p_md = 1e-5, 1e-3
    g, sigma = _small_geometry(seed, N_PAD_VALID)
    base = araim.slope_hpl(g, sigma, p_fa=p_fa, p_md=p_md)
    pos = np.sort(np.asarray(perm[:N_PAD_VALID]))
    invalid = np.ones(N_PAD, bool)
    invalid[pos] = False
    gp = np.zeros((N_PAD, 3))
    sp = np.zeros(N_PAD)
    gp[pos], sp[pos] = g, sigma
    gp[invalid] = np.reshape(junk_g, (-1, 3))
    sp[invalid] = junk_sigma
    padded = araim.slope_hpl(gp, sp, p_fa=p_fa, p_md=p_md, valid=~invalid)
    _compare_padded(base, padded, pos)


def _padded_with(junk_g, junk_sigma):
    g, sigma = _small_geometry(5, N_PAD_VALID)
    gp = np.vstack([g, np.broadcast_to(junk_g, (N_PAD - N_PAD_VALID, 3))])
    sp = np.concatenate([sigma, np.broadcast_to(junk_sigma, (N_PAD - N_PAD_VALID,))])
    valid = np.arange(N_PAD) < N_PAD_VALID
    return (g, sigma), (gp, sp, valid)


@pytest.mark.parametrize("junk", [np.nan, np.inf, -np.inf])
def test_padding_with_nonfinite_geometry(junk):
    (g, sigma), (gp, sp, valid) = _padded_with([junk, 0.5, junk], 1.0)
    base = araim.slope_hpl(g, sigma, p_fa=1e-5, p_md=1e-3)
    padded = araim.slope_hpl(gp, sp, p_fa=1e-5, p_md=1e-3, valid=valid)
    _compare_padded(base, padded, np.arange(N_PAD_VALID))


@pytest.mark.parametrize("junk_sigma", [np.nan, 0.0, -1.0, np.inf])
def test_padding_with_bad_sigma_in_invalid_rows(junk_sigma):
    (g, sigma), (gp, sp, valid) = _padded_with([0.1, 0.2, 0.3], junk_sigma)
    base = araim.slope_hpl(g, sigma, p_fa=1e-5, p_md=1e-3)
    padded = araim.slope_hpl(gp, sp, p_fa=1e-5, p_md=1e-3, valid=valid)
    _compare_padded(base, padded, np.arange(N_PAD_VALID))


@settings(max_examples=25, deadline=None, derandomize=True, database=None)
@given(seed=st.integers(0, 2**32 - 1), perm=st.permutations(range(N_PAD)))
def test_reordering_permutes_slopes_property(seed, perm):
    p_fa, p_md = 1e-7, 1e-5
    g, sigma = _small_geometry(seed, N_PAD)
    valid = np.arange(N_PAD) % 4 != 3  # 9 valid, 3 padding rows
    base = araim.slope_hpl(g, sigma, p_fa=p_fa, p_md=p_md, valid=valid)
    perm = np.asarray(perm)
    res = araim.slope_hpl(g[perm], sigma[perm], p_fa=p_fa, p_md=p_md, valid=valid[perm])
    assert int(res.status) == int(base.status) == Status.OK
    assert float(res.hpl_m) == pytest.approx(float(base.hpl_m), rel=1e-12)
    smax = float(base.slope_max)
    np.testing.assert_allclose(res.slopes, base.slopes[perm], rtol=1e-12, atol=1e-12 * smax)


# ------------------------------------------------------------------------- failures as data


def _failure_batch():
    """(B, 8) batch mixing good geometries with every failure, and the expected statuses."""
    rng = np.random.default_rng(99)
    cases = []

    def add(az_deg, el_deg, status, sigma=None):
        n = len(az_deg)
        g = np.zeros((L_SMALL, 3))
        g[:n] = _rows(np.deg2rad(az_deg), np.deg2rad(el_deg))
        g[n:] = rng.normal(size=(L_SMALL - n, 3))  # finite junk in the padding
        s = np.ones(L_SMALL) if sigma is None else np.concatenate([sigma, np.ones(L_SMALL - n)])
        cases.append((g, s, np.arange(L_SMALL) < n, status))

    good_az, good_el = rng.uniform(0, 360, 8), rng.uniform(10, 90, 8)
    add(good_az, good_el, Status.OK, rng.uniform(0.3, 8, 8))
    add(good_az[:4], good_el[:4], Status.TOO_FEW_SOURCES)  # 4 sources, 4 states
    add([], [], Status.TOO_FEW_SOURCES)  # nothing valid
    # every source at the same az/el: rank-1 normal matrix. It is both singular and (S_ii
    # undefined) undetectable; araim/status.py reports the lowest code: SINGULAR_GEOMETRY.
    add([40.0] * 7, [30.0] * 7, Status.SINGULAR_GEOMETRY)
    add([40.0] * 4, [30.0] * 4, Status.TOO_FEW_SOURCES)  # too few outranks singular
    # six duplicated rows plus one distinct source: singular (rank 2) *and* the lone distinct
    # source has S_ii = 0 (undetectable); the lower code, SINGULAR_GEOMETRY, is reported
    add([40.0] * 6 + [100.0], [30.0] * 6 + [50.0], Status.SINGULAR_GEOMETRY)
    # all sources at the zenith: the up and clock columns coincide
    add([0, 60, 120, 180, 240, 300], [90.0] * 6, Status.SINGULAR_GEOMETRY)
    # all sources in one vertical plane (azimuths 30 / 210 deg): east and north columns
    # are proportional, the horizontal position is not observable
    add([30, 210, 30, 210, 30, 210], [10, 20, 35, 50, 65, 80], Status.SINGULAR_GEOMETRY)
    # four sources at one elevation (random azimuths) plus one higher: without the fifth, up and
    # clock are inseparable, so S_55 = 0 (see the ring-and-zenith derivation; the argument
    # needs only the common elevation): UNDETECTABLE_FAULT
    add(list(rng.uniform(0, 360, 4)) + [123.0], [25.0] * 4 + [70.0], Status.UNDETECTABLE_FAULT)
    add(good_az[:6], good_el[:6], Status.OK)
    g, s, v, status = (np.stack(x) for x in zip(*cases, strict=True))
    return g, s, v, status


def test_failures_are_data():
    p_fa, p_md = 1e-5, 1e-3
    g, sigma, valid, expected = _failure_batch()
    res = araim.slope_hpl(g, sigma, p_fa=p_fa, p_md=p_md, valid=valid)
    for name in res._fields:
        assert not np.any(np.isnan(np.asarray(getattr(res, name)))), name
    s = araim.slopes(g, sigma, valid)
    for name in s._fields:
        assert not np.any(np.isnan(np.asarray(getattr(s, name)))), name
    np.testing.assert_array_equal(res.status, expected)
    np.testing.assert_array_equal(s.status, expected)
    np.testing.assert_array_equal(res.dof, valid.sum(axis=1) - 4)
    bad = expected != Status.OK
    assert np.all(np.asarray(res.hpl_m)[bad] == np.inf)
    assert np.all(np.asarray(res.slope_max)[bad] == np.inf)
    assert np.all(np.asarray(res.lambda_det)[bad] == np.inf)
    assert np.all(np.isfinite(np.asarray(res.hpl_m)[~bad]))
    # failed geometries: inf on valid rows, 0 on padding
    slopes = np.asarray(res.slopes)
    assert np.all(slopes[bad[:, None] & valid] == np.inf)
    assert np.all(slopes[~valid] == 0.0)

    # the good geometries are unaffected by their neighbours: same results as in a batch of
    # the same shape holding only good geometries, and as the reference
    good = np.flatnonzero(~bad)
    pick = np.resize(good, len(expected))
    alone = araim.slope_hpl(g[pick], sigma[pick], p_fa=p_fa, p_md=p_md, valid=valid[pick])
    for j, b in enumerate(pick[: len(good)]):
        np.testing.assert_allclose(res.slopes[b], alone.slopes[j], rtol=1e-15)
        assert float(res.hpl_m[b]) == pytest.approx(float(alone.hpl_m[j]), rel=1e-15)
        v = valid[b]
        ref = slope_hpl_reference(g[b][v], sigma[b][v], p_fa, p_md)
        assert float(res.hpl_m[b]) == pytest.approx(ref, rel=1e-9)


@pytest.mark.parametrize("plane_az_deg", [(0.0, 180.0), (90.0, 270.0)])
def test_axis_aligned_vertical_plane_is_singular(plane_az_deg):
    az = np.deg2rad(np.resize(plane_az_deg, 7))
    el = np.deg2rad([10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0])
    g = np.zeros((L_SMALL, 3))
    g[:7] = _rows(az, el)
    valid = np.arange(L_SMALL) < 7
    res = araim.slope_hpl(g, 1.0, p_fa=1e-5, p_md=1e-3, valid=valid)
    assert int(res.status) == Status.SINGULAR_GEOMETRY
    assert res.hpl_m == np.inf


# --------------------------------------------------------------------------- bad user input


@pytest.mark.parametrize("bad", [0.0, -1.0, np.nan, np.inf, -np.inf])
def test_bad_sigma_raises_naming_sigma(bad):
    g, sigma = _small_geometry(3, L_SMALL)
    sigma = sigma.copy()
    sigma[2] = bad
    with pytest.raises(ValueError, match="sigma_m") as exc:
        araim.slope_hpl(g, sigma, p_fa=1e-5, p_md=1e-3)
    assert str(bad) in str(exc.value)
    with pytest.raises(ValueError, match="sigma_m"):
        araim.slopes(g, sigma)
    with pytest.raises(ValueError, match="sigma_m"):  # a scalar sigma broadcasts
        araim.slopes(g, bad)


@pytest.mark.parametrize(
    ("p_fa", "p_md", "field"), [(0.0, 1e-3, "p_fa"), (1e-3, 1.5, "p_md"), ("x", 1e-3, "p_fa")]
)
def test_bad_probability_raises_before_computing(p_fa, p_md, field):
    g, sigma = _small_geometry(3, L_SMALL)
    with pytest.raises(ValueError, match=field):
        araim.slope_hpl(g, sigma, p_fa=p_fa, p_md=p_md)
