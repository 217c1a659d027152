"""Galileo broadcast navigation records: time, data source, health, SISA and group delays.

Sources: Galileo OS SIS ICD Issue 2.0 (2021) and RINEX 3.05 (IGS/RTCM, 2020) Table A8.

Time. Galileo System Time (GST) counts weeks and seconds of week from its start epoch,
22 August 1999, when it was ahead of UTC by 13 s like GPS time (OS SIS ICD 5.1.2): GST week 0
is GPS week 1024 and both scales carry the same integer seconds. A RINEX 3 navigation file
writes the Galileo week *continuous from the GPS epoch* ("GAL week #, aligned to GPS week",
RINEX 3.05 Table A8): the 2023-01-01 records of
``BRDC00IGS_R_20230010000_01D_MN`` carry week 2243, the GPS week of that day, not the GST week
1219 of the navigation message (2243 - 1024). ``gst_week_from_rinex`` is that subtraction. Epochs
(t_oc, t_oe) are GST; ``readers.navigation`` reads them as GPS time. The two differ by the
GPS/Galileo time offset (GGTO, a few ns: the file's ``GAGP`` header line gives 4.7 ns on
2023-01-01), which enters every Galileo clock alike and is removed with the constellation's
clock datum in ``geometry.sis_error``; orbits move 4 mm/ns, which is negligible.

Data source (RINEX 3.05 Table A8, 'Data sources', a bit field): bit 0 I/NAV E1-B, bit 1 F/NAV
E5a-I, bit 2 I/NAV E5b-I, bit 8 clock parameters (a_f0..a_f2, t_oc, SISA) for the E5a,E1 pair,
bit 9 for E5b,E1. An I/NAV record (bits 0 and/or 2, with 9: 513, 516, 517) and an F/NAV record
(bits 1 and 8: 258) share t_oc and orbit but not the clock: the F/NAV clock is referred to the
E1/E5a ionosphere-free combination, the I/NAV one to E1/E5b (OS SIS ICD 5.1.3). The ARAIM
dual-frequency user (E1/E5a) and the MGEX precise clocks (E1/E5a) use F/NAV: load with
``geometry.load_navigation(path, galileo_source="fnav")``; a single-frequency E1 or E5b user,
I/NAV (``"inav"``). The default (None) keeps both, as before.

Health (RINEX 3.05 Table A8, 'SV health', bits): 0 E1-B data-validity status (DVS), 1-2 E1-B
signal health status (SHS), 3 E5a DVS, 4-5 E5a SHS, 6 E5b DVS, 7-8 E5b SHS. DVS 0 = navigation
data valid, 1 = working without guarantee; SHS 0 = signal OK, 1 = out of service, 2 = extended
operations mode, 3 = in test (OS SIS ICD 5.1.9.3). ``geometry.Ephemeris`` uses a record only
when all its bits are 0.

SISA (OS SIS ICD 5.1.11): the file gives it in metres (the index decoded: 0-0.49 m in 1 cm
steps, 0.5-0.98 m in 2 cm, 1-1.96 m in 4 cm, 2-6 m in 16 cm); -1 is "no accuracy prediction
available" (NAPA, index 255). Healthy satellites broadcast 3.12 m (index 107) on 2023-01-01.

Group delays (OS SIS ICD 5.1.5): a single-frequency user corrects the dual-frequency clock
dt_sv of the record by BGD: on E1, dt_E1 = dt_sv - BGD(E1,E5x); on E5x (x = a with F/NAV,
b with I/NAV), dt_E5x = dt_sv - (f_E1 / f_E5x)^2 BGD(E1,E5x). The ionosphere-free E1/E5x user
applies none. ``Ephemeris.record_field("BGDe5a" | "BGDe5b", t)`` gives the BGD of the record
in use.
"""

import numpy as np

from oaraim.constants import F_E1_HZ, F_E5A_HZ, F_E5B_HZ
from oaraim.readers import gpstime

