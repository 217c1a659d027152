"""The dual-frequency GPS + Galileo ARAIM user of ``rinex-replay`` (``--set signals=dual``).

Per epoch and satellite: the ionosphere-free code pseudorange of ``geometry.dual_frequency``
(GPS L1/L5, else L1/L2 C1C/C2W; Galileo E1/E5a), the broadcast clock without group delays
(GPS LNAV clocks refer to L1/L2 P(Y) ionosphere-free, Galileo F/NAV clocks to E1/E5a; the
uncorrected C1C-C1W DCB and the missing CNAV ISCs of L1/L5 are left to b_nom, as that module
says), the MOPS troposphere, Sagnac; one receiver clock per constellation in the WNLS and the
MHSS. Nominal errors (ADD section 2.2): C_int = sigma_URA^2 + sigma_tropo^2 + sigma_user^2,
C_acc with sigma_URE, sigma_iono = 0, sigma_user the airborne model (``"add"``: the ADD's L1
noise and multipath curves times the iono-free factor of the pair used, 2.59 for L1/L5 and
E1/E5a, 2.98 for L1/L2; ``"ed259a"``: EUROCAE ED-259A's dual-frequency curve, scaled by
factor / 2.59 for L1/L2). sigma_URA, sigma_URE, b_nom, P_sat and P_const per constellation from
an ``araim.Ism`` each (defaults ``araim.ISM_GPS``, ``araim.ISM_GALILEO``).
"""

from typing import NamedTuple

import numpy as np

from oaraim import araim, errors, geometry
from oaraim.constants import C_M_S
from oaraim.errors import (
    sigma_multipath_m,
    sigma_noise_m,
    sigma_tropo_m,
    sigma_user_ed259a_m,
)
from oaraim.geometry import dual_frequency as dfq
from oaraim.geometry import pseudorange_model as prm
from oaraim.readers import navigation_extras, rinex_obs

#: ``signals=single``: the ionosphere of the single-frequency user
SINGLE_NOTE = ("klobuchar (IS-GPS-200) on GPS L1 and, as a stand-in for NeQuick-G (not "
               "implemented), on Galileo E1; sigma_iono DO-229 J.2.3")
#: constellations of the dual-frequency user: (system letter, name)
SYSTEMS = (("G", "GPS"), ("E", "Galileo"))
#: the ADD's L1/L5 (and E1/E5a) factor, the reference of the ED-259A curve
_F_L1L5 = dfq.factor(dfq.F_L1_HZ, dfq.F_L5_HZ)


#: ``galileo_ism`` default: ``araim.ISM_GALILEO`` as text
ISM_GALILEO_TEXT = "1.0,0.75,1e-5,1e-4"


def parse_ism(name, v):
    """'sigma_URA,b_nom,P_sat,P_const' (sigma_URE = 2/3 sigma_URA) -> ``araim.Ism``."""
    if isinstance(v, araim.Ism):
        return v
    try:
        ura, b, ps, pc = (float(x) for x in str(v).split(","))
    except ValueError:
        raise ValueError(f"{name} must be SIGMA_URA_M,B_NOM_M,P_SAT,P_CONST (e.g. "
                         f"{ISM_GALILEO_TEXT}), got {v!r}") from None
    if not (ura > 0 and b >= 0 and 0 < ps < 1 and 0 < pc < 1 and np.isfinite(ura + b)):
        raise ValueError(f"{name}: sigma_URA > 0, b_nom >= 0 and probabilities in (0, 1), "
                         f"got {v!r}")
    return araim.Ism(ura, None, b, ps, pc)


def dual_table(obs_path, obs, signals, lenient):
    """The observation table of the dual-frequency user at the epochs of ``obs`` (the
    ``read_observations`` result), or None for the GPS L1 path (``signals`` 'gps-l1', or 'auto'
    on a file without an ionosphere-free pair); 'dual' on such a file: one-line error."""
    if signals == "gps-l1":
        return None
    table = rinex_obs.read_observation_table(obs_path, lenient=lenient)
    keep = np.isin(table.t_gps_s, obs.t_gps_s)
    table = table._replace(
        t_gps_s=table.t_gps_s[keep], values={c: a[keep] for c, a in table.values.items()},
        lli={c: a[keep] for c, a in table.lli.items()}, epoch_line=table.epoch_line[keep],
        epoch_file=table.epoch_file[keep])
    if signals == "single" or has_dual(table):
        return table
    if signals == "dual":
        raise ValueError(f"{obs_path}: no dual-frequency code pair (GPS C1C with C5Q/C5X/C5I "
                         "or C2W, Galileo C1C/C1X/C1B with C5Q/C5X/C5I): use --set "
                         "signals=gps-l1 or auto")
    return None


