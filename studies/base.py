"""What every study declares: parameters with validation, a run, and a plot that reads results."""

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from oaraim.araim import check_int, check_positive, check_probability, check_range


@dataclass(frozen=True)
class Param:
    """One ``--set KEY=VALUE`` parameter: its default, a parser that validates, and its meaning."""

    default: Any
    """The value used when the user sets none."""
    parse: Callable[[str, Any], Any]
    """``(name, raw value) -> value``; raises ValueError naming ``name`` when invalid."""
    doc: str
    """What the parameter means, one line (``oaraim list`` prints it)."""
    unit: str = ""
    """Its unit, e.g. ``"m"`` or ``"deg"`` ("" when it has none)."""


def probability(name, v):
    """Parser of a probability parameter: a float strictly inside (0, 1)."""
    return check_probability(name, v)


def positive(name, v):
    """Parser of a parameter that must be a finite float > 0."""
    return check_positive(name, v)


def non_negative(name, v):
    """Parser of a parameter that must be a finite float >= 0."""
    return check_positive(name, v, allow_zero=True)


def count(minimum, maximum=None):
    """Parser of an integer parameter in ``minimum..maximum`` (no upper bound if None)."""
    return lambda name, v: check_int(name, v, minimum, maximum)


def in_range(lo, hi):
    """Parser of a float parameter in [``lo``, ``hi``]."""
    return lambda name, v: check_range(name, v, lo, hi)


def keyword_or_file(keywords, what):
    """A parameter that is one of ``keywords`` or the path of an existing file (``what`` names
    the kind of file in the error); returns the keyword or the resolved path."""
    allowed = ", ".join(repr(k) for k in keywords)

    def parse(name, v):
        s = str(v).strip()
        if s in keywords:
            return s
        p = Path(s).expanduser()
        if not p.is_file():
            raise ValueError(f"{name} must be {allowed} or an existing {what}, got {v!r} "
                             "(not found)")
        return str(p.resolve())

    return parse


def parse_choice(*choices):
    """A parameter taking one of ``choices`` (strings)."""
    def parse(name, v):
        v = str(v).strip()
        if v not in choices:
            raise ValueError(f"{name} must be one of {', '.join(choices)}, got {v!r}")
        return v
    return parse


#: the value of a ``recording`` parameter that means "synthesize, replay nothing"
NO_RECORDING = "none"


def parse_recording(name, v):
    """A ``recording`` parameter: 'none' (or empty) to synthesize, else a recorded drive or
    flight in the ``geometry.recording`` format: its folder, or the folder's meta.json. Returns
    'none' or the resolved path; the tables themselves are checked when loaded."""
    s = str(v).strip()
    if s in ("", NO_RECORDING):
        return NO_RECORDING
    p = Path(s).expanduser()
    if p.is_file() and p.name == "meta.json":
        return str(p.resolve())
    if not p.is_dir():
        raise ValueError(f"{name}: {s!r} is not a folder (or its meta.json); give the folder of "
                         "a recording, or 'none' to synthesize (README 'Recorded drives and "
                         "flights')")
    if not (p / "meta.json").is_file():
        raise ValueError(f"{name}: {s!r} has no meta.json; a recording is a folder with "
                         "meta.json and its tables (README 'Recorded drives and flights')")
    return str(p.resolve())


def check_bpp_annulus(p):
    """Cross-checks of the BPP parameters: d_min_m < d_max_m and h_min_m <= h_max_m."""
    if p["d_min_m"] >= p["d_max_m"]:
        raise ValueError(f"d_min_m must be < d_max_m, got d_min_m={p['d_min_m']} and "
                         f"d_max_m={p['d_max_m']}")
    if p["h_min_m"] > p["h_max_m"]:
        raise ValueError(f"h_min_m must be <= h_max_m, got h_min_m={p['h_min_m']} and "
                         f"h_max_m={p['h_max_m']}")


