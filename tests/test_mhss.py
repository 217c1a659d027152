"""Tests of araim.protection_levels: ARAIM / OARAIM MHSS protection levels (seed 004 eqs. 8-16).

The oracle is tests/reference_mhss.py (plain per-geometry NumPy/SciPy, enumerated modes, clock
columns literally removed, bisection to 1e-6 m). Tolerances:

- PLs and EMT within 2e-3 m: the solver returns a PL within 1e-3 m above the root, the
  oracle's bisection is good to 1e-6 m, the rest is float64 rounding of 5x5-ish systems.
- sigma_acc_u, P_not_monitored to a relative 1e-7: both are closed-form sums/products; the
  margin covers the conditioning of the normal matrices (~1e6 at worst here) times 1e-16.

Compiled shapes are kept few (DESIGN.md): every random batch is padded to L = 28 sources
(12 GPS + 8 Galileo + 8 SOP slots) and C = 4 constellation slots (GPS 0, Galileo 1, SOP 2, SOP 3),
the hand cases to L = 8, C = 2.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import optimize, special, stats

from oaraim import araim, geometry
from oaraim import reference_mhss as ref
from oaraim.araim import Status
from oaraim.errors import gnss_variances, sop_variances


def grouped(fn):
    """``fn`` (an MHSS host function) under seed 004's ``grouped`` convention: the
    ``araim.MHSSOptions`` it is given (or the default one, appended) with that rule."""
    def call(*args, **kw):
        opts = [a for a in args if isinstance(a, araim.MHSSOptions)]
        if opts:
            args = tuple(a._replace(fault_modes="grouped")
                         if isinstance(a, araim.MHSSOptions) else a for a in args)
        else:
            args = (*args, araim.MHSSOptions(fault_modes="grouped"))
        return fn(*args, **kw)

    return call


# these tests check the grouped convention (seed 004's SOP studies) against the grouped
# oracle; the ADD conventions are tested in test_conformance.py
protection_levels = grouped(araim.protection_levels)
GROUPED = araim.FaultModeRule("grouped")

L_GPS, L_GAL, L_SOP = 12, 8, 8
L = L_GPS + L_GAL + L_SOP
C = 4
P_CONST = np.array([1e-8, 1e-4, 1e-4, 1e-4])  # GPS (Table I), Galileo (ADD), SOP (Table I)
SIGMA_URA_S = np.array([0.5, *range(1, 26)], float)  # DESIGN.md Fig. 4 grid, 26 values
P_S_S = 10.0 ** (-7.0 + 0.5 * np.arange(13))  # 1e-7 .. 1e-1, two per decade, 13 values
N_RANDOM = 2000  # >= 2000 geometries against the oracle
PL_TOL_M = 2e-3  # solver 1e-3 m above the root + oracle 1e-6 m + rounding
TABLE_I = None  # set lazily: araim.BUDGET_SEED004_TABLE_I

_sky = jax.jit(geometry.random_sky, static_argnums=(1, 3))
_bpp = jax.jit(geometry.bpp_towers, static_argnums=(1, 6))


def budget():
    return araim.BUDGET_SEED004_TABLE_I


def rows(az_rad, el_rad):
    """Geometry rows in NumPy for hand-built cases: [-cos el sin az, -cos el cos az, -sin el]."""
    az, el = np.broadcast_arrays(np.asarray(az_rad, float), np.asarray(el_rad, float))
    return np.stack([-np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), -np.sin(el)], axis=-1)


def random_cases(seed, n):
    """n random GPS + SOP geometries spanning Table I, padded to L = 28, rows shuffled.

    GPS: 5..12 random-sky satellites above a 5, 10 or 15 deg mask; Galileo on for half of the
    geometries (4..8 satellites, same mask); 1..8 BPP towers (distance 200..3000 m, height
    -200..+50 m relative to the receiver: an aircraft mostly above the towers, so SOP verticals
    are not always singular) in one SOP constellation or split at random over two. SOP
    sigma_URA^S and P_s^S from the Fig. 4 grid of DESIGN.md, b_nom^S = 0 (DESIGN.md) except for
    a quarter of the geometries (0.5 m, to exercise eq. 10 on SOPs). GNSS error models from
    araim.error_models (ADD), b_nom = 0.75 m, P_s = 1e-5. Padding rows hold finite junk.
    Returns a dict of arrays (batch first) and the per-geometry counts.
    """
    keys = jax.random.split(jax.random.key(seed), 8)
    rng = np.random.default_rng(seed)
    masks = np.deg2rad([5.0, 10.0, 15.0])
    which = rng.integers(0, 3, n)
    az_g = np.empty((n, L_GPS))
    el_g = np.empty((n, L_GPS))
    az_e = np.empty((n, L_GAL))
    el_e = np.empty((n, L_GAL))
    for k, mask in enumerate(masks):
        a, e = (np.asarray(x) for x in _sky(keys[k], L_GPS, mask, (n,)))
        az_g[which == k], el_g[which == k] = a[which == k], e[which == k]
        a, e = (np.asarray(x) for x in _sky(keys[3 + k], L_GAL, mask, (n,)))
        az_e[which == k], el_e[which == k] = a[which == k], e[which == k]
    tw = _bpp(keys[6], L_SOP, 200.0, 3000.0, -200.0, 50.0, (n,))
    az = np.concatenate([az_g, az_e, np.asarray(tw.az_rad)], axis=1)
    el = np.concatenate([el_g, el_e, np.asarray(tw.el_rad)], axis=1)

    n_gps = rng.integers(5, L_GPS + 1, n)
    n_gal = np.where(rng.random(n) < 0.5, rng.integers(4, L_GAL + 1, n), 0)
    n_sop = rng.integers(1, L_SOP + 1, n)
    two_sop = rng.random(n) < 0.5
    idx = np.arange(L)
    valid = ((idx < n_gps[:, None])
             | ((idx >= L_GPS) & (idx < L_GPS + n_gal[:, None]))
             | ((idx >= L_GPS + L_GAL) & (idx < L_GPS + L_GAL + n_sop[:, None])))
    const = np.broadcast_to(np.where(idx < L_GPS, 0, np.where(idx < L_GPS + L_GAL, 1, 2)),
                            (n, L)).copy()
    split = two_sop[:, None] & (rng.random((n, L)) < 0.5) & (idx >= L_GPS + L_GAL)
    const[split] = 3

    sigma_s = SIGMA_URA_S[rng.integers(0, len(SIGMA_URA_S), n)]
    p_s = P_S_S[rng.integers(0, len(P_S_S), n)]
    vi_g, va_g = (np.asarray(x) for x in gnss_variances(el, 1.0))
    vi_s, va_s = (np.asarray(x) for x in sop_variances(sigma_s[:, None] * np.ones((1, L))))
    sop = const >= 2
    var_int = np.where(sop, vi_s, vi_g)
    var_acc = np.where(sop, va_s, va_g)
    b_sop = np.where(rng.random(n) < 0.25, 0.5, 0.0)
    b_nom = np.where(sop, b_sop[:, None], 0.75)
    p_sat = np.where(sop, p_s[:, None], 1e-5)

    g = np.asarray(geometry.geometry_rows(az, el)).copy()
    bad = ~valid
    g[bad] = rng.normal(0.0, 3.0, (bad.sum(), 3))  # finite junk padding
    var_int[bad] = rng.uniform(0.0, 5.0, bad.sum())
    var_acc[bad] = -1.0
    b_nom[bad] = 7.0
    p_sat[bad] = 0.5
    const[bad] = rng.integers(0, C, bad.sum())

    perm = np.argsort(rng.random((n, L)), axis=1)
    take = np.take_along_axis
    case = dict(g=take(g, perm[..., None], 1), constellation=take(const, perm, 1),
                var_int=take(var_int, perm, 1), var_acc=take(var_acc, perm, 1),
                b_nom=take(b_nom, perm, 1), p_sat=take(p_sat, perm, 1),
                p_const=np.broadcast_to(P_CONST, (n, C)).copy(), valid=take(valid, perm, 1))
    info = dict(n_gps=n_gps, n_gal=n_gal, n_sop=n_sop, two_sop=two_sop, sigma_s=sigma_s, p_s=p_s)
    return case, info


def run_jax(case, bud=None, max_order=3, sl=slice(None)):
    res = protection_levels(araim.Sources(case["g"][sl], case["constellation"][sl],
                                          case["var_int"][sl], case["var_acc"][sl],
                                          case["b_nom"][sl], case["p_sat"][sl], case["valid"][sl]),
                            case["p_const"][sl], bud or budget(), araim.MHSSOptions(max_order))
    return {k: np.asarray(getattr(res, k)) for k in res._fields}


def run_ref(case, i, bud=None, max_order=3, singular_rtol=ref.SINGULAR_RTOL):
    return ref.protection_levels_reference(araim.Sources(case["g"][i], case["constellation"][i],
                                                         case["var_int"][i], case["var_acc"][i],
                                                         case["b_nom"][i], case["p_sat"][i],
                                                         case["valid"][i]), case["p_const"][i],
                                           bud or budget(),
                                           ref.ReferenceOptions(max_order=max_order,
                                                                singular_rtol=singular_rtol))


def borderline_readings(case, i, **kw):
    """The oracle under the two readings of a borderline singularity test: every borderline
    subset monitorable (tolerance well below the band) or singular (well above)."""
    lo = ref.SINGULAR_RTOL / ref.BORDERLINE_FACTOR / 10
    hi = ref.SINGULAR_RTOL * ref.BORDERLINE_FACTOR * 10
    return [run_ref(case, i, singular_rtol=lo, **kw), run_ref(case, i, singular_rtol=hi, **kw)]


def assert_no_nan(res):
    for k, v in res.items():
        assert not np.any(np.isnan(np.asarray(v, float))), k


def compare(res, i, o):
    """Compare geometry i of the batched result with the oracle's result o; returns a list of
    mismatch descriptions (empty when they agree)."""
    bad = []
    st = int(res["status"][i])
    if st != o.status:
        return [f"status {st} != {o.status}"]
    if int(res["order"][i]) != o.order:
        bad.append(f"order {int(res['order'][i])} != {o.order}")
    if o.status in (ref.OK, ref.UNMONITORED_RISK):
        if int(res["n_modes"][i]) != o.n_modes:
            bad.append(f"n_modes {int(res['n_modes'][i])} != {o.n_modes}")
        if not np.isclose(res["p_not_monitored"][i], o.p_not_monitored, rtol=1e-7, atol=1e-18):
            bad.append(f"p_nm {res['p_not_monitored'][i]:.6e} != {o.p_not_monitored:.6e}")
    if o.status == ref.OK:
        for name, want in (("hpl_m", o.hpl_m), ("vpl_m", o.vpl_m), ("emt_m", o.emt_m)):
            if not abs(res[name][i] - want) <= PL_TOL_M:
                bad.append(f"{name} {res[name][i]:.6f} != {want:.6f}")
        if not np.isclose(res["sigma_acc_u_m"][i], o.sigma_acc_u_m, rtol=1e-7):
            bad.append(f"sigma_acc_u {res['sigma_acc_u_m'][i]} != {o.sigma_acc_u_m}")
    else:
        for name in ("hpl_m", "vpl_m", "emt_m", "sigma_acc_u_m"):
            if res[name][i] != np.inf:
                bad.append(f"{name} = {res[name][i]} with status {st}")
    return bad


# --------------------------------------------------------------------------- oracle, random


@pytest.fixture(scope="module")
def random_batch():
    case, info = random_cases(20261125, N_RANDOM)
    res = run_jax(case)
    oracle = [run_ref(case, i) for i in range(N_RANDOM)]
    return case, info, res, oracle


def _describe(info, i):
    return {k: (v[i].item() if hasattr(v[i], "item") else v[i]) for k, v in info.items()}


NOT_CONVERGED = "NOT_CONVERGED where the oracle is OK"


def _mismatches(res, i, o):
    """compare(), with the root finder's failure to converge on an OK geometry reported as its
    own kind (tested separately below, so that it does not mask other disagreements)."""
    if int(res["status"][i]) == Status.NOT_CONVERGED and o.status == ref.OK:
        return [NOT_CONVERGED]
    return compare(res, i, o)


def test_random_geometries_match_oracle(random_batch):
    """>= 2000 GPS + SOP geometries spanning Table I: hpl, vpl, emt within 2e-3 m, status,
    order, n_modes and P_not_monitored equal, wherever both enumerate the same modes: the
    geometries with a fault-tolerant subset whose normal matrix is within a factor 1e3 of the
    singularity tolerance (condition ~1e7..1e13) are compared in the next test instead."""
    case, info, res, oracle = random_batch
    assert_no_nan(res)
    failures = []
    clear = [i for i in range(N_RANDOM) if not oracle[i].borderline]
    assert len(clear) >= 0.97 * N_RANDOM
    for i in clear:
        bad = _mismatches(res, i, oracle[i])
        if bad and bad != [NOT_CONVERGED]:
            failures.append(f"geometry {i} ({_describe(info, i)}): {bad}")
    assert not failures, f"{len(failures)} mismatches:\n" + "\n".join(failures[:20])


def test_borderline_geometries_match_one_reading(random_batch):
    """Geometries with a nearly singular subset: the solver agrees with the oracle under one of
    the two readings of the singularity test (subset monitorable, or not)."""
    case, info, res, oracle = random_batch
    failures = []
    for i in (i for i in range(N_RANDOM) if oracle[i].borderline):
        readings = [_mismatches(res, i, o) for o in borderline_readings(case, i)]
        if all(readings) and [NOT_CONVERGED] not in readings:
            failures.append(f"geometry {i} ({_describe(info, i)}): {readings}")
    assert not failures, f"{len(failures)} mismatches:\n" + "\n".join(failures[:20])


def test_random_geometries_span_the_intended_cases(random_batch):
    """The random set really spans Table I: every order 1..3, OK and UNMONITORED_RISK statuses,
    one and two SOP constellations, Galileo on and off, SOP-fault modes with large priors."""
    case, info, res, _ = random_batch
    assert set(np.unique(res["order"])) == {1, 2, 3}
    assert np.mean(res["status"] == Status.OK) > 0.7
    assert np.any(res["status"] == Status.UNMONITORED_RISK)
    assert np.any(info["two_sop"]) and np.any(~info["two_sop"])
    assert np.any(info["n_gal"] == 0) and np.any(info["n_gal"] > 0)
    ok = res["status"] == Status.OK
    assert np.all(np.isfinite(res["hpl_m"][ok])) and np.all(np.isfinite(res["vpl_m"][ok]))


@pytest.fixture(scope="module")
def order1_batch():
    """200 further geometries with max_order = 1 forced (many need order 2 or 3)."""
    case, info = random_cases(77, 200)
    return case, info, run_jax(case, max_order=1), [run_ref(case, i, max_order=1)
                                                    for i in range(200)]


@pytest.fixture(scope="module")
def lpv_batch():
    """200 further geometries under the LPV-200 budget of the ADD."""
    case, info = random_cases(78, 200)
    bud = araim.BUDGET_LPV200
    return case, info, run_jax(case, bud=bud), [run_ref(case, i, bud=bud) for i in range(200)]


def _agreement_failures(batch):
    case, info, res, oracle = batch
    failures = []
    for i, o in enumerate(oracle):
        if o.borderline:
            continue
        bad = _mismatches(res, i, o)
        if bad and bad != [NOT_CONVERGED]:
            failures.append(f"geometry {i} ({_describe(info, i)}): {bad}")
    return failures


def test_forced_order_one_matches_oracle(order1_batch):
    """max_order = 1 on geometries that need more: order 1, P(more than one constellation
    faulty) counted unmonitored, status UNMONITORED_RISK where it exceeds P_thresh."""
    _, _, res, _ = order1_batch
    assert_no_nan(res)
    assert np.all(res["order"] == 1)
    assert np.any(res["status"] == Status.UNMONITORED_RISK)
    failures = _agreement_failures(order1_batch)
    assert not failures, "\n".join(failures[:20])


def test_lpv200_budget_matches_oracle(lpv_batch):
    """The other preset (LPV-200, ADD): different K_fa and PHMI split, same agreement."""
    assert_no_nan(lpv_batch[2])
    failures = _agreement_failures(lpv_batch)
    assert not failures, "\n".join(failures[:20])


def test_pl_root_finder_converges_where_the_oracle_is_ok(random_batch, order1_batch, lpv_batch):
    """A fixed iteration count must still converge (status OK) wherever the PL exists (an
    Illinois solver with 8 iterations left 75/2000 NOT_CONVERGED, with 7 244/2000)."""
    detail = []
    for name, (_, info, res, oracle) in (("table I", random_batch), ("order 1", order1_batch),
                                        ("LPV-200", lpv_batch)):
        for i, o in enumerate(oracle):
            if int(res["status"][i]) == Status.NOT_CONVERGED and o.status == ref.OK:
                detail.append(f"{name} geometry {i} ({_describe(info, i)}): oracle PL_ENU "
                              f"{o.pl_enu_m}")
    assert not detail, f"{len(detail)} not converged:\n" + "\n".join(detail[:30])


# --------------------------------------------------------------------------- hand-derived cases
#
# Geometry "ring + zenith": constellation 0 has four satellites at elevation e, azimuths 0, 90,
# 180, 270 deg, and one at the zenith, unit variances. With c = cos e, s = sin e the normal
# matrix is block diagonal: E and N get 4 c^2 / 2 = 2 c^2 each, and the (U, clock) block is
# [[4 s^2 + 1, -(4 s + 1)], [-(4 s + 1), 5]] with determinant 4 (1 - s)^2, so
#     sigma_E^2 = sigma_N^2 = 1 / (2 c^2),     sigma_U^2 = 5 / (4 (1 - s)^2),
# and the vertical projector is S_U = 1 / (4 (1 - s)) on each ring satellite, -1 / (1 - s) on the
# zenith one; the east projector is -sin(az) / (2 c) (N: -cos(az) / (2 c)). With the same b_nom
# = b everywhere: b_E = b_N = b / c (eq. 10: 2 b / (2 c)), b_U = 2 b / (1 - s).

EL_RING = np.deg2rad(30.0)
AZ_RING = np.deg2rad([0.0, 90.0, 180.0, 270.0])


def ring_zenith_rows():
    return rows(np.r_[AZ_RING, 0.0], np.r_[np.full(4, EL_RING), 0.5 * np.pi])


def pad(n_rows, *arrays, fill=0.0, length=8):
    """Pad (n_rows, ...) arrays to `length` rows; returns the padded arrays and valid."""
    out = []
    for a in arrays:
        a = np.asarray(a)
        p = np.full((length - n_rows, *a.shape[1:]), fill, dtype=a.dtype)
        out.append(np.concatenate([a, p]))
    return out + [np.arange(length) < n_rows]


def test_fault_free_prior_pl_is_closed_form():
    """P(no fault) = 1 (every P_s and P_const zero): only the fault-free term of eqs. (14)/(16)
    carries probability, so PL_q = b_q^(0) + sigma_q^(0) Q^-1(rhs_q / 2) with P_nm = 0."""
    c, s, b = np.cos(EL_RING), np.sin(EL_RING), 0.4
    g, const, var, bnom, p, valid = pad(5, ring_zenith_rows(), np.zeros(5, int), np.ones(5),
                                        np.full(5, b), np.zeros(5))
    bud = budget()
    res = protection_levels(araim.Sources(g, const, var, var, bnom, p, valid), np.zeros(2), bud,
                            araim.MHSSOptions(1))
    assert int(res.status) == Status.OK
    assert float(res.p_not_monitored) == 0.0
    sig_e, sig_u = 1.0 / np.sqrt(2.0 * c**2), np.sqrt(5.0 / (4.0 * (1.0 - s) ** 2))
    pl_e = b / c + sig_e * -special.ndtri(bud.phmi_h / 4.0)
    pl_u = 2.0 * b / (1.0 - s) + sig_u * -special.ndtri(bud.phmi_v / 2.0)
    assert abs(float(res.hpl_m) - np.sqrt(2.0) * pl_e) <= PL_TOL_M
    assert abs(float(res.vpl_m) - pl_u) <= PL_TOL_M
    assert float(res.sigma_acc_u_m) == pytest.approx(sig_u, rel=1e-12)
    assert float(res.emt_m) == 0.0  # no mode has prior >= P_EMT
    o = ref.protection_levels_reference(araim.Sources(g, const, var, var, bnom, p, valid),
                                        np.zeros(2), bud, ref.ReferenceOptions(max_order=1))
    assert o.hpl_m == pytest.approx(np.sqrt(2.0) * pl_e, abs=1e-5)
    assert o.vpl_m == pytest.approx(pl_u, abs=1e-5)
    # candidate modes: 5 singles (the zenith one singular: the ring alone cannot separate U from
    # the clock) and the whole constellation (singular): 4 monitored
    assert int(res.n_modes) == o.n_modes == 4


def test_lone_sop_mode_closed_form():
    """Ring + zenith (priors 0) plus ONE SOP in its own constellation with P_s = p: the only mode
    with a prior is the lone SOP, whose fault-tolerant solution is the all-in-view one (Theorem
    1: S^(i) = S^(0), T = 0, b^(i) = b^(0)), so eq. (16) reads (2 + p) Q((PL - b0)/sigma0) = rhs:
    PL_q = b_q^(0) + sigma_q^(0) Q^-1(rhs_q / (2 + p)), with the GNSS-only sigma's above."""
    c, s, p = np.cos(EL_RING), np.sin(EL_RING), 1e-3
    g6 = np.vstack([ring_zenith_rows(), rows(np.deg2rad(40.0), np.deg2rad(-5.0))])
    g, const, var, bnom, psat, valid = pad(6, g6, np.r_[np.zeros(5, int), 1],
                                           np.r_[np.ones(5), 9.0], np.zeros(6),
                                           np.r_[np.zeros(5), p])
    bud = budget()
    res = protection_levels(araim.Sources(g, const, var, var, bnom, psat, valid), np.zeros(2), bud,
                            araim.MHSSOptions(1))
    assert int(res.status) == Status.OK
    sig_e, sig_u = 1.0 / np.sqrt(2.0 * c**2), np.sqrt(5.0 / (4.0 * (1.0 - s) ** 2))
    pl_e = sig_e * -special.ndtri(bud.phmi_h / 2.0 / (2.0 + p))
    pl_u = sig_u * -special.ndtri(bud.phmi_v / (2.0 + p))
    assert abs(float(res.hpl_m) - np.sqrt(2.0) * pl_e) <= PL_TOL_M
    assert abs(float(res.vpl_m) - pl_u) <= PL_TOL_M
    assert float(res.p_not_monitored) == 0.0  # whole-GNSS mode is singular but has prior 0
    assert float(res.emt_m) == pytest.approx(0.0, abs=1e-9)  # T = 0 for the lone SOP
    # monitored: 4 ring singles (zenith single singular) + the lone SOP
    assert int(res.n_modes) == 5


