"""One call for the protection levels of a receiver at given epochs: position, time, a sky
source and optional towers in; the MHSS result and the sources it used out.

    r = araim.epoch_protection_levels(40.43, -4.25, 840.0, t_gps_s, "nav/VILL...MN.rnx.gz",
                                      towers=[(40.44, -4.24, 30.0, "A"), ...])
    r.pl.hpl_m, r.pl.vpl_m, r.pl.status, r.sources    # ('G05', 'E11', ..., 'T1')

What it does, step by step (each step a public function of its own layer):

1. ``geometry.satellites``: the orbits of the source (RINEX navigation file, YUMA/SEM
   almanac, ``'nominal'``, loaded orbit objects) at the epochs; ``geometry.ephemeris_gaps``
   refuses epochs the file does not cover (one line naming them) unless ``allow_gaps``.
2. ``geometry.look_angles``: satellites at or above ``mask_deg``; towers (lat, lon, h,
   carrier) at any elevation, each carrier one SOP constellation (labels after GPS 0 and
   Galileo 1, in order of first appearance).
3. The sources of each epoch compacted to those in use, padded to a few static counts
   (``SOURCE_BUCKETS``) so that a day of epochs shares one or two compiled programs: the
   fault-mode conventions' limit on sources (``add-v4.2``: 52) counts sources in view, not
   the satellites of the file.
4. The ISM values of each constellation (``Ism``: sigma_URA, sigma_URE, b_nom, P_sat,
   P_const), the airborne error model of ``errors.AIRBORNE_MODELS`` and
   ``protection_levels`` under the budget and convention given.
"""

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Real

from oaraim.araim.budget import BUDGET_LPV200, IntegrityBudget
from oaraim.araim.fault_modes import MAX_EVENT_SOURCES
from oaraim.araim.mhss import MHSSOptions, MHSSResult, Sources, as_options, protection_levels
from oaraim.araim.validate import check_range
from oaraim.errors import AIRBORNE_MODELS, gnss_variances, sop_variances
from oaraim.geometry import (
    ephemeris_gaps,
    geodetic_to_ecef,
    geometry_rows,
    look_angles,
    satellites,
)
from oaraim.readers import MIN_SEPARATION_M, first_near_pair

__all__ = ["ISM_GALILEO", "ISM_GPS", "ISM_SOP", "SOURCE_BUCKETS", "EpochLevels", "EpochOptions",
           "Ism",
           "epoch_protection_levels"]


class Ism(NamedTuple):
    """The integrity support message values of one constellation (ADD section 2.3): what the
    receiver assumes of its sources' nominal errors and fault probabilities."""

    sigma_ura_m: float = 1.0
    """sigma_URA, integrity (m)."""
    sigma_ure_m: float | None = None
    """sigma_URE, accuracy (m); None: 2/3 sigma_URA for GNSS (ADD), sigma_URA for SOPs."""
    b_nom_m: float = 0.75
    """Nominal bias bound b_nom (m)."""
    p_sat: float = 1e-5
    """Per-source fault probability P_sat (P_s for an SOP) per approach."""
    p_const: float = 1e-8
    """Constellation (operator) fault probability P_const."""


#: GPS and Galileo as MAAST for ARAIM and the ADD's examples assume them (the availability
#: map's defaults): sigma_URA 1 m, b_nom 0.75 m, P_sat 1e-5; P_const 1e-8 GPS, 1e-4 Galileo
ISM_GPS = Ism(1.0, None, 0.75, 1e-5, 1e-8)
ISM_GALILEO = Ism(1.0, None, 0.75, 1e-5, 1e-4)
#: an SOP carrier as seed 004 Table I: sigma_URA^S 1 m, b_nom 0 (Appendix D), P_s^S 1e-5,
#: P_const^S 1e-4
ISM_SOP = Ism(1.0, None, 0.0, 1e-5, 1e-4)

#: the source counts an epoch is padded to: every distinct count is one more compiled program
#: (15-45 s each), every padded slot a little more work
SOURCE_BUCKETS = (8, 12, 16, 20, 24, 32, 40, MAX_EVENT_SOURCES)
#: tower rows are (lat_deg, lon_deg, height_m, carrier)
_TOWER_FIELDS = 4