def has_dual(table) -> bool:
    """Whether an observation table has any ionosphere-free pair of ``geometry.dual_frequency``
    (RINEX 2 files, with C1/P2 codes, have none)."""
    return bool((dfq.iono_free(table.select("GE")).combination > 0).any())


def user_sigma_m(el_rad, noise_factor, model="add"):
    """Airborne dual-frequency code noise and multipath of each source, metres."""
    el = np.asarray(el_rad)
    if model == "ed259a":
        return np.asarray(sigma_user_ed259a_m(el)) * np.maximum(noise_factor / _F_L1L5, 1.0)
    l1 = np.sqrt(np.asarray(sigma_multipath_m(el)) ** 2 + np.asarray(sigma_noise_m(el)) ** 2)
    return noise_factor * l1


class DualUser(NamedTuple):
    """The receiver of ``dual_inputs``: what it assumes and how it solves."""

    mask_deg: float = 5.0
    """Elevation mask (deg)."""
    isms: tuple = (araim.ISM_GPS, araim.ISM_GALILEO)
    """The GPS and Galileo ``araim.Ism``."""
    airborne_model: str = "add"
    """The user error model of the dual-frequency user (``error_models.AIRBORNE_MODELS``)."""
    gps_pair: str = "l1l5"
    """The GPS frequency pair (``dual_frequency.iono_free``)."""
    tropo: str = "mops"
    """The tropospheric correction: "mops" or none."""
    n_passes: int = 3
    """Solutions whose position the corrections are recomputed at."""
    single: bool = False
    """The single-frequency GPS L1 + Galileo E1 user instead (``SINGLE_NOTE``)."""
    systems: str = "GE"
    """The constellations used, by RINEX letter ("GE", "G" or "E")."""


