"""The ``oaraim`` command line: list, run, report, bench, reproduce, data.

User errors (a bad ``--set`` value, an unknown study or key) print one line naming what was
wrong and exit with status 2, without a traceback.
"""

import contextlib
import json
import shutil
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Monte Carlo RAIM / ARAIM / opportunistic ARAIM studies.")
err = Console(stderr=True)
out = Console()

data_app = typer.Typer(add_completion=False, no_args_is_help=True,
                       help="The real GNSS files: list them, fetch them, get a day's broadcast "
                       "ephemeris.")
app.add_typer(data_app, name="data")


def _fail(msg: str):
    err.print(f"[bold red]error:[/] {escape(msg)}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


def _warn(msg: str):
    """A one-line notice on stderr (a run that took over a dead run's lock)."""
    err.print(f"[bold yellow]warning:[/] {escape(msg)}", highlight=False, soft_wrap=True)


@contextlib.contextmanager
def _warnings_as_lines():
    """A study's own warnings (``UserWarning``: epochs with too few sources, a missing
    correction) printed as ``warning: ...`` lines, like the run's other notices, instead of
    Python's ``file:line: UserWarning`` with a line of source code; others as Python prints
    them."""
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, UserWarning):
            _warn(str(message))
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = shown


TRUST_HELP = ("use local data files (OARAIM_DATA folder, ../shared/data) even where their "
              "sha256 differs from the registry's (also OARAIM_TRUST_DATA=1)")


def _trust(on: bool):
    if on:
        import os

        os.environ["OARAIM_TRUST_DATA"] = "1"


@app.command("list")
def list_studies():
    """List the studies with their parameters and defaults."""
    from oaraim.registry import STUDIES
    from oaraim.studies.base import ResumableStudy, SweepStudy

    for name, s in STUDIES.items():
        # the texts are printed literally (markup=False): a "[d_min_m, d_max_m]" in a help
        # text is not Rich markup
        out.print(f"[bold]{name}[/]  {escape(s.title)}", highlight=False)
        out.print(f"  one realization: {s.realization}; default {s.default_realizations:,}, "
                  f"quick {s.quick_realizations:,}" + "".join(
                      f", {k}={v}" for k, v in s.quick_sets.items()),
                  highlight=False, markup=False)
        if isinstance(s, SweepStudy):
            out.print(f"  sweep over {' x '.join(s.axis_names)} (--resume, --workers N, "
                      "--scheduler ADDRESS); realizations are per cell", highlight=False,
                      markup=False)
        elif isinstance(s, ResumableStudy):
            out.print("  resumable (--resume): each finished stage is checkpointed",
                      highlight=False, markup=False)
        for key, p in s.params.items():
            unit = f" {p.unit}" if p.unit else ""
            default = (",".join(str(v) for v in p.default) if isinstance(p.default, tuple)
                       else p.default)
            out.print(f"    --set {key}={default}{unit}  {p.doc}", highlight=False,
                      markup=False)


