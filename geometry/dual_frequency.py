"""Ionosphere-free code pseudoranges of a dual-frequency GPS + Galileo receiver.

``iono_free(table)`` forms, per satellite and epoch, the first pair of ``PAIRS`` its system
offers (RINEX 3 observation codes of ``readers.read_observation_table``):

* GPS L1/L5: C1C with C5Q, C5X or C5I (the ARAIM default, ADD);
* GPS L1/L2: C1C with C2W, else with the civil L2C (C2L, C2X, C2S) for a receiver that does
  not track the semi-codeless P(Y) (its L2C - L2P(Y) bias, a fraction of a nanosecond, stays
  under b_nom like the P1-C1 DCB below); the fallback where a GPS satellite has no L5 (in
  2023-2024 only the Block IIF and III satellites transmit it);
* Galileo E1/E5a: C1C, C1X or C1B with C5Q, C5X or C5I.

P_IF = (f1^2 P1 - f2^2 P2) / (f1^2 - f2^2) removes the first-order ionospheric delay; its
noise is that of one code times ``factor`` = sqrt(f1^4 + f2^4) / (f1^2 - f2^2) for independent
equal noises (2.98 L1/L2, 2.59 L1/L5 and E1/E5a; ``araim.error_models.iono_free_factor``).

Group delays (what the broadcast clocks refer to, and what is not corrected here):

* The GPS LNAV clock refers to the L1 P(Y) / L2 P(Y) ionosphere-free combination
  (IS-GPS-200 20.3.3.3.3.2): C1W/C2W ionosphere-free needs no T_GD. The user combines the
  civil C1C with C2W: C1C - C1W (the P1-C1 differential code bias, DCB, up to about 1 ns)
  enters times f1^2 / (f1^2 - f2^2) = 2.55. The DCB is not in the navigation or observation
  files and is left uncorrected; the nominal bias b_nom of the ISM bounds it (0.75 m).
* The GPS L1/L5 combination needs the inter-signal corrections ISC_L1C, ISC_L5I5/Q5 of the
  CNAV message (IS-GPS-705 20.3.3.3.1.2); a RINEX 3 LNAV record carries none. Uncorrected,
  L1/L5 is metres off the LNAV reference, and differently per satellite block: on the shared
  days the median P_IF(L1/L5) - P_IF(L1/C2W) is -4.7 m on every GPS III satellite and
  +0.3 to +3.1 m on the IIF ones at NIST (2023-01-01), -1.1 to -0.3 m and +4.9 to +7.4 m at
  TLSE (2024-01-01; the stations differ by a common -4.3 m, their receivers' C5 - C2W bias),
  far beyond b_nom = 0.75 m: the NIST day replayed so gave 1,712 detections and 53 failed
  exclusions. ``gps_pair="l1l5"`` (the default) therefore refers each satellite's L1/L5 to
  the L1/L2 reference before use: ``l5_offsets_m`` is, per satellite, the median over the
  file of P_IF(L1/L5) - P_IF(L1/L2) at the epochs both are observed (noise about 0.7 m per
  epoch, so a few centimetres over an hour), and it is subtracted. A satellite with L5 that
  is never seen with an L2 code keeps its L1/L5 uncorrected (``l5_offset_m`` NaN; a receiver
  without L2 altogether has no way to do better without the CNAV ISCs).
  ``gps_pair="l1l5-raw"`` uses L1/L5 uncorrected (to study the bias).
* The Galileo F/NAV clock refers to the E1/E5a ionosphere-free combination (OS SIS ICD
  5.1.3): no BGD for E1/E5a (load the orbits with ``galileo_source="fnav"``).
* Receiver biases common to a constellation's satellites go into its clock; the difference
  between a GPS satellite on L1/L5 and one on L1/L2 (the receiver's C2W - C5 bias, times the
  factors) does not: the L1/L5 offset above removes it with the satellite part.
  ``gps_pair``: ``"l1l5"`` L1/L5 first (offsets removed), ``"l1l5-raw"`` the same without
  the offsets, ``"l1l2"`` L1/L2 only.
"""

from typing import NamedTuple

import numpy as np

from oaraim.constants import F_E1_HZ, F_E5A_HZ

#: carrier frequencies, Hz (IS-GPS-200 3.3.1.1, IS-GPS-705 3.3.1.1; Galileo OS SIS ICD 2.3)
F_L1_HZ, F_L2_HZ, F_L5_HZ = 1575.42e6, 1227.60e6, 1176.45e6

#: combination codes (``IonoFree.combination``): 0 none; single frequency 4 GPS L1, 5 E1
NONE, GPS_L1L5, GPS_L1L2, GAL_E1E5A, GPS_L1, GAL_E1 = 0, 1, 2, 3, 4, 5
COMBINATION_NAMES = {GPS_L1L5: "GPS L1/L5", GPS_L1L2: "GPS L1/L2", GAL_E1E5A: "Galileo E1/E5a",
                     GPS_L1: "GPS L1", GAL_E1: "Galileo E1"}
#: single-frequency codes by preference: (combination, system letter, codes)
SINGLE = ((GPS_L1, "G", ("C1C",)), (GAL_E1, "E", ("C1C", "C1X", "C1B")))
#: (combination, system letter, codes of f1 by preference, codes of f2, f1, f2)
PAIRS = (
    (GPS_L1L5, "G", ("C1C",), ("C5Q", "C5X", "C5I"), F_L1_HZ, F_L5_HZ),
    (GPS_L1L2, "G", ("C1C",), ("C2W", "C2L", "C2X", "C2S"), F_L1_HZ, F_L2_HZ),
    (GAL_E1E5A, "E", ("C1C", "C1X", "C1B"), ("C5Q", "C5X", "C5I"), F_E1_HZ, F_E5A_HZ),
)


