"""The text of a RINEX observation file in any of the forms stations publish it.

Plain text; gzip (``.gz``); Unix compress (``.Z``), bzip2 and zip through the ``hatanaka``
package; Hatanaka-compressed RINEX (CRINEX 1 and 3: ``.crx``, ``.yyd``), alone or under any of
those, decoded with ``hatanaka.crx2rnx`` (the maintained decoder of the format; we write none of
our own). The form is told by the leading bytes, not by the name. Line numbers of a CRINEX file
are those of its decoded RINEX text, and messages say so (``DECODED``).
"""

import functools
import gzip
import os
import re
import warnings
from pathlib import Path
from typing import NamedTuple

#: leading bytes of the compressed forms the ``hatanaka`` package decodes besides gzip: Unix
#: compress (.Z), bzip2, zip
_OTHER_COMPRESSION = (b"\x1f\x9d", b"BZh", b"PK\x03\x04")
#: what a message adds to a line number of a CRINEX file's decoded text
DECODED = " of the decompressed text"


class RinexText(NamedTuple):
    """A RINEX file's text (``read_lines``)."""

    lines: list
    """The lines, without line ends (must not be changed: cached)."""
    ends: bool
    """Whether the text ends with a line break."""
    crinex: bool
    """Whether the file was CRINEX (the lines are those of the decoded text)."""
    notes: tuple
    """What the CRINEX decoder skipped, one message each naming the CRINEX line: it goes on
    past a garbled epoch to the next one it can restart from, with a warning only."""


def _crinex_line(raw: bytes, message: str) -> int:
    """The CRINEX line a decoder message is about: the line it names, else the header record
    its complaint is about (the CRINEX or the RINEX version line), else line 1."""
    m = re.search(r"line (\d+)", message)
    if m:
        return int(m[1])
    label = b"RINEX VERSION / TYPE" if "original RINEX" in message else b"CRINEX VERS"
    for k, line in enumerate(raw.split(b"\n")[:1000]):
        if label in line[60:80]:
            return k + 1
    return 1


def _crinex_decoded(path: Path, raw: bytes, error) -> tuple[bytes, tuple]:
    """(RINEX text, notes) of CRINEX bytes; a file the decoder stops in is ``error`` naming the
    CRINEX line; what it skipped with a warning only becomes a note naming the line."""
    import hatanaka

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            text = hatanaka.crx2rnx(raw)
        except Exception as e:  # HatanakaException, ValueError...: one line for the user
            msg = " ".join(str(e).split())
            raise error(f"{path}: line {_crinex_line(raw, msg)} of the CRINEX text: the CRINEX "
                        f"(Hatanaka) decoder stopped: {msg[:200]}; the file is truncated or "
                        "garbled (re-download it)") from None
    notes = []
    for w in caught:
        msg = " ".join(str(w.message).split())
        notes.append(f"{path}: line {_crinex_line(raw, msg)} of the CRINEX text: the CRINEX "
                     f"(Hatanaka) decoder skipped data it could not decode ({msg[:160]}); the "
                     "file is garbled (re-download it)")
    return text, tuple(notes)


@functools.lru_cache(maxsize=4)
def _cached_lines(path_str: str, mtime_ns: int, size: int, error):
    path = Path(path_str)
    try:
        raw = path.read_bytes()
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        elif raw.startswith(_OTHER_COMPRESSION):
            import hatanaka

            raw = hatanaka.decompress(raw)
        elif path.suffix == ".gz":
            raise OSError("not a gzip file")
    except Exception as e:  # OSError, EOFError, zlib.error, hatanaka's: one line for the user
        raise error(f"{path}: cannot read the file ({e}); check the path and that a compressed "
                    "file is complete") from None
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    crinex = raw[60:80].startswith(b"CRINEX VERS   / TYPE")
    notes = ()
    if crinex:
        raw, notes = _crinex_decoded(path, raw, error)
    text = raw.decode("ascii", errors="replace")
    lines = text.split("\n")
    ends = text.endswith("\n")
    if ends:
        lines.pop()
    return RinexText([s[:-1] if s.endswith("\r") else s for s in lines], ends, crinex, notes)


def read_lines(path: Path, error) -> RinexText:
    """The text of a file in any form (module docstring): a UTF-8 byte-order mark dropped,
    bytes that are not ASCII as U+FFFD (so that they fail every field check), line ends
    without the '\\r'. Cached per (file, mtime, size): the lines must not be changed.
    ``error``: the exception class raised (one line naming the file and line) when the file
    cannot be read or decoded."""
    try:
        st = os.stat(path)
    except OSError as e:
        raise error(f"{path}: cannot read the file ({e}); check the path") from None
    return _cached_lines(str(path), st.st_mtime_ns, st.st_size, error)


def decoded_lines(message: str) -> str:
    """A message about a CRINEX file's decoded text: its first 'line N' becomes 'line N of the
    decompressed text'."""
    return re.sub(r": line (\d+)", lambda m: f": line {m[1]}{DECODED}", message, count=1)


def header_version(path: Path, head: str, error) -> float:
    """The format version in columns 1-9 of a RINEX file's first line ``head``; ``error``
    (the exception class) of one line naming the file when it is not a number."""
    try:
        return float(head[:9])
    except ValueError:
        raise error(f"{path}: line 1: not a RINEX header (expected 'RINEX VERSION / TYPE' with "
                    f"the version in columns 1-9, got {head[:40]!r})") from None
