"""The sky of a receiver: azimuth, elevation and validity of every satellite at every epoch.

``geometry.sky(receiver_ecef_m, t_gps_s, source=..., mask_deg=...)`` batches over receivers
(any leading shape) and epochs and returns padded arrays ``(..., T, S)`` over a fixed satellite
list with a ``valid`` mask (healthy ephemeris within its validity window AND elevation >=
mask), ready for ``geometry.geometry_rows(az, el)`` and ``araim``. Constellation codes are
fixed: GPS 0, Galileo 1 (DESIGN.md); studies append SOP constellations after them.

Sources: ``"nominal"`` (built-in GPS 24-slot + Galileo Walker 24/3/1, the default sky),
``"nominal-gps"``, ``"nominal-galileo"``, a path to a RINEX 2/3 navigation file or a YUMA
almanac (``.txt``/``.yuma``/``.alm``) or a SEM almanac (``.al3``/``.sem``), or an already
loaded ``Ephemeris``/``Almanac`` (or a list of them).

Positions are in the ECEF frame at the epoch t (geometry: the Sagnac rotation during the
~70 ms signal flight moves a direction by ~1.4 arcsec and is left out).
"""

from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Array, Bool, Float, Real, Shaped

from oaraim.geometry.almanac_orbits import Almanac, read_sem, read_yuma
from oaraim.geometry.broadcast_orbits import Ephemeris, load_navigation
from oaraim.geometry.frames import ecef_to_geodetic, enu_rotation
from oaraim.geometry.nominal import galileo_walker, gps_24_slot
from oaraim.readers import GALILEO, GPS

CONSTELLATION_CODES = {"gps": GPS, "galileo": GALILEO}


class Sky(NamedTuple):
    """What ``geometry.sky`` returns: the look angles of a fixed satellite list from each
    receiver at each epoch, padded, with a ``valid`` mask."""

    az_rad: jax.Array
    """(..., T, S) azimuth, radians clockwise from north, in [0, 2 pi)."""
    el_rad: jax.Array
    """(..., T, S) elevation above the local horizon, radians."""
    range_m: jax.Array
    """(..., T, S) geometric receiver-satellite range, metres."""
    valid: jax.Array
    """(..., T, S) bool: usable ephemeris (healthy, in its validity window) and el >= mask."""
    prn: np.ndarray
    """(S,) satellite numbers."""
    constellation: np.ndarray
    """(S,) constellation codes: GPS 0, Galileo 1."""
    sv: np.ndarray
    """(S,) satellite names such as ``'G05'``, ``'E11'``."""
    t_gps_s: np.ndarray
    """(T,) the epochs, GPS seconds."""
    source: str
    """What the satellites came from: the ``repr`` of each orbit object, joined by "; "."""


#: what ``sky``, ``satellites`` and ``resolve_source`` take as the satellites' source
_SkySource = str | Path | Ephemeris | Almanac | Sequence[Ephemeris | Almanac]


def _load_file(path: Path, constellations):
    name = path.name.lower()
    if name.endswith((".al3", ".sem")):
        return [read_sem(path)]
    if name.endswith((".yuma", ".alm")) or (name.endswith(".txt") and _looks_yuma(path)):
        return [read_yuma(path, system="E" if constellations == {GALILEO} else "G")]
    systems = tuple(s for s, c in (("G", GPS), ("E", GALILEO)) if c in constellations)
    return [load_navigation(path, systems=systems)]


def _looks_yuma(path: Path) -> bool:
    with open(path, encoding="ascii", errors="replace") as f:
        return f.read(200).lstrip().startswith("****")


def resolve_source(source: _SkySource, constellations: Sequence[str] = ("gps", "galileo")
                   ) -> tuple[list[Ephemeris | Almanac], set[int], str]:
    """The orbit objects of a ``source`` (see the module docstring) and a description."""
    bad = [c for c in constellations if c not in CONSTELLATION_CODES]
    if bad or not constellations:
        raise ValueError(f"constellations must be a non-empty subset of ('gps', 'galileo'), got "
                         f"{tuple(constellations)!r}")
    codes = {CONSTELLATION_CODES[c] for c in constellations}
    if isinstance(source, Ephemeris | Almanac):
        objs = [source]
    elif isinstance(source, list | tuple) and source and all(
            isinstance(s, Ephemeris | Almanac) for s in source):
        objs = list(source)
    elif isinstance(source, str) and source.startswith("nominal"):
        table = {"nominal": (gps_24_slot, galileo_walker), "nominal-gps": (gps_24_slot,),
                 "nominal-galileo": (galileo_walker,)}
        if source not in table:
            raise ValueError(f"source {source!r} unknown; use 'nominal', 'nominal-gps', "
                             "'nominal-galileo' or a navigation/almanac file path")
        objs = [f() for f in table[source]]
    elif isinstance(source, str | Path):
        p = Path(source).expanduser()
        if not p.is_file():
            raise ValueError(f"sky source {str(source)!r} is neither 'nominal[-gps|-galileo]' "
                             "nor an existing navigation or almanac file")
        objs = _load_file(p, codes)
    else:
        raise ValueError(f"sky source must be 'nominal', a file path, an Ephemeris or an "
                         f"Almanac, got {type(source).__name__}")
    desc = "; ".join(repr(o) for o in objs)
    return objs, codes, desc


