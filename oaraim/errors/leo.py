"""The LEO SOP error model: each LEO constellation an SOP constellation.

Beside the GNSS model (``errors.gnss_variances``: ADD, dual-frequency airborne user) and
the terrestrial SOP model (``errors.sop_variances``: seed 004 App. A, no atmosphere), a
LEO downlink used for ranging is a satellite signal on one frequency whose operator is not a
GNSS provider:

    C_int(l, l) = sigma_URA^LEO^2 + sigma_iono^2 + sigma_tropo^2 + sigma_mp^2 + sigma_noise^2
    C_acc(l, l) = sigma_URE^LEO^2 + (the same elevation-dependent terms)

- sigma_URA^LEO, sigma_URE^LEO, b_nom, P_s^LEO, P_const^LEO: an ``araim.Ism`` (the ISM values
  of one constellation, the receiver's configuration), with the presets of ``araim.LEO_ISM``.
- Ionosphere (``LeoSignal``): one frequency, no ionosphere-free combination; the residual after
  a broadcast-model correction taken as GPS L1's Klobuchar residual (RTCA DO-229 J.2.3,
  tau_vert, default the mid-latitude 4.5 m) scaled to the carrier by (f_L1 / f)^2 (the
  first-order delay is 40.3 TEC / f^2) and mapped by the MOPS thin-shell obliquity (350 km).
  All the TEC is taken to lie below the satellite (``iono_share`` = 1: conservative; at 550 km
  the topside and plasmasphere above, ~20-40 % of the TEC, are not crossed).
- Troposphere: the MOPS residual (``errors.sigma_tropo_m``), the same atmosphere.
- Multipath: the ADD airborne curve (``errors.sigma_multipath_m``), a stand-in for the
  same antenna; code noise: a constant per signal (``sigma_noise_m``, our choice: no
  published code-noise model of these downlinks exists).
- Clocks (``araim.leo_labels``): one clock per constellation (a common time reference, the
  ``"constellation"`` option) or one per satellite (``"satellite"``: each satellite its own SOP
  constellation).
  With one clock per satellite a snapshot receiver learns nothing of its position from the
  LEO pseudoranges (each range only fixes its own clock, seed 004 Theorem 1) and every added
  satellite brings fault modes (Theorem 2 raises the PLs): the option is there to say so, and
  ``tests/test_leo_theorems.py`` checks it.
"""

from typing import NamedTuple, Protocol, runtime_checkable

import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Array, Float, Real

from oaraim.errors.atmosphere import iono_obliquity
from oaraim.errors.gnss import F_L1_HZ, sigma_multipath_m, sigma_tropo_m

#: DO-229 J.2.3 vertical Klobuchar residual at GPS L1, mid geomagnetic latitudes (m)
KLOBUCHAR_TAU_VERT_MID_M = 4.5

class LeoSignal(NamedTuple):
    """The ranging signal of a LEO constellation (a static configuration)."""

    carrier_hz: float
    """Downlink carrier used for ranging, Hz (sets the ionospheric delay, 1 / f^2)."""
    sigma_noise_m: float = 1.0
    """Code noise, metres (our choice; no published model)."""
    tau_vert_l1_m: float = KLOBUCHAR_TAU_VERT_MID_M
    """Vertical residual ionosphere at GPS L1 after the broadcast model (m)."""
    iono_share: float = 1.0
    """Share of the TEC below the satellite (1: all of it, conservative)."""


#: the signals of the named constellations: the downlink bands of their filings, at the band's
#: centre (Starlink and OneWeb user downlinks 10.7-12.7 GHz Ku; Iridium 1,616-1,626.5 MHz L;
#: ORBCOMM 137-138 MHz VHF; Globalstar 2,483.5-2,500 MHz S). At VHF the ionosphere is 130
#: times L1's: ORBCOMM pseudoranges are metre-useless without a dual-frequency or Doppler
#: method, which is why ORBCOMM SOP navigation is Doppler positioning.
LEO_SIGNALS = {
    "starlink": LeoSignal(11.7e9),
    "oneweb": LeoSignal(11.7e9),
    "iridium": LeoSignal(1.62125e9),
    "orbcomm": LeoSignal(137.5e6),
    "globalstar": LeoSignal(2.49175e9),
}

def sigma_iono_leo_m(el_rad, signal: LeoSignal):
    """Residual ionosphere of a single-frequency LEO downlink, metres: tau_vert (f_L1 / f)^2
    x share x obliquity (module docstring)."""
    scale = (F_L1_HZ / signal.carrier_hz) ** 2 * signal.iono_share
    return signal.tau_vert_l1_m * scale * iono_obliquity(el_rad)


def sigma_elevation_leo_m(el_rad, signal: LeoSignal):
    """The elevation-dependent part of a LEO range's error, metres: the root sum of squares
    of ionosphere, troposphere, multipath and code noise."""
    return jnp.sqrt(sigma_iono_leo_m(el_rad, signal) ** 2 + sigma_tropo_m(el_rad) ** 2
                    + sigma_multipath_m(el_rad) ** 2 + signal.sigma_noise_m ** 2)


@runtime_checkable
class _IsmSigmas(Protocol):
    """What ``leo_variances`` reads of an ISM: an ``araim.Ism`` (the receiver's configuration,
    a layer above the error models) or anything with its two sigmas (floats or traced)."""

    sigma_ura_m: float
    sigma_ure_m: float | None


def leo_variances(el_rad: Real[ArrayLike, "..."], ism: _IsmSigmas, signal: LeoSignal
                  ) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """(var_int_m2, var_acc_m2) of LEO sources at elevations ``el_rad`` (..., L), radians, for
    the ISM values ``ism`` (an ``araim.Ism``: ``sigma_ura_m``, ``sigma_ure_m``): sigma_URA^2
    (sigma_URE^2 for accuracy; None: equal to sigma_URA, as ``sop_variances``) plus
    ``sigma_elevation_leo_m``^2. The sigmas may be traced (differentiable)."""
    el_rad = jnp.asarray(el_rad, jnp.float64)
    ura = jnp.asarray(ism.sigma_ura_m, jnp.float64)
    ure = ura if ism.sigma_ure_m is None else jnp.asarray(ism.sigma_ure_m, jnp.float64)
    common = sigma_elevation_leo_m(el_rad, signal) ** 2
    return ura**2 + common, ure**2 + common
