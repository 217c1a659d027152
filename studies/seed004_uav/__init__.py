"""Seed 004 section VII: the UAV flight with GPS + up to 11 LTE towers, snapshot OARAIM per
epoch (Figs. 6-9).

Setup:
  * Flight: ``sim.uav_seed004()`` (815 m in 220 s, origin downtown Riverside, CA) with the
    study's 11 towers (``towers.py``: a table, each tower's SOP number, operator, carrier and
    position, and how they were placed); the seed gives 2880 epochs and 220 s but no rate: we
    take 2880 epochs spread uniformly over the flight (t_k = k 220 / 2880 s, 13.09 Hz). One
    realization = one epoch; ``--realizations N`` replays the first N of the ``n_epochs``.
  * GPS sky: broadcast ephemeris ``nav/brdc0010.22n`` (2022-01-01; the seed does not date the
    flight; ``oaraim.data``, fetched if missing) at ``start_h`` = 20.5 h GPS time (12:30 local:
    the first daylight half hour at which PRN 8, the faulty satellite of Fig. 7, stays above
    the 15 deg mask for the whole flight; 8 GPS in view), or the nominal 24-slot constellation
    on ``--set nav=nominal`` (provenance says which). Mask 15 deg (seed 004 VII-B).
  * SOP constellations by operator (seed 004 VII-A: 739 and 1955 MHz AT&T, 2125 MHz T-Mobile,
    2145 MHz Verizon; eq. 3: one network, one common clock term): the fault mode
    "constellation" of an SOP is its operator, with one receiver clock state per operator. SOPs
    are numbered operator by operator (AT&T 1-5, T-Mobile 6-8, Verizon 9-11) and added in that
    order (seed 004 VII-D: "the order of adding SOPs followed the numbering"): +1 = one AT&T
    tower, a new constellation with one SOP (Theorem 2); +2 .. +5 AT&T; +6 = the first
    T-Mobile tower (a new clock again); +11 = all.
  * Measurements: ``sim.gnss`` (module docstring) with the errors of the shared error world
    (``--set world=realistic``, the default; docs/error-world.md): GPS ``sim.gnss_errors``
    (``sim.GnssErrorModel()``: Gauss-Markov URE at 2/3 sigma_URA, uniform nominal bias within
    b_nom, troposphere residual, 2x the ADD airborne multipath, white noise), towers
    ``sim.sop_errors`` (``sim.ErrorModel()`` with thermal noise ``sigma_pr_m``: multipath,
    NLOS episodes at ``nlos_rate_per_s``, 0 by default: an aircraft above the roofs sees the
    towers in line of sight; each tower's epsilon_n and its operator's common clock term,
    seed 004 eq. 3; the clocks fitted over the whole 300 s GNSS period before take-off
    (``calib_window_s``), seed 000 II-D), drawn from the
    flight's key fold_in(key(seed), 0); ``world_errors``. The PL keeps its own model (GPS
    sigma_URA 1 m with the ADD terms, SOP sigma_URA^S = 3 m, the seed's semi-urban value of
    VII-D: not estimated from the data). ``--set world=clean`` is the study before the error
    world: GPS N(0, C_acc) (ADD accuracy model), LTE N(0, ``sigma_lte_noise_m``^2) with 2 m,
    epoch k from fold_in(key(seed), k) (``draw_noise``). Either way the whole flight is drawn
    and ``--realizations N`` keeps its first N epochs, so an epoch's result does not depend on
    N. ``--set recording=PATH``
    replays a recorded flight (``geometry.recording`` format with gnss, pseudoranges, truth)
    through the same path instead. ``inject_sop_bias_m`` adds a constant bias to one SOP
    (``inject_sop``), an error outside the PL's model: the MI counts can then fail.
  * MI (HPE > HPL) per configuration with its rate and 95 % Clopper-Pearson interval
    (``mc.rate_with_interval``) over the epochs with a finite HPL; the clean world's noise is
    independent from epoch to epoch, so given the geometry the epochs are independent trials;
    the realistic world's errors are correlated (multipath, NLOS episodes, clock drift), and
    the interval, which assumes independence, is then too narrow (the row's note says so).
  * Integrity: Table I (``araim.BUDGET_SEED004_TABLE_I`` by its symbols), P_s^S = 1e-4 and
    sigma_URA^S = 3 m (seed 004 VII-A and VII-D), P_const^S = 1e-4, SOP b_nom = 0, SOP user
    term 0, GPS user term the ADD dual-frequency airborne model (DESIGN.md "silent").
  * Per configuration (GPS + first n SOPs, n = 0..11): WNLS (C_int weights, one clock per
    group) and MHSS all-in-view HPL (``araim.protection_levels``; each configuration's fault-
    mode order is the smallest meeting P_thresh over its epochs). GPS + all SOPs also through
    ``araim.snapshot.replay`` with ``detect_and_exclude`` (Fig. 6: HPE and HPL of the solution
    kept).
  * Fig. 7 (Theorem 1): a bias ramp ``fault_ramp_mps`` from ``fault_onset_s`` on one GPS
    satellite (PRN 8 as in the seed if it is in view the whole flight, else the lowest PRN that
    is); the solution-separation statistic |dx_q| and threshold T_q of that satellite's fault
    mode, GPS only vs GPS + SOP 1, and the detection times (first epoch after the onset with a
    test coefficient tau > 1, any mode). The noise makes those times coincide at the epoch
    spacing (76 ms), so the sensitivity loss is also given without noise: the minimum
    detectable bias on that satellite per epoch (min over monitored modes and axes of
    T_i,q / |separation per metre of bias|, from a unit residual on the satellite alone; the
    separations are linear in the residual) and the time at which the ramp reaches it,
    interpolated between epochs. Theorem 1 makes it larger with one SOP by the K_fa ratio.
"""

from oaraim.studies.seed004_uav.plots import plot_uav
from oaraim.studies.seed004_uav.study import (
    PUBLISHED_EPOCHS,
    Seed004Uav,
    draw_noise,
    inject_bias,
    labels,
    model_variances,
    synthesize,
    world_errors,
)
from oaraim.studies.seed004_uav.towers import (
    CARRIERS_MHZ,
    OPERATORS,
    TOWERS,
    Tower,
    tower_operators,
    towers_enu_m,
)

__all__ = [
    "CARRIERS_MHZ",
    "OPERATORS",
    "PUBLISHED_EPOCHS",
    "TOWERS",
    "Seed004Uav",
    "Tower",
    "draw_noise",
    "inject_bias",
    "labels",
    "model_variances",
    "plot_uav",
    "synthesize",
    "tower_operators",
    "towers_enu_m",
    "world_errors",
]