def axis(parse_one):
    """Parser of a sweep axis parameter: ``"2,3,4"``, a scalar, or a list/tuple -> a non-empty
    tuple of values without duplicates, each parsed by ``parse_one(name, v)`` (e.g.
    ``count(1, 30)``, ``positive``, ``probability``). Errors name the key."""

    def parse(name, v):
        if isinstance(v, str):
            items = [x.strip() for x in v.split(",")]
            if any(not x for x in items):
                raise ValueError(f"{name} takes comma-separated values such as 1,2,3; got "
                                 f"{v!r} (an empty item)")
        elif isinstance(v, list | tuple):
            items = list(v)
        else:
            items = [v]
        if not items:
            raise ValueError(f"{name} needs at least one value")
        vals = tuple(parse_one(name, x) for x in items)
        for i, x in enumerate(vals):
            if x in vals[:i]:
                raise ValueError(f"{name} lists the value {x!r} twice; give each value once")
        return vals

    return parse


class Free(NamedTuple):
    """A parameter that ``oaraim calibrate`` fits: a study parameter the paper leaves open."""

    name: str
    """The study parameter (a key of ``Study.params``, a float)."""
    low: float
    """Smallest value tried."""
    high: float
    """Largest value tried."""


class Target(NamedTuple):
    """A published number that ``oaraim calibrate`` fits: the summary row whose ``quantity``
    matches ``pattern`` (``re.search``), its ``published`` against its ``reproduced``."""

    pattern: str
    """Regular expression found in exactly one summary row's ``quantity``."""
    weight: float = 1.0
    """Weight of its relative residual in the fit."""


class Calibration(NamedTuple):
    """How a study's open parameters were chosen (``oaraim calibrate STUDY``): the ``free``
    parameters are fitted so the ``targets`` rows reproduce their published numbers (least
    squares of the weighted relative residuals, common random numbers: one seed)."""

    free: tuple
    """The fitted parameters (``Free``)."""
    targets: tuple
    """The published numbers (``Target``)."""
    realizations: int
    """Realizations per evaluation (the run's size while fitting)."""
    sets: dict = {}
    """Parameter values of the fitting runs (e.g. a smaller grid that leaves the targets as
    they are); the fitted values apply to the study's defaults."""


@dataclass
class StudyResult:
    """What a study's run returns: its dataset, summary rows, metrics and extra provenance."""

    dataset: Any
    """The ``xarray.Dataset`` stored as ``OUT/STUDY/data.zarr`` (what ``plot`` reads)."""
    rows: list
    """The summary rows, each ``{"quantity", "unit", "published", "reproduced", "note"}``:
    a published number of the seed paper beside ours (``published`` None where the paper
    prints none)."""
    metrics: dict
    """Named numbers of the run (JSON values), stored in summary.json."""
    extra_provenance: dict = field(default_factory=dict)
    """Study-specific entries added to provenance.json."""


