"""The RINEX files a replay reads: one or several per parameter, and the day's navigation file
found beside an observation file (``nav=auto``)."""

import re
from pathlib import Path

from oaraim import data
from oaraim.studies.base import keyword_or_file

#: 'auto' (the shared data file) or an existing file
parse_path = keyword_or_file(("auto",), "RINEX file")


def parse_paths(name, v):
    """'auto', or one or more existing files joined by ',' (hourly observation files of one
    receiver; a station's separate GN and EN navigation files) -> 'auto' or the resolved
    paths joined by ','."""
    parts = [x.strip() for x in (v if isinstance(v, (list, tuple)) else str(v).split(","))]
    parts = [x for x in parts if x]
    if parts == ["auto"] or not parts:
        return parse_path(name, "auto")
    return ",".join(parse_path(name, x) for x in parts)


def as_paths(v):
    """The path, or the list of paths, of a ``parse_paths`` value (one file: a string)."""
    parts = str(v).split(",")
    return parts[0] if len(parts) == 1 else parts


def file_names(v):
    """The files' names for titles and summaries ('a + b' for several); ``v`` a path, a list
    of paths or paths joined by ','."""
    parts = [v] if isinstance(v, (str, Path)) else list(v)
    return " + ".join(Path(y.strip()).name for x in parts for y in str(x).split(","))


#: a RINEX 3 long file name: station, data source, year, day of year (RINEX 3.04 4.1)
_LONG_NAME = re.compile(r"^[A-Z0-9]{9}_[A-Z]_(\d{4})(\d{3})\d{4}_", re.IGNORECASE)
#: a RINEX 2 short observation name: ssssddd[h|0].yyo (RINEX 2.11 4)
_SHORT_NAME = re.compile(r"^[a-z0-9]{4}(\d{3})[a-x0-9]\.(\d{2})[od]", re.IGNORECASE)


def navigation_beside(obs, hint):
    """The navigation file(s) of an observation file's day in its folder, 'auto':
    RINEX 2 ``name.yyn`` beside ``name.yyo``; else, by the day in the file name (RINEX 3 long
    name or RINEX 2 short name), the IGS merged daily file (``oaraim.data.brdc_candidates``,
    gzipped or not), any ``*_YYYYDDD*_MN.rnx`` file, or a ``GN`` + ``EN`` pair of the day.
    One line naming what was looked for when none is there."""
    p = Path(obs)
    cand = p.with_name(p.name[:-1] + "n") if p.name[-1:] in "oO" else None
    if cand is not None and cand.is_file():
        return str(cand)
    m = _LONG_NAME.match(p.name)
    m2 = _SHORT_NAME.match(p.name)
    if m:
        year, doy = int(m.group(1)), int(m.group(2))
    elif m2:
        yy, doy = int(m2.group(2)), int(m2.group(1))
        year = yy + (1900 if yy >= 80 else 2000)
    else:
        raise ValueError(f"no navigation file given for {obs} and its name says no day (RINEX "
                         f"2 .yyo or RINEX 3 long name); {hint}")
    folder = p.parent
    names = data.brdc_candidates(year, doy)
    for n in names + [n[:-3] for n in names if n.endswith(".gz")]:
        if (folder / n).is_file():
            return str(folder / n)
    tag = f"_{year:04d}{doy:03d}"
    mixed = sorted(folder.glob(f"*{tag}*_MN.rnx*")) + sorted(folder.glob(f"*{tag}*_MN.RNX*"))
    if mixed:
        return str(mixed[0])
    gn, en = sorted(folder.glob(f"*{tag}*_GN.rnx*")), sorted(folder.glob(f"*{tag}*_EN.rnx*"))
    if gn:
        return ",".join(str(x) for x in gn[:1] + en[:1])
    raise ValueError(f"no navigation file given for {obs} and none of day {year}-{doy:03d} "
                     f"beside it ({names[0]}, *{tag}*_MN.rnx or *_GN.rnx); get one with "
                     f"`oaraim data nav YYYY-MM-DD`, or {hint}")
