"""How many epochs are run: keys, chunked vmapped execution, streaming reductions, storage,
resumable and distributable parameter sweeps (``mc.sweep``)."""

import jax

jax.config.update("jax_enable_x64", True)

from mc.keys import realization_keys  # noqa: E402
from mc.reduce import BLOCK, EmpiricalCDF, Histogram, Mean  # noqa: E402
from mc.runner import ChunkPlan, run_chunked  # noqa: E402
from mc.store import provenance, read_summary, write_json, write_results  # noqa: E402
from mc.sweep import Axis, SweepResult, run_sweep  # noqa: E402

# The sweep reducers are mc.sweep.Mean, Max, Min, Histogram, Count (mc.Mean and mc.Histogram are
# the streaming reducers of mc.reduce).

__all__ = [
    "BLOCK",
    "Axis",
    "ChunkPlan",
    "EmpiricalCDF",
    "Histogram",
    "Mean",
    "SweepResult",
    "provenance",
    "read_summary",
    "realization_keys",
    "run_chunked",
    "run_sweep",
    "write_json",
    "write_results",
]
