"""``oaraim calibrate``: the fit on studies whose response is known in closed form, and on the
seed 001 Fig. 5 study, whose GPS-only mean HPL scales exactly with sigma_GPS."""

import pytest
from typer.testing import CliRunner

from oaraim.calibrate import SENSITIVITY_STEP, calibrate
from oaraim.cli import app
from oaraim.registry import STUDIES
from oaraim.studies.base import Calibration, Free, Param, Study, StudyResult, Target, positive


class _Linear(Study):
    """reproduced = a * x and x * y: the fit is x = P1 / a, y = a * P2 / P1."""

    name = "fake-linear"
    params = {"x": Param(1.0, positive, "first"), "y": Param(2.0, positive, "second"),
              "a": Param(3.0, positive, "scale")}
    calibration = Calibration(free=(Free("x", 0.1, 10.0), Free("y", 0.1, 10.0)),
                              targets=(Target("^first number$"), Target("^second")),
                              realizations=1)

    def run(self, params, realizations, seed, progress):
        a, x, y = params["a"], params["x"], params["y"]
        rows = [{"quantity": "first number", "unit": "m", "published": 6.0,
                 "reproduced": a * x, "note": ""},
                {"quantity": "second number", "unit": "m", "published": 5.0,
                 "reproduced": a * x * y, "note": ""},
                {"quantity": "unrelated", "unit": "", "published": None, "reproduced": 0.0,
                 "note": ""}]
        return StudyResult(None, rows, {})


def test_two_parameter_fit_and_elasticities_by_hand():
    """a x = 6 and a x y = 5 with a = 3: x = 2, y = 5/6. The elasticities of a product are its
    exponents: d ln(a x) / d ln x = 1, / d ln y = 0; d ln(a x y) = 1 and 1 (central
    differences of a linear function are exact)."""
    res = calibrate(_Linear())
    assert res.fitted["x"] == pytest.approx(2.0, rel=5e-3)
    assert res.fitted["y"] == pytest.approx(5.0 / 6.0, rel=5e-3)
    assert all(abs(t["residual"]) < 5e-3 for t in res.targets)
    assert res.targets[0]["at_default"] == pytest.approx(3.0)  # a x at the default x = 1
    el = res.elasticity
    assert el["first number"] == pytest.approx({"x": 1.0, "y": 0.0}, abs=1e-9)
    assert el["second number"]["x"] == pytest.approx(1.0, abs=1e-9)
    assert el["second number"]["y"] == pytest.approx(1.0, abs=1e-9)
    assert res.defaults == {"x": 1.0, "y": 2.0}


def test_one_parameter_fit_and_fixed_sets():
    """With y fixed by the calibration's sets and x free alone (bounded Brent): a x = 6 with
    a = 4 set by the user gives x = 1.5."""
    class One(_Linear):
        calibration = Calibration(free=(Free("x", 0.1, 10.0),), targets=(Target("^first"),),
                                  realizations=1, sets={"y": "1"})

    res = calibrate(One(), sets={"a": "4"})
    assert res.fitted["x"] == pytest.approx(1.5, rel=2e-3)
    assert res.sets == {"y": "1", "a": "4"}


def test_an_unmatched_target_is_named():
    class Bad(_Linear):
        calibration = Calibration(free=(Free("x", 0.1, 10.0),),
                                  targets=(Target("^no such row"),), realizations=1)

    with pytest.raises(ValueError, match="no such row.*matches 0 summary rows"):
        calibrate(Bad())


def test_cli_study_without_calibration_is_one_line():
    r = CliRunner().invoke(app, ["calibrate", "seed001-fig3-elevation"],
                           catch_exceptions=False)
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.output
    assert "declares no calibration" in lines[0] and "seed001-fig5-madrid-24h" in lines[0]


def test_fig5_calibration_on_a_short_nominal_sky():
    """seed001-fig5 on 2 h of the nominal sky: both published means are met, and the GPS-only
    mean scales exactly with sigma_GPS (slope HPL = slope x sigma sqrt(lambda)), so its
    elasticity to sigma_GPS is 1 and to sigma_SOP 0, to rounding."""
    study = STUDIES["seed001-fig5-madrid-24h"]
    res = calibrate(study, realizations=8, sets={"nav": "nominal", "duration_h": "2",
                                                 "step_s": "300"})
    assert all(abs(t["residual"]) < 2e-3 for t in res.targets), res.targets
    gps = res.elasticity["mean GPS-only HPL over 24 h"]
    assert gps["sigma_gps_m"] == pytest.approx(1.0, abs=1e-9)
    assert gps["sigma_sop_m"] == pytest.approx(0.0, abs=1e-12)
    assert 0.0 < SENSITIVITY_STEP < 0.5
