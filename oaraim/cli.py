"""The ``oaraim`` command line: list, run, report, bench, reproduce, data.

User errors (a bad ``--set`` value, an unknown study or key) print one line naming what was
wrong and exit with status 2, without a traceback.
"""

import json
import shutil
import sys
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
    from oaraim.studies.base import SweepStudy

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
        for key, p in s.params.items():
            unit = f" {p.unit}" if p.unit else ""
            default = (",".join(str(v) for v in p.default) if isinstance(p.default, tuple)
                       else p.default)
            out.print(f"    --set {key}={default}{unit}  {p.doc}", highlight=False,
                      markup=False)


@app.command()
def run(
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
        "--resume", help="sweep studies: keep the finished chunks in OUT/STUDY, compute the "
        "rest")] = False,
    trust_data: Annotated[bool, typer.Option("--trust-data", help=TRUST_HELP)] = False,
):
    """Run one study; writes OUT/STUDY/{data.zarr, summary.json, provenance.json, *.png}."""
    from oaraim.execute import run_study
    from oaraim.mc.sweep import Execution

    _trust(trust_data)

    try:
        summary, sdir, figures, wall = run_study(study, realizations=realizations, seed=seed,
                                                 out=out_dir, sets=set_, quick=quick,
                                                 show_progress=progress, resume=resume,
                                                 execution=Execution(workers=workers,
                                                                     scheduler=scheduler))
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
        write.parent.mkdir(parents=True, exist_ok=True)
        write.write_text(text + "\n")


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
):
    """Run every study and print the reproduction report.

    The real files the studies need are fetched first (one line per file that cannot be had).
    A failing study is reported as FAILED and the others still run; the exit status is 2 if
    any failed. Full size writes OUT/REPORT.md, or DIR/REPORT.md with --results DIR.
    """
    from oaraim.execute import check_data, run_study
    from oaraim.registry import STUDIES
    from oaraim.report import build_report

    _trust(trust_data)

    if quick and results is not None:
        _fail("--results takes the full-size run: drop --quick, or drop --results (a quick run "
              "writes only under --out)")
    from oaraim.mc.store import OutputError, check_output_folder

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
    done = []
    for name in names:
        lost = [f for f in needs.get(name, ()) if f in missing]
        if lost:
            failures[name] = f"data file {', '.join(lost)} unavailable (see above)"
        if name in failures:
            err.print(f"{name}: FAILED: {escape(str(failures[name]))}", highlight=False,
                      soft_wrap=True)
            continue
        try:
            summary, sdir, figures, wall = run_study(name, seed=seed, out=out_dir, quick=quick,
                                                     show_progress=progress)
        except ValueError as e:
            failures[name] = " ".join(str(e).split())
        except Exception as e:  # noqa: BLE001 - one study's bug must not stop the others
            failures[name] = (f"{type(e).__name__}: {' '.join(str(e).split())} (rerun "
                              f"`oaraim run {name}` for the traceback)")
        if name in failures:
            err.print(f"{name}: FAILED: {escape(str(failures[name]))}", highlight=False,
                      soft_wrap=True)
            continue
        done.append(name)
        err.print(f"{name}: {wall:.1f} s -> {sdir}", highlight=False)
        if results is not None:
            dest = results / name
            dest.mkdir(parents=True, exist_ok=True)
            for f in [*figures, sdir / "summary.json", sdir / "provenance.json"]:
                shutil.copy2(f, dest / Path(f).name)
    text = None
    if done:
        if quick:
            text = build_report(out_dir, only=done)
        else:
            folder = out_dir if results is None else results
            text = build_report(folder, figure_dir=folder, only=done)
            (folder / "REPORT.md").write_text(text + "\n")
            err.print(f"wrote {folder / 'REPORT.md'}", highlight=False)
        print(text)
    if failures:
        err.print(f"[bold red]{len(failures)} of {len(names)} studies failed:[/]",
                  highlight=False)
        for name, msg in failures.items():
            err.print(f"  {name}: {escape(str(msg))}", highlight=False, soft_wrap=True)
        raise typer.Exit(2)


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
):
    """Throughput of the kernels and the NumPy reference in the same run."""
    from oaraim import bench as b

    st = b.bench_startup()
    out.print(f"start-up: import oaraim {st['import_oaraim_s']:.2f} s, from oaraim import "
              f"araim, geometry {st['import_araim_geometry_s']:.2f} s, oaraim --help "
              f"{st['cli_help_s']:.2f} s; first protection_levels call (64 geometries) in a new "
              f"process {st['first_call_cold_s']:.1f} s compiling, "
              f"{st['first_call_cached_s']:.1f} s from the compilation cache", highlight=False)
    lat = b.bench_latency(calls=100 if quick else 300)
    out.print("protection_levels latency (warm, " + lat["fault_modes"] + "): " + ", ".join(
        f"batch {n}: median {lat[f'batch_{n}']['median_ms']:.2f} ms, p99 "
        f"{lat[f'batch_{n}']['p99_ms']:.2f} ms" for n in b.LATENCY_BATCHES), highlight=False)

    res = {"startup": st, "latency": lat}
    res["slope_hpl"] = b.bench_slope_hpl(batch=65_536 if quick else 262_144,
                                          ref_geometries=500 if quick else 2_000)
    s = res["slope_hpl"]
    out.print(f"slope HPL (M + N = 9): {s['jax_hpl_per_s']:,.0f} HPL/s "
              f"(batch {s['batch']:,}, best of 5)", highlight=False)
    out.print(f"  NumPy reference: {s['reference_hpl_per_s']:,.0f} HPL/s -> "
              f"{s['speedup']:,.0f}x; max relative difference {s['max_rel_diff']:.1e}",
              highlight=False)
    m = b.bench_mhss(batch=16_384 if quick else 65_536, ref_geometries=50 if quick else 200)
    res["mhss"] = m
    out.print(f"MHSS PLs (9 GPS + 4 SOPs, Table I, {m['n_modes']} modes): "
              f"{m['jax_pl_per_s']:,.0f} PL/s (batch {m['batch']:,}, best of 5, "
              f"{m['threads']} host threads; one thread {m['one_thread_pl_per_s']:,.0f} PL/s)",
              highlight=False)
    if "speedup" in m:
        out.print(f"  NumPy reference: {m['reference_pl_per_s']:,.1f} PL/s -> "
                  f"{m['speedup']:,.0f}x; max |difference| {m['max_abs_diff_m']:.1e} m",
                  highlight=False)
    for key, case in (("mhss_add_v42", "table-i-add-v4.2"),
                      ("mhss_blanch_2012", "blanch-2012-57-modes")):
        res[key] = m = b.bench_mhss(batch=16_384 if quick else 65_536,
                                    ref_geometries=20 if quick else 50, case=case)
        out.print(f"  {case} ({m['fault_modes']}, order {m['order']}, {m['n_modes']} modes): "
                  f"{m['jax_pl_per_s']:,.0f} PL/s; NumPy reference "
                  f"{m['reference_pl_per_s']:,.1f} PL/s -> {m['speedup']:,.0f}x; max "
                  f"|difference| {m['max_abs_diff_m']:.1e} m", highlight=False)
    p = b.profile_mhss(batch=16_384 if quick else 65_536)
    res["mhss_profile"] = p
    out.print(f"  profile ({p['cpu_us_per_pl']:.1f} CPU-us per PL): fault modes "
              f"{p['fault_modes_s'] / p['total_s']:.0%}, projectors (eqs. 9-12) "
              f"{p['projectors_s'] / p['total_s']:.0%}, PL root finding "
              f"{p['pl_root_finding_s'] / p['total_s']:.0%}", highlight=False)
    from oaraim.bench_grad import bench_gradient

    res["mhss_gradient"] = gr = bench_gradient(batch=4_096 if quick else 16_384)
    out.print(f"  value and gradient of HPL (all {len(gr['inputs'])} real inputs, one thread, "
              f"batch {gr['batch']:,}): {gr['value_and_grad_hpl_per_s']:,.0f} HPL/s against "
              f"{gr['value_hpl_per_s']:,.0f} HPL/s for the value alone: "
              f"{gr['ratio']:.1f}x its cost (goal <= 3x)", highlight=False)
    n3 = 100_000 if quick else 1_000_000
    res["fig3"] = b.bench_fig3(n3)
    out.print(f"seed001-fig3-elevation at {n3:,} realizations: {res['fig3']['wall_s']:.1f} s "
              f"wall (compile included)", highlight=False)
    res["sky"] = b.bench_sky()
    sk = res["sky"]
    out.print(f"sky, 1 receiver x 2,880 epochs (24 h at 30 s), nominal GPS + Galileo: "
              f"{sk['one_receiver_2880_epochs_nominal_s']:.3f} s (target < 1 s)",
              highlight=False)
    if "one_receiver_2880_epochs_broadcast_s" in sk:
        out.print(f"  same from the Villafranca broadcast file ({sk['broadcast_satellites']} "
                  f"satellites): {sk['one_receiver_2880_epochs_broadcast_s']:.3f} s "
                  f"(parse {sk['vill_parse_s']:.2f} s, cached per process)", highlight=False)
    out.print(f"sky, 1,000 receivers x 288 epochs, nominal GPS + Galileo: "
              f"{sk['receivers_1000_x_288_epochs_nominal_s']:.3f} s (target < 10 s)",
              highlight=False)
    from oaraim.bench_ekf import bench_ekf_drive

    runs = 100 if quick else 1000
    res["ekf_drive"] = e = bench_ekf_drive(runs)
    out.print(f"EKF-RAIM Monte Carlo, seed 000 drive (1.35 km, 100 Hz IMU), {runs:,} runs, "
              f"without and with exclusion: {e['wall_s']:.1f} s wall, {e['cpu_s']:.1f} s CPU "
              f"(first call with compilation {e['first_call_wall_s']:.1f} s; target 1000 runs "
              f"<= 60 s)", highlight=False)
    res["availability_map"] = a = b.bench_availability_map(
        {"lat_deg": "30:50:10", "lon_deg": "0:20:10"} if quick else None)
    out.print(f"availability-map ({a['service_level']}), {a['users']:,} users x {a['epochs']} "
              f"epochs: {a['wall_s']:.1f} s wall, compile included ({a['pl_per_s']:,.0f} PL/s; "
              f"target < 60 s for the world map)", highlight=False)
    res["integrity_risk"] = r = b.bench_integrity_risk(samples=50_000 if quick else 200_000,
                                                       ref_samples=50 if quick else 200)
    out.print(f"integrity risk, MHSS decisions from the linear maps: {r['samples_per_s']:,.0f} "
              f"samples/s; NumPy reference {r['reference_samples_per_s']:,.1f} samples/s -> "
              f"{r['speedup']:,.0f}x (detections agree on {r['detection_agreement']:.0%}); one "
              f"geometry's risk table {r['risk_table_s']:.1f} s; IS vs crude at equal relative "
              f"error (P = {r['ff_vertical_p']:.1e}): {r['is_speedup_equal_rel_error']:.1e}x",
              highlight=False)
    if dask_map:
        res["availability_map_dask"] = a = b.bench_availability_map(
            {"lat_deg": "-90:90:1", "lon_deg": "-180:179:1"}, workers=2)
        out.print(f"availability-map 1 x 1 deg on Dask (2 workers), {a['users']:,} users x "
                  f"{a['epochs']} epochs: {a['wall_s']:.1f} s wall ({a['pl_per_s']:,.0f} PL/s)",
                  highlight=False)
    if fig4:
        res["fig4"] = f = b.bench_fig4()
        out.print(f"seed004-fig4-hpl-maps full size ({f['cells']:,} cells x "
                  f"{f['realizations']:,}): {f['wall_s']:.1f} s wall, compile included "
                  f"({f['draws_per_s']:,.0f} draws/s)", highlight=False)
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
    """The ``oaraim`` console script: the Typer app, Ctrl-C as one line and exit status 130."""
    try:
        app()
    except KeyboardInterrupt:
        err.print("interrupted (a sweep keeps its finished chunks: rerun with --resume)")
        sys.exit(130)