def test_one_weighted_mode_pl_solves_the_equation():
    """Ring + zenith (priors 0) plus a two-SOP constellation at azimuths 90 and 270 deg on the
    horizon (variance v, P_const = p, P_s = 0). The SOP pair adds only the east difference
    (g1 - g2 = [-2, 0, 0], variance 2 v): all-in-view sigma_E^2 = 1 / (2 c^2 + 2 / v), and the
    whole-SOP mode (prior p, the only one with a prior) has sigma_E^(1)2 = 1 / (2 c^2), with
    sigma_ss,E^2 = sigma_E^(1)2 - sigma_E^(0)2 (C_acc = C_int, so the separation variance is the
    difference of variances), N and U untouched (sigma_ss = 0). N_f = 4 ring singles + 2 SOP
    singles + whole SOP = 7 (zenith single and whole GNSS singular, prior 0), so
    K_fa,E = Q^-1(P_FA_H / 28) and PL_E solves
        2 Q(PL / sigma_E^(0)) + p Q((PL - K_fa,E sigma_ss,E) / sigma_E^(1)) = PHMI_H / 2,
    while PL_N = sigma_N Q^-1(rhs / (2 + p)) and PL_U = sigma_U Q^-1(PHMI_V / (2 + p))."""
    c, s, v, p = np.cos(EL_RING), np.sin(EL_RING), 4.0, 1e-4
    g7 = np.vstack([ring_zenith_rows(), rows(np.deg2rad([90.0, 270.0]), [0.0, 0.0])])
    g, const, var, bnom, psat, valid = pad(7, g7, np.r_[np.zeros(5, int), 1, 1],
                                           np.r_[np.ones(5), v, v], np.zeros(7), np.zeros(7))
    bud = budget()
    res = protection_levels(araim.Sources(g, const, var, var, bnom, psat, valid),
                            np.array([0.0, p]), bud, araim.MHSSOptions(1))
    assert int(res.status) == Status.OK
    assert int(res.n_modes) == 7
    assert float(res.p_not_monitored) == 0.0
    s0_e, s1_e = 1.0 / np.sqrt(2 * c**2 + 2 / v), 1.0 / np.sqrt(2 * c**2)
    s_ss = np.sqrt(s1_e**2 - s0_e**2)
    k_e = -special.ndtri(bud.phmi_h / 28.0)
    q = special.ndtr

    def f(x):
        return 2 * q(-x / s0_e) + p * q(-(x - k_e * s_ss) / s1_e) - bud.phmi_h / 2

    pl_e = optimize.brentq(f, 0.0, 100.0, xtol=1e-12)
    pl_n = s1_e * -special.ndtri(bud.phmi_h / 2 / (2 + p))
    pl_u = np.sqrt(5 / (4 * (1 - s) ** 2)) * -special.ndtri(bud.phmi_v / (2 + p))
    pl = np.asarray(res.pl_enu_m)
    assert abs(pl[0] - pl_e) <= PL_TOL_M and pl[0] >= pl_e - 1e-9  # returned end is the upper
    assert abs(pl[1] - pl_n) <= PL_TOL_M
    assert abs(pl[2] - pl_u) <= PL_TOL_M
    assert float(res.hpl_m) == pytest.approx(np.hypot(pl[0], pl[1]), rel=1e-12)
    o = ref.protection_levels_reference(araim.Sources(g, const, var, var, bnom, psat, valid),
                                        np.array([0.0, p]), bud, ref.ReferenceOptions(max_order=1))
    assert o.n_modes == 7 and o.pl_enu_m == pytest.approx([pl_e, pl_n, pl_u], abs=1e-5)


