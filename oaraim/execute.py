"""Run one study end to end: validate, compute, store, plot (the app layer above studies/)."""

import functools
import sys
import time
from pathlib import Path

from oaraim.mc import (
    Execution,
    OutputError,
    OutputLock,
    ProgressBar,
    check_seed,
    os_error_line,
    provenance,
    write_results,
    writing,
)
from oaraim.mc.checkpoint import Checkpoint, identity
from oaraim.registry import STUDIES, get_study
from oaraim.studies import base
from oaraim.studies.base import ResumableStudy, RunOptions, SweepStudy

__all__ = ["RunOptions", "check_data", "data_provenance", "parse_sets", "run_study",
           "run_sweep_study", "sweep_kernel"]

SWEEP_FLAGS = "--workers and --scheduler"


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


def sweep_kernel(study, params, coords):
    """Kernel factory of a sweep study, picklable for Dask workers: ``study`` is the name of a
    registered study (looked up in ``oaraim.registry`` in the worker) or a study object (one
    defined outside ``studies/``, e.g. in a test; it travels pickled)."""
    s = get_study(study) if isinstance(study, str) else study
    return s.kernel(params, coords)


def _study_ref(study):
    """The study's name where every worker finds it in the registry, else the object."""
    registered = STUDIES.get(study.name) is study
    in_package = type(study).__module__.startswith("oaraim.studies.")
    return study.name if registered and in_package else study


def run_sweep_study(study, params, realizations, seed, out_dir, *, options=None,
                    progress=True):
    """``studies.base.run_sweep_study`` (``options``: a ``RunOptions``, resume and execution)
    with a kernel factory that Dask workers can rebuild: a registered study travels by name
    (``sweep_kernel``). Returns (StudyResult, SweepResult).
    """
    return base.run_sweep_study(
        study, params, realizations, seed, out_dir, options=options, progress=progress,
        kernel_factory=functools.partial(sweep_kernel, _study_ref(study), params))


def _check_sweep_flags(study, resume, execution):
    workers, scheduler = execution.workers, execution.scheduler
    if resume and not isinstance(study, SweepStudy | ResumableStudy):
        able = [n for n, s in STUDIES.items() if isinstance(s, SweepStudy | ResumableStudy)]
        raise ValueError(f"--resume applies to resumable studies only and {study.name} is not "
                         "one (it runs in one piece); drop --resume. Resumable: "
                         + (", ".join(able) or "none registered"))
    if not isinstance(study, SweepStudy):
        if workers is not None or scheduler is not None:
            sweeps = [n for n, s in STUDIES.items() if isinstance(s, SweepStudy)]
            raise ValueError(f"{SWEEP_FLAGS} apply to sweep studies only and {study.name} is not "
                             "one; sweep studies: " + (", ".join(sweeps) or "none registered"))
        return
    if workers is not None and scheduler is not None:
        raise ValueError("give either --workers N (a local Dask cluster) or --scheduler ADDRESS "
                         "(an existing one), not both")
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")


def _stderr_line(text):
    print(f"warning: {text}", file=sys.stderr, flush=True)


def run_study(name, *, realizations=None, seed=0, out="out", sets=(), quick=False,
              show_progress=True, options=None):
    """Run study ``name`` and write ``out/name/``; returns (summary dict, output folder, figure
    paths, wall time in s). ``options`` (a ``RunOptions``, default all off): sweep studies and
    ``ResumableStudy`` ones take ``options.resume`` (reuse the finished chunks or checkpointed
    units in ``out/name/``); sweep studies also take ``options.execution`` (an
    ``mc.sweep.Execution``: local Dask ``workers`` or a ``scheduler`` address).
    ``options.notice(text)`` says, in one line, what the run did on its own (taking over the
    lock of a run that died); default: printed to stderr as ``warning: ...``.

    Every user error is a ``ValueError`` with one line (the CLI exits 2): bad parameters, a
    seed outside ``mc.keys.SEED_RANGE``, an unusable ``--out`` and any ``OSError`` while the
    run reads or writes (a full disk: the path, and what to do, ``mc.store.os_error_line``).
    """
    options = RunOptions() if options is None else options
    resume, notice = options.resume, options.notice
    execution = Execution() if options.execution is None else options.execution
    options = options._replace(execution=execution)
    study = get_study(name)
    seed = check_seed(seed)
    _check_sweep_flags(study, resume, execution)
    overrides = parse_sets(sets)
    if quick:
        overrides = {**study.quick_sets, **overrides}
    params = study.validate(overrides)
    fixed = study.fixed_realizations(params)
    if fixed is not None:
        if realizations is not None and realizations != fixed:
            raise ValueError(f"{study.name} sets its realizations from its grid ({fixed:,} per "
                             "cell); drop --realizations and change the grid with --set")
        realizations = fixed
    if realizations is None:
        realizations = study.quick_realizations if quick else study.default_realizations
    if realizations < 1:
        raise ValueError(f"--realizations must be >= 1, got {realizations}")
    limit = study.realization_limit()
    if fixed is None and limit is not None and realizations > limit:
        raise ValueError(study.too_many_realizations(realizations, limit))
    out_dir = Path(out) / study.name
    resumable = isinstance(study, SweepStudy | ResumableStudy)
    try:
        with OutputLock(out_dir) as lock:
            if lock.taken_over is not None:
                (notice or _stderr_line)(
                    f"{out_dir}: took over the lock of process {lock.taken_over}, which is no "
                    "longer running" if lock.taken_over else
                    f"{out_dir}: took over a lock file that names no process")
            return _run_locked(study, params, realizations, seed, out_dir, show_progress,
                               options)
    except (OutputError, ConnectionError, TimeoutError):
        raise  # one line already; a Dask scheduler's network error says what it is
    except OSError as e:  # a full disk, a folder made read-only: the path and what to do
        raise OutputError(os_error_line(e, out_dir, resumable)) from None