#: data-source bits (RINEX 3.05 Table A8)
SRC_INAV_E1B, SRC_FNAV_E5A, SRC_INAV_E5B = 1 << 0, 1 << 1, 1 << 2
SRC_CLOCK_E5A, SRC_CLOCK_E5B = 1 << 8, 1 << 9
#: signal health status values (OS SIS ICD 5.1.9.3)
SHS_NAMES = {0: "OK", 1: "out of service", 2: "extended operations mode", 3: "in test"}
_HEALTH_BITS = {"E1B": 0, "E5a": 3, "E5b": 6}  # DVS bit; SHS is the two bits above it


def gst_week_from_rinex(week) -> np.ndarray | np.integer:
    """The GST week number of the navigation message from the RINEX 3 'GAL week' (continuous
    from the GPS epoch, aligned to the GPS week): week - 1024."""
    return np.asarray(week, np.int64) - gpstime.WEEK_ROLLOVER


def record_kind(data_source) -> np.ndarray:
    """'fnav', 'inav' or '' (neither bit set) per value of the RINEX 'Data sources' field."""
    d = np.asarray(data_source, np.float64)
    d = np.where(np.isfinite(d), d, 0).astype(np.int64)
    return np.where(d & SRC_FNAV_E5A, "fnav",
                    np.where(d & (SRC_INAV_E1B | SRC_INAV_E5B), "inav", ""))


def clock_pair(data_source) -> np.ndarray:
    """The signal pair the record's clock refers to: 'E1/E5a' (bit 8), 'E1/E5b' (bit 9), or ''
    when the field sets neither."""
    d = np.asarray(data_source, np.float64)
    d = np.where(np.isfinite(d), d, 0).astype(np.int64)
    return np.where(d & SRC_CLOCK_E5A, "E1/E5a", np.where(d & SRC_CLOCK_E5B, "E1/E5b", ""))


def decode_health(word) -> dict:
    """The 'SV health' field as {signal: (DVS, SHS)} for E1B, E5a and E5b, each an int array
    shaped like ``word``."""
    w = np.asarray(word, np.float64)
    w = np.where(np.isfinite(w), w, 0).astype(np.int64)
    return {sig: ((w >> b) & 1, (w >> (b + 1)) & 3) for sig, b in _HEALTH_BITS.items()}


def signal_usable(word, signals=("E1B", "E5a")) -> np.ndarray:
    """True where every signal of ``signals`` has DVS 0 and SHS 0 (the dual-frequency E1/E5a
    user by default)."""
    h = decode_health(word)
    bad = [(h[s][0] != 0) | (h[s][1] != 0) for s in signals]
    return ~np.logical_or.reduce(bad)


def sisa_m(value) -> np.ndarray:
    """SISA in metres from the RINEX field; NaN for NAPA (-1) or a blank field."""
    v = np.asarray(value, np.float64)
    return np.where(v >= 0, v, np.nan)


def single_frequency_clock_s(dt_sv_s, bgd_s, signal="E1", pair="E1/E5a"):
    """The satellite clock for a single-frequency user on ``signal`` ('E1' or the pair's second
    signal) from the dual-frequency clock ``dt_sv_s`` of a record referred to ``pair`` and its
    ``bgd_s`` = BGD(E1, E5x) (OS SIS ICD 5.1.5)."""
    f2 = {"E1/E5a": F_E5A_HZ, "E1/E5b": F_E5B_HZ}.get(pair)
    if f2 is None:
        raise ValueError(f"pair must be 'E1/E5a' or 'E1/E5b', got {pair!r}")
    if signal == "E1":
        return np.asarray(dt_sv_s) - np.asarray(bgd_s)
    if signal == pair[3:]:
        return np.asarray(dt_sv_s) - (F_E1_HZ / f2) ** 2 * np.asarray(bgd_s)
    raise ValueError(f"signal must be 'E1' or {pair[3:]!r} for the pair {pair}, got {signal!r}")