def test_pl_brackets_the_root_of_the_oracle_equation(random_batch):
    """The returned PL satisfies eqs. (14)/(16) built from the oracle's sigmas, biases,
    thresholds and priors: risk(PL) <= rhs (the PL is on the safe side) and
    risk(PL - 2e-3 m) > rhs (within the tolerance of the root)."""
    case, _, res, oracle = random_batch
    bud = budget()
    checked = 0
    for i in range(0, N_RANDOM, 5):
        o = oracle[i]
        if o.status != ref.OK or o.borderline or res["status"][i] != Status.OK:
            continue
        for q in range(3):
            x = res["pl_enu_m"][i, q]
            lhs, rhs = ref.pl_equation(o, bud, q, x)
            assert lhs <= rhs * (1 + 1e-9), (i, q, x)
            lhs, rhs = ref.pl_equation(o, bud, q, x - PL_TOL_M)
            assert lhs > rhs, (i, q, x)
        checked += 1
    assert checked > 250


# --------------------------------------------------------------------------- invariances


# These reuse the 2000-geometry batch: the kernel runs 2000 geometries in well under a second,
# while every new batch shape costs a compilation of several seconds.


def _pad_with_junk(case, extra, perm_seed=None):
    """Append `extra` invalid rows of NaN/inf geometry, NaN variances and probabilities and an
    out-of-range label; with perm_seed, also shuffle every geometry's rows."""
    n = case["g"].shape[0]
    junk = {"g": np.nan, "constellation": 99, "var_int": np.nan, "var_acc": np.inf,
            "b_nom": np.nan, "p_sat": np.nan, "valid": False}
    big = {"p_const": case["p_const"]}
    for k, v in case.items():
        if k != "p_const":
            shape = (n, extra) + v.shape[2:]
            big[k] = np.concatenate([v, np.full(shape, junk[k], dtype=v.dtype)], axis=1)
    big["g"][:, L:, 0] = np.inf
    if perm_seed is not None:
        perm = np.argsort(np.random.default_rng(perm_seed).random((n, L + extra)), axis=1)
        for k in big:
            if k != "p_const":
                p = perm if big[k].ndim == 2 else perm[..., None]
                big[k] = np.take_along_axis(big[k], p, 1)
    return big


