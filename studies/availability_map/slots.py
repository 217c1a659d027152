"""The availability map's skies and the kernel's GNSS slots: the constellations' orbits over the
day (``constellation_orbits``), the most satellites in view over a grid (``max_visible``,
the kernel's slot count), and the kernel's in-view flags and slot order without an arctangent
per satellite or a sort (``in_view``, ``in_view_first``), each equal to what ``look_angles``
and a stable argsort give (tested)."""

import functools
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import data, geometry
from oaraim.geometry import Ephemeris, elevation, look_angles, resolve_source
from oaraim.readers import GALILEO, GPS
from oaraim.studies.common import sky

GPS_ALMANAC = "almanac/almmops.txt"
GALILEO_ALMANAC = "almanac/alm_gal_ed259.txt"


def _orbit_source(choice, default_file, nominal):
    if choice == "none":
        return None
    if choice == "nominal":
        return nominal
    if choice == "auto":
        return str(data.path(default_file))
    return choice


#: ``sky_time``: where the map's epoch 0 lies for an almanac
SKY_TIMES = ("week", "toa")


@functools.lru_cache(maxsize=4)
def constellation_orbits(gps, galileo, duration_s, step_s, sky_time="week", allow_gaps=False):
    """Satellite ECEF ``(T, S, 3)``, usable mask ``(T, S)``, constellation codes ``(S,)``,
    satellite names, epoch offsets ``(T,)`` (s from the start) and a description.

    ``sky_time="week"`` (MAAST): every almanac is evaluated at the same time of its own GPS
    week, epoch 0 at the week's start (MAAST's ``alm2satposvel`` at t = TStart .. TEnd with
    t_k = t - t_oa in seconds of the week), so GPS and Galileo almanacs of different epochs see
    the sky of one common time. ``"toa"``: each almanac from its own earliest time of
    applicability (the sky closest to its epoch). A navigation file runs from 00:00 of the day
    holding most of its records, a nominal constellation from its reference epoch, in both.
    The offsets are the epochs of the map: 0, step_s, ... < duration_s. A navigation file
    that does not cover them (``geometry.ephemeris_gaps``: a file cut short, or of fewer
    hours than the map) is refused in one line naming the file and the epochs, unless
    ``allow_gaps`` (the map then counts those epochs as they are: few or no satellites).
    """
    if sky_time not in SKY_TIMES:
        raise ValueError(f"sky_time must be one of {', '.join(SKY_TIMES)}, got {sky_time!r}")
    t_off = np.arange(0.0, duration_s - 1e-9, step_s)
    parts, desc = [], []
    for name, choice, default, nominal, code in (
            ("gps", gps, GPS_ALMANAC, "nominal-gps", GPS),
            ("galileo", galileo, GALILEO_ALMANAC, "nominal-galileo", GALILEO)):
        src = _orbit_source(choice, default, nominal)
        if src is None:
            continue
        objs, _, d = resolve_source(src, (name,))
        for o in objs:
            keep = np.asarray(o.constellation) == code
            if not keep.any():
                continue
            if isinstance(o, Ephemeris):
                t0 = sky.file_day_start(o)
            elif hasattr(o, "records"):
                r = o.records
                t0 = float(np.min(r.toa_s) if sky_time == "toa" else
                           np.min(np.asarray(r.toa_s) - np.asarray(r.toa_tow_s)))
            else:  # a nominal constellation: its own reference epoch
                t0 = float(getattr(o, "reference_t_gps_s", 0.0))
            e, v, sv = o.sat_position_ecef(t0 + t_off, prns=o.prns[keep])
            gaps = (geometry.ephemeris_gaps(v, np.full(int(keep.sum()), code))
                    if isinstance(o, Ephemeris) and not allow_gaps else np.zeros(0, bool))
            if gaps.any():  # almanacs and nominal orbits have no gaps
                bad = np.flatnonzero(gaps)
                raise ValueError(
                    f"{name}={Path(src).name}: no usable orbits for most satellites at "
                    f"{bad.size} of {t_off.size} map epochs (from {t_off[bad[0]] / 3600:.2f} h "
                    f"to {t_off[bad[-1]] / 3600:.2f} h after the day's start); the file ends "
                    "early or covers fewer hours than duration_s: use a whole day's file, a "
                    "shorter duration_s, or --set allow_gaps=yes to map them as they are")
            parts.append((np.asarray(e), np.asarray(v), np.full(int(keep.sum()), code),
                          np.asarray(sv)))
        desc.append(f"{name}: {Path(src).name if src not in (nominal,) else src}")
    if not parts:
        raise ValueError("gps and galileo are both 'none': the map needs at least one "
                         "constellation")
    ecef = np.concatenate([p[0] for p in parts], 1)
    ok = np.concatenate([p[1] for p in parts], 1)
    cons = np.concatenate([p[2] for p in parts])
    sv = np.concatenate([p[3] for p in parts])
    return ecef, ok, cons, sv, t_off, "; ".join(desc)


