"""PRNG keys of Monte Carlo realizations, and the named random streams derived from them.

The key of realization i of grid cell c is fold_in(fold_in(key(seed), c), i): it depends on
(study seed, c, i) alone, so every realization is the same whatever the chunk size, worker count
or order of execution (DESIGN.md, Randomness).

Inside a realization (or a cell), independent draws take named streams:
``stream(key, name, index)`` is ``fold_in(key, STREAMS[name] + index)``. The table's integer
tags are the offsets the studies wrote inline before the table existed, so every key is what it
was; a new draw gets a new name whose tag range is disjoint from the others used under the
same parent key (docs/conventions.md lists them).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

MAX_REALIZATIONS = 2**32  # fold_in takes a uint32 index
#: the seeds ``jax.random.key`` takes (a signed 64-bit integer; each gives its own key)
SEED_RANGE = (-(2**63), 2**63 - 1)


def check_seed(seed, option="--seed"):
    """``seed`` as an ``int`` if it lies in ``SEED_RANGE`` (what the key derivation takes),
    else a one-line ``ValueError`` naming ``option``, the value and the range."""
    ok = isinstance(seed, int | np.integer) and not isinstance(seed, bool)
    if not ok or not SEED_RANGE[0] <= int(seed) <= SEED_RANGE[1]:
        raise ValueError(f"{option} must be an integer in [-2^63, 2^63 - 1] (the 64-bit seed of "
                         f"the random keys), got {seed!r}; choose a seed in that range")
    return int(seed)


def cell_key(seed: int, cell: int):
    """Key of grid cell ``cell`` of a study run with ``seed``."""
    return jax.random.fold_in(jax.random.key(int(seed)), int(cell))


@functools.partial(jax.jit, static_argnames=("seed", "count"))
def _realization_keys(seed, cell, start, count):
    base = jax.random.fold_in(jax.random.key(seed), cell)
    idx = start + jnp.arange(count, dtype=jnp.uint32)
    return jax.vmap(lambda i: jax.random.fold_in(base, i))(idx)


def realization_keys(seed: int, cell: int, start: int, count: int):
    """Keys of realizations ``start .. start + count - 1`` of one cell, shape ``(count,)``:
    ``fold_in(cell_key(seed, cell), i)``, in one compiled call (integer arithmetic, the same
    bits; op by op it was ~0.35 ms a call, a sixth of a seed 004 Fig. 4 cell's host time)."""
    if start < 0 or start + count > MAX_REALIZATIONS:
        raise ValueError(f"realization indices must lie in [0, 2^32), got {start}..{start + count}")
    return _realization_keys(int(seed), np.uint32(cell), np.uint32(start), int(count))


#: name -> integer tag of the named streams, grouped by the parent key they are derived from;
#: an indexed stream uses tags tag .. tag + n - 1 (n given in the comment)
STREAMS = {
    # under the key of one geometry draw of the seed 004 studies (studies.common.seed004)
    "gps_epoch": 0,  # the epoch of the day's GPS sky table
    "bpp_towers": 1,  # the BPP tower placement (seed 004 section III-D)
    # under the key of one integrity-risk cell (studies.integrity_risk)
    "risk_geometry": 0,  # + geometry index g, n = geometries (below 1000)
    "risk_cross_check": 1000,  # + scenario index, n = 3 (the IS-vs-crude cross-check)
    # under the key of one integrity-risk geometry ("risk_geometry")
    "risk_table": 2,  # the importance-sampling estimates of the geometry's scenarios
    "risk_ramp": 100,  # + 2 j + direction (0 horizontal, 1 vertical) for SOP j, n = 2 n_sops
    # under the key of one cross-check scenario ("risk_cross_check")
    "risk_rerun": 1,  # the timed second run (the first, compiling run uses the parent key)
    # under the key of a tower-placement run (studies.tower_placement: key(seed))
    "placement_random": 0,  # the random placements, one (P, T, 2) draw
    "placement_candidates": 1,  # the 'auto' candidate sites, one (K, 2) draw
    # under the key of one simulated drive run (sim.drive: split(key, 3) holds 0..2)
    "world_calibration": 3,  # the GNSS period's SOP errors (sim.measurement.calibrate)
    # under the key of one snapshot noise draw (sim.measurement.sop_errors, sim.gnss)
    "world_sop_epochs": 4,  # the SOP errors epoch by epoch (fold_in by epoch below it)
    "world_gnss": 5,  # the GNSS errors of sim.gnss.gnss_errors
    # under the key of one drive epoch (sim.measurement.drive_epoch; normal(key) is the rest)
    "world_sop": 0,  # normals: tower clock epsilon_n and the operators' common terms
    "world_nlos": 1,  # uniforms: NLOS episode starts, ends and excess delays
}


def stream(key, name: str, index=0):
    """Key of the named random stream ``name`` under ``key`` (``index`` for an indexed stream:
    the tower, the scenario, the geometry): ``fold_in(key, STREAMS[name] + index)``.
    jit-safe (``index`` may be traced); an unknown name raises ``KeyError`` naming the known
    ones."""
    try:
        tag = STREAMS[name]
    except KeyError:
        raise KeyError(f"unknown random stream {name!r}; the streams are {sorted(STREAMS)} "
                       "(mc.keys.STREAMS: add a name with its tag there)") from None
    return jax.random.fold_in(key, tag + index)
