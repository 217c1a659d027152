"""Low-Earth-orbit constellations as ranging sources: Walker shells and two-line element sets.

Two kinds of orbits, one signature (``sat_position_ecef(t_gps_s) -> (ecef (T, S, 3) m,
usable (T, S), names (S,))``, that of ``Almanac`` and ``Ephemeris``), so that a LEO
constellation composes with the GNSS skies (``leo_sky``, ``combine_skies``):

- ``WalkerShell``: a nominal Walker shell i: T/P/F (altitude, inclination, P planes of S
  satellites, phasing F; nodes spread over 360 deg for a delta pattern, 180 deg for a star
  pattern such as Iridium's and OneWeb's near-polar shells). Circular orbits of radius
  a = WGS-84 a + altitude, propagated in JAX (batched over epochs and satellites) with the
  secular J2 rates of the node, the argument of perigee and the mean anomaly (first order,
  e = 0: the rates SGP4 applies at first order) and nothing else: no short-period J2 terms,
  no drag, no station-keeping. Checked against SGP4 (``tests/test_leo_sky.py``): the TLEs of
  the same mean elements, propagated with ``sgp4``, lie within ``SGP4_AGREEMENT_M`` over a day.
  ``j2=False`` gives the pure two-body circle (the nodes then drift against SGP4's by the
  nodal regression, ~5 deg/day at 550 km: within the same bound for half an hour).
- ``TleConstellation``: the satellites of a TLE file (two- or three-line format, as
  CelesTrak serves them) through the ``sgp4`` package (Vallado's SGP4, WGS-72 as the TLEs
  are fitted to), TEME rotated to ECEF by the Greenwich mean sidereal time (IAU 1982, ``sgp4``'s
  own); polar motion is left out (~10 m at LEO radius). TLE epochs are UTC, converted with the
  GPS - UTC leap-second table of ``oaraim.constants``. A satellite whose propagation fails
  (decayed, SGP4 error code) is unusable at that epoch.

Named shells (``LEO_PRESETS``) cite their filings; where a filing leaves a number open (the
Walker phasing F, the node of plane 0) the choice is ours and stated.
"""

from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from jaxtyping import Int, Real

from oaraim.constants import (
    GPS_UTC_LEAP_SECONDS,
    OMEGA_E_GNSS_RAD_S,
    WGS84_A_M,
    WGS84_GM_M3_S2,
    WGS84_J2,
)
from oaraim.geometry.almanac_orbits import Almanac
from oaraim.geometry.broadcast_orbits import Ephemeris
from oaraim.geometry.sky import Sky, look_angles
from oaraim.readers import gpstime

#: the largest 3-D distance (m) between a Walker shell propagated here (secular J2) and
#: SGP4 on the TLEs of the same mean elements (SGP4's Brouwer mean motion equal to ours) over
#: a day (``tests/test_leo_sky.py``). What remains is what a mean circular orbit leaves out:
#: SGP4's short-period J2 terms (radius ~ J2 R^2 / a, a few km), its J3 long-period
#: eccentricity (e ~ J3 / (2 J2) (R / a) sin i ~ 8e-4, ~6 km of excursion) and its
#: second-order secular node rate (J2^2, J4: 3e-3 of the node rate, ~1 km a day). Measured
#: at 300 s over 24 h: 12.9 km (Starlink shell 1), 17.6 km (OneWeb), 18.0 km (Iridium),
#: 11.8 km (ORBCOMM), 12.4 km (Globalstar); 8-16 km of it already at the epoch. Overhead at
#: 550 km, 20 km is 2 deg of direction; a nominal shell is a representative sky, not a
#: prediction of where a satellite is. Without J2 (``j2=False``) the same bound holds for
#: for half an hour (Globalstar: 15.3 km at 30 min, 20.7 km at 1 h).
SGP4_AGREEMENT_M = 20_000.0