class EpochLevels(NamedTuple):
    """What ``epoch_protection_levels`` returns: the protection levels and the sources behind
    them. Arrays have the shape of ``t_gps_s`` (() for one epoch, (T,) for several)."""

    pl: MHSSResult
    """The MHSS result (``hpl_m``, ``vpl_m``, ``emt_m``, ``sigma_acc_u_m``, ``status``, ...)."""
    sources: tuple | list
    """The ids of the sources used, e.g. ``('G05', 'E11', 'T1')`` (towers numbered from 1 in
    the order given); for several epochs a list of such tuples, one per epoch."""
    az_deg: tuple | list
    """Azimuth of each source used (deg), in the order of ``sources``."""
    el_deg: tuple | list
    """Elevation of each source used (deg), in the order of ``sources``."""
    constellations: tuple
    """The name of each constellation label: ``('GPS', 'Galileo', 'SOP A', ...)``."""
    n_sources: np.ndarray
    """Sources used per epoch."""
    t_gps_s: np.ndarray
    """The epochs (GPS seconds)."""


def _towers(towers):
    """(lat_deg, lon_deg, h_m) arrays and carrier names of ``towers`` (rows of 4)."""
    if towers is None:
        return np.zeros((0, 3)), []
    rows = list(towers)
    if rows and isinstance(rows[0], str | bytes):
        raise ValueError("towers must be rows (lat_deg, lon_deg, height_m, carrier), got a "
                         "string; read a tower CSV first, one tuple per tower")
    pos, carriers = [], []
    for i, row in enumerate(rows):
        if len(row) != _TOWER_FIELDS:
            raise ValueError(f"towers row {i + 1}: (lat_deg, lon_deg, height_m, carrier) "
                             f"expected, got {row!r}")
        try:
            lat, lon, h = (float(x) for x in row[:3])
        except (TypeError, ValueError):
            raise ValueError(f"towers row {i + 1}: lat_deg, lon_deg, height_m must be numbers, "
                             f"got {row[:3]!r}") from None
        if not (np.isfinite([lat, lon, h]).all() and -90.0 <= lat <= 90.0):
            raise ValueError(f"towers row {i + 1}: latitude in [-90, 90] and finite longitude "
                             f"and height expected, got {row[:3]!r}")
        pos.append((lat, lon, h))
        carriers.append(str(row[3]))
    return np.asarray(pos, np.float64).reshape(-1, 3), carriers


def _bucket(n):
    for b in SOURCE_BUCKETS:
        if n <= b:
            return b
    raise ValueError(f"{n} sources in view at one epoch; the fault-mode conventions take at "
                     f"most {MAX_EVENT_SOURCES}: raise mask_deg or use fewer towers")


def _ism(ism, key, default):
    v = (ism or {}).get(key, default)
    if not isinstance(v, Ism):
        raise ValueError(f"ism[{key!r}] must be an araim.Ism, got {type(v).__name__}")
    return v


class EpochOptions(NamedTuple):
    """How ``epoch_protection_levels`` models its receiver: the mask, the ISM, the user error
    model, the constellations read from the sky and the MHSS options."""

    mask_deg: float = 5.0
    """Elevation mask of the satellites (deg); towers have none."""
    ism: dict | None = None
    """``{"gps": Ism, "galileo": Ism, "sop": Ism}``, each optional (defaults ``ISM_GPS``,
    ``ISM_GALILEO``, ``ISM_SOP``; ``"sop"`` applies to every carrier, or name a carrier
    ``"sop:A"``)."""
    airborne_model: str = "ed259a"
    """The GNSS user error model of ``error_models.AIRBORNE_MODELS`` (``'ed259a'``, MAAST for
    ARAIM 2; ``'add'`` the ADD's curve)."""
    constellations: Sequence[str] = ("gps", "galileo")
    """The constellations of ``sky`` used."""
    allow_gaps: bool = False
    """Keep epochs the navigation file does not cover (they count as unavailable: few or no
    satellites) instead of refusing them."""
    mhss: MHSSOptions = MHSSOptions()
    """The fault-mode convention and order (None: the smallest at which nothing beyond is
    monitored, ``protection_levels``) and the other ``MHSSOptions``."""


