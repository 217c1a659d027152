"""Built-in nominal constellations: the default sky when no navigation file is given.

GPS: the 24-slot reference constellation of the GPS Standard Positioning Service Performance
Standard (GPS SPS PS, 4th edition, September 2008, section 3.2.1, Tables 3.2-1 and 3.2-2): epoch
0000Z 1 July 1993, Greenwich hour angle 18h 36m 14.4s, semi-major axis 26,559.7 km, e = 0,
i = 55 deg, six planes A-F and the slot RAANs and arguments of latitude below. The SPS PS
defines the constellation at its epoch; we propagate it as two-body circular orbits with
WGS-84/IS-GPS-200 constants and no nodal regression (the real constellation is maintained
against J2 drift), so at a date far from 1993 it is *a representative* 24-slot sky with the
right relative geometry, not the real one. PRNs 1-24 are assigned to slots A1, A2, ..., F4 in
order (a labelling choice; the SPS PS slots carry no PRNs).

Galileo: a Walker 24/3/1 constellation (Galileo OS Service Definition Document, Issue 1.1,
2019, section 2.1: 24 nominal slots in 3 planes, semi-major axis 29,599.8 km, i = 56 deg): 8
slots per plane 45 deg apart, planes 120 deg apart, adjacent planes phased by
f 360 / 24 = 15 deg. The epoch (00:00 GPS time, 22 August 1999: the GST/week-1024 origin) and
the node of plane A (longitude 0 deg at that epoch) are our choices; PRNs E01-E24 are the slots
A1..A8, B1..B8, C1..C8.

Both are returned as ``geometry.Almanac`` objects (one circular Keplerian record per
satellite), so they share the almanac propagation and ``sat_position_ecef`` signature.
"""

import functools

import numpy as np

from oaraim.constants import OMEGA_E_GNSS_RAD_S
from oaraim.geometry.almanac_orbits import Almanac
from oaraim.readers import GALILEO, GPS, AlmanacRecords, gpstime

#: SPS PS Table 3.2-2 reference epoch: 0000Z (UTC) 1 July 1993. GPS - UTC was 9 s after the leap
#: second of 30 June 1993 (IERS Bulletin C 5), hence + 9 s to express it in GPS time.
GPS_SPS_EPOCH_T_GPS_S = float(gpstime.gps_seconds(1993, 7, 1)) + 9.0
#: Greenwich hour angle at that epoch: 18h 36m 14.4s = 279.06 deg (SPS PS 2008, Table 3.2-2)
GPS_SPS_GHA_DEG = (18.0 + 36.0 / 60.0 + 14.4 / 3600.0) * 15.0
#: semi-major axis, eccentricity, inclination (SPS PS 2008, Table 3.2-1)
GPS_SPS_A_M = 26_559_700.0
GPS_SPS_I_DEG = 55.0
#: RAAN of planes A-F at the epoch, deg (SPS PS 2008, Table 3.2-2)
GPS_SPS_RAAN_DEG = {"A": 272.847, "B": 332.847, "C": 32.847, "D": 92.847, "E": 152.847,
                    "F": 212.847}
#: argument of latitude of slots 1-4 of each plane at the epoch, deg (SPS PS 2008, Table 3.2-2)
GPS_SPS_ARG_LAT_DEG = {
    "A": (268.126, 161.786, 11.676, 41.806),
    "B": (80.956, 173.336, 309.976, 204.376),
    "C": (111.876, 11.796, 339.666, 241.556),
    "D": (135.226, 265.446, 35.156, 167.356),
    "E": (197.046, 302.596, 66.066, 333.686),
    "F": (238.886, 345.226, 105.206, 135.346),
}

#: Galileo Walker 24/3/1 (Galileo OS SDD Issue 1.1, section 2.1)
GAL_A_M = 29_599_800.0
GAL_I_DEG = 56.0
GAL_PLANES, GAL_PER_PLANE, GAL_PHASING = 3, 8, 1
#: our epoch for it: 1999-08-22 00:00:00 GPS time (GPS week 1024, the Galileo System Time
#: origin), plane A's node at Greenwich longitude 0 at that epoch
GAL_EPOCH_T_GPS_S = float(gpstime.gps_seconds(1999, 8, 22))
GAL_NODE_A_LON_DEG = 0.0


def _circular(prn, raan_at_epoch_deg, arg_lat_deg, gha_deg, epoch_t_gps_s, a_m, i_deg):
    """Almanac records of circular orbits given inertial RAAN and argument of latitude at an
    epoch whose Greenwich hour angle is ``gha_deg``.

    The almanac's Omega_0 is the node longitude at the start of the week of t_oa, so with
    t_oa = epoch: node longitude at the epoch = Omega_0 - Omega_e t_oa_tow = RAAN - GHA.
    """
    n = len(prn)
    week, tow = gpstime.week_tow(epoch_t_gps_s)
    omega0 = np.deg2rad(np.asarray(raan_at_epoch_deg) - gha_deg) + OMEGA_E_GNSS_RAD_S * tow
    omega0 = np.mod(omega0 + np.pi, 2 * np.pi) - np.pi
    full = lambda v: np.full(n, v, np.float64)  # noqa: E731
    return AlmanacRecords(
        prn=np.asarray(prn, np.int32), health=np.zeros(n, np.int64), e=full(0.0),
        toa_s=full(epoch_t_gps_s), toa_tow_s=full(tow), i_rad=full(np.deg2rad(i_deg)),
        omegadot_rad_s=full(0.0), sqrt_a=full(np.sqrt(a_m)), omega0_rad=omega0,
        omega_rad=full(0.0), m0_rad=np.deg2rad(np.asarray(arg_lat_deg, np.float64)),
        af0_s=full(0.0), af1_s_s=full(0.0))


@functools.cache
def gps_24_slot() -> Almanac:
    """The GPS SPS PS 24-slot reference constellation (PRNs 1-24 = slots A1..F4)."""
    raan, u = [], []
    for plane in "ABCDEF":
        for slot_u in GPS_SPS_ARG_LAT_DEG[plane]:
            raan.append(GPS_SPS_RAAN_DEG[plane])
            u.append(slot_u)
    rec = _circular(np.arange(1, 25), raan, u, GPS_SPS_GHA_DEG, GPS_SPS_EPOCH_T_GPS_S,
                    GPS_SPS_A_M, GPS_SPS_I_DEG)
    return Almanac(rec, GPS, "nominal GPS 24-slot (SPS PS 2008)")


@functools.cache
def galileo_walker() -> Almanac:
    """Galileo Walker 24/3/1 (PRNs E01-E24 = slots A1..A8, B1..B8, C1..C8)."""
    total = GAL_PLANES * GAL_PER_PLANE
    raan, u = [], []
    for p in range(GAL_PLANES):
        for s in range(GAL_PER_PLANE):
            raan.append(GAL_NODE_A_LON_DEG + 360.0 * p / GAL_PLANES)
            u.append(360.0 * s / GAL_PER_PLANE + GAL_PHASING * 360.0 * p / total)
    # GHA 0: the RAANs above are node longitudes at the epoch
    rec = _circular(np.arange(1, total + 1), raan, u, 0.0, GAL_EPOCH_T_GPS_S, GAL_A_M, GAL_I_DEG)
    return Almanac(rec, GALILEO, "nominal Galileo Walker 24/3/1")