#: the elevation margin (rad) of ``max_visible``'s first pass: far above the rounding of an
#: elevation (~1e-15 rad), far below any real satellite's distance from the mask
_MASK_MARGIN_RAD = 1e-9


@jax.jit
def _most_in_view(lat_rad, lons_rad, h_m, sat_ecef, sat_ok, mask_rad):
    """Most satellites in view from the users of one latitude row at any epoch: the count of
    ``look_angles``' valid flags, as the map kernel sees them."""
    rx = geometry.geodetic_to_ecef(lat_rad, lons_rad, h_m)  # (n_lon, 3)
    return jnp.max(jnp.sum(look_angles(rx, sat_ecef, sat_ok, mask_rad)[3], -1))


def _row_enu(lat_rad, lons_rad, h_m, sat_ecef):
    """East, north, up of every satellite from every user of a latitude row, (n_lon, T, S)
    each: ``line_of_sight``'s components, unnormalised."""
    rx = geometry.geodetic_to_ecef(lat_rad, lons_rad, h_m)
    lat, lon, _ = geometry.ecef_to_geodetic(rx)
    r = geometry.enu_rotation(lat, lon)[:, :, None, None, :]  # (n_lon, 3, 1, 1, 3)
    d = [sat_ecef[None, :, :, k] - rx[:, None, None, k] for k in range(3)]  # (n_lon, T, S)
    return tuple(sum(r[:, i, ..., k] * d[k] for k in range(3)) for i in range(3))


@jax.jit
def _in_view_bounds(lat_rad, lons_rad, h_m, sat_ecef, sat_ok, tan_lo, tan_hi):
    """Lower and upper bounds of ``_most_in_view`` without an arctangent per satellite: a
    satellite counts for the lower bound where its elevation is surely >= the mask (above
    mask + margin: up >= horizontal x tan_hi) and for the upper bound where it may be (above
    mask - margin)."""
    sure, maybe = _mask_bounds(*_row_enu(lat_rad, lons_rad, h_m, sat_ecef), sat_ok, tan_lo,
                               tan_hi)
    return jnp.max(jnp.sum(sure, -1)), jnp.max(jnp.sum(maybe, -1))


@jax.jit
def _most_maybe_in_view(lat_rad, lons_rad, h_m, sat_ecef, sat_ok, tan_lo):
    """The upper bound of ``_in_view_bounds`` alone, in one fused pass (int32 counts):
    measured on the 1 x 1 deg world, 0.9 s for the 181 rows against 5.8 s for both bounds."""
    e, n, up = _row_enu(lat_rad, lons_rad, h_m, sat_ecef)
    maybe = _mask_bounds(e, n, up, sat_ok, tan_lo, tan_lo)[1]
    return jnp.max(jnp.sum(maybe, -1, dtype=jnp.int32))


def _mask_bounds(e, n, u, usable, tan_lo, tan_hi):
    """(sure, maybe): usable and elevation surely above atan(tan_hi), and maybe above
    atan(tan_lo), from the line-of-sight components without an arctangent (up >= t x
    horizontal, compared squared by sign)."""
    h2 = e * e + n * n

    def above(t):
        return jnp.where(u >= 0, (t <= 0) | (u * u >= t * t * h2),
                         (t < 0) & (u * u <= t * t * h2))

    return usable & above(tan_hi), usable & above(tan_lo)