class Study:
    """Base class. Subclasses set the class attributes and implement ``run`` and ``plot``."""

    name: str = ""
    title: str = ""
    seed_file: str = ""
    realization: str = ""  # what one realization is
    default_realizations: int = 1
    quick_realizations: int = 1
    #: parameter values of ``--quick`` (``reproduce --quick``) where the user sets none: the
    #: reduction of a study whose size is a parameter rather than a realization count
    quick_sets: dict = {}
    #: rough seconds of ``--quick`` on 2 cores with an empty compilation cache (measured; a
    #: scheduling hint only: ``reproduce --jobs`` starts the costliest studies first so that
    #: its processes finish together)
    quick_cost_s: float = 10.0
    #: most realizations one run holds (a study that keeps its realizations in memory; sweep
    #: studies chunk them to disk and are bound by the keys' 32-bit realization index only):
    #: None = 20 x ``default_realizations``
    max_realizations: int | None = None
    params: dict = {}
    #: registry name (``oaraim.data``) of the real file that ``--set nav=auto`` uses, if any
    nav_file: str = ""
    #: how ``oaraim calibrate`` fits the parameters the paper leaves open (``Calibration``),
    #: or None where nothing is fitted
    calibration: "Calibration | None" = None

    def data_files(self, params: dict) -> tuple:
        """Registry names (``oaraim data list``) of the real files a run with ``params`` reads:
        ``reproduce`` fetches them before running and provenance records their sha256."""
        if params.get("recording", NO_RECORDING) != NO_RECORDING:
            return ()  # a replayed recording brings its own sky
        return (self.nav_file,) if self.nav_file and params.get("nav") == "auto" else ()

    def realization_limit(self) -> int | None:
        """The most realizations a run accepts (None: no bound)."""
        return (self.max_realizations if self.max_realizations is not None
                else 20 * self.default_realizations)

    def too_many_realizations(self, n: int, limit: int) -> str:
        """The one line refusing ``--realizations n`` above ``limit``: why, and what to do
        instead (a study whose realizations are not random draws says what it does)."""
        return (f"--realizations {n:,} is more than {self.name} holds in one run (at most "
                f"{limit:,}, it keeps them in memory); run several --seed values and combine "
                "them")

    def validate(self, overrides: dict) -> dict:
        """Defaults updated with ``overrides`` (raw strings or values), each parsed and checked."""
        unknown = sorted(set(overrides) - set(self.params))
        if unknown:
            raise ValueError(
                f"unknown parameter {unknown[0]!r} for study {self.name}; valid keys: "
                + ", ".join(sorted(self.params)))
        out = {}
        for key, p in self.params.items():
            out[key] = p.parse(key, overrides.get(key, p.default))
        self.check(out)
        return out

    def check(self, params: dict) -> None:
        """Cross-parameter checks (e.g. d_min < d_max); raise ValueError naming the fields."""

    def fixed_realizations(self, params: dict) -> int | None:
        """Realizations per cell when the parameters set them (a study whose realizations are
        the elements of a grid, not samples), else None (``--realizations`` chooses)."""
        return None

    def run(self, params: dict, realizations: int, seed: int, progress) -> StudyResult:
        """Compute the study: ``params`` as ``validate`` returns them, ``realizations`` draws
        from ``seed`` (``mc.keys``: the same seed gives the same result), ``progress`` an
        object with ``advance(n)`` (``mc.progress.ProgressBar``) to count realizations done.
        Returns the dataset, summary rows and metrics; writes nothing (``oaraim.execute``
        stores them in ``OUT/STUDY/``)."""
        raise NotImplementedError

    def plot(self, out_dir) -> list:
        """Draw the figures from the stored results in ``out_dir`` (``data.zarr``, never
        recomputed) into ``out_dir``; returns the paths of the files written."""
        raise NotImplementedError


class ResumableStudy(Study):
    """A study whose run is a sequence of units of work (an optimiser's starts, a root per grid
    point), each checkpointed (``mc.checkpoint``): ``oaraim run STUDY --resume`` reuses the
    units an interrupted run finished, and the result is bit-identical to an uninterrupted run.

    Subclasses implement ``run_units``, computing each unit as ``checkpoint.unit(name,
    compute)`` (``compute()`` returns arrays, numbers, strings, lists, tuples or dicts; a name
    is unique in the run and a file name) and deriving everything else from the units' values.
    ``oaraim.execute.run_study`` passes an ``mc.checkpoint.Checkpoint`` in ``OUT/STUDY/``.
    """

    def run(self, params, realizations, seed, progress=None, checkpoint=None) -> StudyResult:
        """``run_units`` with ``checkpoint`` (default: ``mc.checkpoint.NoCheckpoint``, every
        unit computed, nothing stored)."""
        from oaraim.mc.checkpoint import NoCheckpoint

        checkpoint = NoCheckpoint() if checkpoint is None else checkpoint
        return self.run_units(params, realizations, seed, progress, checkpoint)

    def run_units(self, params, realizations, seed, progress, checkpoint) -> StudyResult:
        """``Study.run`` with every unit of work computed through ``checkpoint.unit``."""
        raise NotImplementedError


