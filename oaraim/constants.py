"""Physical and geodetic constants, each defined once, with its source.

Every other module imports these; none writes a literal of its own.
"""

#: speed of light in vacuum, m/s (IS-GPS-200 20.3.4.3; exact by definition, SI)
C_M_S = 299792458.0

#: WGS-84 semi-major axis a, m (NIMA TR8350.2, 3rd ed. 2000, Table 3.1)
WGS84_A_M = 6378137.0
#: WGS-84 flattening f = 1 / 298.257223563 (NIMA TR8350.2 Table 3.1)
WGS84_F = 1.0 / 298.257223563
#: WGS-84 first eccentricity squared e^2 = f (2 - f) (NIMA TR8350.2 Table 3.3: 6.69437999014e-3)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
#: WGS-84 semi-minor axis b = a (1 - f), m (NIMA TR8350.2 Table 3.3: 6356752.3142 m)
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
#: WGS-84 second eccentricity squared e'^2 = e^2 / (1 - e^2) (NIMA TR8350.2 Table 3.3)
WGS84_EP2 = WGS84_E2 / (1.0 - WGS84_E2)
#: WGS-84 GM including the atmosphere, m^3/s^2 (NIMA TR8350.2 Table 3.1; Galileo OS SIS ICD
#: Issue 2.0 Table 59 uses the same value for the Galileo broadcast model)
WGS84_GM_M3_S2 = 3.986004418e14
#: WGS-84 angular velocity of the Earth, rad/s (NIMA TR8350.2 Table 3.1)
WGS84_OMEGA_E_RAD_S = 7.292115e-5

#: Earth rotation rate of the GPS and Galileo broadcast models, rad/s (IS-GPS-200 Table 20-IV;
#: Galileo OS SIS ICD Issue 2.0 Table 59): the value the ephemeris user algorithm must use
OMEGA_E_GNSS_RAD_S = 7.2921151467e-5
#: pi as IS-GPS-200 20.3.3.4.3 fixes it for the semicircle conversions of the broadcast data
GPS_PI = 3.1415926535898
#: GM of the GPS broadcast model, m^3/s^2 (IS-GPS-200 Table 20-IV)
MU_GPS_M3_S2 = 3.986005e14
#: GM of the Galileo broadcast model, m^3/s^2 (Galileo OS SIS ICD Issue 2.0 Table 59)
MU_GAL_M3_S2 = WGS84_GM_M3_S2

#: standard gravity g_0, m/s^2 (3rd CGPM 1901; BIPM SI brochure, exact): datasheet mg units and
#: the surface g of the RTCA MOPS troposphere model (DO-229 A.4.2.4)
STANDARD_GRAVITY_MPS2 = 9.80665

#: WGS-84 normal gravity at the equator, m/s^2 (NIMA TR8350.2 Table 3.4)
WGS84_GAMMA_E_MPS2 = 9.7803253359
#: WGS-84 normal gravity at the poles, m/s^2 (NIMA TR8350.2 Table 3.4)
WGS84_GAMMA_P_MPS2 = 9.8321849378
#: Somigliana constant k = (b gamma_p - a gamma_e) / (a gamma_e) (NIMA TR8350.2 eq. 4-1)
WGS84_SOMIGLIANA_K = 0.00193185265241
#: free-air gradient of WGS-84 normal gravity near the surface, 1/s^2: the first-order height
#: term of NIMA TR8350.2 eq. (4-3), 2 gamma_e (1 + f + m) / a, at the equator (the
#: latitude-dependent and second-order terms change it by < 0.3 % below 1 km)
FREE_AIR_GRADIENT_PER_S2 = 3.0877e-6

#: Global-average SISRE weights (w_R, w_AC^2) of the radial and the along/cross-track orbit errors,
#: SISRE = sqrt((w_R R - c dt)^2 + w_AC^2 (A^2 + C^2)): the user-averaged projection over the
#: visible Earth for each orbit altitude (Montenbruck, Steigenberger, Hauschild, "Broadcast
#: versus precise ephemerides: a multi-GNSS perspective", GPS Solutions 19 (2015) 321-333,
#: Table of SISRE weight factors): GPS (20,200 km) 0.98 and 1/49, Galileo (23,200 km) 0.98 and
#: 1/61, BeiDou MEO 0.98 and 1/54, BeiDou IGSO/GEO 0.99 and 1/126 (key 'C_IGSO')
SISRE_WEIGHTS = {"G": (0.98, 1.0 / 49.0), "E": (0.98, 1.0 / 61.0), "C": (0.98, 1.0 / 54.0),
                 "C_IGSO": (0.99, 1.0 / 126.0)}

#: Galileo carrier frequencies, Hz (Galileo OS SIS ICD Issue 2.0, Table 2: E1 1575.42 MHz, E5a
#: 1176.45 MHz, E5b 1207.14 MHz)
F_E1_HZ = 1575.42e6
F_E5A_HZ = 1176.45e6
F_E5B_HZ = 1207.14e6

#: BeiDou Time: GPS time minus BDT, s, and the GPS week of BDT week 0 (BDT starts 2006-01-01
#: 00:00:00 UTC, when GPS - UTC was 14 s: BDS-SIS-ICD-B1I Version 3.0 (2019), 4.1.2)
GPS_MINUS_BDT_S = 14.0
BDT_WEEK_OFFSET = 1356
#: CGCS2000 constants of the BeiDou broadcast orbit (BDS-SIS-ICD-B1I 3.0, 5.2.4.10): GM,
#: m^3/s^2, and the Earth rotation rate, rad/s
MU_BDS_M3_S2 = 3.986004418e14
OMEGA_E_BDS_RAD_S = 7.2921150e-5
#: BeiDou B1I and B3I carrier frequencies, Hz (BDS-SIS-ICD-B1I 3.0, 3.1: 1561.098 MHz;
#: BDS-SIS-ICD-B3I 1.0, 3.1: 1268.52 MHz)
F_B1I_HZ = 1561.098e6
F_B3I_HZ = 1268.52e6

#: WGS-84 second zonal harmonic J2 = -sqrt(5) C_20 with C_20 = -0.484166774985e-3 (NIMA
#: TR8350.2, 3rd ed. 2000, Table 5.1, EGM96): the secular node and perigee rates of LEO
#: Walker shells (``geometry.leo``)
WGS84_J2 = 1.08262998905e-3
#: GPS - UTC leap seconds: (UTC date the count starts, count), IERS Bulletin C (the 18th, of
#: 1 January 2017, is the latest here: add a row when a Bulletin C announces one). Used only to
#: read UTC epochs (two-line element sets)
GPS_UTC_LEAP_SECONDS = (
    ((1981, 7, 1), 1), ((1982, 7, 1), 2), ((1983, 7, 1), 3), ((1985, 7, 1), 4),
    ((1988, 1, 1), 5), ((1990, 1, 1), 6), ((1991, 1, 1), 7), ((1992, 7, 1), 8),
    ((1993, 7, 1), 9), ((1994, 7, 1), 10), ((1996, 1, 1), 11), ((1997, 7, 1), 12),
    ((1999, 1, 1), 13), ((2006, 1, 1), 14), ((2009, 1, 1), 15), ((2012, 7, 1), 16),
    ((2015, 7, 1), 17), ((2017, 1, 1), 18))
