"""The availability map's LEO option (``--set leo=starlink|oneweb|iridium|orbcomm|globalstar|
FILE``): a LEO constellation as one SOP constellation beside GPS and Galileo.

The LEO sky of a latitude row is computed once, on the host side of the kernel, as slots:
per (longitude, epoch) the ``leo_max`` satellites in view (elevation >= ``leo_mask_deg``) of
highest elevation, their azimuth, elevation and error variances (``errors.leo``). The
map kernel gathers a realization's slots as it gathers CSV towers, so a shell of 1,584
satellites costs the kernel ``leo_max`` sources, not 1,584.

Epochs: a Walker shell is placed at the map's epoch 0 (plane 0's node at longitude 0 then);
a TLE file is propagated from its own earliest epoch at the map's offsets. The phase between
the LEO and the GNSS skies is therefore arbitrary: both are representative skies, as MAAST's
almanac days are (stated in the summary's ``leo_sky``).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from oaraim import araim, errors, geometry

#: the LEO choices besides a TLE file path
LEO_CHOICES = ("none", *geometry.LEO_PRESETS)


def parse_leo(name, v):
    """``leo``: none, a preset name or an existing TLE file."""
    from pathlib import Path

    v = str(v)
    if v in LEO_CHOICES or Path(v).expanduser().is_file():
        return v
    raise ValueError(f"{name} must be one of {', '.join(LEO_CHOICES)} or a TLE file path, "
                     f"got {v!r}")


@functools.lru_cache(maxsize=4)
def leo_orbits(spec, duration_s, step_s):
    """ECEF (T, S, 3), usable (T, S) of the LEO constellation over the map's epochs, and its
    description."""
    t_off = np.arange(0.0, duration_s - 1e-9, step_s)
    obj = geometry.leo_constellation(spec, 0.0)
    t0 = getattr(obj, "epoch_t_gps_s", 0.0)
    ecef, ok, _ = obj.sat_position_ecef(t0 + t_off)
    return np.asarray(ecef), np.asarray(ok), repr(obj)


@functools.partial(jax.jit, static_argnames=("k",))
def _row_slots(lat_rad, lons_rad, h_m, sat_ecef, sat_ok, mask_rad, *, k):
    """Per longitude (n_lon, T, k): the k satellites in view of highest elevation (az, el,
    valid) and the count in view (n_lon, T); one longitude at a time (lax.map) so a shell of
    thousands of satellites stays within memory."""
    def one(lon):
        rx = geometry.geodetic_to_ecef(lat_rad, lon, h_m)
        az, el, _, vis = geometry.look_angles(rx, sat_ecef, sat_ok, mask_rad)  # (T, S)
        score = jnp.where(vis, el, -10.0)
        top, idx = jax.lax.top_k(score, k)
        a = jnp.take_along_axis(az, idx, -1)
        return a, jnp.where(top > -10.0, top, 0.0), top > -10.0, jnp.sum(vis, -1)

    return jax.lax.map(one, lons_rad)


def most_in_view(spec, duration_s, step_s, mask_deg, lats_deg, lons_deg, h_m, cap):
    """min(``cap``, the most LEO satellites in view at any grid point and epoch): the rows
    from the equator outwards, stopping at the first that sees ``cap`` (the map keeps at most
    ``cap`` LEO slots, so more rows would not change the layout; a Starlink-class shell
    reaches it in the first row)."""
    ecef, ok, _ = leo_orbits(spec, duration_s, step_s)
    lons = jnp.asarray(np.deg2rad(np.asarray(lons_deg, float)))
    most = 0
    for la in sorted(lats_deg, key=abs):
        n = _row_slots(float(np.deg2rad(la)), lons, float(h_m), jnp.asarray(ecef),
                       jnp.asarray(ok), float(np.deg2rad(mask_deg)), k=1)[3]
        most = max(most, int(jnp.max(n)))
        if most >= cap:
            return cap
    return most


def leo_ism(p):
    """The ``araim.Ism`` of the run's LEO constellation: the preset ``leo_ism`` with the
    sigma_URA and priors the parameters set (``preset`` keeps the preset's)."""
    base = araim.LEO_ISM[p["leo_ism"]]
    ura = base.sigma_ura_m if p["sigma_ura_leo_m"] == "preset" else float(p["sigma_ura_leo_m"])
    ure = base.sigma_ure_m if p["sigma_ura_leo_m"] == "preset" else 2.0 / 3.0 * ura
    return araim.Ism(ura, ure, 0.0, float(p["p_s_leo"]), float(p["p_const_leo"]))


def leo_signal(p):
    """The ``errors.LeoSignal`` of the run: the named constellation's downlink (a TLE file:
    ``leo_signal``'s preset)."""
    name = p["leo"] if p["leo"] in errors.LEO_SIGNALS else p["leo_signal"]
    return errors.LEO_SIGNALS[name]


def leo_slots(p, lat_deg, n_leo):
    """The kernel's LEO slots of one latitude row: dict of (n_lon, T, n_leo) arrays az, el,
    valid, var_int, var_acc, p_sat, label (labels from 2: one clock, or one per slot)."""
    ecef, ok, _ = leo_orbits(p["leo"], p["duration_s"], p["step_s"])
    lons = jnp.asarray(np.deg2rad(np.asarray(p["lon_deg"], float)))
    az, el, valid, _ = _row_slots(float(np.deg2rad(lat_deg)), lons, float(p["height_m"]),
                                  jnp.asarray(ecef), jnp.asarray(ok),
                                  float(np.deg2rad(p["leo_mask_deg"])), k=n_leo)
    ism, sig = leo_ism(p), leo_signal(p)
    vi, va = errors.leo_variances(jnp.where(valid, el, jnp.pi / 2), ism, sig)
    label = araim.leo_labels(n_leo, 2, p["leo_clocks"])
    return {"az": az, "el": el, "valid": valid, "var_int": vi, "var_acc": va,
            "p_sat": jnp.full(az.shape, ism.p_sat),
            "label": jnp.broadcast_to(jnp.asarray(label), az.shape)}


def leo_groups(p, n_leo):
    """Clock groups (P_const entries) the LEO slots add: 1, or n_leo with one clock each."""
    if not n_leo:
        return 0
    return 1 if p["leo_clocks"] == "constellation" else n_leo


def layout_labels(p, n_leo):
    """The labels (list) of the n_leo LEO slots (from 2), for the layout's order rule."""
    return [int(x) for x in araim.leo_labels(n_leo, 2, p["leo_clocks"])]


def leo_description(p, n_leo):
    """The LEO constellation of a run in words."""
    ism = leo_ism(p)
    return (f"LEO {p['leo']} (up to {n_leo} of highest elevation above {p['leo_mask_deg']:g} "
            f"deg), sigma_URA {ism.sigma_ura_m:g} m, P_s {ism.p_sat:g}, P_const "
            f"{ism.p_const:g}, clocks per {p['leo_clocks']}")


def _sigma_or_preset(name, v):
    if str(v) == "preset":
        return "preset"
    from oaraim.studies.base import positive

    return positive(name, v)


def _params():
    from oaraim.studies.base import Param, count, in_range, parse_choice, probability

    return {
        "leo": Param("none", parse_leo, "LEO constellation as an SOP constellation: none, "
                     f"{', '.join(geometry.LEO_PRESETS)} (Walker shells of the operators' "
                     "filings, docs/leo.md) or a TLE file (SGP4)"),
        "leo_max": Param(12, count(1, 30), "LEO satellites used per user and epoch: those of "
                         "highest elevation in view (GNSS slots + this stay <= 52, the "
                         "add-v4.2 limit)"),
        "leo_mask_deg": Param(25.0, in_range(0.0, 89.0), "LEO elevation mask (Starlink's "
                              "filed minimum user elevation, 25 deg)", "deg"),
        "leo_ism": Param("estimated", parse_choice(*araim.LEO_ISM), "LEO ISM preset: "
                         "estimated (sigma_URA 1 m, GPS-like), degraded-20x (20 m) or tle "
                         "(1 km: public TLEs)"),
        "sigma_ura_leo_m": Param("preset", _sigma_or_preset, "LEO sigma_URA (sigma_URE 2/3 of "
                                 "it) or preset (leo_ism's)", "m"),
        "p_s_leo": Param(1e-5, probability, "LEO per-satellite fault prior P_s^LEO"),
        "p_const_leo": Param(1e-4, probability, "LEO constellation fault prior P_const^LEO"),
        "leo_clocks": Param("constellation", parse_choice(*araim.LEO_CLOCKS), "one LEO clock "
                            "per constellation, or one per satellite (then LEO ranges cannot "
                            "help a snapshot user: seed 004 Theorem 1)"),
        "leo_signal": Param("starlink", parse_choice(*errors.LEO_SIGNALS), "downlink error "
                            "model of a TLE file's satellites (a preset's own otherwise)"),
    }


#: the map's LEO parameters (``availability-map --set leo=...``)
LEO_PARAMS = _params()
