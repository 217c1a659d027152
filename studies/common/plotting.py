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


#: axis labels of the seed 004 sweeps (mathtext)
SIGMA_URA_SOP_LABEL = r"$\sigma_{\mathrm{URA}}^{S}$ (m)"
P_S_SOP_LABEL = r"$P_{s}^{S}$"


def power_of_ten_label(v):
    """A probability as mathtext: ``$10^{-4}$``, ``$3{\\times}10^{-5}$``."""
    e = int(np.floor(np.log10(v) + 1e-9))
    m = v / 10.0**e
    if abs(m - round(m)) < 1e-6:
        m = round(m)
    return rf"$10^{{{e}}}$" if m == 1 else rf"${m:g}{{\times}}10^{{{e}}}$"


def categorical_ticks(axis, values, *, powers_of_ten=False, max_labels=14):
    """One tick per grid value at positions 0..n-1 (cells drawn with edges -0.5..n-0.5),
    labelled with the value (``%g``, or a power of ten); on a long log axis only the decades
    are labelled, the other values get minor ticks."""
    values = np.asarray(values, float)
    pos = np.arange(values.size)
    if powers_of_ten:
        decade = np.isclose(np.log10(values), np.round(np.log10(values)))
        show = np.ones(values.size, bool) if values.size <= 6 or not decade.any() else decade
        axis.set_ticks(pos[show], [power_of_ten_label(v) for v in values[show]])
        axis.set_ticks(pos[~show], minor=True)
    else:
        step = max(1, -(-values.size // max_labels))
        show = np.zeros(values.size, bool)
        show[::step] = True
        axis.set_ticks(pos[show], [f"{v:g}" for v in values[show]])
        axis.set_ticks(pos[~show], minor=True)
