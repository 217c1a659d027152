"""The GPS sky the studies share: the ``nav`` parameter and where a run's ephemeris comes from.

DESIGN.md, default sky: a study whose paper used real ephemerides reads the real file
(``oaraim.data``: the data folder, else fetched into the cache); the built-in nominal
constellation only when asked for (``--set nav=nominal``); never a silent fallback.
"""

from pathlib import Path

import numpy as np

from oaraim import data
from oaraim.readers import gpstime
from oaraim.studies.base import keyword_or_file

#: 'auto' (the study's default real file), 'nominal' (built-in constellation), or a path
parse_nav = keyword_or_file(("auto", "nominal"), "RINEX navigation file")


def resolve_sky(nav, default_file):
    """(source, description, is_real_file). ``nav`` is 'auto' (registry file ``default_file``
    through ``oaraim.data.path``: the data folder, else fetched into the cache; unavailable ->
    ``DataUnavailable``, one line with the fix), 'nominal' (the built-in constellation, only
    when asked for), or a file path. There is no silent fallback to the nominal sky."""
    if nav == "nominal":
        return "nominal-gps", "nominal GPS 24-slot (SPS PS 2008), requested", False
    if nav == "auto":
        try:
            nav = str(data.path(default_file))
        except data.DataUnavailable as e:
            raise data.DataUnavailable(f"{e}; or run with --set nav=nominal (the built-in "
                                       "24-slot GPS constellation) or --set nav=PATH") from None
    return nav, f"broadcast ephemeris {Path(nav).name}", True


def file_day_start(ephemeris):
    """00:00 GPS time of the day holding most of the file's records."""
    toe = ephemeris.toe_healthy_s
    days = np.floor(toe / gpstime.SECONDS_PER_DAY).astype(np.int64)
    vals, counts = np.unique(days, return_counts=True)
    return float(vals[np.argmax(counts)] * gpstime.SECONDS_PER_DAY)