def epoch_protection_levels(lat_deg: float, lon_deg: float, h_m: float,
                            t_gps_s: Real[ArrayLike, " T"] | Real[ArrayLike, ""],
                            sky: Any = "nominal", towers: Sequence | None = None, *,
                            budget: IntegrityBudget = BUDGET_LPV200,
                            options: EpochOptions | None = None) -> EpochLevels:
    """The MHSS protection levels of a receiver at ``(lat_deg, lon_deg, h_m)`` (WGS-84) at
    GPS time(s) ``t_gps_s`` (a number or (T,) array; ``geometry.gpstime``), with the
    satellites of ``sky`` at or above ``mask_deg`` and the ``towers`` given.

    Args:
      sky: what ``geometry.sky`` takes: a RINEX 2/3 navigation file, a YUMA/SEM almanac,
        ``'nominal'`` (built-in GPS + Galileo), or loaded orbit objects.
      towers: rows ``(lat_deg, lon_deg, height_m, carrier)``; every tower is used (SOPs have
        no elevation mask), one SOP constellation per carrier.
      budget: an ``IntegrityBudget`` (default LPV-200).
      options: ``EpochOptions`` (None: the defaults): mask, ISM, user error model,
        constellations, gaps, and the ``MHSSOptions`` (fault modes, order).

    Returns:
      ``EpochLevels``. An epoch with too few sources or an unmet budget has infinite PLs and
      its ``Status``, like every receiver function.
    """
    options = EpochOptions() if options is None else options
    if not isinstance(options, EpochOptions):
        raise ValueError("options must be an araim.EpochOptions, got "
                         f"{type(options).__name__}")
    mask_deg, ism, airborne_model, constellations, allow_gaps, mhss = options
    lat = check_range("lat_deg", lat_deg, -90.0, 90.0)
    lon = check_range("lon_deg", lon_deg, -180.0, 360.0)
    h = check_range("h_m", h_m, -1000.0, 1e5)
    if airborne_model not in AIRBORNE_MODELS:
        raise ValueError(f"airborne_model must be one of {', '.join(AIRBORNE_MODELS)}, got "
                         f"{airborne_model!r}")
    scalar = np.ndim(t_gps_s) == 0
    t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)):
        raise ValueError("t_gps_s must be a finite number or a 1-D array of GPS seconds")
    mask = check_range("mask_deg", mask_deg, 0.0, 90.0)
    if mask == 90.0:
        raise ValueError(f"mask_deg must be below 90 (no sky is left above it), got {mask_deg!r}")
    mhss = as_options(mhss).checked()  # a bad name fails here, before the sky is computed

    rx = np.asarray(geodetic_to_ecef(np.deg2rad(lat), np.deg2rad(lon), h))
    ecef, usable, _, cons, sv, desc = satellites(sky, t, tuple(constellations))
    gaps = ephemeris_gaps(usable, cons)
    if gaps.any() and not allow_gaps:
        bad = np.flatnonzero(gaps)
        raise ValueError(f"the sky source ({desc}) has no usable orbits for most satellites "
                         f"at {bad.size} of {t.size} epochs (first t_gps_s={t[bad[0]]:.0f}); "
                         "the file ends early or does not cover these times: use a file of "
                         "that day, or allow_gaps=True to keep them as unavailable")
    az, el, _, vis = (np.asarray(x) for x in look_angles(rx, ecef, usable, np.deg2rad(mask)))
    tw_pos, carriers = _towers(towers)
    names = list(dict.fromkeys(carriers))
    n_tw = tw_pos.shape[0]
    if n_tw:
        tw_ecef = np.asarray(geodetic_to_ecef(np.deg2rad(tw_pos[:, 0]),
                                              np.deg2rad(tw_pos[:, 1]), tw_pos[:, 2]))
        if np.any(np.linalg.norm(tw_ecef - rx, axis=-1) < 1.0):
            raise ValueError("a tower is within 1 m of the receiver: no line of sight; "
                             "check the towers' coordinates")
        near = first_near_pair(tw_ecef, carriers)
        if near is not None:
            a, b, d = near
            raise ValueError(f"towers rows {a + 1} and {b + 1}: carrier {carriers[b]!r} twice "
                             f"within {MIN_SEPARATION_M:g} m ({d:.3g} m apart): one transmitter "
                             "given twice would count as two independent ranges; give one row "
                             "per transmitter")
        ta, te, _, _ = (np.asarray(x) for x in look_angles(
            rx, tw_ecef[None], np.ones((1, n_tw), bool), -np.pi / 2))
        az = np.concatenate([az, np.broadcast_to(ta, (t.size, n_tw))], -1)
        el = np.concatenate([el, np.broadcast_to(te, (t.size, n_tw))], -1)
        vis = np.concatenate([vis, np.ones((t.size, n_tw), bool)], -1)
        cons = np.concatenate([cons, 2 + np.array([names.index(c) for c in carriers])])
        sv = np.concatenate([sv, [f"T{i + 1}" for i in range(n_tw)]])
    n_c = 2 + len(names)
    ism_of = [_ism(ism, "gps", ISM_GPS), _ism(ism, "galileo", ISM_GALILEO)] + [
        _ism(ism, f"sop:{c}", _ism(ism, "sop", ISM_SOP)) for c in names]

    # compact every epoch to its sources in use, padded to one bucket for all epochs
    n_used = vis.sum(-1)
    L = _bucket(max(int(n_used.max()), 1))
    order = np.argsort(~vis, axis=-1, kind="stable")[:, :L]
    take = lambda x: np.take_along_axis(x, order, -1)  # noqa: E731
    az_c, el_c, valid = take(az), take(el), take(vis)
    if order.shape[1] < L:  # fewer candidate sources than the bucket: pad
        pad = L - order.shape[1]
        az_c, el_c = (np.pad(x, ((0, 0), (0, pad))) for x in (az_c, el_c))
        valid = np.pad(valid, ((0, 0), (0, pad)))
        order = np.pad(order, ((0, 0), (0, pad)))
    label = cons[order]
    el_safe = np.where(valid, el_c, np.pi / 2)
    user = AIRBORNE_MODELS[airborne_model]
    var_int, var_acc = np.ones(label.shape), np.ones(label.shape)
    b_nom, p_sat = np.zeros(label.shape), np.zeros(label.shape)
    for c, s in enumerate(ism_of):
        m = label == c
        if c < 2:
            vi, va = gnss_variances(el_safe, s.sigma_ura_m, s.sigma_ure_m, user_model=user)
        else:
            vi, va = sop_variances(np.full(label.shape, s.sigma_ura_m), s.sigma_ure_m)
        var_int = np.where(m, np.asarray(vi), var_int)
        var_acc = np.where(m, np.asarray(va), var_acc)
        b_nom = np.where(m, s.b_nom_m, b_nom)
        p_sat = np.where(m, s.p_sat, p_sat)
    p_const = np.broadcast_to(np.array([s.p_const for s in ism_of]), (t.size, n_c))
    g = np.asarray(geometry_rows(az_c, np.where(valid, el_c, 0.0)))
    g = np.where(valid[..., None], g, 0.0)
    pl = protection_levels(Sources(g, label, var_int, var_acc, b_nom, p_sat, valid), p_const,
                           budget, mhss)

    ids = [tuple(sv[order[i, valid[i]]].tolist()) for i in range(t.size)]
    a_deg = [tuple(np.rad2deg(az_c[i, valid[i]]).tolist()) for i in range(t.size)]
    e_deg = [tuple(np.rad2deg(el_c[i, valid[i]]).tolist()) for i in range(t.size)]
    const_names = ("GPS", "Galileo") + tuple(f"SOP {c}" for c in names)
    if scalar:
        pl = MHSSResult(*(np.asarray(x)[0] for x in pl))
        return EpochLevels(pl, ids[0], a_deg[0], e_deg[0], const_names, n_used[0], t[0])
    return EpochLevels(MHSSResult(*(np.asarray(x) for x in pl)), ids, a_deg, e_deg,
                       const_names, n_used, t)