@pytest.mark.parametrize("perm_seed", [None, 11], ids=["appended", "shuffled"])
def test_padding_invariance_nan_and_inf_rows(random_batch, perm_seed):
    """Extra invalid rows with NaN/inf geometry, NaN variances and probabilities and an
    out-of-range label, appended after the valid rows or with every geometry's rows shuffled:
    same status, order, n_modes; sigma_acc_u and P_nm to 1e-9 relative; PLs and EMT within the
    solver tolerance 1e-3 m. Not bit-identical: another L is another compiled program (other
    reduction lengths and orders: rounding differs), and the fixed-count root finder returns a
    bracket end anywhere within 1e-3 m above the root, so a rounding-level change of its inputs
    can move it inside that band (up to ~2e-5 m seen with an earlier solver); most PLs agree to
    1e-9 m."""
    case, _, base, _ = random_batch
    out = run_jax(_pad_with_junk(case, 4, perm_seed))
    assert_no_nan(out)
    for k in ("status", "order", "n_modes"):
        np.testing.assert_array_equal(out[k], base[k], err_msg=k)
    for k in ("sigma_acc_u_m", "p_not_monitored"):
        np.testing.assert_allclose(out[k], base[k], rtol=1e-9, atol=1e-18, err_msg=k)
    for k in ("hpl_m", "vpl_m", "emt_m"):
        np.testing.assert_allclose(out[k], base[k], rtol=0, atol=1e-3, err_msg=k)
    ok = base["status"] == Status.OK
    assert np.mean(np.abs(out["vpl_m"][ok] - base["vpl_m"][ok]) <= 1e-9) > 0.95


def test_absent_constellation_p_const_is_ignored(random_batch):
    """A constellation slot with no valid source has no clock and no P_const event: changing its
    P_const changes nothing (Galileo off, or an empty second SOP constellation)."""
    case, _, base, _ = random_batch
    present = np.zeros((case["g"].shape[0], C), bool)
    for c in range(C):
        present[:, c] = np.any(case["valid"] & (case["constellation"] == c), axis=1)
    assert np.any(~present)
    alt = dict(case)
    alt["p_const"] = np.where(present, case["p_const"], 0.3)
    out = run_jax(alt)
    for k in base:
        np.testing.assert_array_equal(out[k], base[k], err_msg=k)


def test_batch_shape_invariance():
    """(4,) batch, (2, 2) batch and single geometries give identical results (the small GNSS
    cases below, OK and failed ones mixed)."""
    cases = [_gps_only(8), _gps_only(4), _gps_only(7), _gps_only(8, p_const_gps=1e-6)]
    stacked = [np.stack([c[k] for c in cases]) for k in range(8)]
    flat = protection_levels(araim.Sources(*stacked[:6], stacked[-1]), stacked[6], budget(),
                             araim.MHSSOptions(1))
    four = [a.reshape((2, 2) + a.shape[1:]) for a in stacked]
    shaped = protection_levels(araim.Sources(*four[:6], four[7]), four[6], budget(),
                               araim.MHSSOptions(1))
    for k in flat._fields:
        a, b = np.asarray(getattr(flat, k)), np.asarray(getattr(shaped, k))
        assert b.shape[:2] == (2, 2), k
        np.testing.assert_array_equal(b.reshape(a.shape), a, err_msg=k)
    for i, c in enumerate(cases):
        one = protection_levels(araim.Sources(*c[:6], c[-1]), c[6], budget(), araim.MHSSOptions(1))
        for k in flat._fields:
            np.testing.assert_allclose(np.asarray(getattr(one, k)),
                                       np.asarray(getattr(flat, k))[i], rtol=1e-12, err_msg=k)


