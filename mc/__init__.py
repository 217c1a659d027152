"""How many epochs are run: keys, chunked vmapped execution, streaming reductions, storage,
resumable and distributable parameter sweeps (``mc.sweep``), and checkpoints of the studies
that are not sweeps (``mc.checkpoint``)."""

if __name__ != "oaraim.mc":  # the source folder is importable from the checkout's root
    raise ImportError(f"import oaraim.mc, not {__name__}: the folder mc/ installs as "
                      "oaraim.mc (pip install -e .), which also enables JAX's float64 mode")

from oaraim.mc.intervals import clopper_pearson, rate_with_interval
from oaraim.mc.keys import STREAMS, realization_keys, stream
from oaraim.mc.reduce import BLOCK, Count, EmpiricalCDF, Histogram, Max, Mean, Min, Values
from oaraim.mc.runner import ChunkPlan, run_chunked
from oaraim.mc.store import provenance, read_summary, write_json, write_results
from oaraim.mc.sweep import Axis, Draws, Execution, Storage, SweepResult, run_sweep

# One reducer family (mc.reduce) serves sweeps (mc.sweep re-exports it) and streamed chunks.

__all__ = [
    "BLOCK",
    "STREAMS",
    "Axis",
    "ChunkPlan",
    "Count",
    "Draws",
    "EmpiricalCDF",
    "Execution",
    "Histogram",
    "Max",
    "Mean",
    "Min",
    "Storage",
    "SweepResult",
    "Values",
    "clopper_pearson",
    "provenance",
    "rate_with_interval",
    "read_summary",
    "realization_keys",
    "run_chunked",
    "run_sweep",
    "stream",
    "write_json",
    "write_results",
]

# What the other layers use, through this face only (tools/structure.py: "imports past a
# package's face"); ``checkpoint`` is a namespace.
from oaraim.mc import checkpoint  # noqa: E402
from oaraim.mc.keys import MAX_REALIZATIONS, cell_key, check_seed  # noqa: E402
from oaraim.mc.progress import ProgressBar  # noqa: E402
from oaraim.mc.runner import DEFAULT_CHUNK  # noqa: E402
from oaraim.mc.store import (  # noqa: E402
    OutputError,
    OutputLock,
    check_output_folder,
    os_error_line,
    writing,
)
from oaraim.mc.sweep_store import remove_if_nothing_finished  # noqa: E402

__all__ += ["DEFAULT_CHUNK", "MAX_REALIZATIONS", "OutputError", "OutputLock", "ProgressBar",
            "cell_key", "check_output_folder", "check_seed", "checkpoint", "os_error_line",
            "remove_if_nothing_finished", "writing"]