#: GPS seconds of the Julian date 2444244.5 (1980-01-06 00:00 UTC, the GPS origin)
_JD_GPS_ORIGIN = 2444244.5


class WalkerShell(NamedTuple):
    """One Walker shell i: T/P/F of circular orbits (a static configuration)."""

    name: str
    """Short name (``'starlink'``); the satellites are named ``NAME-PP-SS``."""
    altitude_m: float
    """Altitude above the WGS-84 equatorial radius, metres (a = 6,378,137 m + altitude)."""
    inclination_deg: float
    """Inclination, degrees."""
    planes: int
    """Number of orbital planes P."""
    per_plane: int
    """Satellites per plane (T = P x per_plane)."""
    phasing: int = 1
    """Walker phasing F in 0..P-1: plane p's satellites lead plane p-1's by F 360 / T deg."""
    raan_spread_deg: float = 360.0
    """Span of the planes' nodes: 360 (delta pattern) or 180 (star pattern)."""
    node0_lon_deg: float = 0.0
    """Longitude of plane 0's ascending node at the shell's epoch (our choice)."""
    source: str = ""
    """Where the numbers come from."""

    @property
    def total(self) -> int:
        """T, the number of satellites."""
        return self.planes * self.per_plane

    @property
    def a_m(self) -> float:
        """Semi-major axis, metres."""
        return WGS84_A_M + self.altitude_m


#: Named shells. Altitude, inclination, planes and satellites per plane from the operators'
#: filings; the Walker phasing F and the node of plane 0 are ours (no filing we found gives
#: them), F = 1 throughout.
LEO_PRESETS = {
    "starlink": WalkerShell(
        "starlink", 550e3, 53.0, 72, 22, 1, 360.0, 0.0,
        "SpaceX Starlink first shell: 1,584 satellites at 550 km, 53.0 deg (FCC file "
        "SAT-MOD-20181108-00083, granted FCC 19-30, April 2019), 72 planes of 22 (FCC 21-48, "
        "April 2021, the modification order's table of the 550 km shell)"),
    "oneweb": WalkerShell(
        "oneweb", 1200e3, 87.9, 12, 49, 1, 180.0, 0.0,
        "OneWeb phase 1 polar shell: 588 satellites, 12 planes of 49 at 1,200 km, 87.9 deg "
        "(OneWeb FCC file SAT-MOD-20200526-00067, Attachment A/B: the 716-satellite "
        "configuration, 87.9 deg planes; 12 x 49 as launched); star pattern (nodes over "
        "~180 deg, planes ~15.2 deg apart)"),
    "iridium": WalkerShell(
        "iridium", 780e3, 86.4, 6, 11, 1, 180.0, 0.0,
        "Iridium NEXT: 66 satellites, 6 planes of 11 at 780 km, 86.4 deg (Iridium FCC "
        "licence S2110, the NEXT replacement modification; planes ~30 deg apart: star "
        "pattern)"),
    "orbcomm": WalkerShell(
        "orbcomm", 750e3, 48.5, 3, 6, 1, 360.0, 0.0,
        "ORBCOMM Generation 2: 18 satellites in 3 planes of 6, 750 km circular, 48.5 deg "
        "(FCC DA 08-633, file SAT-MOD-20070531-00076, March 2008)"),
    "globalstar": WalkerShell(
        "globalstar", 1414e3, 52.0, 8, 6, 1, 360.0, 0.0,
        "Globalstar: 48 satellites in 8 planes of 6 at 1,414 km, 52 deg (the first-generation "
        "licence, FCC 1995; the second generation keeps the orbits)"),
}