def factor(f1_hz, f2_hz):
    """Noise amplification of the ionosphere-free combination of two equal, independent code
    noises: sqrt(f1^4 + f2^4) / (f1^2 - f2^2)."""
    return float(np.sqrt(f1_hz**4 + f2_hz**4) / (f1_hz**2 - f2_hz**2))


class IonoFree(NamedTuple):
    """Ionosphere-free pseudoranges of an observation table (T epochs, S satellites)."""

    pseudorange_m: np.ndarray
    """(T, S) P_IF, metres (NaN where no pair)."""
    combination: np.ndarray
    """(T, S) int8: the pair used (``GPS_L1L5``, ``GPS_L1L2``, ``GAL_E1E5A``), 0 none."""
    noise_factor: np.ndarray
    """(T, S) ``factor`` of that pair (1 where none)."""
    l5_offset_m: np.ndarray
    """(S,) the median P_IF(L1/L5) - P_IF(L1/L2) removed from a GPS satellite's L1/L5 (module
    docstring), metres; NaN where none was removed (no L5, never seen with L2, or a
    ``gps_pair`` other than ``"l1l5"``)."""


#: ``gps_pair`` choices of ``iono_free``
GPS_PAIRS = ("l1l5", "l1l5-raw", "l1l2")


def _pair(table, c1, c2, f1, f2):
    p1, _ = table.pick(c1)
    p2, _ = table.pick(c2)
    val = f1**2 / (f1**2 - f2**2) * p1 - f2**2 / (f1**2 - f2**2) * p2
    return np.where(np.isfinite(val) & (p1 > 0) & (p2 > 0), val, np.nan)


def l5_offsets_m(table):
    """(S,) per satellite the median over the table's epochs of P_IF(L1/L5) - P_IF(L1/L2)
    where both are observed, metres (NaN where never both): what refers a GPS satellite's
    L1/L5 to the LNAV clock's L1/L2 reference without the CNAV ISCs (module docstring)."""
    (_, _, a1, a2, fa1, fa2), (_, _, b1, b2, fb1, fb2) = PAIRS[0], PAIRS[1]
    diff = _pair(table, a1, a2, fa1, fa2) - _pair(table, b1, b2, fb1, fb2)
    gps = np.array([s[0] == "G" for s in table.sv])
    both = np.isfinite(diff) & gps[None, :]
    out = np.full(table.sv.size, np.nan)
    for j in np.flatnonzero(both.any(0)):
        out[j] = float(np.median(diff[both[:, j], j]))
    return out


def iono_free(table, gps_pair="l1l5") -> IonoFree:
    """Per satellite and epoch, the first pair of ``PAIRS`` observed (module docstring);
    ``gps_pair``: ``"l1l5"`` (L1/L5 referred to L1/L2 by ``l5_offsets_m``), ``"l1l5-raw"``
    (uncorrected) or ``"l1l2"`` (GPS on L1/L2 only)."""
    if gps_pair not in GPS_PAIRS:
        raise ValueError(f"gps_pair must be one of {', '.join(GPS_PAIRS)}, got {gps_pair!r}")
    n_t, n_s = table.t_gps_s.size, table.sv.size
    pr = np.full((n_t, n_s), np.nan)
    comb = np.zeros((n_t, n_s), np.int8)
    fac = np.ones((n_t, n_s))
    offset = np.full(n_s, np.nan)
    system = np.array([s[0] for s in table.sv])
    for code, sysch, c1, c2, f1, f2 in PAIRS:
        if code == GPS_L1L5 and gps_pair == "l1l2":
            continue
        cols = system == sysch
        if not cols.any():
            continue
        val = _pair(table, c1, c2, f1, f2)
        if code == GPS_L1L5 and gps_pair == "l1l5":
            offset = l5_offsets_m(table)
            val = val - np.nan_to_num(offset)[None, :]
        fill = cols[None, :] & (comb == NONE) & np.isfinite(val)
        pr[fill] = val[fill]
        comb[fill] = code
        fac[fill] = factor(f1, f2)
    offset[~(comb == GPS_L1L5).any(0)] = np.nan
    return IonoFree(pr, comb, fac, offset)


def single_frequency(table) -> IonoFree:
    """GPS L1 C/A (C1C) and Galileo E1 (C1C, C1X or C1B) code pseudoranges, per satellite and
    epoch (``combination`` ``GPS_L1`` / ``GAL_E1``, ``noise_factor`` 1); the ionosphere stays
    in them."""
    n_t, n_s = table.t_gps_s.size, table.sv.size
    pr = np.full((n_t, n_s), np.nan)
    comb = np.zeros((n_t, n_s), np.int8)
    system = np.array([s[0] for s in table.sv])
    for code, sysch, codes in SINGLE:
        p, _ = table.pick(codes)
        fill = (system == sysch)[None, :] & np.isfinite(p) & (p > 0)
        pr[fill] = p[fill]
        comb[fill] = code
    return IonoFree(pr, comb, np.ones((n_t, n_s)), np.full(n_s, np.nan))