def test_broadcast_arguments(random_batch):
    """Scalars and per-constellation p_const broadcast over the batch like full arrays."""
    case = random_batch[0]
    full = dict(case)
    full["b_nom"] = np.full_like(case["b_nom"], 0.75)
    a = run_jax(full)
    res = protection_levels(araim.Sources(case["g"], case["constellation"], case["var_int"],
                                          case["var_acc"], 0.75, case["p_sat"], case["valid"]),
                            P_CONST, budget(), araim.MHSSOptions(3))
    for k in a:
        np.testing.assert_array_equal(np.asarray(getattr(res, k)), a[k], err_msg=k)


# --------------------------------------------------------------------------- failures as data


def _gps_only(n_sats, el_deg=None, p_const_gps=1e-8, length=8):
    rng = np.random.default_rng(n_sats)
    az = rng.uniform(0, 2 * np.pi, n_sats)
    el = np.deg2rad(el_deg if el_deg is not None else rng.uniform(10, 80, n_sats))
    vi, va = (np.asarray(x) for x in gnss_variances(el * np.ones(n_sats)))
    g, const, vi, va, b, p, valid = pad(n_sats, rows(az, el * np.ones(n_sats)),
                                        np.zeros(n_sats, int), vi, va, np.full(n_sats, 0.75),
                                        np.full(n_sats, 1e-5), length=length)
    vi[~valid] = va[~valid] = 1.0
    return g, const, vi, va, b, p, np.array([p_const_gps, 1e-4]), valid


def _assert_failed(res, status):
    for k in ("hpl_m", "vpl_m", "emt_m", "sigma_acc_u_m"):
        v = np.asarray(getattr(res, k))
        assert np.all(v == np.inf), (k, v)
    for k in res._fields:
        assert not np.any(np.isnan(np.asarray(getattr(res, k), float))), k
    assert np.all(np.asarray(res.status) == status)


def test_too_few_sources_is_inf_with_status_1():
    """4 GPS satellites: 3 + 1 states + 1 redundancy needed = 5 sources; also 0 sources."""
    args = _gps_only(4)
    _assert_failed(protection_levels(araim.Sources(*args[:6], args[-1]), args[6], budget(),
                                     araim.MHSSOptions(1)),
                   Status.TOO_FEW_SOURCES)
    none = np.zeros(8, bool)
    _assert_failed(protection_levels(araim.Sources(*args[:6], none), args[6], budget(),
                                     araim.MHSSOptions(1)),
                   Status.TOO_FEW_SOURCES)
    o = ref.protection_levels_reference(araim.Sources(*args[:6], args[-1]), args[6], budget(),
                                        ref.ReferenceOptions(max_order=1))
    assert o.status == ref.TOO_FEW_SOURCES and o.hpl_m == np.inf


def test_singular_all_in_view_is_inf_with_status_2():
    """Six satellites all at 40 deg elevation: up and clock columns are collinear."""
    args = _gps_only(6, el_deg=40.0)
    _assert_failed(protection_levels(araim.Sources(*args[:6], args[-1]), args[6], budget(),
                                     araim.MHSSOptions(1)),
                   Status.SINGULAR_GEOMETRY)
    o = ref.protection_levels_reference(araim.Sources(*args[:6], args[-1]), args[6], budget(),
                                        ref.ReferenceOptions(max_order=1))
    assert o.status == ref.SINGULAR_GEOMETRY


def test_unmet_p_thresh_is_inf_with_status_5():
    """GPS only with P_const = 1e-6 > P_thresh: the whole-GPS mode is singular (nothing left),
    so P_nm >= 1e-6 > 6e-8: UNMONITORED_RISK, P_nm still reported."""
    args = _gps_only(8, p_const_gps=1e-6)
    res = protection_levels(araim.Sources(*args[:6], args[-1]), args[6], budget(),
                            araim.MHSSOptions(1))
    _assert_failed(res, Status.UNMONITORED_RISK)
    o = ref.protection_levels_reference(araim.Sources(*args[:6], args[-1]), args[6], budget(),
                                        ref.ReferenceOptions(max_order=1))
    assert o.status == ref.UNMONITORED_RISK
    assert float(res.p_not_monitored) == pytest.approx(o.p_not_monitored, rel=1e-9)
    assert float(res.p_not_monitored) > 1e-6


def test_mixed_batch_failures_do_not_leak():
    """A batch mixing OK, too-few, singular and unmet-P_thresh geometries: each row gets its own
    status and the OK rows equal their single-geometry results."""
    cases = [_gps_only(8), _gps_only(4), _gps_only(6, el_deg=40.0), _gps_only(8, p_const_gps=1e-6)]
    stacked = [np.stack([c[k] for c in cases]) for k in range(8)]
    res = protection_levels(araim.Sources(*stacked[:6], stacked[-1]), stacked[6], budget(),
                            araim.MHSSOptions(1))
    np.testing.assert_array_equal(np.asarray(res.status), [0, 1, 2, 5])
    for k in res._fields:
        assert not np.any(np.isnan(np.asarray(getattr(res, k), float))), k
    c0 = cases[0]
    one = protection_levels(araim.Sources(*c0[:6], c0[7]), c0[6], budget(), araim.MHSSOptions(1))
    assert float(res.hpl_m[0]) == pytest.approx(float(one.hpl_m), abs=1e-9)
    assert np.isinf(np.asarray(res.hpl_m[1:])).all()


def test_bad_input_is_rejected_with_the_field_name():
    args = list(_gps_only(8))
    with pytest.raises(ValueError, match="var_int"):
        protection_levels(araim.Sources(args[0], args[1], -args[2], *args[3:6], args[7]),
                          args[6], budget(), araim.MHSSOptions(1))
    with pytest.raises(ValueError, match="p_sat"):
        protection_levels(araim.Sources(*args[:5], args[5] + 1.5, args[7]), args[6], budget(),
                          araim.MHSSOptions(1))


@pytest.mark.parametrize("name, value, match", [
    ("var_int_m2", np.nan, "var_int_m2"), ("var_int_m2", np.inf, "var_int_m2"),
    ("var_acc_m2", 0.0, "var_acc_m2"), ("b_nom_m", -1e-9, "b_nom_m"),
    ("b_nom_m", np.nan, "b_nom_m"), ("p_sat", 1.0, "p_sat"), ("p_sat", -1e-12, "p_sat"),
    ("constellation", 2, "constellation labels"), ("constellation", -1, "constellation labels")])