def satellites(source: _SkySource, t_gps_s: Real[ArrayLike, " T"] | Real[ArrayLike, ""],
               constellations: Sequence[str] = ("gps", "galileo")
               ) -> tuple[Float[Array, "T S 3"], Bool[Array, "T S"], Shaped[np.ndarray, " S"],
                          Shaped[np.ndarray, " S"], Shaped[np.ndarray, " S"], str]:
    """The satellites of a source restricted to the requested constellations at GPS times
    ``t_gps_s`` ((T,) or a scalar, taken as (1,)): ``(ecef_m, usable, prn, constellation, sv,
    description)``, ECEF positions ``(T, S, 3)`` (metres), usable mask ``(T, S)``, satellite
    numbers, constellation codes and names ``(S,)``, and what the satellites came from."""
    objs, codes, desc = resolve_source(source, constellations)
    t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
    ecef, valid, prn, cons, sv = [], [], [], [], []
    for o in objs:
        keep = np.isin(o.constellation, list(codes))
        if not np.any(keep):
            continue
        e, v, names = o.sat_position_ecef(t, prns=o.prns[keep])
        ecef.append(e)
        valid.append(v)
        prn.append(o.prn_number[keep])
        cons.append(o.constellation[keep])
        sv.append(names)
    if not ecef:
        raise ValueError(f"the sky source ({desc}) holds no satellite of {tuple(constellations)}")
    return (jnp.concatenate(ecef, 1), jnp.concatenate(valid, 1), np.concatenate(prn),
            np.concatenate(cons), np.concatenate(sv), desc)


#: an epoch is a gap of a constellation's orbits when fewer of its satellites have a usable
#: orbit there than this share of the most at any epoch asked for. Measured on the project's
#: real navigation files over their day at 300 s: a station's own file (Elko, Villafranca)
#: keeps Galileo at >= 0.39 of its satellites and >= 0.62 for GPS, the most at any epoch at
#: most ~1.4 times the least; an IGS merged file >= 0.91. A file cut short falls to 0.
GAP_SHARE = 0.5


def ephemeris_gaps(usable: Bool[ArrayLike, "T S"], constellation: Shaped[ArrayLike, " S"]
                   ) -> Bool[np.ndarray, " T"]:
    """(T,) bool: the epochs at which some constellation of a source has usable orbits for
    fewer than ``GAP_SHARE`` of the most satellites it has at any of the epochs, or for none
    (a navigation file that ends early or starts late: its satellites vanish without a
    word). ``usable`` (T, S) is the orbit mask of ``satellites`` (health and record age, not
    elevation), ``constellation`` (S,) the codes. Almanacs and nominal orbits have no gaps."""
    usable = np.asarray(usable, bool)
    constellation = np.asarray(constellation)
    gaps = np.zeros(usable.shape[0], bool)
    for c in np.unique(constellation):
        n = usable[:, constellation == c].sum(-1)
        gaps |= (n == 0) | (n < GAP_SHARE * n.max())
    return gaps


def line_of_sight(receiver_ecef_m: Real[ArrayLike, "*rx 3"], sat_ecef_m: Real[ArrayLike, "T S 3"]
                  ) -> tuple[Float[Array, "*rx T S"], Float[Array, "*rx T S"],
                             Float[Array, "*rx T S"]]:
    """East, north and up components (m) of the lines of sight from receivers ``(..., 3)`` to
    satellites ``(T, S, 3)`` (ECEF, metres): three arrays ``(..., T, S)``."""
    rx = jnp.asarray(receiver_ecef_m, jnp.float64)
    lat, lon, _ = ecef_to_geodetic(rx)
    r = enu_rotation(lat, lon)  # (..., 3, 3)
    # line of sight projected on east, north, up: R (sat - rx), as matrix products over T x S
    proj = jnp.einsum("...ik,tsk->...tsi", r, sat_ecef_m)
    proj = proj - jnp.einsum("...ik,...k->...i", r, rx)[..., None, None, :]
    return proj[..., 0], proj[..., 1], proj[..., 2]


