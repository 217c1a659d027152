"""The error world the simulations draw from (the parameters; the draws are ``oaraim.sim``'s):
``ErrorModel``, the terrestrial SOPs' pseudorange errors, tower clocks and injected fault of a
simulated drive or flight, and ``GnssErrorModel``, the satellites' errors of the mixed GNSS +
SOP studies. docs/error-world.md gives every parameter with its source.
"""

from typing import NamedTuple

from oaraim.errors.gnss import URE_OVER_URA

#: the outcome the fault-free default world is checked against: Shamaei and Kassas, "LTE
#: receiver design and multipath analysis for navigation in urban environments", NAVIGATION
#: 65(4), 2018 (seed 000 ref. [9]): an LTE-only receiver on a 1.44 km urban drive, position
#: RMSE 3.17 m against the GPS solution (standard deviation 1.06 m, maximum 6.58 m). The
#: defaults below give a fault-free 2D RMSE of about 3 m on the seed 000 drive
#: (docs/error-world.md; tests/test_world.py)
LTE_URBAN_POSITION_RMSE_M = 3.17


class ErrorModel(NamedTuple):
    """The error world of a simulated drive or flight: every parameter of the LTE pseudorange
    errors, the tower clocks and the injected fault (a pytree: every field may be traced, so one
    compilation serves a sweep over them).

    The defaults are the realistic world (docs/error-world.md: each default, its source, and
    which ones the papers leave open for a later calibration); ``ErrorModel.clean()`` is the
    clean world the first studies used (white noise, no multipath, NLOS or clock residual,
    the filter told the truth's sigma), which the theorem checks and the exact-recovery tests use.

    Pseudorange of tower n at time t (after the receiver's calibrated clock polynomial):
    ``z = range + c dt_rx - c dt_n,poly + mp_n + nlos_n + eps_n + common_op(n) - fit_n(t)
    + fault_n + sigma_pr eps``, where ``fit_n`` is the line the receiver fitted by least squares
    to its tower-clock data during the GNSS period (seed 000 section II-D), so the residual
    grows once GNSS is gone.
    """

    #: 1-sigma white (thermal) noise of each pseudorange, m (seed 000 section I: "meter-level"
    #: LTE ranging; the value is open: 1 m)
    sigma_pr_m: float = 1.0
    #: stationary 1-sigma of the per-tower first-order Gauss-Markov short-delay multipath, m
    #: (open: 1.5 m is our choice, which with the rest of the world gives the fault-free 2D
    #: RMSE of ``LTE_URBAN_POSITION_RMSE_M``; 0: off)
    mp_sigma_m: float = 1.5
    #: correlation time of that multipath, s (seed 002 cites the time-correlated model of
    #: Shamaei, Morales and Kassas 2019, whose value we could not read: open, 10 s is our
    #: choice, ~110 m of travel at 25 mph, a city block; calibration will fit it)
    mp_tau_s: float = 10.0
    #: 0-based index of the tower that carries the injected fault
    fault_tower: int = 0
    #: time from which the fault is on, s (inf: no fault)
    fault_onset_s: float = 25.0
    #: magnitude of the injected constant fault bias, m
    fault_bias_m: float = 30.0
    #: onsets per second of line-of-sight blockage (NLOS) episodes on each tower (seed 000
    #: section I and seed 002 name LOS blockage as the cause of biased LTE pseudoranges but
    #: give no rate: open; 1/250 s is our choice, each tower blocked ~2 % of the time)
    nlos_rate_per_s: float = 1.0 / 250.0
    #: mean duration of an NLOS episode, s (open; 5 s: one building passed at 25 mph)
    nlos_duration_s: float = 5.0
    #: mean excess delay of an NLOS episode, m; each episode draws its constant positive bias
    #: from an exponential distribution of this mean (open; 10 m is our choice, the order of
    #: seed 000's faults)
    nlos_bias_m: float = 10.0
    #: stationary 1-sigma of each tower's own clock deviation epsilon_n of seed 004 eq. (3),
    #: m, a first-order Gauss-Markov process (seed 004 cites Khalife and Kassas 2017 for the
    #: model, not for a value: open; 0.5 m is our choice)
    clk_eps_sigma_m: float = 0.5
    #: correlation time of epsilon_n, s (open; 60 s is our choice)
    clk_eps_tau_s: float = 60.0
    #: clock-bias PSD of the common term of one operator's towers (seed 004 eq. 3), s: the
    #: towers' common reference drifts as a double integrator; OCXO value of seed 000 IV-A
    clk_s_wdt_s: float = 1.3e-22
    #: clock-drift PSD of that common term, 1/s (OCXO, seed 000 section IV-A)
    clk_s_wdtdot_per_s: float = 7.89e-25
    #: length of the GNSS period before t = 0 over which the receiver fits each tower's clock
    #: bias and drift by least squares (seed 000 section II-D) and estimates its measurement
    #: variance from the fit residuals ("determined empirically", seed 000 IV-A), s (the seed
    #: gives no length: open; 120 s is our choice; at most ``drive_setup``'s ``calib_s``;
    #: 0: no fit, no estimate)
    calib_window_s: float = 120.0

    @classmethod
    def clean(cls, sigma_pr_m=2.0, fault_tower=0, fault_onset_s=25.0, fault_bias_m=30.0,
              mp_sigma_m=0.0, mp_tau_s=5.0):
        """The clean world the first studies used: white ``sigma_pr_m`` noise, optional unmodelled
        multipath, no NLOS, no tower-clock residual, no calibration (the filter then uses
        ``sigma_pr_m``: it is told the truth)."""
        return cls(sigma_pr_m=sigma_pr_m, mp_sigma_m=mp_sigma_m, mp_tau_s=mp_tau_s,
                   fault_tower=fault_tower, fault_onset_s=fault_onset_s,
                   fault_bias_m=fault_bias_m, nlos_rate_per_s=0.0, clk_eps_sigma_m=0.0,
                   clk_s_wdt_s=0.0, clk_s_wdtdot_per_s=0.0, calib_window_s=0.0)