def walker_elements(shell: WalkerShell):
    """(node longitude at the epoch (S,), argument of latitude at the epoch (S,)), radians,
    plane-major order: plane p's node at node0 + spread p / P, satellite s of plane p at
    360 s / per_plane + F 360 p / T."""
    p = np.repeat(np.arange(shell.planes), shell.per_plane)
    s = np.tile(np.arange(shell.per_plane), shell.planes)
    node = np.deg2rad(shell.node0_lon_deg + shell.raan_spread_deg * p / shell.planes)
    u = np.deg2rad(360.0 * s / shell.per_plane + shell.phasing * 360.0 * p / shell.total)
    return node, u


def secular_rates(a_m, inclination_rad, j2=True):
    """(node rate, argument-of-latitude rate), rad/s, of a circular orbit: the two-body mean
    motion n = sqrt(GM / a^3) and, with ``j2``, the first-order secular J2 rates (e = 0)
    dOmega/dt = -3/2 n J2 (R/a)^2 cos i, du/dt = n (1 + 3/4 J2 (R/a)^2 (3 cos^2 i - 1))
    + 3/4 n J2 (R/a)^2 (5 cos^2 i - 1) (mean anomaly plus argument of perigee; Vallado,
    Fundamentals of Astrodynamics, 4th ed., eqs. 9-41)."""
    n = np.sqrt(WGS84_GM_M3_S2 / a_m**3)
    if not j2:
        return 0.0, n
    k = WGS84_J2 * (WGS84_A_M / a_m) ** 2
    c2 = np.cos(inclination_rad) ** 2
    node_dot = -1.5 * n * k * np.cos(inclination_rad)
    u_dot = n * (1.0 + 0.75 * k * (3.0 * c2 - 1.0)) + 0.75 * n * k * (5.0 * c2 - 1.0)
    return node_dot, u_dot


@jax.jit
def circular_ecef(dt_s, node0_rad, u0_rad, a_m, inclination_rad, node_dot, u_dot):
    """ECEF positions (T, S, 3), metres, of circular orbits at times ``dt_s`` (T,) after the
    epoch: node longitude node0 + (dOmega/dt - omega_E) dt, argument of latitude
    u0 + du/dt dt."""
    dt = jnp.asarray(dt_s)[:, None]
    lon = node0_rad[None] + (node_dot - OMEGA_E_GNSS_RAD_S) * dt
    u = u0_rad[None] + u_dot * dt
    cu, su = jnp.cos(u), jnp.sin(u)
    cl, sl = jnp.cos(lon), jnp.sin(lon)
    ci, si = jnp.cos(inclination_rad), jnp.sin(inclination_rad)
    x = a_m * (cl * cu - sl * su * ci)
    y = a_m * (sl * cu + cl * su * ci)
    z = a_m * (su * si) * jnp.ones_like(cl)
    return jnp.stack([x, y, z], -1)


class WalkerConstellation:
    """A ``WalkerShell`` placed at an epoch (GPS seconds): the orbits object of the shell."""

    def __init__(self, shell: WalkerShell, epoch_t_gps_s: float, j2: bool = True):
        self.shell = shell
        self.epoch_t_gps_s = float(epoch_t_gps_s)
        self.j2 = bool(j2)
        self.name = shell.name
        self.names = np.array([f"{shell.name}-{p:02d}-{s:02d}" for p in range(shell.planes)
                               for s in range(shell.per_plane)])

    def __repr__(self):
        s = self.shell
        return (f"WalkerConstellation({s.name}: {s.inclination_deg:g} deg: {s.total}/{s.planes}/"
                f"{s.phasing} at {s.altitude_m / 1e3:g} km{', J2' if self.j2 else ''})")

    def sat_position_ecef(self, t_gps_s):
        """``(ecef (T, S, 3) m, usable (T, S) all True, names (S,))`` at GPS times (T,)."""
        t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
        node, u = walker_elements(self.shell)
        inc = np.deg2rad(self.shell.inclination_deg)
        node_dot, u_dot = secular_rates(self.shell.a_m, inc, self.j2)
        ecef = circular_ecef(jnp.asarray(t - self.epoch_t_gps_s), jnp.asarray(node),
                             jnp.asarray(u), self.shell.a_m, inc, node_dot, u_dot)
        return ecef, jnp.ones(ecef.shape[:2], bool), self.names