# The command's options are the user interface (its flags and help); the function is private
# so that its Python signature, one parameter per flag, is no public API.
@app.command("run")
def _run(
    study: Annotated[str, typer.Argument(help="study name (see `oaraim list`)")],
    realizations: Annotated[int | None, typer.Option(help="Monte Carlo samples per cell")] = None,
    seed: Annotated[int, typer.Option(help="study seed")] = 0,
    out_dir: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out"),
    set_: Annotated[list[str] | None, typer.Option("--set", help="KEY=VALUE parameter")] = None,
    quick: Annotated[bool, typer.Option(help="use the study's quick size")] = False,
    progress: Annotated[bool, typer.Option(help="show a progress bar on stderr")] = True,
    workers: Annotated[int | None, typer.Option(
        help="sweep studies: run on a local Dask cluster of N worker processes")] = None,
    scheduler: Annotated[str | None, typer.Option(
        help="sweep studies: run on an existing Dask scheduler (tcp://HOST:PORT)")] = None,
    resume: Annotated[bool, typer.Option(
        "--resume", help="resumable studies (sweeps, tower-placement, sop-requirements): keep the "
        "finished chunks or units in OUT/STUDY, compute the rest")] = False,
    trust_data: Annotated[bool, typer.Option("--trust-data", help=TRUST_HELP)] = False,
):
    """Run one study; writes OUT/STUDY/{data.zarr, summary.json, provenance.json, *.png}."""
    from oaraim.execute import RunOptions, run_study
    from oaraim.mc import Execution

    _trust(trust_data)

    try:
        with _warnings_as_lines():
            summary, sdir, figures, wall = run_study(
                study, realizations=realizations, seed=seed, out=out_dir, sets=set_,
                quick=quick, show_progress=progress, options=RunOptions(
                    resume=resume, execution=Execution(workers=workers, scheduler=scheduler),
                    notice=_warn))
    except (ValueError, OSError) as e:  # bad input, unusable --out, a full disk: one line
        _fail(str(e))
    _print_rows(summary)
    err.print(f"done in {wall:.1f} s; results in {sdir}", highlight=False)


def _print_rows(summary):
    t = Table(title=summary["study"], show_lines=False)
    for col in ("quantity", "unit", "published", "reproduced"):
        t.add_column(col)
    for r in summary["rows"]:
        pub = "-" if r["published"] is None else f"{r['published']:.4g}"
        t.add_row(escape(r["quantity"]), escape(r["unit"]), pub, f"{r['reproduced']:.4g}")
    out.print(t)


@app.command()
def calibrate(
    study: Annotated[str, typer.Argument(help="study name (see `oaraim list`)")],
    realizations: Annotated[int | None, typer.Option(
        help="realizations per run (default: the study's calibration size)")] = None,
    seed: Annotated[int, typer.Option(help="the one seed of every run")] = 0,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="KEY=VALUE parameter held fixed while fitting")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="write the fit here")] = None,
):
    """Fit the parameters the paper leaves open to its published numbers; print the fitted
    values, the residuals and their sensitivities."""
    from oaraim.calibrate import calibrate as fit
    from oaraim.execute import parse_sets
    from oaraim.registry import get_study

    try:
        s = get_study(study)
        res = fit(s, realizations=realizations, seed=seed, sets=parse_sets(set_),
                  say=lambda text: err.print(escape(text), highlight=False))
    except ValueError as e:
        _fail(str(e))
    say = lambda text: out.print(escape(text), highlight=False, soft_wrap=True)  # noqa: E731
    say(f"{res.study}: {res.realizations:,} realizations per run, {res.evaluations} runs, "
        f"seed {seed}")
    for k, v in res.fitted.items():
        say(f"  {k}: fitted {v:.4g} (default {res.defaults[k]:.4g})")
    for r in res.targets:
        el = ", ".join(f"{k} {e:+.2f}" for k, e in res.elasticity[r["quantity"]].items())
        say(f"  {r['quantity']}: published {r['published']:.4g}, at the default "
            f"{r['at_default']:.4g}, at the fit {r['at_fit']:.4g} ({100 * r['residual']:+.1f} "
            f"%); elasticity (dT/T)/(dp/p): {el}")
    if json_out is not None:
        json_out.write_text(json.dumps(res._asdict(), indent=2) + "\n")


@app.command()
def report(
    out_dir: Annotated[Path, typer.Option("--out", help="folder holding the study runs")] =
    Path("out"),
    write: Annotated[Path | None, typer.Option(help="also write the Markdown here")] = None,
):
    """Markdown table of every study's published vs reproduced numbers."""
    from oaraim.report import build_report

    text = build_report(out_dir)
    if text is None:
        _fail(f"no study results under {out_dir}; run `oaraim run STUDY --out {out_dir}` first")
    print(text)
    if write is not None:
        from oaraim.mc import os_error_line, writing

        try:
            write.parent.mkdir(parents=True, exist_ok=True)
            with writing(write):
                write.write_text(text + "\n")
        except OSError as e:
            _fail(os_error_line(e, write).replace("another --out", "another --write"))


