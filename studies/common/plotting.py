"""Plotting helpers the studies share (plots read stored results only)."""

import numpy as np


def cell_edges(x, log):
    """Cell edges for pcolormesh around centres x (geometric means on a log axis)."""
    x = np.asarray(x, float)
    if x.size == 1:
        return np.array([x[0] / 2, x[0] * 2]) if log else np.array([x[0] - 0.5, x[0] + 0.5])
    t = np.log10(x) if log else x
    mid = (t[1:] + t[:-1]) / 2
    e = np.concatenate([[t[0] - (mid[0] - t[0])], mid, [t[-1] + (t[-1] - mid[-1])]])
    return 10.0**e if log else e
