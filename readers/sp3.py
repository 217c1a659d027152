"""SP3-c/d precise orbit files (IGS): satellite centre-of-mass positions and clocks.

Format: "The Extended Standard Product 3 Orbit Format (SP3-c)", S. Hilla, NGS, 2010, and SP3-d
(IGS, 2016): epoch lines ``*  YYYY MM DD hh mm ss.ssssssss``, position lines
``PSnn x y z clk`` with x, y, z in km and the clock in microseconds; 0.000000 positions and
999999.999999 clocks mark missing values. IGS orbits give the *centre of mass*, whereas the
broadcast ephemeris refers to the antenna phase centre (about 1 m apart for GPS Block IIR/IIF):
a broadcast-vs-SP3 comparison keeps that offset in its error budget.

Only files in GPS time (``%c`` time system 'GPS', the IGS convention) are accepted: that is
the time scale of ``t_gps_s``; a UTC file would need the leap-second count.
"""

import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from oaraim.readers import gpstime


class SP3Error(ValueError):
    """A malformed SP3 file: names the file, line and how to fix it."""


class PreciseOrbits(NamedTuple):
    """The tabulated orbits and clocks of one SP3 file (``read_sp3``), on its epoch grid."""

    t_gps_s: np.ndarray
    """(E,) epochs, GPS seconds."""
    prns: np.ndarray
    """(S,) satellite names such as ``'G05'``."""
    ecef_m: np.ndarray
    """(E, S, 3) centre-of-mass position, ECEF metres (0 where missing)."""
    clock_s: np.ndarray
    """(E, S) satellite clock offset, seconds (0 where missing)."""
    valid: np.ndarray
    """(E, S) bool: the position is present (not all zero)."""
    clock_valid: np.ndarray
    """(E, S) bool: the clock is present (not the 999999.999999 bad-value marker)."""
    time_system: str
    """The file's time system from its ``%c`` line: ``"GPS"`` (or ``"ccc"``, read as GPS)."""


def read_sp3(path: str | os.PathLike) -> PreciseOrbits:
    """Read an SP3-c or SP3-d file (plain text or .gz) into arrays."""
    import gzip

    p = Path(path).expanduser()
    if not p.is_file():
        raise SP3Error(f"SP3 file {str(path)!r} not found; give an existing SP3-c/d file")
    opener = gzip.open if p.suffix == ".gz" else open
    try:
        with opener(p, "rt", encoding="ascii", errors="replace") as f:
            lines = f.read().splitlines()
    except (OSError, EOFError) as e:
        raise SP3Error(f"{p}: cannot read the file ({e})") from None
    if not lines or not lines[0].startswith("#") or lines[0][1:2] not in "abcd":
        raise SP3Error(f"{p}: line 1: not an SP3 file (expected '#c' or '#d' in columns 1-2)")
    time_system = "GPS"
    for line in lines:
        if line.startswith("%c"):
            time_system = line[9:12].strip() or "GPS"
            break
    if time_system not in ("GPS", "ccc"):
        raise SP3Error(f"{p}: time system {time_system!r}; only GPS-time SP3 files are supported")
    epochs, records = [], {}
    for k, line in enumerate(lines, start=1):
        if line.startswith("* "):
            try:
                y, mo, d, h, mi = (int(v) for v in line[3:31].split()[:5])
                sec = float(line[3:31].split()[5])
            except (ValueError, IndexError):
                raise SP3Error(f"{p}: line {k}: cannot read the epoch {line.strip()!r}") from None
            epochs.append(float(gpstime.gps_seconds(y, mo, d, h, mi, sec)))
        elif line.startswith("P") and epochs:
            sv = line[1:4].replace(" ", "0")
            try:
                x, yv, z = (float(line[4 + 14 * i: 18 + 14 * i]) for i in range(3))
                clk_field = line[46:60].strip()
                clk = float(clk_field) if clk_field else 999999.999999
            except ValueError:
                raise SP3Error(f"{p}: line {k}: cannot read the position record "
                               f"{line[:60]!r}") from None
            records[(len(epochs) - 1, sv)] = (x, yv, z, clk)
        elif line.startswith("EOF"):
            break
    if not epochs:
        raise SP3Error(f"{p}: line {len(lines)}: no epoch lines ('*  YYYY ...'); the file is "
                       "truncated or not SP3")
    prns = np.array(sorted({sv for _, sv in records}))
    col = {sv: j for j, sv in enumerate(prns)}
    ecef = np.zeros((len(epochs), prns.size, 3))
    clock = np.zeros((len(epochs), prns.size))
    valid = np.zeros((len(epochs), prns.size), bool)
    clock_valid = np.zeros_like(valid)
    for (e, sv), (x, yv, z, clk) in records.items():
        j = col[sv]
        if x != 0.0 or yv != 0.0 or z != 0.0:
            ecef[e, j] = (1e3 * x, 1e3 * yv, 1e3 * z)
            valid[e, j] = True
        if abs(clk) < 999999.0:
            clock[e, j] = 1e-6 * clk
            clock_valid[e, j] = True
    return PreciseOrbits(np.array(epochs), prns, ecef, clock, valid, clock_valid, time_system)
