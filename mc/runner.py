"""Chunked, vmapped Monte Carlo execution with bounded memory.

A study supplies a jitted kernel ``keys -> dict of per-realization arrays`` (leading axis the
chunk). The runner feeds it fixed-size chunks of realization keys (``mc.keys``), trims the
padded last chunk, and hands each chunk's outputs to the study's reducers on the host. Chunk
sizes are multiples of ``mc.reduce.BLOCK`` so that floating reductions are bit-identical for any
chunk size.
"""

from dataclasses import dataclass

import jax
import numpy as np

from oaraim.mc.keys import realization_keys
from oaraim.mc.reduce import BLOCK

DEFAULT_CHUNK = 32 * BLOCK


@dataclass(frozen=True)
class ChunkPlan:
    """Realizations 0..n-1 cut into chunks of ``chunk_size`` (a multiple of BLOCK)."""

    n: int
    chunk_size: int = DEFAULT_CHUNK

    def __post_init__(self):
        if self.n < 1:
            raise ValueError(f"realizations must be >= 1, got {self.n}")
        size = max(BLOCK, -(-int(self.chunk_size) // BLOCK) * BLOCK)
        # never compute more than the rounded-up realization count
        size = min(size, -(-self.n // BLOCK) * BLOCK)
        object.__setattr__(self, "chunk_size", size)

    def chunks(self):
        """Yield ``(start, size)`` of each chunk in order; the last may be shorter."""
        for start in range(0, self.n, self.chunk_size):
            yield start, min(self.chunk_size, self.n - start)

    def __len__(self):
        return -(-self.n // self.chunk_size)


def run_chunked(kernel, n, *, seed, cell=0, chunk_size=DEFAULT_CHUNK, on_chunk=None,
                keep=(), progress=None):
    """Run ``kernel`` over realizations 0..n-1 of one cell.

    Args:
      kernel: jitted function of a ``(chunk,)`` key array returning a dict of arrays whose leading
        axis is the chunk.
      n: number of realizations.
      seed, cell: identify the keys (``mc.keys.realization_keys``).
      chunk_size: realizations per kernel call (rounded up to a multiple of BLOCK); bounds memory.
      on_chunk: ``on_chunk(start, outputs)`` called in index order with the trimmed outputs
        (NumPy arrays); feed reducers here.
      keep: names of outputs to keep for every realization (concatenated and returned).
      progress: an object with ``advance(n)`` (``mc.progress.ProgressBar``) or None.

    Returns:
      dict name -> ``(n, ...)`` NumPy array of the kept outputs.
    """
    plan = ChunkPlan(int(n), chunk_size)
    kept = {name: [] for name in keep}
    for start, count in plan.chunks():
        keys = realization_keys(seed, cell, start, plan.chunk_size)
        out = jax.device_get(kernel(keys))
        out = {k: np.asarray(v)[:count] for k, v in out.items()}
        if on_chunk is not None:
            on_chunk(start, out)
        for name in keep:
            kept[name].append(out[name])
        if progress is not None:
            progress.advance(count)
    return {name: np.concatenate(parts) for name, parts in kept.items()}
