"""The grid of a parameter sweep: named axes, the canonical text of a cell and its key id.

A cell's draws depend on the values of its *key axes* only (``cell_key_id``), not on grid
indices, so a cell gives the same draws whether the grid is full or narrowed from the CLI
(``mc.sweep``).
"""

import hashlib
import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np


def plain_value(name, v):
    """An axis value as a plain Python scalar (bool, int, float or str)."""
    if isinstance(v, np.generic):
        v = v.item()
    if not isinstance(v, bool | int | float | str):
        raise ValueError(f"axis {name!r}: values must be ints, floats or strings, got {v!r} "
                         f"({type(v).__name__})")
    if isinstance(v, float) and math.isnan(v):
        raise ValueError(f"axis {name!r}: NaN is not a valid axis value")
    return v


@dataclass(frozen=True)
class Axis:
    """One sweep axis: a name and its values (plain ints, floats or strings; at least one; no
    duplicates). NumPy scalars are converted to plain Python values."""

    name: str
    values: tuple

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ValueError(f"axis names must be identifiers, got {self.name!r}")
        raw = self.values
        if isinstance(raw, np.ndarray):
            raw = raw.tolist()
        if not isinstance(raw, list | tuple):
            raw = (raw,)
        vals = tuple(plain_value(self.name, v) for v in raw)
        if not vals:
            raise ValueError(f"axis {self.name!r} needs at least one value")
        seen = []
        for v in vals:
            if v in seen:
                raise ValueError(f"axis {self.name!r} lists the value {v!r} twice")
            seen.append(v)
        object.__setattr__(self, "values", vals)


def canonical(coords: dict, names: Iterable[str]) -> str:
    """``"a=1;b=0.5"``: the canonical text of ``coords`` restricted to ``names`` (in that order)."""
    return ";".join(f"{n}={coords[n]!r}" for n in names)


def cell_key_id(coords: dict, key_axes: Iterable[str]) -> int:
    """The cell-key id of a cell (``mc.keys.cell_key``'s ``cell``): crc32 of the canonical text of
    its key-axis values, names sorted. Cells that agree on every key axis share their draws."""
    return zlib.crc32(canonical(coords, sorted(key_axes)).encode("utf-8"))


def cell_hash(cell_text: str) -> str:
    """The 16-hex-digit name of a cell's chunk files (sha1 of its canonical text)."""
    return hashlib.sha1(cell_text.encode("utf-8")).hexdigest()[:16]



@dataclass(frozen=True)
class Cell:
    """One cell of the grid: its index, coordinates, canonical text, file hash and key id."""

    index: tuple
    coords: dict
    text: str
    hash: str
    key_id: int


def cells(axes, key_axes):
    """(shape, [Cell]) of the Cartesian product of ``axes`` in C order."""
    shape = tuple(len(a.values) for a in axes)
    names = [a.name for a in axes]
    out = []
    for idx in np.ndindex(*shape):
        coords = {a.name: a.values[i] for a, i in zip(axes, idx, strict=True)}
        text = canonical(coords, names)
        out.append(Cell(tuple(int(i) for i in idx), coords, text, cell_hash(text),
                        cell_key_id(coords, key_axes)))
    return shape, out
