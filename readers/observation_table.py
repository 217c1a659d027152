"""Every observation of a RINEX file, per observation type: ``ObservationTable``.

``readers.read_observation_table`` returns one table for one file or several
(hourly files of a day, say): epochs x satellites of every system, one ``(T, S)`` array per
observation type the header declares (code ``C``, carrier phase ``L``, Doppler ``D``, C/N0
``S``; RINEX 3 codes such as ``C1C``, ``C5Q``, ``L2W``; RINEX 2 codes such as ``C1``, ``P2``),
NaN where the field is blank or the satellite's system does not declare the type. A later
signal choice reads it per satellite and epoch: ``table.pick(("C1C", "C1X"))``.
"""

from typing import NamedTuple

import numpy as np


class ObservationTable(NamedTuple):
    """The observations of one receiver, every system and observation type."""

    t_gps_s: np.ndarray
    """(T,) receiver time tags, GPS seconds (strictly increasing)."""
    sv: np.ndarray
    """(S,) satellite ids such as 'G05', 'E11', 'C27', 'R09', 'S23', sorted."""
    types: dict
    """{system letter: tuple of observation codes in header order} (RINEX 2: the one list of
    the header, given to every system present)."""
    values: dict
    """{observation code: (T, S) float64}: the field as written (metres, cycles, Hz, dB-Hz),
    NaN where blank, absent, or not declared for that satellite's system."""
    lli: dict
    """{carrier-phase code ('L...'): (T, S) int8}: loss-of-lock indicator, 0 where blank."""
    epoch_line: np.ndarray
    """(T,) line of each epoch in its file (of the decompressed text for CRINEX files)."""
    epoch_file: np.ndarray
    """(T,) index into ``paths`` of the file of each epoch."""
    approx_position_m: np.ndarray | None
    """(3,) the first file's header APPROX POSITION XYZ, or None."""
    interval_s: float | None
    """Header INTERVAL, seconds, or None."""
    version: float
    """RINEX version of the (first) file."""
    marker: str
    """MARKER NAME."""
    paths: tuple
    """The files read, in time order."""
    skipped: tuple = ()
    """Lenient reads: one message per skipped epoch (file and line)."""

    def system_mask(self, systems) -> np.ndarray:
        """(S,) bool: the satellites of the given system letters (e.g. ``"GE"``)."""
        return np.array([s[0] in systems for s in self.sv], bool)

    def select(self, systems) -> "ObservationTable":
        """The same table restricted to the satellites of ``systems`` (letters, e.g. ``"G"``)."""
        m = self.system_mask(systems)
        return self._replace(
            sv=self.sv[m], types={k: v for k, v in self.types.items() if k in systems},
            values={c: a[:, m] for c, a in self.values.items()},
            lli={c: a[:, m] for c, a in self.lli.items()})

    def pick(self, codes) -> tuple[np.ndarray, np.ndarray]:
        """The first of ``codes`` (in order of preference) observed, per satellite and epoch.

        Returns ``(value (T, S) NaN where none, which (T, S) int8: index into codes, -1 where
        none)``; a code the file does not hold is passed over.
        """
        out = np.full((self.t_gps_s.size, self.sv.size), np.nan)
        which = np.full(out.shape, -1, np.int8)
        for k, c in enumerate(codes):
            a = self.values.get(c)
            if a is None:
                continue
            fill = np.isnan(out) & ~np.isnan(a)
            out[fill] = a[fill]
            which[fill] = k
        return out, which


