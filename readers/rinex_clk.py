"""RINEX clock files (``*_CLK.CLK``, plain or .gz): the precise satellite clocks of the IGS and
its analysis centres.

Format: "RINEX Extensions to Handle Clock Information", version 3.00 (J. Ray, W. Gurtner,
2010) and 3.04 (IGS, 2017). Header lines carry their label in columns 61-80 up to ``END OF
HEADER``; the time system is ``TIME SYSTEM ID`` (GPS when absent). Data records used here:

``AS G01  2023  1  1  0  0  0.000000  2   -0.629946612233E-03  0.1E-10``

type ``AS`` (analysis, satellite), the satellite, the epoch, the number of values that follow
(1-6: clock bias in seconds, its sigma, rate, ...) and the values in free format. The
3.04 layout widens the name to 9 characters (``AS G01      2023 ...``); both are read by
splitting the line on blanks. ``AR`` (receiver) records are skipped.

The clocks of an analysis centre are referenced to its own clock datum (WUM: the station
``ANALYSIS CLK REF``, "not re-aligned to broadcast GPS time" in its header), so a comparison
with broadcast clocks removes a per-epoch datum offset (``geometry.sis_error``). For GPS the
clocks refer to the L1/L2 P-code ionosphere-free combination (IGS convention), for Galileo to
E1/E5a (MGEX convention; the file's ``SYS / DCBS APPLIED`` lines say which biases were used).
"""

import gzip
import os
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from oaraim.readers import gpstime


class ClockFileError(ValueError):
    """A RINEX clock file that cannot be read: names the file, the line and how to fix it."""


class PreciseClocks(NamedTuple):
    """The satellite clocks of one RINEX clock file (``read_clock_rinex``) on its epoch grid."""

    t_gps_s: np.ndarray
    """(E,) epochs, GPS seconds (sorted)."""
    sats: np.ndarray
    """(S,) satellite names such as ``'G05'``, ``'E11'`` (sorted)."""
    clock_s: np.ndarray
    """(E, S) clock bias, seconds (0 where missing)."""
    valid: np.ndarray
    """(E, S) bool: the file gives the clock at that epoch."""
    time_system: str
    """``TIME SYSTEM ID`` of the header (``"GPS"`` when absent)."""


def read_clock_rinex(path: str | os.PathLike, systems: Sequence[str] | None = None
                     ) -> PreciseClocks:
    """The ``AS`` (satellite) clock records of a RINEX 3 clock file (plain text or .gz).

    Args:
      path: the file.
      systems: RINEX system letters to keep (e.g. ``"GE"``); None keeps all.

    Raises:
      ClockFileError: (a ValueError) the file is missing, not a clock file, not in GPS time,
        or a satellite record is malformed (with its line).
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise ClockFileError(f"clock file {str(path)!r} not found; give an existing RINEX clock "
                             "file (plain or .gz)")
    try:
        raw = gzip.decompress(p.read_bytes()) if p.suffix == ".gz" else p.read_bytes()
    except (OSError, EOFError, zlib.error) as e:
        raise ClockFileError(f"{p}: cannot read the file ({e}); check that a .gz file is "
                             "complete") from None
    lines = raw.decode("ascii", errors="replace").splitlines()
    if not lines or lines[0][60:80].strip() != "RINEX VERSION / TYPE" or lines[0][20:21] != "C":
        raise ClockFileError(f"{p}: line 1: not a RINEX clock file (expected 'C' in column 21 "
                             "and 'RINEX VERSION / TYPE')")
    end = next((k for k, s in enumerate(lines) if s[60:80].strip() == "END OF HEADER"), None)
    if end is None:
        raise ClockFileError(f"{p}: no 'END OF HEADER' line; the header is truncated")
    time_system = "GPS"
    for s in lines[:end]:
        if s[60:80].strip() == "TIME SYSTEM ID":
            time_system = s[:6].strip() or "GPS"
    if time_system != "GPS":
        raise ClockFileError(f"{p}: time system {time_system!r}; only GPS-time clock files are "
                             "supported")
    keep = None if systems is None else set(systems)
    epochs: dict = {}
    records = []
    for k in range(end + 1, len(lines)):
        s = lines[k]
        if not s.startswith("AS "):
            continue
        parts = s[3:].split()
        try:
            sv = parts[0]
            if keep is not None and sv[0] not in keep:
                continue
            y, mo, d, h, mi = (int(v) for v in parts[1:6])
            sec = float(parts[6])
            n = int(parts[7])
            bias = float(parts[8].replace("D", "E"))
            if n < 1 or len(sv) != 3 or not np.isfinite(bias):
                raise ValueError
        except (ValueError, IndexError):
            raise ClockFileError(f"{p}: line {k + 1}: cannot read the satellite clock record "
                                 f"{s[:60].strip()!r}") from None
        key = (y, mo, d, h, mi, sec)
        if key not in epochs:
            epochs[key] = float(gpstime.gps_seconds(y, mo, d, h, mi, sec))
        records.append((epochs[key], sv, bias))
    if not records:
        raise ClockFileError(f"{p}: no satellite clock ('AS') records"
                             + ("" if keep is None else f" of systems {''.join(sorted(keep))}"))
    t = np.array(sorted(set(epochs.values())))
    sats = np.array(sorted({r[1] for r in records}))
    ti = np.searchsorted(t, [r[0] for r in records])
    si = np.searchsorted(sats, [r[1] for r in records])
    clock = np.zeros((t.size, sats.size))
    valid = np.zeros((t.size, sats.size), bool)
    clock[ti, si] = [r[2] for r in records]
    valid[ti, si] = True
    return PreciseClocks(t, sats, clock, valid, time_system)