def test_input_checks_see_valid_sources_only(name, value, match):
    """The range checks, on the host (``prepare_inputs``: fast path on the minimum and maximum,
    masked test when that fails) and in the kernel (``protection_levels`` with ``max_order``
    given: ``invalid_input_flags``, then the host check for the message): a bad value at a valid
    source raises naming its argument; the same value at a source marked invalid (padding,
    whatever it holds) is accepted, and the PLs are those of the clean batch."""
    from oaraim.araim.mhss import prepare_inputs

    keys = ["g", "constellation", "var_int_m2", "var_acc_m2", "b_nom_m", "p_sat", "p_const",
            "valid"]
    base = dict(zip(keys, (np.asarray(a).copy() for a in _gps_only(8)), strict=True))
    base["g"], base["valid"] = np.stack([base["g"]] * 3), np.stack([base["valid"]] * 3)
    for k in ("constellation", "var_int_m2", "var_acc_m2", "b_nom_m", "p_sat"):
        base[k] = np.stack([base[k]] * 3)
    base["valid"][1, 5] = False
    def sources(d):
        return araim.Sources(*(d[k] for k in keys[:6]), d["valid"])

    prepare_inputs(sources(base), base["p_const"])  # the clean batch passes
    clean = protection_levels(sources(base), base["p_const"], budget(), araim.MHSSOptions(1))
    padded = {k: v.copy() for k, v in base.items()}
    padded[name][1, 5] = value
    prepare_inputs(sources(padded), padded["p_const"])  # at an invalid source: accepted
    got = protection_levels(sources(padded), padded["p_const"], budget(), araim.MHSSOptions(1))
    np.testing.assert_array_equal(np.asarray(got.hpl_m), np.asarray(clean.hpl_m))
    used = {k: v.copy() for k, v in base.items()}
    used[name][2, 3] = value
    with pytest.raises(ValueError, match=match):
        prepare_inputs(sources(used), used["p_const"])
    for max_order in (1, None):  # in the kernel, and on the host before required_order
        with pytest.raises(ValueError, match=match):
            protection_levels(sources(used), used["p_const"], budget(),
                              araim.MHSSOptions(max_order))