class TleFileError(ValueError):
    """A TLE file that cannot be read (names the file, the line and what was wrong)."""


def gps_minus_utc_s(t_gps_s):
    """GPS - UTC, seconds, at GPS times (leap seconds of ``GPS_UTC_LEAP_SECONDS``)."""
    t = np.asarray(t_gps_s, np.float64)
    out = np.zeros(t.shape)
    for when, count in GPS_UTC_LEAP_SECONDS:
        out = np.where(t >= float(gpstime.gps_seconds(*when)) + count, count, out)
    return out


def julian_utc(t_gps_s):
    """(jd, fraction) UTC Julian dates of GPS times, as ``sgp4`` takes them."""
    t = np.asarray(t_gps_s, np.float64)
    days = (t - gps_minus_utc_s(t)) / 86400.0
    whole = np.floor(days)
    return _JD_GPS_ORIGIN + whole, days - whole


def read_tle(path):
    """The satellites of a TLE file: a list of (name, line1, line2). Three-line sets (a name
    line before each pair) and bare two-line sets are both read; blank lines are skipped."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise TleFileError(f"TLE file {str(path)!r} does not exist; give a path to a two- or "
                           "three-line element file (e.g. CelesTrak's gp.php?FORMAT=tle)")
    lines = [ln.rstrip() for ln in p.read_text(encoding="ascii", errors="replace").splitlines()]
    lines = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip()]
    out, k, name = [], 0, None
    while k < len(lines):
        no, ln = lines[k]
        if ln.startswith("1 ") and k + 1 < len(lines) and lines[k + 1][1].startswith("2 "):
            l2 = lines[k + 1][1]
            if ln[2:7] != l2[2:7]:
                raise TleFileError(f"{p.name} line {no}: lines 1 and 2 name different "
                                   f"satellites ({ln[2:7]!r}, {l2[2:7]!r})")
            out.append((name or ln[2:7].strip(), ln, l2))
            name, k = None, k + 2
        elif ln.startswith(("1 ", "2 ")):
            raise TleFileError(f"{p.name} line {no}: element line {ln[:1]} without its "
                               "partner; each satellite needs a line 1 followed by a line 2")
        else:
            name = ln.strip().removeprefix("0 ").strip()
            k += 1
    if not out:
        raise TleFileError(f"{p.name}: no two-line element set found (lines starting "
                           "'1 ' and '2 ')")
    return out


class TleConstellation:
    """The satellites of a TLE file, propagated with SGP4 (module docstring)."""

    def __init__(self, path, name=None):
        from sgp4.api import Satrec, SatrecArray

        self.path = Path(path)
        sets = read_tle(path)
        sats = []
        for nm, l1, l2 in sets:
            try:
                sats.append(Satrec.twoline2rv(l1, l2))
            except Exception as e:  # noqa: BLE001 (sgp4 raises several kinds)
                raise TleFileError(f"{self.path.name}: satellite {nm!r}: not a valid TLE "
                                   f"({e})") from None
        self._array = SatrecArray(sats)
        self.names = np.array([nm for nm, _, _ in sets])
        self.name = name or self.path.stem
        jd = np.array([s.jdsatepoch + s.jdsatepochF for s in sats])
        # epoch of the earliest set, GPS seconds (UTC + leap seconds)
        t_utc = (jd.min() - _JD_GPS_ORIGIN) * 86400.0
        self.epoch_t_gps_s = float(t_utc + gps_minus_utc_s(t_utc))

    def __repr__(self):
        return f"TleConstellation({self.name}: {self.names.size} satellites from {self.path.name})"

    def sat_position_ecef(self, t_gps_s):
        """``(ecef (T, S, 3) m, usable (T, S), names (S,))`` at GPS times (T,): SGP4 in TEME,
        rotated to ECEF by GMST; usable where SGP4 returned no error."""
        t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
        jd, fr = julian_utc(t)
        err, r_km, _ = self._array.sgp4(jd, fr)  # (S, T), (S, T, 3)
        theta = gmst_rad(jd, fr)  # (T,)
        c, s = np.cos(theta), np.sin(theta)
        x, y, z = (np.moveaxis(r_km[..., k], 0, 1) * 1e3 for k in range(3))  # (T, S)
        ecef = np.stack([c[:, None] * x + s[:, None] * y, -s[:, None] * x + c[:, None] * y, z],
                        -1)
        ok = (np.moveaxis(err, 0, 1) == 0) & np.all(np.isfinite(ecef), -1)
        return jnp.asarray(np.where(ok[..., None], ecef, 0.0)), jnp.asarray(ok), self.names


def gmst_rad(jd, fr):
    """Greenwich mean sidereal time (IAU 1982, as SGP4's TEME frame defines it), radians,
    of UTC Julian dates jd + fr, taking UT1 = UTC (|UT1 - UTC| < 0.9 s: at most 0.9 s of
    Earth rotation, ~0.4 km at the equator, ~0.5 km at LEO radius)."""
    from sgp4.propagation import gstime

    return np.array([gstime(a + b) for a, b in zip(np.ravel(jd), np.ravel(fr), strict=True)])


def _brouwer_mean_motion(sat):
    """SGP4's Brouwer mean motion (rad/min) of a ``Satrec``'s Kozai mean motion (the un-Kozai
    step of SGP4's initialisation, Hoots and Roehrich, Spacetrack Report No. 3, 1980)."""
    c2 = np.cos(sat.inclo) ** 2
    e2 = 1.0 - sat.ecco**2
    ak = (sat.xke / sat.no_kozai) ** (2.0 / 3.0)
    d1 = 0.75 * sat.j2 * (3.0 * c2 - 1.0) / (np.sqrt(e2) * e2)
    de = d1 / ak**2
    adel = ak * (1.0 - de * de - de * (1.0 / 3.0 + 134.0 * de * de / 81.0))
    return sat.no_kozai / (1.0 + d1 / adel**2)


#: what ``leo_sky`` takes as its constellation: ``leo_constellation``'s argument (a preset name,
#: a ``WalkerShell``, a TLE file path) or an orbits object with ``sat_position_ecef``
_LeoSource = (str | Path | WalkerShell | WalkerConstellation | TleConstellation | Almanac
              | Ephemeris)


def walker_tle_text(shell: WalkerShell, epoch_t_gps_s: float, every: int = 1
                    ) -> tuple[str, Int[np.ndarray, " S"]]:
    """(text of a three-line TLE file, satellite indices (S',)): every ``every``-th satellite
    of ``shell`` as SGP4 mean elements at ``epoch_t_gps_s`` (GPS seconds) that reproduce our
    Walker orbit: e = 0, the inclination, the inertial node (node longitude + GMST), mean
    anomaly = argument of latitude, and the Kozai mean motion whose SGP4 Brouwer mean motion
    equals our two-body n (fixed point, six passes). SGP4 on this file and
    ``WalkerConstellation(shell, t)`` for any t give the same Earth-fixed skies at the same
    offsets from their epochs, within ``SGP4_AGREEMENT_M`` over a day."""
    from sgp4 import exporter
    from sgp4.api import WGS72, Satrec

    node, u = walker_elements(shell)
    inc = np.deg2rad(shell.inclination_deg)
    n = np.sqrt(WGS84_GM_M3_S2 / shell.a_m**3) * 60.0  # rad/min
    jd, fr = julian_utc(float(epoch_t_gps_s))
    theta = gmst_rad(jd, fr)[0]
    epoch = float(jd + fr - 2433281.5)  # SGP4's epoch: days from 1949-12-31 00:00 UT
    idx = np.arange(0, shell.total, int(every))
    lines = []
    for i in idx:
        n_kozai = n
        for _ in range(6):
            sat = Satrec()
            sat.sgp4init(WGS72, "i", int(i) + 1, epoch, 0.0, 0.0, 0.0, 0.0, 0.0, inc,
                         float(np.mod(u[i], 2 * np.pi)), n_kozai,
                         float(np.mod(node[i] + theta, 2 * np.pi)))
            n_kozai *= n / _brouwer_mean_motion(sat)
        l1, l2 = exporter.export_tle(sat)
        lines += [f"{shell.name.upper()} {i}", l1, l2]
    return "\n".join(lines) + "\n", idx


def leo_constellation(spec: str | Path | WalkerShell, epoch_t_gps_s: float | None = None,
                      j2: bool = True) -> WalkerConstellation | TleConstellation:
    """The orbits object of ``spec``: a preset name (``LEO_PRESETS``), a ``WalkerShell``, or
    a TLE file path. Walker shells are placed at ``epoch_t_gps_s`` (default: the GPS origin);
    a TLE file carries its own epochs."""
    if isinstance(spec, WalkerShell):
        return WalkerConstellation(spec, epoch_t_gps_s or 0.0, j2)
    if isinstance(spec, str) and spec in LEO_PRESETS:
        return WalkerConstellation(LEO_PRESETS[spec], epoch_t_gps_s or 0.0, j2)
    if isinstance(spec, str | Path) and Path(spec).expanduser().is_file():
        return TleConstellation(spec)
    raise ValueError(f"LEO constellation {str(spec)!r} unknown: use one of "
                     f"{', '.join(LEO_PRESETS)} or the path of a TLE file")


def leo_sky(receiver_ecef_m: Real[ArrayLike, "*rx 3"],
            t_gps_s: Real[ArrayLike, " T"] | Real[ArrayLike, ""], leo: _LeoSource,
            mask_deg: float = 10.0, code: int = 2) -> Sky:
    """The ``Sky`` of a LEO constellation (``leo_constellation``'s argument, or an orbits
    object) from receivers ``(..., 3)`` (ECEF m) at GPS times (T,): ``(..., T, S)`` look
    angles, valid above ``mask_deg``; every satellite carries constellation code ``code``
    (an SOP constellation label: GPS 0 and Galileo 1 come first)."""
    obj = leo if hasattr(leo, "sat_position_ecef") else leo_constellation(leo)
    t = np.atleast_1d(np.asarray(t_gps_s, np.float64))
    ecef, ok, names = obj.sat_position_ecef(t)
    az, el, rng, v = look_angles(np.asarray(receiver_ecef_m, np.float64), ecef, ok,
                                 np.deg2rad(float(mask_deg)))
    n = names.size
    return Sky(az, el, rng, v, np.arange(1, n + 1), np.full(n, code), names, t, repr(obj))


def combine_skies(*skies: Sky) -> Sky:
    """One ``Sky`` of several over the same receivers and epochs: satellites concatenated in
    order (e.g. ``geometry.sky(...)`` then ``leo_sky(...)``), each keeping its code."""
    if not skies:
        raise ValueError("combine_skies needs at least one Sky")
    t = skies[0].t_gps_s
    for s in skies[1:]:
        if s.t_gps_s.shape != t.shape or not np.array_equal(s.t_gps_s, t):
            raise ValueError("combine_skies: the skies must share their epochs (t_gps_s)")
    cat = lambda k: jnp.concatenate([getattr(s, k) for s in skies], -1)  # noqa: E731
    npcat = lambda k: np.concatenate([getattr(s, k) for s in skies])  # noqa: E731
    return Sky(cat("az_rad"), cat("el_rad"), cat("range_m"), cat("valid"), npcat("prn"),
               npcat("constellation"), npcat("sv"), t, "; ".join(s.source for s in skies))
