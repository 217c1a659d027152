"""PRNG keys of Monte Carlo realizations.

The key of realization i of grid cell c is fold_in(fold_in(key(seed), c), i): it depends on
(study seed, c, i) alone, so every realization is the same whatever the chunk size, worker count
or order of execution (DESIGN.md, Randomness).
"""

import jax
import jax.numpy as jnp

MAX_REALIZATIONS = 2**32  # fold_in takes a uint32 index


def cell_key(seed: int, cell: int):
    """Key of grid cell ``cell`` of a study run with ``seed``."""
    return jax.random.fold_in(jax.random.key(int(seed)), int(cell))


@jax.jit
def _fold_many(base, idx):
    return jax.vmap(lambda i: jax.random.fold_in(base, i))(idx)


def realization_keys(seed: int, cell: int, start: int, count: int):
    """Keys of realizations ``start .. start + count - 1`` of one cell, shape ``(count,)``."""
    if start < 0 or start + count > MAX_REALIZATIONS:
        raise ValueError(f"realization indices must lie in [0, 2^32), got {start}..{start + count}")
    idx = jnp.arange(start, start + count, dtype=jnp.uint32)
    return _fold_many(cell_key(seed, cell), idx)