def merge_tables(tables, error) -> ObservationTable:
    """One table from the tables of several files of one receiver, in time order.

    ``error(message)`` builds the exception raised (one line) when the files are of different
    stations, overlap in time, or differ in interval.
    """
    tables = sorted(tables, key=lambda t: t.t_gps_s[0])
    first = tables[0]
    for a, b in zip(tables, tables[1:], strict=False):
        if b.marker != first.marker:
            raise error(f"{b.paths[0]}: MARKER NAME {b.marker!r} differs from {first.marker!r} "
                        f"of {first.paths[0]}: files of one receiver only")
        if b.t_gps_s[0] <= a.t_gps_s[-1]:
            raise error(f"{b.paths[0]}: line {b.epoch_line[0]}: its first epoch is not after the "
                        f"last epoch of {a.paths[0]} (line {a.epoch_line[-1]}): the files overlap "
                        "or are given twice")
        if b.interval_s != first.interval_s:
            raise error(f"{b.paths[0]}: INTERVAL {b.interval_s} s differs from "
                        f"{first.interval_s} s of {first.paths[0]}")
    sv = np.array(sorted({s for t in tables for s in t.sv}), dtype=str)
    col = {s: j for j, s in enumerate(sv)}
    types: dict = {}
    for t in tables:
        for sysch, codes in t.types.items():
            types[sysch] = tuple(dict.fromkeys(types.get(sysch, ()) + tuple(codes)))
    n_t = sum(t.t_gps_s.size for t in tables)
    codes = list(dict.fromkeys(c for t in tables for c in t.values))
    values = {c: np.full((n_t, sv.size), np.nan) for c in codes}
    lli = {c: np.zeros((n_t, sv.size), np.int8) for c in codes if c in
           {x for t in tables for x in t.lli}}
    i0 = 0
    for t in tables:
        rows = slice(i0, i0 + t.t_gps_s.size)
        cols = np.array([col[s] for s in t.sv], np.int64)
        for c, a in t.values.items():
            values[c][rows, cols] = a
        for c, a in t.lli.items():
            lli[c][rows, cols] = a
        i0 += t.t_gps_s.size
    paths = tuple(p for t in tables for p in t.paths)
    offsets = np.cumsum([0] + [len(t.paths) for t in tables[:-1]])
    return first._replace(
        t_gps_s=np.concatenate([t.t_gps_s for t in tables]), sv=sv, types=types,
        values=values, lli=lli, epoch_line=np.concatenate([t.epoch_line for t in tables]),
        epoch_file=np.concatenate([t.epoch_file + o for t, o in zip(tables, offsets,
                                                                     strict=True)]),
        paths=paths, skipped=tuple(m for t in tables for m in t.skipped))


def decode_fields(types: dict, rows: list, v3: bool):
    """(sv (S,), {code: (T, S) values}, {L code: (T, S) LLI}) of checked epochs ``rows`` (one
    {satellite: its observation fields, 16 columns each} per epoch; RINEX 2: ``types['G']``
    for every system), each system's fields decoded at once: F14.3 as float, blank as NaN;
    the LLI digit after a carrier phase, blank as 0."""
    svs = np.array(sorted({s for r in rows for s in r}), dtype=str)
    col = {s: j for j, s in enumerate(svs)}
    n_t = len(rows)
    codes = list(dict.fromkeys(c for sysch in sorted(types) for c in types[sysch]))
    values = {c: np.full((n_t, svs.size), np.nan) for c in codes}
    lli = {c: np.zeros((n_t, svs.size), np.int8) for c in codes if c[0] == "L"}
    by_system: dict = {}
    for i, r in enumerate(rows):
        for s, text in r.items():
            by_system.setdefault(s[0] if v3 else "G", []).append((i, col[s], text))
    for sysch, entries in by_system.items():
        sys_types = types[sysch]
        width = 16 * len(sys_types)
        raw = "".join(f"{e[2]:{width}s}"[:width] for e in entries).encode("ascii")
        cells = np.frombuffer(raw, "S1").reshape(len(entries), len(sys_types), 16)
        text = np.ascontiguousarray(cells[:, :, :14]).view("S14")[..., 0]
        text = np.char.strip(text)
        text[text == b""] = b"nan"
        vals = text.astype(np.float64)
        flag = cells[:, :, 14].view(np.uint8).astype(np.int16) - ord("0")
        flag = np.where((flag >= 0) & (flag <= 9), flag, 0).astype(np.int8)
        ii = np.array([e[0] for e in entries], np.int64)
        jj = np.array([e[1] for e in entries], np.int64)
        for m, c in enumerate(sys_types):
            values[c][ii, jj] = vals[:, m]
            if c in lli:
                lli[c][ii, jj] = flag[:, m]
    return svs, values, lli