def test_required_order_is_the_largest_per_geometry_order():
    """``max_order=None``: ``required_order`` (one jitted pass over the batch) picks the largest
    of the oracle's per-geometry orders (``reference_mhss.fault_mode_set``), capped at 3, for
    random batches of 1-4 present constellations with P_s 1e-6..1e-2 and P_const 1e-9..1e-3;
    and each single geometry gets its own order."""
    from oaraim.araim.mhss import required_order

    rng = np.random.default_rng(7)
    n, n_src, n_const = 400, 10, 4
    valid = rng.random((n, n_src)) < 0.85
    lab = rng.integers(0, n_const, (n, n_src))
    p_sat = 10.0 ** rng.uniform(-6, -2, (n, n_src))
    p_const = 10.0 ** rng.uniform(-9, -3, (n, n_const))
    p_thresh = araim.BUDGET_SEED004_TABLE_I.p_thresh
    orders = np.array([ref.fault_mode_set(valid[i], lab[i], p_sat[i], p_const[i], p_thresh,
                                          3).order for i in range(n)])
    assert set(orders) == {1, 2, 3}  # the batch spans every order
    for i in range(40):
        assert required_order(valid[i:i + 1], lab[i:i + 1], p_sat[i:i + 1], p_const[i:i + 1],
                              p_thresh) == orders[i], i
    low = np.flatnonzero(orders <= 2)
    assert required_order(valid[low], lab[low], p_sat[low], p_const[low], p_thresh) == 2
    assert required_order(valid.reshape(2, n // 2, n_src), lab.reshape(2, n // 2, n_src),
                          p_sat.reshape(2, n // 2, n_src), p_const.reshape(2, n // 2, n_const),
                          p_thresh) == 3
    assert required_order(valid, lab, p_sat, p_const, p_thresh, cap=2) == 2


def test_root_finder_q_and_density_match_scipy():
    """The root finder's (Q, phi) pair against SciPy: Q to 1e-14 relative wherever
    Q > 1e-29 (its docstring claims 1e-15 against erfc; SciPy's ndtr adds its own rounding),
    phi = exp(-t^2/2)/sqrt(2 pi) to 1e-15 plus the conditioning of exp at z = t^2/2 (an
    argument rounded by eps moves exp(-z) by z eps relative; both sides round z, twice:
    4 z eps), over t from -10 to 11 plus the branch point x = 1 (t = sqrt 2) from both sides."""
    from oaraim.araim.mhss.root import q_and_density, q_and_density_fast

    t = np.concatenate([np.linspace(-10.0, 11.0, 20_001),
                        np.sqrt(2.0) + np.array([-1e-12, 0.0, 1e-12])])
    q, phi = (np.asarray(a) for a in jax.jit(q_and_density)(t))
    q_ref = special.ndtr(-t)
    phi_ref = np.exp(-0.5 * t * t) / np.sqrt(2.0 * np.pi)
    keep = q_ref > 1e-29
    assert keep.sum() > 19_000
    assert np.max(np.abs(q[keep] / q_ref[keep] - 1.0)) < 1e-14
    z = 0.5 * t * t
    assert np.all(np.abs(phi / phi_ref - 1.0) < 1e-15 + 4.0 * z * np.finfo(float).eps)
    # the fast path's steps: one erfc branch for all x, Q within 1e-8 relative (measured
    # 9.8e-9 on [0, 1) for erfc, the largest near x = 0; Q(t < 0) = 1 - Q(-t) halves it)
    q_fast, phi_fast = (np.asarray(a) for a in jax.jit(q_and_density_fast)(t))
    assert np.max(np.abs(q_fast[keep] / q_ref[keep] - 1.0)) < 1e-8
    assert np.max(np.abs(q_fast[np.abs(t) >= np.sqrt(2.0)] / q[np.abs(t) >= np.sqrt(2.0)]
                         - 1.0)) < 1e-15  # the same branch as q_and_density there
    np.testing.assert_array_equal(phi_fast, phi)


def test_root_finder_bracket_q_inverse_bounds():
    """The bracket of ``solve_pl`` rests on two bounds of Q^-1(p), checked against SciPy's
    ndtri on a log grid over [1e-300, 1/2] and on (1/2, 1):
    - ``q_inverse_approx`` (A&S 26.2.23, published |error| < 4.5e-4) stays within 4.5e-4, so
      k_lo = approx - Q_INVERSE_APPROX_MARGIN (1e-3) is below Q^-1 (lower end valid);
    - the Chernoff end sqrt(-2 ln 2p) (0 above p = 1/2) is never below Q^-1 (upper end
      valid), and at most 0.52 above it for p >= 1e-300."""
    from oaraim.araim.mhss import Q_INVERSE_APPROX_MARGIN, q_inverse_approx

    p_low = np.logspace(-300.0, np.log10(0.5), 200_001)
    p = np.concatenate([p_low, 1.0 - p_low[p_low > 1e-15], np.linspace(0.3, 0.7, 20_001)])
    exact = -special.ndtri(p)
    k = np.asarray(jax.jit(q_inverse_approx)(p))
    err = np.abs(k - exact)
    assert err.max() < 4.5e-4
    assert np.all(k - Q_INVERSE_APPROX_MARGIN < exact)
    chernoff = np.sqrt(np.maximum(-2.0 * np.log(2.0 * p), 0.0))
    assert np.all(chernoff >= exact - 1e-12)
    assert np.max((chernoff - exact)[p <= 0.5]) < 0.52


def _random_pl_terms(seed, n=4000, terms=24):
    """PL equations like the random geometries' (fault-free term first, coef 2), batch last."""
    rng = np.random.default_rng(seed)
    rhs = np.where(rng.random(n) < 0.5, 1e-9, 9.8e-8)
    # priors from 1/10 of the budget to 0.1, a fifth of them within 3x of it (such a term can
    # dominate where it is concave, t < 0), a fifth unmonitored (0)
    coef = rhs * 10.0 ** rng.uniform(-1.0, np.log10(0.1 / rhs), (terms, n))
    near = rng.random((terms, n)) < 0.2
    coef[near] = (rhs * rng.uniform(1.0, 3.0, (terms, n)))[near]
    coef[rng.random((terms, n)) < 0.2] = 0.0
    coef[0] = 2.0
    mean = rng.uniform(0.0, 60.0, (terms, n))
    mean[0] = rng.uniform(0.0, 2.0, n)
    sd = 10.0 ** rng.uniform(-0.5, 2.0, (terms, n))
    return coef, mean, sd, rhs


def _roots(coef, mean, sd, rhs):
    def f(x, j):
        return np.sum(coef[:, j] * special.ndtr(-(x - mean[:, j]) / sd[:, j])) - rhs[j]
    return np.array([optimize.brentq(f, -1e3, 1e5, args=(j,), xtol=1e-13)
                     for j in range(rhs.size)])


def test_lower_slope_bound_holds_for_convex_and_concave_terms():
    """The fast path's lower proof: R(x - delta) >= R(x) + delta Dl(x) (``risk_lower_slope``)
    for terms convex, concave (t < 0) and mixed on [x - delta, x], with exact SciPy values;
    Dl <= D = -R' (``risk_sum``, checked by central differences), and Dl = D where every term has
    t >= e / 2."""
    from oaraim.araim.mhss.root import risk_lower_slope, risk_sum

    coef, mean, sd, rhs = _random_pl_terms(3, n=3000)
    rng = np.random.default_rng(4)
    x = rng.uniform(-20.0, 80.0, rhs.size)
    for delta in (1e-4, 1e-3, 0.5, 5.0):
        r, dl = (np.asarray(a) for a in jax.jit(risk_lower_slope)(
            x, delta, coef, mean, 1.0 / sd, coef / sd))
        r_, d = (np.asarray(a) for a in jax.jit(risk_sum)(x, coef, mean, 1.0 / sd))
        np.testing.assert_allclose(r, r_, rtol=1e-14)

        def risk(y):
            return np.sum(coef * special.ndtr(-(y[None] - mean) / sd), axis=0)

        lower = risk(x - delta)
        assert np.all(lower >= (r + delta * dl) * (1 - 1e-12)), delta
        assert np.all(dl <= d * (1 + 1e-14))
        t_min = np.min(np.where(coef > 0, (x[None] - mean) / sd - 0.5 * delta / sd, np.inf), 0)
        np.testing.assert_allclose(dl[t_min >= 0], d[t_min >= 0], rtol=1e-14)
    h = 1e-5  # rounding of R ~ 2 (the fault-free term) over 2 h: ~1e-10 absolute
    numeric = (risk(x - h) - risk(x + h)) / (2 * h)
    np.testing.assert_allclose(d, numeric, rtol=1e-5, atol=1e-9)


def test_halley_step_one_term_closed_form():
    """One term c Q((x - m)/s) = rhs has the root m + s Q^-1(rhs / c). Halley's method in z
    space converges cubically: from 0.6 m (0.3 s) below the root, 6.8e-4 m after one step,
    8.7e-13 m after two."""
    from oaraim.araim.mhss.root import halley_step, risk_curvature

    c, m, s = np.array([[1e-5]]), np.array([[3.0]]), np.array([[2.0]])
    rhs = np.array([1e-9])
    root = m[0] + s[0] * -special.ndtri(rhs / c[0])
    x = root - 0.3 * s[0]
    errors = []
    for _ in range(2):
        x = np.asarray(halley_step(x, *risk_curvature(x, c, m, 1 / s, c / s, c / s**2),
                                    np.sqrt(-2 * np.log(rhs))))
        errors.append(abs(float(x[0] - root[0])))
    e0 = 0.3 * float(s[0, 0])
    assert errors[0] < 1e-3 and errors[1] < 1e-11, errors
    # cubic: the same constant e_k+1 / e_k^3 for both steps (measured 3.1e-3 / m^2 and 2.8e-3)
    ratio = (errors[1] / errors[0] ** 3) / (errors[0] / e0**3)
    assert 0.3 < ratio < 3, ratio


def test_taylor_third_derivative_bound_holds():
    """``solve_pl``'s Taylor proof: |R'''(s)| <= ``TAYLOR_B3_FACTOR`` B3(x) at every s within h
    of x where h max_j (1 / sd_j) <= ``TAYLOR_E_MAX`` (``risk_taylor``), R''' in closed form
    (sum_j coef_j (1 - t^2) phi(t) / sd_j^3) at 41 points of the interval, for terms with t from
    -45 to 45 (phi underflowing at either end); and its R, D, D2 are ``risk_curvature``'s to
    1e-8 (that one's approximate Q) and D, D2 exactly. The bound for both forms of the sums
    (terms written out, and one array over the terms, used beyond ``UNROLL_TERMS`` terms)."""
    from oaraim.araim.mhss.root import (
        TAYLOR_B3_FACTOR,
        TAYLOR_E_MAX,
        risk_curvature,
        risk_taylor,
    )

    coef, mean, sd, rhs = _random_pl_terms(5, n=3000, terms=12)
    rng = np.random.default_rng(6)
    x = mean[0] + sd[0] * rng.uniform(-45.0, 45.0, rhs.size)
    mean = np.where(rng.random(mean.shape) < 0.5, x - sd * rng.uniform(-45, 45, mean.shape), mean)
    inv_sd = 1.0 / sd
    cw = coef * inv_sd
    r_, d_, d2_ = (np.asarray(a) for a in jax.jit(risk_curvature)(
        x, coef, mean, inv_sd, cw, cw * inv_sd))
    h = TAYLOR_E_MAX / np.max(np.where(coef > 0, inv_sd, 0.0), axis=0)
    thirds = [np.sum(coef * (1 - t**2) * stats.norm.pdf(t) * inv_sd**3, axis=0)
              for t in ((x + f * h - mean) * inv_sd for f in np.linspace(-1.0, 1.0, 41))]
    for unroll_terms in (64, 0):  # terms written out, and one array over the terms
        r, d, d2, b3 = (np.asarray(a) for a in jax.jit(
            lambda *a, u=unroll_terms: risk_taylor(*a, unroll_terms=u))(
            x, coef, mean, inv_sd, cw, cw * inv_sd, cw * inv_sd**2))
        if unroll_terms:  # (the other form agrees with this one to rounding: test below)
            np.testing.assert_allclose(r, r_, rtol=1e-8, atol=1e-300)
            np.testing.assert_allclose(d, d_, rtol=1e-14, atol=0)
            np.testing.assert_allclose(d2, d2_, rtol=1e-14, atol=0)
        for third in thirds:
            assert np.all(np.abs(third) <= TAYLOR_B3_FACTOR * b3), unroll_terms
    # the tails are exercised: a tenth of the terms where phi(t) underflows (B3's floor term)
    assert np.mean(np.abs((x - mean) * inv_sd) > 38.5) > 0.1


def test_risk_sums_unrolled_and_vectorised_agree():
    """The two forms of the risk sums (terms written out, for the fast path; one array over the
    terms, for the rarely run parts of ``solve_pl`` and beyond ``UNROLL_TERMS`` terms, cheaper to
    compile) give the same R, D, lower slope, D2 and third-derivative bound to rounding
    (summation order only)."""
    from oaraim.araim.mhss.root import risk_lower_slope, risk_sum, risk_taylor

    coef, mean, sd, rhs = _random_pl_terms(3)
    x = mean.max(axis=0) + sd.max(axis=0)
    inv_sd = 1.0 / sd
    cw = coef * inv_sd
    for f, args in ((risk_sum, (x, coef, mean, inv_sd)),
                    (risk_lower_slope, (x, 1e-4, coef, mean, inv_sd, cw)),
                    (risk_taylor, (x, coef, mean, inv_sd, cw, cw * inv_sd, cw * inv_sd**2))):
        unrolled = jax.jit(lambda *a, f=f: f(*a, unroll_terms=64))(*args)
        vectorised = jax.jit(lambda *a, f=f: f(*a, unroll_terms=0))(*args)
        for u, v in zip(unrolled, vectorised, strict=True):
            np.testing.assert_allclose(np.asarray(v), np.asarray(u), rtol=1e-13, atol=0)


def test_solve_pl_fast_path_and_fallback_bracket_the_root():
    """``solve_pl`` on 4000 hard random PL equations (24 terms, priors from 1/10 of the budget
    to 0.1, means up to 60 m, sd 0.3-100 m): every PL is at or above the exact root (SciPy
    brentq) and within 1e-3 m of it, within 1e-4 m where the fast path proved it. Counted with
    the bracketed branch replaced by NaN: the Taylor proof of the two Halley steps alone proves
    90.6 %, with the first probe 97.7 %, then 99.6 %, 99.9 %, and the default rounds all.
    With one round allowed, the bracketed branch runs for the rest and still brackets the
    root; the bracketed solver alone agrees within 1e-3 m."""
    from oaraim.araim import mhss
    from oaraim.araim.mhss import root as root_finder

    coef, mean, sd, rhs = _random_pl_terms(11)
    root = _roots(coef, mean, sd, rhs)

    def solve(rounds=mhss.FAST_EXTRA_ROUNDS, bracketed=True):
        def no_bracketed(coef, mean, sd, rhs, iterations, **_):
            return jnp.full(rhs.shape, jnp.nan), jnp.zeros(rhs.shape, bool)
        with pytest.MonkeyPatch.context() as mp:
            if not bracketed:
                mp.setattr(root_finder, "solve_pl_bracketed", no_bracketed)
            mp.setattr(root_finder, "FAST_EXTRA_ROUNDS", rounds)
            # a new function each time: jit's cache would reuse a trace made under other patches
            pl, converged = jax.jit(lambda *a: mhss.solve_pl(*a))(coef, mean, sd, rhs)
        return np.asarray(pl), np.asarray(converged)

    def check(pl, converged):
        assert converged.all()
        assert np.all(pl >= root - 1e-9) and np.all(pl - root <= mhss.PL_TOLERANCE_M)

    pl, converged = solve()
    check(pl, converged)
    proved = [solve(rounds, bracketed=False)[1] for rounds in (0, 1, mhss.FAST_EXTRA_ROUNDS)]
    assert proved[0].sum() < proved[1].sum() < rhs.size == proved[2].sum()
    assert np.all(pl - root <= mhss.FAST_PROOF_TOL_M)
    check(*solve(rounds=1))  # the bracketed branch runs for the 2.3 % left
    pl_b, converged_b = (np.asarray(a) for a in jax.jit(mhss.solve_pl_bracketed)(
        coef, mean, sd, rhs))
    assert converged_b.all() and np.all(np.abs(pl_b - pl) <= mhss.PL_TOLERANCE_M)


def test_bench_case_is_proved_by_the_taylor_step():
    """The fast path's reason to exist: on the issue-3 benchmark case (9 GPS + 4 SOPs, Table I)
    the Taylor proof of the two Halley steps alone settles the PL equations, so the probe loop
    and the bracketed branch stay idle in (almost) every tile. With both disabled (no probe
    round, bracketed solver returning NaN), at most 1 of 4096 geometries is NOT_CONVERGED
    (measured: 1 of 65,536 at seed 0, where the first Halley step was 7e-3 m off)."""
    from oaraim.araim.mhss import Sources, protection_levels_kernel, root
    from oaraim.batching import jit_kernel
    from oaraim.bench import mhss_bench_inputs

    x = mhss_bench_inputs(4096, seed=3)

    def no_bracketed(coef, mean, sd, rhs, iterations, **_):
        return jnp.full(rhs.shape, jnp.nan), jnp.zeros(rhs.shape, bool)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(root, "solve_pl_bracketed", no_bracketed)
        mp.setattr(root, "FAST_EXTRA_ROUNDS", 0)
        # a new jitted function: the cached kernels were traced without these patches
        res = jit_kernel(lambda s, p_const: protection_levels_kernel(s, p_const, budget(),
                                                                     araim.MHSSOptions(1)))(
            Sources(*(x[k] for k in Sources._fields)), x["p_const"])
    status = np.asarray(res.status)
    assert np.sum(status == Status.NOT_CONVERGED) <= 1
    assert np.sum(status == Status.OK) >= status.size - 1


def test_threaded_split_is_bit_identical_to_one_call():
    """oaraim.batching.map_threads: parts of whole tiles on host threads give exactly the bits
    of one call, for a batch that splits unevenly into 2 or 3 parts, and one that is not split
    (fewer than 2 tiles per thread)."""
    from oaraim.araim.mhss import prepare_inputs, protection_levels_threaded
    from oaraim.batching import TILE
    from oaraim.bench import mhss_bench_inputs

    x = mhss_bench_inputs(6 * TILE + 37, seed=5)
    src, pc = prepare_inputs(araim.Sources(*(x[k] for k in araim.Sources._fields[:6]),
                                           x["valid"]), x["p_const"])
    args = (*src[:6], pc, src.valid)
    budget = araim.BUDGET_SEED004_TABLE_I
    opts = araim.MHSSOptions(1, fault_modes=GROUPED)
    one = protection_levels_threaded(src, pc, budget, opts, threads=1)
    # shapes compiled: 1573 (one call), 1024 (2 parts of 4 tiles), 768 (3 parts of 3 tiles,
    # and the unsplit 3-tile batch)
    for n, threads in ((6 * TILE + 37, 2), (6 * TILE + 37, 3), (3 * TILE, 2)):
        part = araim.Sources(*(a[:n] for a in src))
        ref = one if n == 6 * TILE + 37 else protection_levels_threaded(
            part, pc[:n], budget, opts, threads=1)
        got = protection_levels_threaded(part, pc[:n], budget, opts, threads=threads)
        for name, a, b in zip(got._fields, got, ref, strict=True):
            assert a.shape == b.shape and np.array_equal(np.asarray(a), np.asarray(b)), name
    assert np.all(np.isfinite(np.asarray(one.hpl_m)))
    # inside a caller's jit the split is skipped (threads cannot share a trace): same bits
    part = args  # 7 tiles: split into 2 parts were it not traced
    jitted = jax.jit(lambda *a: protection_levels(araim.Sources(*a[:6], a[7]), a[6], budget,
                                                  araim.MHSSOptions(1), threads=2).hpl_m)(*part)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(one.hpl_m), rtol=1e-12)
    with pytest.raises(ValueError, match="threads"):
        protection_levels(araim.Sources(*args[:6], args[7]), args[6], budget, araim.MHSSOptions(1),
                          threads=0)
    # the public call: split over 2 threads with the kernel's input flags, same bits; a bad
    # value at a valid source of the second part is caught there and named by the host check
    public = protection_levels(araim.Sources(*args[:6], args[7]), args[6], budget,
                               araim.MHSSOptions(1), threads=2)
    for name, a, b in zip(public._fields, public, one, strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b)), name
    bad = np.array(args[3])
    bad[6 * TILE + 3, 2] = -1.0
    with pytest.raises(ValueError, match="var_acc_m2"):
        protection_levels(araim.Sources(*args[:3], bad, *args[4:6], args[7]), args[6], budget,
                          araim.MHSSOptions(1), threads=2)


