"""Tests of oaraim.errors (gnss, sop): the nominal error models of seed 004 Appendix A (ADD
terms), and the earlier homes that re-export them (araim.error_models, geometry, sim).

Hand-derived values:
- troposphere (MOPS / ADD): 0.12 m * 1.001 / sqrt(0.002001 + sin^2 el); at the zenith
  0.002001 + 1 = 1.001^2, so sigma_tropo = 0.12 m exactly;
- airborne code noise and multipath (ADD, L1/L5 ionosphere-free):
  sqrt((f1^4 + f5^4) / (f1^2 - f5^2)^2) * sqrt(sigma_MP^2 + sigma_noise^2),
  sigma_MP = 0.13 + 0.53 exp(-el / 10 deg), sigma_noise = 0.15 + 0.43 exp(-el / 6.9 deg). With
  f1 = 154 f0 and f5 = 115 f0 (f0 = 10.23 MHz) the factor is sqrt(154^4 + 115^4) / (154^2 -
  115^2) = sqrt(737349281) / 10491 = 2.5883...;
- variances add (DESIGN.md): C_int = URA^2 + tropo^2 + user^2, C_acc = URE^2 + tropo^2 + user^2,
  URE = 2/3 URA by default; SOPs: URA^S^2 + user^2, URE^S = URA^S by default.
Tolerances: 1e-12 relative (a few float64 operations).
"""

import math

import numpy as np
import pytest

from oaraim import errors as em

F0 = 10.23e6
ELS_DEG = np.array([5.0, 10.0, 15.0, 30.0, 45.0, 60.0, 90.0])


def tropo_hand(el_deg):
    return 0.12 * 1.001 / math.sqrt(0.002001 + math.sin(math.radians(el_deg)) ** 2)


def user_hand(el_deg):
    k = math.sqrt(154**4 + 115**4) / (154**2 - 115**2)
    mp = 0.13 + 0.53 * math.exp(-el_deg / 10.0)
    noise = 0.15 + 0.43 * math.exp(-el_deg / 6.9)
    return k * math.sqrt(mp**2 + noise**2)


def test_carrier_frequencies_are_154_and_115_f0():
    assert em.F_L1_HZ == pytest.approx(154 * F0, rel=1e-15)
    assert em.F_L5_HZ == pytest.approx(115 * F0, rel=1e-15)


def test_iono_free_factor():
    want = math.sqrt(737349281) / 10491
    assert want == pytest.approx(2.5883, abs=1e-4)
    assert float(em.iono_free_factor()) == pytest.approx(want, rel=1e-12)


def test_tropo_zenith_is_exactly_12_cm():
    assert float(em.sigma_tropo_m(np.pi / 2)) == pytest.approx(0.12, rel=1e-14)


@pytest.mark.parametrize("el_deg", ELS_DEG)
def test_tropo_and_user_terms(el_deg):
    el = math.radians(el_deg)
    assert float(em.sigma_tropo_m(el)) == pytest.approx(tropo_hand(el_deg), rel=1e-12)
    assert float(em.sigma_user_airborne_m(el)) == pytest.approx(user_hand(el_deg), rel=1e-12)


def test_user_term_at_5_deg_by_hand():
    """el = 5 deg: sigma_MP = 0.13 + 0.53 e^-0.5 = 0.451461..., sigma_noise = 0.15 + 0.43
    e^(-5/6.9) = 0.358335...; 2.5883 sqrt(0.451461^2 + 0.358335^2) = 1.49188 m; tropo
    0.12 * 1.001 / sqrt(0.002001 + 0.0075961) = 1.22615 m (sin 5 deg = 0.0871557)."""
    mp = 0.13 + 0.53 * math.exp(-0.5)
    noise = 0.15 + 0.43 * math.exp(-5 / 6.9)
    assert mp == pytest.approx(0.451461, abs=1e-6)
    assert noise == pytest.approx(0.358335, abs=1e-6)
    assert float(em.sigma_user_airborne_m(math.radians(5))) == pytest.approx(1.49188, abs=1e-5)
    assert float(em.sigma_tropo_m(math.radians(5))) == pytest.approx(1.22615, abs=1e-5)


