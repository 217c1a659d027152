"""Run one study end to end: validate, compute, store, plot."""

import time
from pathlib import Path

from mc.progress import ProgressBar
from mc.store import provenance, write_results
from studies.registry import get_study


def parse_sets(sets):
    """``["k=v", "k2=a,b"]`` -> {k: "v", k2: "a,b"}; the study's parsers interpret the values."""
    out = {}
    for item in sets or ():
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        out[key] = value.strip()
    return out


def run_study(name, *, realizations=None, seed=0, out="out", sets=(), quick=False,
              show_progress=True):
    """Run study ``name`` and write ``out/name/``; returns (summary dict, output folder)."""
    study = get_study(name)
    params = study.validate(parse_sets(sets))
    if realizations is None:
        realizations = study.quick_realizations if quick else study.default_realizations
    if realizations < 1:
        raise ValueError(f"--realizations must be >= 1, got {realizations}")
    out_dir = Path(out) / study.name
    t0 = time.perf_counter()
    with ProgressBar(realizations, study.name, enabled=show_progress) as bar:
        result = study.run(params, realizations, seed, bar)
    wall_s = time.perf_counter() - t0
    summary = {"study": study.name, "title": study.title, "rows": result.rows,
               "metrics": result.metrics}
    prov = provenance(study.name, params, seed, realizations, wall_s,
                      realization=study.realization, seed_paper=study.seed_file,
                      **result.extra_provenance)
    write_results(out_dir, result.dataset, summary, prov)
    figures = study.plot(out_dir)
    return summary, out_dir, figures, wall_s
