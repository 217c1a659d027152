"""``oaraim calibrate STUDY``: fit the parameters a paper leaves open to its published numbers.

A study declares its ``calibration`` (``studies.base.Calibration``): the free parameters with
their ranges and the summary rows whose published numbers they must reproduce. ``calibrate``
runs the study at the calibration's size, one seed for every evaluation (common random
numbers: the objective is a deterministic function of the parameters), and minimises the sum of
the squared weighted relative residuals ``(reproduced - published) / |published|``: one free
parameter by bounded Brent search, several by Nelder-Mead in the box of their ranges. At the
fit it reports each target's residual and the elasticities ``(dT / T) / (dp / p)`` from central
differences of +-``SENSITIVITY_STEP``: how strongly each number pins each parameter.
"""

import math
import re
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from oaraim.mc import check_seed

#: relative step of the sensitivity differences (+-5 %)
SENSITIVITY_STEP = 0.05
#: relative tolerance of the fitted parameters (of their range)
X_TOL = 1e-3
#: tolerance of the sum of squared relative residuals (residuals of ~3e-3: a Monte Carlo
#: target's own noise at the calibration sizes; 1e-7 left seed 000's 200-run fit crawling for
#: 20 evaluations within 0.01 m of its answer)
F_TOL = 1e-5
#: Nelder-Mead's first simplex: this share of each parameter's range from the start
SIMPLEX_STEP = 0.1


class CalibrationResult(NamedTuple):
    """What ``calibrate`` found."""

    study: str
    """The study's name."""
    fitted: dict
    """Free parameter -> fitted value."""
    defaults: dict
    """Free parameter -> the study's default value."""
    targets: list
    """Per target: ``{"quantity", "published", "at_default", "at_fit", "residual"}``
    (residual relative to the published number, at the fit)."""
    elasticity: dict
    """``{target quantity: {parameter: (dT / T) / (dp / p)}}`` at the fit."""
    evaluations: int
    """Study runs made (fit and sensitivities)."""
    realizations: int
    """Realizations per run."""
    sets: dict
    """The fixed parameter values of the runs."""


def _match_rows(study, rows, targets):
    out = []
    for t in targets:
        hits = [r for r in rows if re.search(t.pattern, r["quantity"])]
        if len(hits) != 1:
            raise ValueError(f"calibration target {t.pattern!r} of {study.name} matches "
                             f"{len(hits)} summary rows (want 1): check the --set values")
        if not hits[0].get("published"):
            raise ValueError(f"calibration target {hits[0]['quantity']!r} has no published "
                             "number")
        out.append(hits[0])
    return out


def calibrate(study, *, realizations=None, seed=0, sets=None,
              say: Callable[[str], None] = lambda _text: None) -> CalibrationResult:
    """Fit ``study.calibration.free`` to its targets (module docstring). ``realizations``
    and ``sets`` override the calibration's own size and fixed parameters; ``say`` receives a
    line per evaluation (progress).

    Raises:
      ValueError: the study declares no calibration, a set value is invalid, the seed is
        outside ``mc.keys.SEED_RANGE``, or a target does not match exactly one summary row
        (the message names it).
    """
    cal = study.calibration
    if cal is None:
        from oaraim.registry import STUDIES

        names = ", ".join(k for k, v in STUDIES.items() if v.calibration is not None)
        raise ValueError(f"{study.name} declares no calibration (no open parameter fitted to "
                         f"its published numbers); studies with one: {names}")
    seed = check_seed(seed)
    n = int(realizations or cal.realizations)
    fixed = {**cal.sets, **(sets or {})}
    base_params = study.validate(fixed)
    names = [f.name for f in cal.free]
    lows = np.array([f.low for f in cal.free], float)
    highs = np.array([f.high for f in cal.free], float)
    weights = np.array([t.weight for t in cal.targets], float)
    cache = {}

    def values(x):
        key = tuple(round(float(v), 12) for v in x)
        if key not in cache:
            params = study.validate({**fixed, **dict(zip(names, key, strict=True))})
            res = study.run(params, n, seed, None)
            rows = _match_rows(study, res.rows, cal.targets)
            cache[key] = ([float(r["reproduced"]) for r in rows],
                          [float(r["published"]) for r in rows],
                          [r["quantity"] for r in rows])
            v, p, _ = cache[key]
            shown = ", ".join(f"{a}={b:.4g}" for a, b in zip(names, key, strict=True))
            got = ", ".join(f"{a:.4g} ({b:.4g})" for a, b in zip(v, p, strict=True))
            say(f"run {len(cache)}: {shown} -> {got}")
        return cache[key]

    def cost(x):
        v, p, _ = values(x)
        r = weights * (np.array(v) - np.array(p)) / np.abs(np.array(p))
        return float(np.sum(np.where(np.isfinite(r), r, 1e6) ** 2))

    x0 = np.clip([float(base_params[k]) for k in names], lows, highs)
    if len(names) == 1:
        from scipy.optimize import minimize_scalar

        r = minimize_scalar(lambda v: cost([v]), bounds=(lows[0], highs[0]), method="bounded",
                            options={"xatol": X_TOL * (highs[0] - lows[0])})
        x = np.array([r.x])
    else:
        from scipy.optimize import minimize

        span = highs - lows
        u0 = (x0 - lows) / span
        # a simplex of SIMPLEX_STEP of each range (scipy's default, 5 % of the start's own
        # coordinates, crawls when a default sits near the low end of its range)
        simplex = [u0] + [np.where(np.arange(len(names)) == i,
                                   u0 + (SIMPLEX_STEP if u0[i] + SIMPLEX_STEP <= 1.0
                                         else -SIMPLEX_STEP), u0)
                          for i in range(len(names))]
        r = minimize(lambda u: cost(lows + span * u), u0, method="Nelder-Mead",
                     bounds=[(0.0, 1.0)] * len(names),
                     options={"xatol": X_TOL, "fatol": F_TOL, "maxfev": 80 * len(names),
                              "initial_simplex": np.array(simplex)})
        x = lows + span * np.clip(r.x, 0.0, 1.0)
    v_fit, pub, quantities = values(x)
    v_def, _, _ = values([float(study.params[k].default) for k in names])
    elasticity = {q: {} for q in quantities}
    for i, name in enumerate(names):
        up, down = x.copy(), x.copy()
        up[i] *= 1 + SENSITIVITY_STEP
        down[i] *= 1 - SENSITIVITY_STEP
        vu, _, _ = values(up)
        vd, _, _ = values(down)
        for q, a, b, c in zip(quantities, vu, vd, v_fit, strict=True):
            elasticity[q][name] = ((a - b) / (2 * SENSITIVITY_STEP * c)
                                   if c and math.isfinite(a - b) else float("nan"))
    targets = [{"quantity": q, "published": p, "at_fit": f, "at_default": d,
                "residual": (f - p) / abs(p)}
               for q, p, f, d in zip(quantities, pub, v_fit, v_def, strict=True)]
    return CalibrationResult(study.name, dict(zip(names, map(float, x), strict=True)),
                             {k: float(study.params[k].default) for k in names}, targets,
                             elasticity, len(cache), n, fixed)