class GnssErrorModel(NamedTuple):
    """The GNSS pseudorange errors of the mixed GNSS + SOP studies' truth
    (docs/error-world.md): consistent with, but not identical to, the ADD models the protection
    levels assume (``errors.gnss``: Gaussian, white, sigma_URA for integrity). Each term is a
    first-order Gauss-Markov process per satellite (stationary start), plus a constant bias:

    * clock and ephemeris: sigma ``ure_over_ura`` x sigma_URA (the ADD's accuracy value,
      2/3), correlation time ``ure_tau_s``;
    * nominal bias: a constant per satellite and draw, uniform in +-``b_nom_m`` (the ADD's
      integrity b_nom is 0.75 m; the PL of seed 001 assumes none);
    * troposphere residual: sigma_tropo(el) (RTCA DO-229 / ADD), correlation time
      ``tropo_tau_s``;
    * ionosphere residual: ``sigma_iono_m`` (0: dual-frequency iono-free, seed 004 App. A);
    * multipath: ``mp_scale`` x the ADD airborne multipath sigma(el) x the iono-free factor,
      correlation time ``mp_tau_s``; receiver noise white, the ADD noise sigma(el) x the
      iono-free factor.
    """

    #: sigma_URE / sigma_URA (ADD convention, DESIGN.md: 2/3)
    ure_over_ura: float = URE_OVER_URA
    #: correlation time of the clock and ephemeris error, s (open; 1800 s, our choice: orbit
    #: and clock errors change over tens of minutes)
    ure_tau_s: float = 1800.0
    #: half-width of the uniform nominal bias per satellite, m (ADD b_nom for integrity 0.75 m;
    #: our truth draws within it)
    b_nom_m: float = 0.75
    #: correlation time of the troposphere residual, s (Joerger and Pervan's bounds are
    #: 900-2700 s, NAVIGATION, "multipath and troposphere error models" table: the middle)
    tropo_tau_s: float = 1800.0
    #: ionosphere residual 1-sigma, m (0: iono-free dual frequency, seed 004 App. A)
    sigma_iono_m: float = 0.0
    #: multipath sigma relative to the ADD airborne model (1: airborne; a car sees more: open)
    mp_scale: float = 2.0
    #: multipath correlation time, s (Joerger and Pervan's lower bound for code multipath,
    #: 10 s; a moving car decorrelates fast)
    mp_tau_s: float = 10.0