@app.command()
def reproduce(
    quick: Annotated[bool, typer.Option(help="quick size: minutes; nothing written outside "
                                        "OUT")] = False,
    out_dir: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out"),
    seed: Annotated[int, typer.Option(help="study seed")] = 0,
    progress: Annotated[bool, typer.Option(help="show progress bars")] = True,
    results: Annotated[Path | None, typer.Option(
        "--results", help="full size only: copy each study's figures, summary.json and "
        "provenance.json into DIR/STUDY and write DIR/REPORT.md (the committed results: "
        "--results results)")] = None,
    only: Annotated[list[str] | None, typer.Option(
        "--only", hidden=True, help="run only these studies (tests)")] = None,
    trust_data: Annotated[bool, typer.Option(
        "--trust-data", help=TRUST_HELP)] = False,
    jobs: Annotated[int, typer.Option(
        "--jobs", "-j", help="studies run at once, each in a process of its own (a first run "
        "is mostly compilation, one core's work per program); 1: one after the other in this "
        "process, with each study's progress bar")] = 2,
):
    """Run every study and print the reproduction report.

    The real files the studies need are fetched first (one line per file that cannot be had).
    A failing study is reported as FAILED and the others still run; the exit status is 2 if
    any failed. Full size writes OUT/REPORT.md, or DIR/REPORT.md with --results DIR.
    """
    from oaraim.execute import check_data
    from oaraim.registry import STUDIES
    from oaraim.report import build_report

    _trust(trust_data)

    if quick and results is not None:
        _fail("--results takes the full-size run: drop --quick, or drop --results (a quick run "
              "writes only under --out)")
    if jobs < 1:
        _fail(f"--jobs must be >= 1, got {jobs}")
    from oaraim.mc import OutputError, check_output_folder, check_seed, os_error_line, writing

    try:  # once, not one failure per study
        check_seed(seed)
    except ValueError as e:
        _fail(str(e))

    try:  # once, before any study: not one failure per study after its computation
        check_output_folder(out_dir)
        if results is not None:
            check_output_folder(results, "--results")
    except OutputError as e:
        _fail(str(e))
    names = list(only or STUDIES)
    unknown = [n for n in names if n not in STUDIES]
    if unknown:
        _fail(f"unknown study {unknown[0]!r}; known studies: {', '.join(STUDIES)}")
    failures = {}
    needs = {}
    for name in names:
        try:
            needs[name] = STUDIES[name].data_files(STUDIES[name].validate({}))
        except ValueError as e:
            failures[name] = str(e)
    missing = check_data([f for n in names for f in needs.get(n, ())], progress=progress)
    for msg in missing.values():
        err.print(f"[bold red]missing data:[/] {escape(msg)}", highlight=False, soft_wrap=True)
    todo = []
    for name in names:
        lost = [f for f in needs.get(name, ()) if f in missing]
        if lost:
            failures[name] = f"data file {', '.join(lost)} unavailable (see above)"
        if name in failures:
            err.print(f"{name}: FAILED: {escape(str(failures[name]))}", highlight=False,
                      soft_wrap=True)
        else:
            todo.append(name)
    done = []
    for name, outcome in _run_studies(todo, jobs, seed=seed, out=out_dir, quick=quick,
                                      show_progress=progress):
        if isinstance(outcome, str):
            failures[name] = outcome
            err.print(f"{name}: FAILED: {escape(outcome)}", highlight=False, soft_wrap=True)
            continue
        _summary, sdir, figures, wall = outcome
        done.append(name)
        err.print(f"{name}: {wall:.1f} s -> {sdir}", highlight=False)
        if results is not None:
            dest = results / name
            try:
                dest.mkdir(parents=True, exist_ok=True)
                for f in [*figures, sdir / "summary.json", sdir / "provenance.json"]:
                    shutil.copy2(f, dest / Path(f).name)
            except OSError as e:  # a full disk: this study fails, with the path
                failures[name] = os_error_line(e, dest).replace("another --out",
                                                                "another --results")
                err.print(f"{name}: FAILED: {escape(failures[name])}", highlight=False,
                          soft_wrap=True)
                continue
    text = None
    if done:
        if quick:
            text = build_report(out_dir, only=done)
        else:
            folder = out_dir if results is None else results
            text = build_report(folder, figure_dir=folder, only=done)
            try:
                with writing(folder / "REPORT.md"):
                    (folder / "REPORT.md").write_text(text + "\n")
            except OSError as e:
                _fail(os_error_line(e, folder))
            err.print(f"wrote {folder / 'REPORT.md'}", highlight=False)
        print(text)
    if failures:
        err.print(f"[bold red]{len(failures)} of {len(names)} studies failed:[/]",
                  highlight=False)
        for name, msg in failures.items():
            err.print(f"  {name}: {escape(str(msg))}", highlight=False, soft_wrap=True)
        raise typer.Exit(2)