class SweepStudy(Study):
    """A study that is a grid of cells (``mc.sweep``): resumable (``--resume``) and
    distributable (``--workers``, ``--scheduler``).

    Subclasses declare their axes as parameters parsed by ``axis(...)`` and list them in
    ``axis_names`` (grid order); ``key_axes`` are the axes whose values change the random draws
    (the others reuse them: common random numbers). They implement ``kernel`` (``coords ->
    keys -> dict of (batch,) arrays``; the engine calls it with ``batch_size(params)`` keys,
    1024 by default, whatever the chunk), ``reducers`` and ``finish`` (the reduced grid ->
    ``StudyResult``). ``oaraim.execute.run_study`` runs them through ``mc.sweep.run_sweep``.
    """

    axis_names: tuple = ()

    def realization_limit(self) -> int | None:
        """2^32 per cell: chunked to disk (``mc.sweep``), bound only by the 32-bit index of a
        realization in its key (``mc.keys.MAX_REALIZATIONS``)."""
        from oaraim.mc import MAX_REALIZATIONS

        return MAX_REALIZATIONS

    def too_many_realizations(self, n: int, limit: int) -> str:
        """The one line refusing more realizations per cell than the keys index."""
        return (f"--realizations {n:,} is more than a sweep draws per cell (at most 2^32 = "
                f"{limit:,}: a realization's index in its random key is 32-bit); run several "
                "--seed values (each draws other realizations) and combine them")
    key_axes: tuple = ()
    chunk_param: str = "chunk"  # the parameter giving realizations per task / chunk file

    def axes(self, params) -> tuple:
        """The grid: one ``mc.sweep.Axis`` per name of ``axis_names``, with the values of the
        parameter of that name (a tuple, parsed by ``axis(...)``)."""
        from oaraim.mc import Axis

        return tuple(Axis(k, tuple(params[k])) for k in self.axis_names)

    def kernel(self, params, coords):
        """The kernel of one cell: ``coords`` (axis name -> value) -> a function of a
        ``(batch_size(params),)`` key array returning a dict of ``(batch,)`` arrays, the
        outputs the reducers read. Jit it; it is built once per cell and process."""
        raise NotImplementedError

    def reducers(self, params) -> tuple:
        """The reducers of the kernel's outputs (``mc.reduce``: ``Mean``, ``Max``,
        ``Histogram``, ``EmpiricalCDF``, ...), one dataset variable each per cell."""
        raise NotImplementedError

    def finish(self, params, dataset, realizations, seed) -> StudyResult:
        """The reduced grid (``SweepResult.dataset``: dims = axis names, one variable per
        reducer output) -> the study's ``StudyResult`` (dataset to store, rows, metrics)."""
        raise NotImplementedError

    def chunk_size(self, params) -> int:
        """Realizations per task and chunk file (never changes a result)."""
        from oaraim.mc import DEFAULT_CHUNK

        return int(params.get(self.chunk_param, DEFAULT_CHUNK))

    def batch_size(self, params) -> int:
        """Keys per kernel call, the one shape the kernel is compiled for (a multiple of
        mc.reduce.BLOCK). XLA may round differently at another batch shape, so this is part of
        a run's identity (a resume must use the same). Override for bigger calls."""
        from oaraim.mc import BLOCK

        return BLOCK

    def run(self, params, realizations, seed, progress=None) -> StudyResult:
        """Convenience for tests and notebooks: the whole sweep in this process, its chunk files
        in a temporary folder that is deleted afterwards (``progress`` is ignored). The command
        line goes through ``oaraim.execute.run_study`` instead (resume, Dask, output folder)."""
        import tempfile

        fixed = self.fixed_realizations(params)
        if fixed is not None and realizations != fixed:
            raise ValueError(f"{self.name}: the parameters set the realizations ({fixed:,} per "
                             f"cell), got {realizations:,}")
        with tempfile.TemporaryDirectory(prefix="oaraim-sweep-") as tmp:
            result, _ = run_sweep_study(self, params, realizations, seed, tmp, progress=False)
        return result