class OrbitWindow(NamedTuple):
    """Which GNSS orbits a map reads over which epochs: ``constellation_orbits``' arguments
    (hashable: the memoized functions take it whole)."""

    gps: object
    """The GPS source (a navigation file, an almanac, ``'nominal'``, ``'none'``)."""
    galileo: object
    """The Galileo source."""
    duration_s: float
    """The span of epochs (s)."""
    step_s: float
    """The epoch step (s)."""
    sky_time: str = "week"
    """Where the epochs start (``constellation_orbits``)."""
    allow_gaps: bool = False
    """Keep epochs a file does not cover."""


@functools.lru_cache(maxsize=8)
def max_visible(orbits: OrbitWindow, mask_deg, lats, lons, h_m):
    """Most satellites in view at any grid point and epoch: the GNSS slots of the kernel.

    Exactly the count of the map kernel's ``look_angles``. Every row's upper bound first
    (``_most_maybe_in_view``); then, rows in decreasing bound until no bound exceeds the count
    found, each row's count: its bounds (``_in_view_bounds``) where they agree, the exact count
    (``_most_in_view``) only where a satellite lies within ``_MASK_MARGIN_RAD`` of the mask at
    the busiest epoch. Measured, the 1 x 1 deg world: 52 s op by op, 21 s compiled with an
    arctangent per satellite, 5.8 s with both bounds of every row, ~1 s with this order."""
    ecef, ok, *_ = constellation_orbits(*orbits)
    lo = jnp.asarray(np.deg2rad(np.asarray(lons, float)))
    ecef, ok = jnp.asarray(ecef), jnp.asarray(ok)
    mask = float(np.deg2rad(mask_deg))
    tan_lo, tan_hi = (float(np.tan(mask + d)) for d in (-_MASK_MARGIN_RAD, _MASK_MARGIN_RAD))
    rows = [(float(np.deg2rad(la)), lo, float(h_m), ecef, ok) for la in lats]
    bound = [_most_maybe_in_view(*args, tan_lo) for args in rows]  # dispatched, then read
    bound = np.array([int(b) for b in bound])
    most = 0
    for i in np.argsort(-bound, kind="stable"):
        if bound[i] <= most:
            break
        sure, maybe = (int(x) for x in _in_view_bounds(*rows[i], tan_lo, tan_hi))
        most = max(most, sure if sure == maybe else int(_most_in_view(*rows[i], mask)))
    return most


def in_view(e, n, u, usable, mask_rad):
    """``look_angles``' in-view flags, usable & (elevation >= mask), from the line-of-sight
    components (``line_of_sight``), without an arctangent per satellite: squared comparisons
    where the elevation lies more than ``_MASK_MARGIN_RAD`` from the mask (as
    ``_in_view_bounds``), the elevation itself only in a batch where one lies closer (a
    branch that a world map practically never takes). Measured on the 1 x 1 deg map's 48
    satellites: the arctangents were 0.9 us per geometry, 8 % of the kernel."""
    sure, maybe = _mask_bounds(e, n, u, usable, jnp.tan(mask_rad - _MASK_MARGIN_RAD),
                               jnp.tan(mask_rad + _MASK_MARGIN_RAD))
    return jax.lax.cond(jnp.any(sure != maybe),
                        lambda: usable & (elevation(e, n, u) >= mask_rad), lambda: sure)


def in_view_first(vis, n_slots):
    """The first ``n_slots`` of ``jnp.argsort(~vis, axis=-1, stable=True)`` for vis (B, S):
    the satellites in view in index order, then the others in index order. Without a sort:
    a satellite's place is a running count of its kind, and slot k takes the index whose place
    is k, written out over the S satellites on batch-last arrays (vectorised along the
    batch). Measured on the 1 x 1 deg map's 48 satellites: the stable argsort cost 2.6 us per
    geometry (a third of the kernel's front end), this 0.3 us."""
    v = jnp.moveaxis(vis, -1, 0)  # (S, B)
    n_sat = v.shape[0]
    seen, count = [], jnp.zeros(v.shape[1:], jnp.int32)
    for s in range(n_sat):  # in view up to and including s
        count = count + v[s]
        seen.append(count)
    place = [jnp.where(v[s], seen[s] - 1, count + s - seen[s]) for s in range(n_sat)]
    slots = []
    for k in range(n_slots):
        idx = jnp.zeros_like(count)
        for s in range(n_sat):
            idx = jnp.where(place[s] == k, s, idx)
        slots.append(idx)
    return jnp.stack(slots, axis=-1)