def study_outcome(name, *, seed, out, quick, show_progress):
    """``run_study`` for ``reproduce``: its (summary, folder, figures, wall) or, where it fails,
    the one line that says why (a worker process of ``reproduce --jobs`` runs this)."""
    try:
        return run_study(name, seed=seed, out=out, quick=quick, show_progress=show_progress)
    except ValueError as e:
        return " ".join(str(e).split())
    except Exception as e:  # noqa: BLE001 - one study's bug must not stop the others
        return (f"{type(e).__name__}: {' '.join(str(e).split())} (rerun `oaraim run {name}` "
                "for the traceback)")


def _run_locked(study, params, realizations, seed, out_dir, show_progress, options):
    t0 = time.perf_counter()
    extra = {}
    resume = options.resume
    if isinstance(study, SweepStudy):
        result, sweep = run_sweep_study(study, params, realizations, seed, out_dir,
                                        options=options, progress=show_progress)
        extra["sweep"] = _sweep_provenance(sweep, resume)
    elif isinstance(study, ResumableStudy):
        checkpoint = Checkpoint(out_dir, identity(study.name, params, seed, realizations),
                                resume=resume)
        try:
            with ProgressBar(realizations, study.name, enabled=show_progress) as bar:
                result = study.run(params, realizations, seed, bar, checkpoint=checkpoint)
        except BaseException:
            checkpoint.remove_if_nothing_finished()  # finished units stay for --resume
            raise
        extra["checkpoint"] = checkpoint.provenance()
    else:
        with ProgressBar(realizations, study.name, enabled=show_progress) as bar:
            result = study.run(params, realizations, seed, bar)
    wall_s = time.perf_counter() - t0
    summary = {"study": study.name, "title": study.title, "rows": result.rows,
               "metrics": result.metrics}
    extra["data_files"] = data_provenance(study, params)
    prov = provenance(study.name, params, seed, realizations, wall_s,
                      realization=study.realization, seed_paper=study.seed_file,
                      **{**result.extra_provenance, **extra})
    figures = write_results(out_dir, result.dataset, summary, prov,
                            before_summary=lambda: _plot(study, out_dir))
    return summary, out_dir, figures, wall_s


def _plot(study, out_dir):
    with writing(out_dir):  # a figure that cannot be written names the folder
        return study.plot(out_dir)


def data_provenance(study, params):
    """{name or path: {"path", "sha256"}} of the real files the run read: the registry files of
    ``study.data_files(params)`` and any file given as ``nav``/``obs``/``recording``."""
    from oaraim import data

    out = {}
    for name in study.data_files(params):
        try:
            p = data.path(name, fetch=False)
        except data.DataUnavailable:
            continue
        out[name] = {"path": str(p), "sha256": data.sha256(p)}
    for key in ("nav", "obs", "recording"):
        v = params.get(key)
        if isinstance(v, str) and v not in ("auto", "nominal", "none") and Path(v).is_file():
            out[v] = {"path": v, "sha256": data.sha256(v)}
    return out


def check_data(names, progress=True):
    """Fetch each registry file in ``names`` now (the data folder or cache first); returns
    {name: one-line error} for those that cannot be had."""
    from oaraim import data

    missing = {}
    for name in dict.fromkeys(names):
        try:
            data.path(name, progress=progress)
        except data.DataUnavailable as e:
            missing[name] = str(e)
    return missing


def _sweep_provenance(sweep, resume):
    import importlib.metadata

    def version(pkg):
        try:
            return importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {"cells": sweep.cells, "chunk_size": sweep.chunk_size, "batch_size": sweep.batch_size,
            "chunks_computed": sweep.chunks_computed, "chunks_reused": sweep.chunks_reused,
            "realizations_computed": sweep.realizations_computed, "resumed": bool(resume),
            "workers": sweep.workers, "scheduler": sweep.scheduler, "threads": sweep.threads,
            "sweep_wall_time_s": sweep.wall_s,
            "dask": version("dask"), "distributed": version("distributed"),
            "chunk_files": str(Path(sweep.out_dir) / "chunks")}