def azimuth(east_m: Real[ArrayLike, "..."], north_m: Real[ArrayLike, "..."]
            ) -> Float[Array, "..."]:
    """Azimuth (rad, [0, 2 pi), clockwise from north) of a line of sight."""
    return jnp.mod(jnp.arctan2(east_m, north_m), 2.0 * jnp.pi)


def elevation(east_m: Real[ArrayLike, "..."], north_m: Real[ArrayLike, "..."],
              up_m: Real[ArrayLike, "..."]) -> Float[Array, "..."]:
    """Elevation (rad) of a line of sight."""
    return jnp.arctan2(up_m, jnp.hypot(east_m, north_m))


@jax.jit
def look_angles(receiver_ecef_m: Real[ArrayLike, "*rx 3"], sat_ecef_m: Real[ArrayLike, "T S 3"],
                sat_valid: Bool[ArrayLike, "*#rx #T #S"], mask_rad: Real[ArrayLike, ""]
                ) -> tuple[Float[Array, "*rx T S"], Float[Array, "*rx T S"],
                           Float[Array, "*rx T S"], Bool[Array, "*rx T S"]]:
    """Az, el, range and validity of satellites ``(T, S, 3)`` from receivers ``(..., 3)``.

    Returns arrays ``(..., T, S)``; entries of unusable satellites hold az = el = range = 0.
    """
    e, n, u = line_of_sight(receiver_ecef_m, sat_ecef_m)
    az = azimuth(e, n)
    el = elevation(e, n, u)
    rng = jnp.hypot(jnp.hypot(e, n), u)
    usable = jnp.broadcast_to(sat_valid, el.shape)
    valid = usable & (el >= mask_rad)
    zero = jnp.zeros_like(el)
    return (jnp.where(usable, az, zero), jnp.where(usable, el, zero),
            jnp.where(usable, rng, zero), valid)


def sky(receiver_ecef_m: Real[ArrayLike, "*rx 3"],
        t_gps_s: Real[ArrayLike, " T"] | Real[ArrayLike, ""], source: _SkySource = "nominal",
        mask_deg: float = 5.0, constellations: Sequence[str] = ("gps", "galileo")) -> Sky:
    """Azimuth/elevation of every satellite of ``source`` at GPS times ``t_gps_s`` (T,), seen
    from receivers ``receiver_ecef_m`` ``(..., 3)`` (metres, WGS-84 ECEF).

    Args:
      receiver_ecef_m: ``(3,)`` or ``(..., 3)`` receiver positions.
      t_gps_s: epochs, GPS seconds (``readers.gpstime``), shape ``(T,)`` or scalar.
      source: 'nominal' (default: built-in GPS 24-slot + Galileo Walker), 'nominal-gps',
        'nominal-galileo', a RINEX navigation / YUMA / SEM file, or loaded orbit objects.
      mask_deg: elevation mask in degrees, [0, 90). Default 5 deg (ARAIM practice).
      constellations: which of ('gps', 'galileo') to keep.

    Returns:
      ``Sky`` with ``(..., T, S)`` arrays; ``valid`` marks the satellites in view and usable.
    """
    try:
        mask = float(mask_deg)
    except (TypeError, ValueError):
        raise ValueError(f"mask_deg must be a number in [0, 90), got {mask_deg!r}") from None
    if not (0.0 <= mask < 90.0):
        raise ValueError(f"mask_deg must be a number in [0, 90), got {mask_deg!r}")
    rx = np.asarray(receiver_ecef_m, np.float64)
    if rx.shape[-1:] != (3,) or not np.all(np.isfinite(rx)):
        raise ValueError(f"receiver_ecef_m must be finite with last axis 3 (x, y, z metres), got "
                         f"shape {rx.shape}")
    if np.any(np.linalg.norm(rx, axis=-1) < 6.0e6):
        raise ValueError("receiver_ecef_m must be ECEF metres near the Earth's surface (|r| >= "
                         "6,000 km); convert latitude/longitude with geometry.geodetic_to_ecef")
    t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
    ecef, valid, prn, cons, sv, desc = satellites(source, t, tuple(constellations))
    az, el, rng, v = look_angles(rx, ecef, valid, np.deg2rad(mask))
    return Sky(az, el, rng, v, prn, cons, sv, t, desc)
