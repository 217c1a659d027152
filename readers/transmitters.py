"""One transmitter, one row: the check that finds a transmitter given twice.

Two rows of a tower file or a recording whose antennas lie closer than
``MIN_SEPARATION_M`` and share a clock group (a carrier) are one transmitter given twice: as
two sources they would count as two independent ranges (their errors are one), and a
receiver would trust the geometry twice. Rows 1e-9 deg apart used to pass as distinct, because
the check compared the numbers exactly. Towers of one carrier on one mast are one transmitter;
carriers sharing a mast are different clock groups and stay separate rows.

1 m is far below the spacing of real transmitters of one operator (sectors of a site share
one position and clock; separate sites are hundreds of metres apart) and far above the
rounding of a written position (1e-9 deg is 0.1 mm).
"""

from collections.abc import Sequence

import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Real, Shaped

#: the smallest distance (m) between two transmitters of one clock group
MIN_SEPARATION_M = 1.0


def first_near_pair(xyz_m: Real[ArrayLike, "n 3"],
                    group: Shaped[ArrayLike, " n"] | Sequence[str | int],
                    min_m: float = MIN_SEPARATION_M) -> tuple[int, int, float] | None:
    """The first pair of rows (in row order: the smallest later row, then the smallest
    earlier one) of one ``group`` whose positions ``xyz_m`` ((n, 3) metres, e.g. ECEF) lie
    closer than ``min_m``: ``(earlier, later, distance_m)``, or None."""
    from scipy.spatial import cKDTree

    xyz = np.asarray(xyz_m, np.float64).reshape(-1, 3)
    group = np.asarray(group)
    best = None
    for g in np.unique(group):
        rows = np.flatnonzero(group == g)
        if rows.size < 2:
            continue
        for a, b in cKDTree(xyz[rows]).query_pairs(min_m):
            i, j = sorted((int(rows[a]), int(rows[b])))
            d = float(np.linalg.norm(xyz[i] - xyz[j]))
            if d < min_m and (best is None or (j, i) < (best[1], best[0])):
                best = (i, j, d)
    return best
