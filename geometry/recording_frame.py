"""A recording in its local frame: the ENU frame of meta.json's origin
(``readers.recording``: the format, the loader and the writer, which keep WGS-84 ECEF)."""

from typing import NamedTuple

import numpy as np

from oaraim.geometry import frames
from oaraim.readers import Recording, transmitters_ecef_m


def origin_ecef_m(recording: Recording) -> np.ndarray:
    """ECEF (3,) of the ENU origin in meta.json."""
    o = recording.meta["origin"]
    return np.asarray(frames.geodetic_to_ecef(np.deg2rad(o["lat_deg"]), np.deg2rad(o["lon_deg"]),
                                              o["h_m"]))


def to_enu_m(recording: Recording, ecef_m) -> np.ndarray:
    """ENU (..., 3) of ECEF points ``(..., 3)`` in the recording's local frame."""
    return np.asarray(frames.ecef_to_enu(np.asarray(ecef_m, np.float64),
                                         origin_ecef_m(recording)))


def transmitters_enu_m(recording: Recording, tx_ids=None) -> np.ndarray:
    """ENU positions (L, 3) of the transmitters, in ``tx_ids`` (default: table) order."""
    return to_enu_m(recording, transmitters_ecef_m(recording, tx_ids))


class TruthENU(NamedTuple):
    """The truth table in the local ENU frame of meta.json's origin."""

    t_s: np.ndarray  # (T,)
    position_enu_m: np.ndarray  # (T, 3)
    velocity_enu_mps: np.ndarray | None  # (T, 3) or None when the truth has no velocity
    quaternion: np.ndarray | None  # (T, 4) JPL ^B_G q [qx, qy, qz, qw] (G = the ENU frame)


def truth_enu(recording: Recording) -> TruthENU:
    """Ground truth in the local ENU frame of meta.json (velocity rotated, not translated)."""
    tr = recording.truth
    if tr is None:
        raise ValueError("the recording has no truth table")
    pos = to_enu_m(recording, tr[["x_m", "y_m", "z_m"]].to_numpy(np.float64))
    vel = None
    if "vx_mps" in tr:
        o = recording.meta["origin"]
        r = np.asarray(frames.enu_rotation(np.deg2rad(o["lat_deg"]), np.deg2rad(o["lon_deg"])))
        vel = tr[["vx_mps", "vy_mps", "vz_mps"]].to_numpy(np.float64) @ r.T
    q = tr[["qx", "qy", "qz", "qw"]].to_numpy(np.float64) if "qw" in tr else None
    return TruthENU(tr["t_s"].to_numpy(np.float64), pos, vel, q)
