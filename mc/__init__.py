"""How many epochs are run: keys, chunked vmapped execution, streaming reductions, storage."""

import jax

jax.config.update("jax_enable_x64", True)

from mc.keys import realization_keys  # noqa: E402
from mc.reduce import BLOCK, EmpiricalCDF, Histogram, Mean  # noqa: E402
from mc.runner import ChunkPlan, run_chunked  # noqa: E402
from mc.store import provenance, read_summary, write_json, write_results  # noqa: E402

__all__ = [
    "BLOCK",
    "ChunkPlan",
    "EmpiricalCDF",
    "Histogram",
    "Mean",
    "provenance",
    "read_summary",
    "realization_keys",
    "run_chunked",
    "write_json",
    "write_results",
]