def dual_inputs(table, nav_path, user: DualUser | None = None):
    """Per-epoch inputs of ``araim.snapshot.replay`` for the dual-frequency user (module
    docstring; ``user``: its mask, ISMs, error model, frequency pair, troposphere, passes,
    single-frequency variant and constellations), in the layout of
    ``studies.rinex_replay.gnss_replay_inputs`` plus ``constellation`` (T, S) clock groups,
    ``p_sat``, ``b_nom_m`` (T, S), ``p_const`` (C,), ``combination`` (T, S) pair codes,
    ``constellations`` (names) and ``sv`` (S,). ``user`` None: ``DualUser()``."""
    user = DualUser() if user is None else user
    mask_deg, isms, airborne_model, gps_pair, tropo, n_passes, single, systems = user
    table = table.select(systems)
    t = table.t_gps_s
    sv = table.sv
    iof = dfq.single_frequency(table) if single else dfq.iono_free(table, gps_pair)
    eph = geometry.load_navigation(nav_path, systems=("G", "E"),
                                   galileo_source="inav" if single else "fnav")
    pr = np.where(iof.combination > 0, iof.pseudorange_m, 0.0)
    observed = iof.combination > 0
    n_t, n_s = pr.shape
    alpha = beta = None
    gd_s = np.zeros((n_t, n_s))
    if single:
        extras = navigation_extras(nav_path)
        alpha, beta = extras.alpha, extras.beta
        for ch, field in (("G", "TGD"), ("E", "BGDe5b")):
            cols = np.flatnonzero(np.array([s[0] == ch for s in sv])
                                  & np.isin(sv, eph.prns))
            if cols.size:
                gd_s[:, cols] = np.nan_to_num(eph.record_field(field, t, prns=sv[cols]))
    sat = prm.satellites_at_transmit(eph, t, pr, observed, sv, gd_s)
    valid = sat.valid
    letters = np.array([s[0] for s in sv])
    present = [k for k, (ch, _) in enumerate(SYSTEMS) if (valid[:, letters == ch]).any()]
    if not present:
        present = [0]
    label = np.zeros(n_s, np.int32)
    for new, k in enumerate(present):
        label[letters == SYSTEMS[k][0]] = new
    n_clocks = len(present)
    cons = np.broadcast_to(label, (n_t, n_s))
    ism_of = np.array([present.index(k) if k in present else 0
                       for k in (0 if ch == "G" else 1 for ch in letters)])
    used_isms = [isms[k] for k in present]
    ura = np.array([i.sigma_ura_m for i in used_isms])[ism_of]
    ure = np.array([(i.sigma_ure_m if i.sigma_ure_m is not None
                     else errors.URE_OVER_URA * i.sigma_ura_m)
                    for i in used_isms])[ism_of]
    clock_m = C_M_S * (sat.clock_s - sat.tgd_s)
    rot, _ = prm.sagnac_rotate(np.zeros((n_t, 3)), sat.ecef_tx_m)
    sol = araim.wnls(np.where(valid, pr + clock_m, 0.0), np.asarray(rot), 1.0,
                     valid=valid, clock_index=cons,
                     options=araim.WNLSOptions(n_clocks))
    x = np.asarray(sol.position_m)
    mask = np.deg2rad(mask_deg)

    def terms(x):
        rt = prm.receiver_terms(x, sat.ecef_tx_m, t, alpha, beta)
        el = np.asarray(rt.el_rad)
        tropo_m = np.asarray(rt.tropo_m) if tropo == "mops" else np.zeros_like(el)
        v = valid & (el >= mask)
        common = (np.asarray(sigma_tropo_m(el)) ** 2
                  + user_sigma_m(el, iof.noise_factor, "add" if single else airborne_model) ** 2
                  + (np.asarray(rt.sigma_iono_m) ** 2 if single else 0.0))
        return rt, el, tropo_m, v, ura**2 + common, ure**2 + common, np.asarray(rt.iono_m)

    for _ in range(max(2, n_passes) - 1):
        rt, el, tropo_m, v, var_int, _, iono_m = terms(x)
        sol = araim.wnls(np.where(v, pr + clock_m - iono_m - tropo_m, 0.0),
                         np.asarray(rt.sat_ecef_m),
                         np.sqrt(np.where(v, var_int, 1.0)), x0_m=x, valid=v,
                         clock_index=cons, options=araim.WNLSOptions(n_clocks))
        x = np.where(np.isfinite(np.asarray(sol.position_m)), np.asarray(sol.position_m), x)
    rt, el, tropo_m, v, var_int, var_acc, iono_m = terms(x)
    z = lambda a: np.where(valid, np.asarray(a), 0.0)  # noqa: E731
    p_sat = np.array([i.p_sat for i in used_isms])[ism_of]
    b_nom = np.array([i.b_nom_m for i in used_isms])[ism_of]
    return {
        "pseudorange_m": pr, "correction_m": z(clock_m - iono_m - tropo_m),
        "tx_pos_m": np.where(valid[..., None], np.asarray(rt.sat_ecef_m), 0.0),
        "var_int_m2": np.where(v, var_int, 1.0), "var_acc_m2": np.where(v, var_acc, 1.0),
        "valid": v, "az_rad": z(rt.az_rad), "el_rad": z(el), "iono_m": z(iono_m),
        "tropo_m": z(tropo_m), "sat_clock_m": z(C_M_S * sat.clock_s),
        "tgd_m": z(C_M_S * sat.tgd_s),
        "ephemeris_age_s": z(sat.age_s), "observed": observed, "ephemeris_valid": sat.valid,
        "x_ecef_m": x, "iono_model": (SINGLE_NOTE if single else
                                      "none (ionosphere-free combinations)"),
        "constellation": np.ascontiguousarray(cons),
        "p_sat": np.broadcast_to(p_sat, (n_t, n_s)).copy(),
        "b_nom_m": np.broadcast_to(b_nom, (n_t, n_s)).copy(),
        "p_const": tuple(i.p_const for i in used_isms),
        "combination": np.where(v, iof.combination, 0).astype(np.int8),
        "l5_offset_m": iof.l5_offset_m, "gps_pair": "single" if single else gps_pair,
        "constellations": [SYSTEMS[k][1] for k in present], "sv": sv, "ephemeris": eph,
    }


def combination_text(comb, constellations):
    """One line: the pairs used and their share of the satellite-epochs."""
    n = max(int(np.sum(comb > 0)), 1)
    parts = [f"{dfq.COMBINATION_NAMES[c]} {100 * np.sum(comb == c) / n:.0f} %"
             for c in sorted(dfq.COMBINATION_NAMES) if np.any(comb == c)]
    kind = ("single-frequency " if np.any(comb >= dfq.GPS_L1)
            else "dual-frequency ionosphere-free ")
    return kind + " + ".join(constellations) + ": " + ", ".join(parts)


#: LPV-200 availability (MAAST's criterion): VPL, HPL, EMT, sigma_acc (vertical) limits, m
LPV200_LIMITS = {"vpl": 35.0, "hpl": 40.0, "emt": 15.0, "sigma_acc": 1.87}


def sv_numbers(sv):
    """Integer satellite coordinate: the GPS PRN, Galileo 100 + PRN (a string coordinate has no
    stable Zarr v3 encoding; the names are in the ``sv_names`` attribute)."""
    return np.array([int(s[1:]) + (100 if s[0] == "E" else 0) for s in sv], np.int64)


