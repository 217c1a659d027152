"""GPS time: seconds since the GPS epoch, GPS week and time of week, calendar readings.

Time inside the toolkit is one float64 number, ``t_gps_s``: seconds of GPS time since the GPS
epoch 1980-01-06 00:00:00 (IS-GPS-200 section 3.3.4 and 6.2.4; GPS week 0 starts there). At
~1.3e9 s a float64 resolves 2.4e-7 s, i.e. 1 mm of satellite motion: ample for geometry and
for the broadcast model's time differences t - t_oe.

GPS time is continuous: it has no leap seconds. A *calendar reading in GPS time* (what RINEX
navigation epochs, SP3 files with time system GPS, and this module use) converts to GPS seconds
by plain calendar arithmetic. UTC differs from GPS time by the integer leap-second count
(GPS - UTC = 18 s since 2017-01-01); nothing here needs UTC, so no leap-second table is kept;
code that starts from a UTC reading adds the count itself (``geometry.nominal`` does, for the
SPS PS reference epoch). Galileo System Time is aligned with GPS time (same week origin
modulo 1024 in RINEX 3, a GGTO offset of a few tens of nanoseconds that geometry ignores).

These are host-side NumPy helpers (they parse and format times); the JAX kernels take the
resulting float seconds.
"""

import numpy as np

#: seconds in a GPS week
SECONDS_PER_WEEK = 604800
#: seconds in a day
SECONDS_PER_DAY = 86400
#: the legacy navigation message counts weeks modulo 1024 (IS-GPS-200 20.3.3.3.1.1)
WEEK_ROLLOVER = 1024
#: the GPS epoch as a calendar reading in GPS time
GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")


def gps_seconds(year, month, day, hour=0, minute=0, second=0.0):
    """GPS seconds of a calendar reading in GPS time (vectorized over NumPy arrays).

    Proleptic Gregorian calendar. ``second`` may be fractional (and >= 60 is simply carried).
    """
    year, month, day, hour, minute = (np.asarray(v, np.int64)
                                      for v in (year, month, day, hour, minute))
    if np.any((month < 1) | (month > 12)) or np.any((day < 1) | (day > 31)):
        raise ValueError(f"calendar date out of range: month={month!r}, day={day!r}")
    months = (year - 1970) * 12 + (month - 1)
    date = months.astype("datetime64[M]").astype("datetime64[D]") + (day - 1)
    days = (date - GPS_EPOCH.astype("datetime64[D]")).astype(np.int64)
    return (days * SECONDS_PER_DAY + hour * 3600 + minute * 60).astype(np.float64) + np.asarray(
        second, np.float64)


def calendar(t_gps_s):
    """Calendar reading in GPS time of GPS seconds: ``(year, month, day, hour, minute, second)``.

    Integers except ``second`` (float, in [0, 60)). Vectorized.
    """
    t = np.asarray(t_gps_s, np.float64)
    days = np.floor(t / SECONDS_PER_DAY).astype(np.int64)
    sod = t - days * SECONDS_PER_DAY
    date = GPS_EPOCH.astype("datetime64[D]") + days
    y = date.astype("datetime64[Y]").astype(np.int64) + 1970
    m = date.astype("datetime64[M]").astype(np.int64) % 12 + 1
    d = (date - date.astype("datetime64[M]").astype("datetime64[D]")).astype(np.int64) + 1
    hour = np.floor(sod / 3600).astype(np.int64)
    minute = np.floor((sod - 3600 * hour) / 60).astype(np.int64)
    return y, m, d, hour, minute, sod - 3600 * hour - 60 * minute


def week_tow(t_gps_s):
    """``(week, seconds of week)`` of GPS seconds: full week number (no rollover), tow in
    [0, 604800)."""
    t = np.asarray(t_gps_s, np.float64)
    week = np.floor(t / SECONDS_PER_WEEK).astype(np.int64)
    return week, t - week * SECONDS_PER_WEEK


def from_week_tow(week, tow_s):
    """GPS seconds of a full week number and a time of week (tow may lie outside one week)."""
    return np.asarray(week, np.int64) * SECONDS_PER_WEEK + np.asarray(tow_s, np.float64)


def resolve_week(week, reference_t_gps_s):
    """Full week number of a week given modulo 1024 (a broadcast 10-bit week), taken as the
    candidate nearest to a reference time (IS-GPS-200 20.3.3.3.1.1: the user resolves the
    rollover from another source). Weeks already >= 1024 are returned unchanged."""
    week = np.asarray(week, np.int64)
    ref_week, _ = week_tow(reference_t_gps_s)
    base = week % WEEK_ROLLOVER
    k = np.round((ref_week - base) / WEEK_ROLLOVER).astype(np.int64)
    return np.where(week >= WEEK_ROLLOVER, week, base + k * WEEK_ROLLOVER)


def from_datetime64(dt):
    """GPS seconds of ``numpy.datetime64`` values read as calendar readings in GPS time."""
    dt = np.asarray(dt).astype("datetime64[ns]")
    return (dt - GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64) / 1e9


def to_datetime64(t_gps_s):
    """``numpy.datetime64[ns]`` calendar readings (GPS time scale) of GPS seconds."""
    t = np.asarray(t_gps_s, np.float64)
    return GPS_EPOCH + np.round(t * 1e9).astype(np.int64).astype("timedelta64[ns]")


def day_start(t_gps_s):
    """GPS seconds of 00:00:00 (GPS time) of the day containing ``t_gps_s``."""
    t = np.asarray(t_gps_s, np.float64)
    return np.floor(t / SECONDS_PER_DAY) * SECONDS_PER_DAY