def _run_studies(names, jobs, **kw):
    """(name, outcome) of each study as it finishes: ``execute.study_outcome``'s (summary,
    folder, figures, wall) or one-line failure. ``jobs`` > 1 runs the studies that many at a
    time in fresh processes (spawned: JAX does not survive a fork), the costliest first
    (``Study.quick_cost_s``), with one bar over the studies; studies registered at run time
    (tests) are not importable by a new process and run here, as everything does with 1."""
    from oaraim.execute import study_outcome
    from oaraim.registry import STUDIES

    if jobs == 1 or len(names) < 2 or not all(STUDIES.is_builtin(n) for n in names):
        for name in names:
            yield name, study_outcome(name, **kw)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from oaraim.mc import ProgressBar

    order = sorted(names, key=lambda n: -STUDIES[n].quick_cost_s)
    show, kw = kw["show_progress"], {**kw, "show_progress": False}
    with ProgressBar(len(order), f"{len(order)} studies, {jobs} at a time", enabled=show,
                     rate_unit=None) as bar, \
            ProcessPoolExecutor(min(jobs, len(order)),
                                mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(study_outcome, n, **kw): n for n in order}
        for fut in as_completed(futures):
            try:
                outcome = fut.result()
            except Exception as e:  # noqa: BLE001 - a worker that died (memory, a signal)
                outcome = (f"its process ended ({type(e).__name__}: {' '.join(str(e).split())});"
                           " rerun with --jobs 1, or `oaraim run` the study alone")
            bar.advance(1)
            yield futures[fut], outcome


@app.command()
def bench(
    quick: Annotated[bool, typer.Option(help="smaller sizes (seconds instead of a minute)")] =
    False,
    json_out: Annotated[Path | None, typer.Option("--json", help="write the numbers here")] =
    None,
    dask_map: Annotated[bool, typer.Option(
        "--dask-map", help="also the 1 x 1 deg, 24 h availability map on a local Dask cluster "
        "of 2 worker processes (minutes)")] = False,
    fig4: Annotated[bool, typer.Option(
        "--fig4", help="also seed004-fig4-hpl-maps at its full size (minutes)")] = False,
    world_map: Annotated[bool, typer.Option(
        "--world-map", help="also the 1 x 1 deg, 24 h availability map in this process "
        "(minutes; the accelerator's row where JAX has one)")] = False,
    only: Annotated[str | None, typer.Option(
        help="run only these comma-separated parts: startup, latency, slope, mhss, fig3, sky, "
        "ekf, filterbank, map, risk, leo (--fig4, --world-map and --dask-map add theirs)")] = None,
    mhss_batch: Annotated[int | None, typer.Option(
        help="batch of the MHSS throughput rows (default 65,536, 16,384 with --quick; an "
        "accelerator wants ~10^6)")] = None,
):
    """Throughput of the kernels and the NumPy reference in the same run."""
    from oaraim.bench_run import BENCH_PARTS, run_bench

    parts = set(BENCH_PARTS)
    if only is not None:
        parts = {p.strip() for p in only.split(",") if p.strip()}
        unknown = sorted(parts - set(BENCH_PARTS))
        if unknown:
            _fail(f"--only: unknown part(s) {', '.join(unknown)}; choose from "
                  f"{', '.join(BENCH_PARTS)}")
    if mhss_batch is not None and mhss_batch < 1:
        _fail(f"--mhss-batch must be a positive integer, got {mhss_batch}")
    if fig4:
        parts.add("fig4")
    if world_map:
        parts.add("world-map")
    if dask_map:
        parts.add("dask-map")
    res = run_bench(parts, quick=quick, mhss_batch=mhss_batch,
                    say=lambda text: out.print(text, highlight=False))
    if json_out is not None:
        json_out.write_text(json.dumps(res, indent=2) + "\n")


