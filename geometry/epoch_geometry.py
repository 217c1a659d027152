"""Per-epoch replay inputs of a drive or flight: the arrays the snapshot replay
(``araim.snapshot.replay``) takes, over epochs T and sources L (GPS satellites, then the
terrestrial transmitters), in WGS-84 ECEF.

``from_recording`` reads them from a recording (``readers.recording``: a real drive or a
synthesized one); ``oaraim.sim.scenario_geometry`` builds the noise-free ones of a simulated
drive or flight, so both go through the same replay path.
"""

from typing import NamedTuple

import numpy as np

from oaraim.geometry import frames
from oaraim.readers import (
    Recording,
    epochs,
    gnss_matrix,
    gpstime,
    pseudorange_matrix,
    tower_clock_m,
)


class EpochGeometry(NamedTuple):
    """Noise-free per-epoch geometry of one drive or flight; sources = GPS then towers."""

    t_s: np.ndarray  # (T,) seconds since the start
    t_gps_s: np.ndarray  # (T,) GPS seconds
    truth_m: np.ndarray  # (T, 3) ECEF receiver positions
    tx_pos_m: np.ndarray  # (T, L, 3) ECEF transmitter positions
    range_m: np.ndarray  # (T, L) geometric ranges (0 where not valid)
    valid: np.ndarray  # (T, L) GPS: usable and above the mask; towers: True
    el_rad: np.ndarray  # (T, L) elevation at the truth
    is_gps: np.ndarray  # (L,)
    ids: np.ndarray  # (L,) "G08", ..., tower ids "T1", ...
    group: np.ndarray  # (L,) clock group name: "GPS" or the tower's carrier
    tx_clock_m: np.ndarray  # (T, L) c dt_tx (towers; 0 for GPS)
    rx_clock_m: np.ndarray  # (T,)
    origin_ecef_m: np.ndarray  # (3,)
    sky_source: str
    real_ephemeris: bool


class Measured(NamedTuple):
    """Replay inputs of a recording: ``EpochGeometry`` (range_m = 0 and rx_clock_m = 0: not
    known from data) plus the measured pseudoranges and the corrections to add to them."""

    geom: EpochGeometry
    pseudorange_m: np.ndarray  # (T, L)
    correction_m: np.ndarray  # (T, L): GNSS + sat_clock_m - iono_m - tropo_m; towers + c dt_n


def from_recording(rec: Recording, mask_deg=15.0) -> Measured:
    """Per-epoch replay inputs from a recording with ``gnss`` and/or ``pseudoranges`` tables and
    a ``truth`` table (interpolated linearly to the epochs). GNSS sources below ``mask_deg``
    (``el_deg`` if given, else computed at the truth) are not valid. GNSS rows form the group
    "GPS" (any system letter: one group per system would need a P_const each; only GPS is
    supported here, other systems are dropped with their rows)."""
    if rec.truth is None:
        raise ValueError("the recording has no truth table: the snapshot studies compare the "
                         "solution with the truth (HPE)")
    t = epochs(rec)
    truth_t = rec.truth["t_s"].to_numpy(np.float64)
    truth = np.stack([np.interp(t, truth_t, rec.truth[c].to_numpy(np.float64))
                      for c in ("x_m", "y_m", "z_m")], -1)
    parts = []  # (ids, group, pr, valid, tx, corr, el, is_gps)
    if rec.gnss is not None:
        sv_all = sorted(rec.gnss["sv_id"].astype(str).unique())
        sv = [s for s in sv_all if s.startswith("G")]
        pr = gnss_matrix(rec, sv, t_s=t)
        pos = gnss_matrix(rec, sv, ["sat_x_m", "sat_y_m", "sat_z_m"], t_s=t).values
        corr = gnss_matrix(rec, sv, "sat_clock_m", t_s=t).values
        for col in ("iono_m", "tropo_m"):
            if col in rec.gnss.columns:
                corr = corr - np.nan_to_num(gnss_matrix(rec, sv, col, t_s=t).values)
        d = pos - truth[:, None]
        o = frames.ecef_to_geodetic(truth)
        r = np.asarray(frames.enu_rotation(o[0], o[1]))  # (T, 3, 3)
        up = np.einsum("tj,tlj->tl", r[:, 2], d)
        el = np.arcsin(np.clip(up / np.maximum(np.linalg.norm(d, axis=-1), 1.0), -1, 1))
        if "el_deg" in rec.gnss.columns:
            el = np.where(pr.valid, np.deg2rad(gnss_matrix(rec, sv, "el_deg", t_s=t).values), el)
        v = pr.valid & (el >= np.deg2rad(mask_deg))
        parts.append((np.asarray(sv, object), np.asarray(["GPS"] * len(sv), object), pr.values,
                      v, pos, corr, el, np.ones(len(sv), bool)))
    if rec.pseudoranges is not None:
        ids = rec.transmitters["tx_id"].astype(str).tolist()
        pr = pseudorange_matrix(rec, ids, t_s=t)
        pos = rec.transmitters[["x_m", "y_m", "z_m"]].to_numpy(np.float64)
        pos = np.broadcast_to(pos, (t.size,) + pos.shape)
        d = pos - truth[:, None]
        o = frames.ecef_to_geodetic(truth)
        r = np.asarray(frames.enu_rotation(o[0], o[1]))
        el = np.arcsin(np.clip(np.einsum("tj,tlj->tl", r[:, 2], d)
                               / np.maximum(np.linalg.norm(d, axis=-1), 1.0), -1, 1))
        parts.append((np.asarray(ids, object),
                      rec.transmitters["group"].astype(str).to_numpy(object), pr.values,
                      pr.valid, pos, tower_clock_m(rec, t, ids), el, np.zeros(len(ids), bool)))
    cat = lambda k, ax: np.concatenate([p[k] for p in parts], ax)  # noqa: E731
    o = rec.meta["origin"]
    origin = np.asarray(frames.geodetic_to_ecef(np.deg2rad(o["lat_deg"]),
                                                np.deg2rad(o["lon_deg"]), o["h_m"]))
    t0 = 0.0
    if "t0_gps_week" in rec.meta:
        t0 = rec.meta["t0_gps_week"] * gpstime.SECONDS_PER_WEEK + rec.meta["t0_gps_tow_s"]
    valid = cat(3, 1)
    geom = EpochGeometry(
        t_s=t, t_gps_s=t0 + t, truth_m=truth, tx_pos_m=np.where(valid[..., None], cat(4, 1), 0.0),
        range_m=np.zeros(valid.shape), valid=valid, el_rad=cat(6, 1), is_gps=cat(7, 0),
        ids=cat(0, 0), group=cat(1, 0), tx_clock_m=np.zeros(valid.shape),
        rx_clock_m=np.zeros(t.size), origin_ecef_m=origin,
        sky_source=f"recording {rec.meta.get('name', '')}".strip(),
        real_ephemeris=rec.meta.get("source", {}).get("kind") == "real")
    return Measured(geom, np.where(valid, cat(2, 1), 0.0), np.where(valid, cat(5, 1), 0.0))
