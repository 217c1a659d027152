"""Run a batch kernel chunk by chunk so its intermediates stay in cache.

The MHSS kernel holds a few (modes x sources) arrays per geometry; over a batch of 65,536 each
is ~100 MB and the kernel becomes memory-bound (measured: 23k PL/s unchunked, 80k PL/s in
chunks of 1024, 9 GPS + 4 SOPs, 2 cores). ``lax.map`` over fixed-size chunks keeps every
intermediate small: after the Newton root finder (2026-11-25, otherwise idle machine, best of 5
per setting, two passes) chunks of 64 / 128 / 256 / 1024 / 4096 gave 118k / 146-188k /
154-159k / 129-133k / 132k PL/s; 256 is the steadiest (its (modes x sources) arrays stay in
L2). Batches larger than one chunk are computed in chunks of exactly this shape, so there a
geometry's result does not depend on the caller's batch size (XLA rounds differently at
different shapes); a batch of at most one chunk runs at its own shape. Every geometry is
computed independently and the padding geometries are dropped, so changing ``CHUNK`` moves
results only by rounding (last bits), never by more.
"""

import jax
import jax.numpy as jnp

#: geometries per chunk
CHUNK = 256


def map_chunks(fn, arrays, batch_shape, chunk=CHUNK):
    """Apply ``fn`` to arrays whose leading axes are ``batch_shape`` in chunks of ``chunk``.

    ``fn`` takes the arrays with one flattened leading batch axis and returns a pytree of
    arrays with that leading axis; the result has ``batch_shape`` restored.
    """
    n = 1
    for d in batch_shape:
        n *= d
    flat = [x.reshape((n,) + x.shape[len(batch_shape):]) for x in arrays]
    if n <= chunk:
        out = fn(*flat)
    else:
        n_chunks = -(-n // chunk)
        pad = n_chunks * chunk - n
        # pad by repeating the first geometry: a real geometry, so no special cases inside
        flat = [jnp.concatenate([x, jnp.broadcast_to(x[:1], (pad,) + x.shape[1:])])
                if pad else x for x in flat]
        stacked = [x.reshape((n_chunks, chunk) + x.shape[1:]) for x in flat]
        out = jax.lax.map(lambda xs: fn(*xs), stacked)
        out = jax.tree.map(lambda y: y.reshape((n_chunks * chunk,) + y.shape[2:])[:n], out)
    return jax.tree.map(lambda y: y.reshape(tuple(batch_shape) + y.shape[1:]), out)