@data_app.command("list")
def data_list():
    """Every known real file: size, whether it is here (data folder / cache), origin, licence."""
    from oaraim import data

    try:
        rows = [(e, data.status(e.name)[0]) for e in data.registry().values()]
        where = data.where()
    except data.DataUnavailable as e:
        _fail(str(e))
    t = Table(title="oaraim data files", show_lines=False)
    for col in ("name", "size", "here", "origin", "licence"):
        t.add_column(col, overflow="fold")
    style = {"folder": "green", "cached": "green", "missing": "yellow"}
    for e, state in rows:
        t.add_row(e.name, f"{e.size / 1e3:,.0f} kB", f"[{style[state]}]{state}[/]", e.url,
                  e.licence)
    out.print(t)
    out.print(f"files come from {where}", highlight=False, soft_wrap=True)


@data_app.command("fetch")
def data_fetch(
    names: Annotated[list[str] | None, typer.Argument(
        help="file names as `oaraim data list` shows them")] = None,
    all_: Annotated[bool, typer.Option("--all", help="every known file")] = False,
    progress: Annotated[bool, typer.Option(help="show a progress bar on a terminal")] = True,
):
    """Fetch files into the cache (checksums checked); prints each file's local path."""
    from oaraim import data

    reg = data.registry()
    if all_ and names:
        _fail("give file names or --all, not both")
    if not all_ and not names:
        _fail("give file names (see `oaraim data list`) or --all")
    unknown = [n for n in names or () if n not in reg]
    if unknown:
        _fail(f"unknown data file {unknown[0]!r}; known files: {', '.join(reg)}")
    failed = 0
    for name in (list(reg) if all_ else names):
        try:
            p = data.path(name, progress=progress)
        except data.DataUnavailable as e:
            err.print(f"[bold red]error:[/] {e}", highlight=False, soft_wrap=True)
            failed += 1
            continue
        out.print(f"{name}: {p}", highlight=False, soft_wrap=True)
    if failed:
        raise typer.Exit(2)


@data_app.command("nav")
def data_nav(
    date: Annotated[str, typer.Argument(help="the day, YYYY-MM-DD")],
    archive: Annotated[str | None, typer.Option(
        help="archive base URL laid out as BASE/YYYY/DDD/FILE (default: OARAIM_BRDC_ARCHIVE, "
        "else BKG's IGS BRDC folder)")] = None,
    progress: Annotated[bool, typer.Option(help="show a progress bar on a terminal")] = True,
):
    """The IGS merged daily broadcast ephemeris of a day; prints its path (for --set nav=PATH).
    """
    from oaraim import data

    try:
        p = data.fetch_daily_nav(date, archive=archive, progress=progress)
    except data.DataUnavailable as e:
        _fail(str(e))
    print(p)


def main():
    """The ``oaraim`` console script: the Typer app, Ctrl-C as one line and exit status 130.
    NumPy's large arrays on small pages (``config.small_pages_for_numpy``)."""
    from oaraim import config

    config.small_pages_for_numpy()
    try:
        app()
    except KeyboardInterrupt:
        err.print("interrupted (a resumable study keeps its finished chunks or units: rerun "
                  "with --resume)")
        sys.exit(130)
