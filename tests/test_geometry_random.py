"""Tests of geometry.rows and geometry.random_sky (seed 001 sections 2.4 and 3.3).

Statistical tests use fixed PRNG keys, so each is deterministic: it either always passes or always
fails. A KS test asserting p > 1e-3 on a *correct* sampler fails for a fraction 1e-3 of possible
seeds (the p-value of a correct continuous sampler is U(0, 1)); the seeds below were not chosen
by looking at p-values. A wrong distribution with ~20000 samples gives p-values many orders of
magnitude below 1e-3 for any shift of the cdf larger than ~0.02 (KS critical distance
1.95 / sqrt(20000) = 0.014 at p = 1e-3).
"""

import jax
import numpy as np
import pytest
from scipy import stats

from oaraim import geometry

N_KS = 20_000  # samples per KS test
P_MIN = 1e-3  # KS p-value below which a sampler is declared wrong (see module docstring)


# --------------------------------------------------------------------------- geometry_rows


@pytest.mark.parametrize(
    ("az_deg", "el_deg", "expected"),
    [
        (0.0, 0.0, [0.0, -1.0, 0.0]),  # transmitter due north on the horizon
        (90.0, 0.0, [-1.0, 0.0, 0.0]),  # due east on the horizon
        (180.0, 0.0, [0.0, 1.0, 0.0]),  # due south
        (270.0, 0.0, [1.0, 0.0, 0.0]),  # due west
        (0.0, 90.0, [0.0, 0.0, -1.0]),  # zenith
        (123.0, 90.0, [0.0, 0.0, -1.0]),  # zenith: azimuth irrelevant
        # az = 45, el = 45: cos el sin az = cos el cos az = 1/2, sin el = 1/sqrt(2)
        (45.0, 45.0, [-0.5, -0.5, -np.sqrt(0.5)]),
    ],
)
def test_geometry_rows_hand_values(az_deg, el_deg, expected):
    g = np.asarray(geometry.geometry_rows(np.deg2rad(az_deg), np.deg2rad(el_deg)))
    assert g.shape == (3,)
    # cos(pi/2) = 6.1e-17 in float64, so "0" components are only zero to ~1e-16
    np.testing.assert_allclose(g, expected, rtol=0, atol=1e-15)


def _rows_np(az, el):
    """Seed 001 section 2.4 row, written out in NumPy."""
    az, el = np.broadcast_arrays(az, el)
    return np.stack([-np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), -np.sin(el)], axis=-1)


def test_geometry_rows_unit_norm_and_dtype():
    rng = np.random.default_rng(11)
    az = rng.uniform(0, 2 * np.pi, (40, 7))
    el = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, (40, 7))
    g = geometry.geometry_rows(az, el)
    assert g.dtype == np.float64
    assert g.shape == (40, 7, 3)
    np.testing.assert_allclose(np.linalg.norm(np.asarray(g), axis=-1), 1.0, rtol=0, atol=4e-16)
    np.testing.assert_allclose(g, _rows_np(az, el), rtol=0, atol=1e-15)


def test_geometry_rows_broadcast_shapes():
    rng = np.random.default_rng(12)
    az = rng.uniform(0, 2 * np.pi, (3, 1, 4))
    el = rng.uniform(0, 0.5 * np.pi, (2, 4))
    g = np.asarray(geometry.geometry_rows(az, el))
    assert g.shape == (3, 2, 4, 3)
    np.testing.assert_allclose(g, _rows_np(az, el), rtol=0, atol=1e-15)
    # a scalar elevation broadcasts against an array of azimuths (and vice versa)
    az2 = rng.uniform(0, 2 * np.pi, (40, 7))
    g0 = np.asarray(geometry.geometry_rows(az2, 0.0))
    assert g0.shape == (40, 7, 3)
    np.testing.assert_array_equal(g0[..., 2], 0.0)
    np.testing.assert_allclose(g0, _rows_np(az2, 0.0), rtol=0, atol=1e-15)
    # shapes only (abstract evaluation, nothing compiled)
    for a_shape, e_shape, out in [
        ((5,), (), (5, 3)),
        ((), (6,), (6, 3)),
        ((2, 1, 5), (3, 5), (2, 3, 5, 3)),
        ((4, 1), (1, 9), (4, 9, 3)),
    ]:
        spec = jax.eval_shape(
            geometry.geometry_rows,
            jax.ShapeDtypeStruct(a_shape, np.float64),
            jax.ShapeDtypeStruct(e_shape, np.float64),
        )
        assert spec.shape == out