def test_kernel_compiler_options_change_no_bit():
    """oaraim.batching.KERNEL_COMPILER_OPTIONS (512-bit vectors) change speed only: the kernel
    compiled with them gives exactly the bits of XLA's default options (the bench case, at the
    shape and seed of the threaded test above, whose compiled kernel it reuses). Checked once
    beyond this: the 2000 random geometries of ``random_cases`` at orders 1, 2 and
    3 (whole, single and generic modes) and the FDE functions, all bit-identical."""
    from oaraim.araim.mhss import (
        Sources,
        prepare_inputs,
        protection_levels_kernel,
        protection_levels_threaded,
    )
    from oaraim.batching import KERNEL_COMPILER_OPTIONS, TILE
    from oaraim.bench import mhss_bench_inputs

    assert KERNEL_COMPILER_OPTIONS  # else this compares a kernel with itself
    x = mhss_bench_inputs(6 * TILE + 37, seed=5)
    src, pc = prepare_inputs(Sources(*(x[k] for k in Sources._fields[:6]), x["valid"]),
                             x["p_const"])
    budget = araim.BUDGET_SEED004_TABLE_I
    opts = araim.MHSSOptions(1, fault_modes=GROUPED)
    got = protection_levels_threaded(src, pc, budget, opts, threads=1)
    # a plain jax.jit around the kernel: XLA's default options (the kernel runs inline)
    want = jax.jit(lambda s, p_const: protection_levels_kernel(s, p_const, budget, opts))(
        src, pc)
    assert np.all(np.isfinite(np.asarray(want.hpl_m)))
    for name, a, b in zip(got._fields, got, want, strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b)), name