def test_gnss_variances_add():
    el = np.radians(ELS_DEG)
    var_int, var_acc = (np.asarray(x) for x in em.gnss_variances(el, 1.0))
    t2 = np.array([tropo_hand(e) ** 2 for e in ELS_DEG])
    u2 = np.array([user_hand(e) ** 2 for e in ELS_DEG])
    np.testing.assert_allclose(var_int, 1.0 + t2 + u2, rtol=1e-12)
    np.testing.assert_allclose(var_acc, (2 / 3) ** 2 + t2 + u2, rtol=1e-12)
    # explicit URE, other URA, and the zenith value by hand: 0.12^2 + 2.5883^2 (0.13^2 + 0.15^2)
    vi, va = (np.asarray(x) for x in em.gnss_variances(el, 2.0, sigma_ure_m=0.5))
    np.testing.assert_allclose(vi - var_int, 3.0, rtol=1e-12)
    np.testing.assert_allclose(va, 0.25 + t2 + u2, rtol=1e-12)
    k2 = 737349281 / 10491**2
    zen = 1.0 + 0.12**2 + k2 * ((0.13 + 0.53 * math.exp(-9)) ** 2
                                + (0.15 + 0.43 * math.exp(-90 / 6.9)) ** 2)
    assert var_int[-1] == pytest.approx(zen, rel=1e-12)


def test_sop_variances_add():
    vi, va = (np.asarray(x) for x in em.sop_variances(np.array([0.5, 3.0, 25.0])))
    np.testing.assert_allclose(vi, [0.25, 9.0, 625.0], rtol=1e-15)
    np.testing.assert_allclose(va, vi, rtol=1e-15)  # URE^S defaults to URA^S
    vi, va = (np.asarray(x) for x in em.sop_variances(3.0, sigma_ure_m=2.0, sigma_user_m=1.5))
    assert float(vi) == pytest.approx(9.0 + 2.25, rel=1e-15)
    assert float(va) == pytest.approx(4.0 + 2.25, rel=1e-15)


def test_models_are_replaceable():
    """gnss_variances takes the troposphere and user models as functions."""
    el = np.radians(ELS_DEG)
    vi, va = (np.asarray(x) for x in em.gnss_variances(
        el, 1.0, tropo_model=lambda e: 0.0 * e, user_model=lambda e: 0.0 * e + 0.5))
    np.testing.assert_allclose(vi, 1.25, rtol=1e-15)
    np.testing.assert_allclose(va, 4 / 9 + 0.25, rtol=1e-15)


def test_the_earlier_homes_re_export_the_one_home():
    """``araim.error_models`` (the README's ``araim.error_models.gnss_variances(el)``), the
    geometry face's atmosphere and IMU names and the sim face's world models are the objects of
    ``oaraim.errors``, not copies: one definition, whichever name a user wrote."""
    from oaraim import araim, geometry, sim
    from oaraim.araim import error_models

    assert araim.error_models is error_models
    assert error_models.__all__
    for name in error_models.__all__:
        assert getattr(error_models, name) is getattr(em, name), name
    assert geometry.atmosphere is em.atmosphere and geometry.imu is em.imu
    assert geometry.ImuSpec is em.ImuSpec and geometry.vn100 is em.vn100
    assert sim.ErrorModel is em.ErrorModel and sim.GnssErrorModel is em.GnssErrorModel
    assert geometry.SISError is em.SISError and geometry.sis_error.summary is em.sis.summary
    for name in ("LEO_SIGNALS", "LeoSignal", "leo_variances", "sigma_iono_leo_m",
                 "sigma_elevation_leo_m", "KLOBUCHAR_TAU_VERT_MID_M"):
        assert getattr(araim.leo_errors, name) is getattr(em, name), name
    assert araim.leo_variances is em.leo_variances and araim.LEO_SIGNALS is em.LEO_SIGNALS
    el = np.deg2rad(ELS_DEG)
    np.testing.assert_array_equal(araim.error_models.gnss_variances(el)[0],
                                  em.gnss_variances(el)[0])