def study_kernel(study, params, coords):
    """Kernel factory of a sweep study object: ``study.kernel(params, coords)`` (picklable as
    ``functools.partial(study_kernel, study, params)`` when the study is)."""
    return study.kernel(params, coords)


def sweep_fingerprint(study, params, realizations, seed):
    """What determines a sweep's results (stored in OUT/STUDY/sweep.json; a resume must match).
    The chunk size is left out: results do not depend on it and a resume may change it."""
    return {"study": study.name,
            "params": {k: v for k, v in params.items() if k != study.chunk_param},
            "seed": int(seed), "realizations": int(realizations)}


class RunOptions(NamedTuple):
    """How a study is run (``oaraim.execute.run_study``, ``run_sweep_study``); none of it
    changes a result."""

    resume: bool = False
    """Keep the finished chunks (a sweep) or checkpointed units (a ``ResumableStudy``) of an
    earlier run in the output folder and compute the rest."""
    execution: Any = None
    """An ``mc.Execution`` (host threads, local Dask workers or a scheduler, the chunk size) of
    a sweep study; None: in-process."""
    notice: Callable[[str], Any] | None = None
    """``notice(text)`` says, in one line, what the run did on its own (taking over the lock of
    a run that died); None: printed to stderr as ``warning: ...``."""


def run_sweep_study(study, params, realizations, seed, out_dir, *, options=None, progress=True,
                    kernel_factory=None):
    """Run a ``SweepStudy`` through ``mc.sweep.run_sweep`` into ``out_dir`` (its chunks and
    sweep.json); returns (StudyResult from ``study.finish``, SweepResult).

    ``options`` (a ``RunOptions``) says whether to resume and where to compute:
    ``options.execution`` (an ``mc.sweep.Execution``: threads, Dask workers or scheduler)
    defaults to in-process; the chunk size is the study's (``chunk_size(params)``) unless the
    execution sets one. ``kernel_factory`` (``coords -> kernel``) defaults to the study object's
    own kernel; ``oaraim.execute`` passes one that Dask workers look up by study name. A run
    that fails before any chunk is finished removes ``sweep.json`` and ``chunks/`` again.
    """
    from oaraim.mc import Draws, Execution, Storage, remove_if_nothing_finished, run_sweep

    options = RunOptions() if options is None else options
    resume, execution = options.resume, options.execution
    execution = Execution() if execution is None else execution
    if execution.chunk_size is None:
        execution = execution._replace(chunk_size=study.chunk_size(params))
    if kernel_factory is None:
        kernel_factory = functools.partial(study_kernel, study, params)
    storage = Storage(out_dir, sweep_fingerprint(study, params, realizations, seed),
                      resume=resume)
    try:
        sweep = run_sweep(kernel_factory, study.axes(params), study.reducers(params),
                          Draws(realizations, seed, key_axes=study.key_axes,
                                batch_size=study.batch_size(params)),
                          storage=storage, execution=execution, progress=progress,
                          description=study.name)
    except BaseException:
        # a run that failed before finishing a chunk (a kernel's first chunk failed) leaves
        # no sweep.json and chunks/; finished chunks stay for --resume
        remove_if_nothing_finished(Path(out_dir))
        raise
    return study.finish(params, sweep.dataset, realizations, seed), sweep


def fault_modes_param(default, why):
    """The ``fault_modes`` parameter of a study that runs the MHSS receiver: the convention
    (``araim.FaultModeRule``, docs/conformance.md), with the study's reason for its default."""
    from oaraim.araim import FAULT_MODE_CONVENTIONS as CONVENTIONS

    return Param(default, parse_choice(*CONVENTIONS),
                 f"fault-mode convention: {', '.join(CONVENTIONS)} (docs/conformance.md); "
                 f"default {default}: {why}")
