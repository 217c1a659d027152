"""Availability and coverage of ARAIM service levels (the criteria MAAST and the ADD apply).

An epoch at a user location is *available* when the protection levels and the accuracy meet
every requirement of the service level: VPL <= VAL, HPL <= HAL, EMT <= EMT threshold and the
vertical accuracy sigma_acc <= its threshold (the ADD's fault-free accuracy requirement:
MAAST tests sigma_acc <= 1.87 m, which covers both the 95 % (4 m / 1.96 = 2.04 m) and the
1e-7 (10 m / 5.33 = 1.876 m) rules). A PL that could not be computed (``inf``, any non-OK
status) is unavailable.

*Availability* of a location is the share of its epochs that are available; *coverage* of a
region is the share of its area (grid points weighted by cos(latitude), the area of a
latitude-longitude cell) whose availability is at least a target (99.5 % for LPV-200 in the
ADD and MAAST).

Service levels (``SERVICE_LEVELS``), each with its availability target:

- ``lpv200`` (default of the maps): MAAST for ARAIM's LPV-200 settings (``main_maast_araim.m``,
  2018 release and ``stanford-gps-lab/maast_for_araim_2``): ``vhal = [35, 40, 15, 1.87]`` (VAL,
  HAL, EMT, sigma_acc, metres), ``percent = 0.995`` and its allocation
  ``BUDGET_LPV200_MAAST``.
- ``lpv200-add``: the same criteria with the ADD's allocation table (``BUDGET_LPV200``).
- ``h-araim``: horizontal ARAIM, HAL 185 m (RNP 0.1 in MAAST's plots) at 99.9 % availability
  (MAAST 2024's H-ARAIM target), with seed 004 Table I's budget (MAAST's H-ARAIM allocation of
  its 2018 release but P_FA_HOR 9.9e-8 for 1e-7, DESIGN.md); no vertical, EMT or accuracy
  criterion. MAAST tests hpl < HAL there; we apply <= throughout (equal only on a tie).
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from oaraim.araim.budget import (
    BUDGET_LPV200,
    BUDGET_LPV200_MAAST,
    BUDGET_SEED004_TABLE_I,
    IntegrityBudget,
)
from oaraim.araim.status import Status


class Requirements(NamedTuple):
    """Alert limits and thresholds of a service level, metres; ``inf`` means not applied."""

    val_m: float
    """Vertical alert limit VAL: VPL <= VAL."""
    hal_m: float
    """Horizontal alert limit HAL: HPL <= HAL."""
    emt_m: float
    """Effect-of-monitor-threshold limit: EMT <= it."""
    sigma_acc_v_m: float
    """Vertical fault-free accuracy limit: sigma_acc <= it (1.87 m for LPV-200)."""


class ServiceLevel(NamedTuple):
    """One entry of ``SERVICE_LEVELS``: what an epoch must meet to be available and what
    share of epochs a location needs to count as covered."""

    name: str
    """Display name, e.g. ``"LPV-200"``."""
    requirements: Requirements
    """The alert limits and thresholds an available epoch meets."""
    budget: IntegrityBudget
    """The integrity and continuity allocation the protection levels are computed with."""
    target: float
    """Availability a location needs to count as covered, in [0, 1] (0.995 for LPV-200)."""
    source: str
    """Where the criteria and the allocation come from (MAAST, the ADD, seed 004)."""


_LPV200 = Requirements(val_m=35.0, hal_m=40.0, emt_m=15.0, sigma_acc_v_m=1.87)

SERVICE_LEVELS = {
    "lpv200": ServiceLevel("LPV-200", _LPV200, BUDGET_LPV200_MAAST, 0.995,
                           "MAAST for ARAIM, main_maast_araim.m (vhal, percent, allocation)"),
    "lpv200-add": ServiceLevel("LPV-200 (ADD allocation)", _LPV200, BUDGET_LPV200, 0.995,
                               "criteria of MAAST, allocation of the ADD table"),
    "h-araim": ServiceLevel(
        "H-ARAIM", Requirements(val_m=np.inf, hal_m=185.0, emt_m=np.inf, sigma_acc_v_m=np.inf),
        BUDGET_SEED004_TABLE_I, 0.999, "MAAST's H-ARAIM preset (RNP 0.1 HAL, 99.9 %)"),
}


def available(hpl_m, vpl_m, emt_m, sigma_acc_v_m, status, requirements: Requirements):
    """Per epoch: every criterion of ``requirements`` met and the PLs computed (status OK)."""
    r = requirements
    return ((jnp.asarray(status) == Status.OK) & (jnp.asarray(vpl_m) <= r.val_m)
            & (jnp.asarray(hpl_m) <= r.hal_m) & (jnp.asarray(emt_m) <= r.emt_m)
            & (jnp.asarray(sigma_acc_v_m) <= r.sigma_acc_v_m))


def availability(available_epochs, axis=-1):
    """Share of available epochs along ``axis`` (NumPy, in [0, 1])."""
    return np.mean(np.asarray(available_epochs, bool), axis=axis)


def pl_percentile(pl_m, q=99.5, axis=-1):
    """The ``q``-th percentile of a PL over epochs, ``inf`` when more than (100 - q) % of the
    epochs are unavailable (infinite). Nearest-rank definition: the smallest value that at
    least q % of the epochs do not exceed (no interpolation, so it is one of the PLs)."""
    x = np.sort(np.asarray(pl_m, np.float64), axis=axis)
    n = x.shape[axis]
    k = max(int(np.ceil(q / 100.0 * n)) - 1, 0)
    return np.take(x, k, axis=axis)


def coverage(availability_share, lat_deg, target=0.995):
    """Area-weighted share of grid points with availability >= ``target``.

    ``availability_share`` is ``(lat, lon)``; each point weighs cos(latitude) (the area of its
    cell on a regular grid). A grid of the poles alone (all weights 0) raises ValueError.
    """
    a = np.asarray(availability_share, np.float64)
    w = np.cos(np.deg2rad(np.asarray(lat_deg, np.float64)))[:, None] * np.ones_like(a)
    w = np.where(np.abs(w) < 1e-12, 0.0, w)  # cos(90 deg) is 6e-17, not 0
    if w.sum() <= 0:
        raise ValueError("coverage needs at least one grid latitude away from the poles")
    return float(np.sum(w * (a >= target)) / np.sum(w))