def _used(inp, out):
    return np.asarray(inp["valid"]) & ~np.asarray(out["mhss_excluded"])


def _labels(inp, sv):
    letters = np.array([s[0] for s in sv])
    names = inp.get("constellations", ["GPS"])
    return [(n, letters == dict((b, a) for a, b in SYSTEMS)[n]) for n in names]


def dataset_extras(inp, out):
    """Per-epoch satellites used (after the MHSS exclusion) per constellation, and the pair
    each satellite used (``combination``: ``geometry.dual_frequency`` codes)."""
    sv = inp.get("sv")
    if sv is None:
        return {"n_used_gps": (("epoch",), _used(inp, out).sum(-1).astype(np.int16))}
    used = _used(inp, out)
    ds = {f"n_used_{n.lower()}": (("epoch",), used[:, m].sum(-1).astype(np.int16))
          for n, m in _labels(inp, sv)}
    ds["combination"] = (("epoch", "sv"), inp["combination"])
    return ds


def summary_extras(inp, out, sv):
    """``constellations``, ``combination`` (and per pair the share of satellite-epochs),
    ``lpv200_available_pct`` (MAAST's criterion, ``LPV200_LIMITS``, on the MHSS solution kept),
    ``misleading_information_epochs`` (HPE > HPL or VPE > VPL, MHSS), the share of epochs each
    satellite was excluded (of the epochs it was in view) and satellites used per
    constellation."""
    hpl, vpl = out["hpl_mhss_m"], out["vpl_mhss_m"]
    hpe, vpe = out["hpe_mhss_m"], out["vpe_mhss_m"]
    lim = LPV200_LIMITS
    ok = ((vpl <= lim["vpl"]) & (hpl <= lim["hpl"]) & (out["emt_mhss_m"] <= lim["emt"])
          & (out["sigma_acc_mhss_m"] <= lim["sigma_acc"]))
    n = max(hpl.size, 1)
    mi = (np.isfinite(hpl) & np.isfinite(hpe) & (hpe > hpl)) | (
        np.isfinite(vpl) & np.isfinite(vpe) & (vpe > vpl))
    valid = np.asarray(inp["valid"])
    seen = valid.sum(0)
    excl = np.asarray(out["mhss_excluded"]).sum(0)
    used = _used(inp, out)
    m = {"lpv200_available_pct": float(100.0 * ok.sum() / n),
         "misleading_information_epochs": int(mi.sum()),
         "excluded_share": {str(s): round(float(excl[j] / seen[j]), 6)
                            for j, s in enumerate(sv) if seen[j]}}
    if "combination" in inp:
        comb = inp["combination"]
        k = max(int((comb > 0).sum()), 1)
        m["constellations"] = list(inp["constellations"])
        m["combination"] = combination_text(comb, inp["constellations"])
        m["combination_share"] = {dfq.COMBINATION_NAMES[c]: float((comb == c).sum() / k)
                                  for c in dfq.COMBINATION_NAMES}
        m["satellites_used_median_per_constellation"] = {
            name: float(np.median(used[:, mk].sum(-1))) for name, mk in _labels(inp, sv)}
        off = np.asarray(inp.get("l5_offset_m", np.full(len(sv), np.nan)))
        on_l5 = (comb == dfq.GPS_L1L5).any(0)
        m["gps_pair"] = inp.get("gps_pair", "l1l5")
        m["gps_l5_offset_removed_m"] = {str(s): round(float(off[j]), 3)
                                        for j, s in enumerate(sv) if np.isfinite(off[j])}
        m["gps_l5_uncorrected"] = [str(s) for j, s in enumerate(sv)
                                   if on_l5[j] and not np.isfinite(off[j])]
    else:
        m["constellations"] = ["GPS"]
        m["combination"] = "GPS L1 single frequency (L1 C/A code), Klobuchar"
        m["satellites_used_median_per_constellation"] = {"GPS": float(np.median(
            used.sum(-1))) if used.size else 0.0}
    return m


def draw_satellites_used(ds, out_dir):
    """``satellites_used.png``: satellites used per constellation (after the MHSS exclusion)
    over the file; the path."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3))
    h = ds["hours"].values
    for name in ("gps", "galileo"):
        if f"n_used_{name}" in ds:
            ax.step(h, ds[f"n_used_{name}"].values, where="post", lw=1,
                    label="GPS" if name == "gps" else "Galileo")
    ax.set_xlabel(f"hours from {ds.attrs['start_gps']} (GPS time)")
    ax.set_ylabel("satellites used")
    ax.set_title(f"{ds.attrs['obs_file']}: {ds.attrs.get('combination', '')}", fontsize=8)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    p = f"{out_dir}/satellites_used.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p
