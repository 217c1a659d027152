"""Deprecated: the speed helpers moved to ``oaraim.batching``, a layer of their own below
``araim`` (docs/design.md), where the fixed number of geometries one compiled program
computes is a *tile*: ``CHUNK`` is ``TILE``, ``map_chunks`` is ``map_tiles`` and the
``chunk=`` keyword is ``tile=`` (docs/conventions.md). The old names still work here and warn
(``DeprecationWarning``); this module goes in a later version."""

import warnings

from oaraim import batching as _batching

#: old name -> new name in ``oaraim.batching``
RENAMED = {"CHUNK": "TILE", "map_chunks": "map_tiles"}


def _tile_keyword(fn):
    def call(*args, chunk=None, **kwargs):
        if chunk is not None:
            kwargs["tile"] = chunk
        return fn(*args, **kwargs)

    call.__doc__ = fn.__doc__
    return call


def __getattr__(name):
    new = RENAMED.get(name, name)
    if name.startswith("__") or not hasattr(_batching, new):
        raise AttributeError(f"module 'oaraim.araim.batching' has no attribute {name!r}")
    warnings.warn(f"oaraim.araim.batching.{name} is deprecated: use oaraim.batching.{new}"
                  + (" (chunk= is tile=)" if new in ("map_tiles", "map_threads", "bucket")
                     else ""), DeprecationWarning, stacklevel=2)
    value = getattr(_batching, new)
    return _tile_keyword(value) if new in ("map_tiles", "map_threads", "bucket") else value