def _enu_from_az_el_range(az, el, rng_m):
    return rng_m[..., None] * np.stack(
        [np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1
    )


def test_geometry_rows_equal_rows_from_enu_positions():
    rng = np.random.default_rng(13)
    az = rng.uniform(0, 2 * np.pi, (40, 7))
    el = rng.uniform(-0.2, 0.5 * np.pi, (40, 7))
    rng_m = rng.uniform(5.0, 3e7, (40, 7))
    tx = _enu_from_az_el_range(az, el, rng_m)
    g_angles = np.asarray(geometry.geometry_rows(az, el))
    # unit vectors: 1e-15 absolute is a few ulps of each component
    np.testing.assert_allclose(geometry.geometry_rows_enu(tx), g_angles, rtol=0, atol=1e-15)
    # the same with the receiver off the frame origin
    rx = rng.uniform(-1000.0, 1000.0, (40, 3))
    np.testing.assert_allclose(
        geometry.geometry_rows_enu(tx + rx[:, None, :], rx), g_angles, rtol=0, atol=1e-12
    )


# ------------------------------------------------------------------------------- random_sky


SKY_BATCH, SKY_N = N_KS // 10, 10  # one compiled shape for every concrete random_sky call


def test_random_sky_shapes():
    mask = np.deg2rad(15.0)
    az, el = geometry.random_sky(jax.random.key(1), SKY_N, mask, batch_shape=(SKY_BATCH,))
    assert az.shape == el.shape == (SKY_BATCH, SKY_N)
    assert az.dtype == el.dtype == np.float64
    # other batch shapes, abstractly (nothing compiled)
    for batch in [(), (4, 5), (1,)]:
        az_s, el_s = jax.eval_shape(
            lambda k, batch=batch: geometry.random_sky(k, 7, mask, batch), jax.random.key(1)
        )
        assert az_s.shape == el_s.shape == (*batch, 7)
        assert az_s.dtype == el_s.dtype == np.float64


def test_random_sky_distribution_ks():
    mask = np.deg2rad(15.0)
    az, el = geometry.random_sky(jax.random.key(2024), SKY_N, mask, batch_shape=(SKY_BATCH,))
    az, el = np.asarray(az).ravel(), np.asarray(el).ravel()
    assert az.size == N_KS
    assert np.all((az >= 0.0) & (az < 2 * np.pi))
    assert np.all((el >= mask) & (el <= 0.5 * np.pi))
    p_az = stats.kstest(az, stats.uniform(loc=0.0, scale=2 * np.pi).cdf).pvalue
    p_el = stats.kstest(el, stats.uniform(loc=mask, scale=0.5 * np.pi - mask).cdf).pvalue
    assert p_az > P_MIN, p_az
    assert p_el > P_MIN, p_el
    # azimuth and elevation are independent draws (correlation of 2e4 samples: sd 0.007)
    assert abs(np.corrcoef(az, el)[0, 1]) < 0.03


def test_random_sky_keys():
    a1 = geometry.random_sky(jax.random.key(5), SKY_N, 0.1, (SKY_BATCH,))
    a2 = geometry.random_sky(jax.random.key(5), SKY_N, 0.1, (SKY_BATCH,))
    b = geometry.random_sky(jax.random.key(6), SKY_N, 0.1, (SKY_BATCH,))
    for x, y in zip(a1, a2, strict=True):
        np.testing.assert_array_equal(x, y)
    for x, y in zip(a1, b, strict=True):
        assert not np.any(np.asarray(x) == np.asarray(y))


# ------------------------------------------------------------------------------- bpp_towers

D_MIN, D_MAX = 5.0, 3000.0  # seed 001 section 3.3
H_MIN, H_MAX = 10.0, 60.0
BPP_BATCH, BPP_N = N_KS // 8, 8  # one compiled shape for every concrete bpp_towers call


def _bpp(seed, h_min=H_MIN, h_max=H_MAX):
    return geometry.bpp_towers(
        jax.random.key(seed), BPP_N, D_MIN, D_MAX, h_min, h_max, batch_shape=(BPP_BATCH,)
    )


@pytest.fixture(scope="module")
def towers():
    return _bpp(77)


def test_bpp_towers_shapes(towers):
    for name in ("az_rad", "el_rad", "range_m", "distance_m", "height_m"):
        arr = getattr(towers, name)
        assert arr.shape == (BPP_BATCH, BPP_N), name
        assert arr.dtype == np.float64, name
    assert towers.enu_m.shape == (BPP_BATCH, BPP_N, 3)
    for batch in [(), (2, 3)]:
        spec = jax.eval_shape(
            lambda k, batch=batch: geometry.bpp_towers(k, 4, D_MIN, D_MAX, batch_shape=batch),
            jax.random.key(1),
        )
        for name in ("az_rad", "el_rad", "range_m", "distance_m", "height_m"):
            assert getattr(spec, name).shape == (*batch, 4), name
        assert spec.enu_m.shape == (*batch, 4, 3)


def test_bpp_towers_distance_uniform_in_area(towers):
    d = np.asarray(towers.distance_m).ravel()
    assert np.all((d >= D_MIN) & (d <= D_MAX))

    def cdf(x):  # uniform in the annulus area: P(D <= x) = (x^2 - dmin^2) / (dmax^2 - dmin^2)
        return np.clip((x**2 - D_MIN**2) / (D_MAX**2 - D_MIN**2), 0.0, 1.0)

    p = stats.kstest(d, cdf).pvalue
    assert p > P_MIN, p
    # the same samples are far from uniform in *distance* (the test has power)
    p_wrong = stats.kstest(d, stats.uniform(loc=D_MIN, scale=D_MAX - D_MIN).cdf).pvalue
    assert p_wrong < 1e-10


def test_bpp_towers_azimuth_and_height_uniform(towers):
    az = np.asarray(towers.az_rad).ravel()
    h = np.asarray(towers.height_m).ravel()
    assert np.all((az >= 0.0) & (az < 2 * np.pi))
    assert np.all((h >= H_MIN) & (h <= H_MAX))
    assert stats.kstest(az, stats.uniform(loc=0.0, scale=2 * np.pi).cdf).pvalue > P_MIN
    assert stats.kstest(h, stats.uniform(loc=H_MIN, scale=H_MAX - H_MIN).cdf).pvalue > P_MIN


def test_bpp_towers_derived_fields(towers):
    az = np.asarray(towers.az_rad)
    d = np.asarray(towers.distance_m)
    h = np.asarray(towers.height_m)
    # relative 1e-15 is a few ulps: these are single elementary operations
    np.testing.assert_allclose(towers.el_rad, np.arctan(h / d), rtol=1e-15, atol=0)
    np.testing.assert_allclose(towers.range_m, np.sqrt(d**2 + h**2), rtol=1e-15, atol=0)
    enu = np.stack([d * np.sin(az), d * np.cos(az), h], axis=-1)
    # metres: 1e-12 m on distances up to 3 km
    np.testing.assert_allclose(towers.enu_m, enu, rtol=0, atol=1e-12)
    # the rows built from angles point away from the ENU positions (consistency of conventions)
    np.testing.assert_allclose(
        geometry.geometry_rows(towers.az_rad, towers.el_rad),
        geometry.geometry_rows_enu(towers.enu_m),
        rtol=0,
        atol=1e-15,
    )


def test_bpp_towers_zero_height_gives_zero_elevation():
    t = _bpp(3, 0.0, 0.0)
    np.testing.assert_array_equal(t.height_m, 0.0)
    np.testing.assert_array_equal(t.el_rad, 0.0)
    np.testing.assert_array_equal(t.range_m, t.distance_m)
    np.testing.assert_array_equal(t.enu_m[..., 2], 0.0)
    # default heights are zero too (seed 001 Fig. 4: towers at 0 deg elevation)
    t_default = geometry.bpp_towers(
        jax.random.key(3), BPP_N, D_MIN, D_MAX, batch_shape=(BPP_BATCH,)
    )
    np.testing.assert_array_equal(t_default.el_rad, 0.0)


def test_bpp_towers_keys():
    a1, a2, b = _bpp(9), _bpp(9), _bpp(10)
    for name in a1._fields:
        np.testing.assert_array_equal(getattr(a1, name), getattr(a2, name), err_msg=name)
    for name in ("az_rad", "distance_m", "height_m"):
        assert not np.any(np.asarray(getattr(a1, name)) == np.asarray(getattr(b, name))), name
