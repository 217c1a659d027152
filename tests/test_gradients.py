"""Gradients of the MHSS protection levels: ``jax.jvp`` / ``jax.grad`` through
``araim.protection_levels_kernel``, whose PL roots are differentiated by the implicit function
theorem (``araim.mhss.implicit``), against hand derivations, central finite differences of the
kernel and of the NumPy oracle, and ``jax.test_util.check_grads``.

One batch of 16 geometries (a bucket size of the kernel) serves every test, so that each
transformation compiles once: rows 0-11 the bench case (9 GPS + 4 BPP SOPs, grouped, order 1;
GPS P_s 0.8e-5, ``BENCH_GPS_P_SAT``; positions moved horizontally, ``HORIZONTAL``),
row 12 the same sky with every prior 0 (the fault-free term alone: a closed form), row 13 with
one SOP turned into padding (junk values), row 14 with too few sources and row 15 with
unmonitored risk (P_NM > P_thresh): inf PLs whose gradients must be 0, never NaN.

The inputs are parameterised physically: GPS rows by azimuth and elevation (rad), SOP rows by
tower and receiver positions in a local ENU frame (m, ``geometry.geometry_rows_enu``), the
variances, biases and priors as they are. Finite-difference steps, chosen by hand:

- angles 1e-5 rad, positions 0.1 m (a tower 1-3 km away turns by ~5e-5 rad): the PLs move by
  ~1e-4 m, far above the kernel's root noise (the fast path returns the root + 1e-6 m to
  ~3e-11 m: an FD error of ~3e-6 relative at worst), and the truncation error (step^2
  f''' / 6) is ~1e-10 relative;
- variances, priors: 1e-4 relative; biases 1e-4 m (GPS only: an SOP's b_nom is 0 and may not
  go negative).

Tolerance: |AD - FD| <= 1e-5 |FD| + 1e-10 m / h: the second term is the FD's own noise, a
value noise of 1e-10 m (the kernel's root within ~3e-11 m of the exact one, the oracle's
re-solved to 1e-12 m, float64 rounding of ~20 m) divided by the step; it also lets exact zeros
(the EMT with respect to a bias) compare absolutely. Geometries within 1e-3 (relative,
ten times the steps) of a decision switch (``switch_flags_kernel``) are excluded, and the test
checks that the bench rows have none.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy import optimize, special

from oaraim import araim, geometry
from oaraim import reference_mhss as ref
from oaraim.araim import Sources, Status
from oaraim.araim.mhss import implicit_root, solve_pl
from oaraim.bench import mhss_bench_inputs

BUDGET = araim.BUDGET_SEED004_TABLE_I
N, N_GPS, N_SOP = 16, 9, 4
OK_ROWS = np.arange(14)  # rows whose PLs are finite
FAILED_ROWS = (14, 15)
RTOL, VALUE_NOISE_M = 1e-5, 1e-10
#: (kind, FD step); directions: N(0, 1) in the kind's unit, relative for variances and priors
STEPS = {"gps_az_rad": 1e-5, "gps_el_rad": 1e-5, "tower_enu_m": 0.1, "receiver_enu_m": 0.1,
         "var_int_m2": 1e-4, "var_acc_m2": 1e-4, "b_nom_m": 1e-4, "p_sat": 1e-4,
         "p_const": 1e-4}
RELATIVE = ("var_int_m2", "var_acc_m2", "p_sat", "p_const")
OUTPUTS = ("hpl_m", "vpl_m", "emt_m", "sigma_acc_u_m")
BENCH_GPS_P_SAT = 0.8e-5
#: positions move horizontally only (east, north): the bench puts the towers at the
#: receiver's height, where the SOP-only mode (GPS excluded) has no vertical information at all
#: (singular, its pivot exactly 0); any vertical move makes it regular, with a vertical sigma
#: of hundreds of metres that then sets the VPL: a switch (not flagged: an exactly zero pivot
#: is not near the tolerance in ratio; docs/gradients.md)
HORIZONTAL = np.array([1.0, 1.0, 0.0])


def _params():
    """The 16 geometries as physical parameters (module docstring)."""
    x = {k: np.array(v) for k, v in mhss_bench_inputs(N, seed=7).items()}
    g = x["g"]
    el = np.arcsin(-g[..., 2])
    az = np.arctan2(-g[..., 0], -g[..., 1])
    rng = np.random.default_rng(27)
    dist = rng.uniform(1000.0, 3000.0, (N, N_SOP, 1))
    p = dict(gps_az_rad=az[:, :N_GPS], gps_el_rad=el[:, :N_GPS],
             tower_enu_m=-g[:, N_GPS:] * dist, receiver_enu_m=np.zeros((N, 3)),
             var_int_m2=x["var_int_m2"], var_acc_m2=x["var_acc_m2"], b_nom_m=x["b_nom_m"],
             p_sat=x["p_sat"], p_const=x["p_const"])
    # the bench's GPS P_s = 1e-5 gives single-satellite priors 1e-5 (1 - ~1e-4), within 1e-4
    # (relative) below P_EMT = 1e-5: a relative FD step of 1e-4 would cross the EMT's switch
    # (test_switch_flags_mark_the_bench_emt_edge); 0.8e-5 keeps them 20 % below
    p["p_sat"][:, :N_GPS] = BENCH_GPS_P_SAT
    valid = x["valid"].copy()
    p["p_sat"][12], p["p_const"][12] = 0.0, 0.0  # the fault-free term alone
    valid[13, -1] = False  # a padding source holding junk
    p["var_int_m2"][13, -1], p["b_nom_m"][13, -1], p["p_sat"][13, -1] = -1.0, 7.0, 0.5
    valid[14, 4:] = False  # 4 GPS only: too few sources
    p["p_const"][15, 0] = 1e-3  # P(GPS and SOP constellations faulty) ~1e-7 > P_thresh
    return p, valid, x["constellation"]


@pytest.fixture(scope="module")
def case():
    p, valid, constellation = _params()
    return {k: jnp.asarray(v) for k, v in p.items()}, jnp.asarray(valid), jnp.asarray(
        constellation)


def _sources(p, valid, constellation):
    g = jnp.concatenate([geometry.geometry_rows(p["gps_az_rad"], p["gps_el_rad"]),
                         geometry.geometry_rows_enu(p["tower_enu_m"], p["receiver_enu_m"])],
                        axis=-2)
    return Sources(g, constellation, p["var_int_m2"], p["var_acc_m2"], p["b_nom_m"],
                   p["p_sat"], valid)


def _outputs(p, valid, constellation):
    r = araim.protection_levels_kernel(_sources(p, valid, constellation), p["p_const"], BUDGET,
                                       araim.MHSSOptions(1, fault_modes="grouped"))
    return {k: getattr(r, k) for k in OUTPUTS} | {"status": r.status, "pl_enu_m": r.pl_enu_m}


# One jitted program; the derivatives below are taken of it from outside (not jitted
# themselves), so that JAX compiles its JVP and its linearization once and every test, and
# check_grads, reuses them (compilation is most of this file's time)
_value = jax.jit(_outputs)


def _jvp(p, valid, constellation, v):
    return jax.jvp(lambda q: _value(q, valid, constellation), (p,), (v,))[1]


def _total(out):
    """The sum of every finite output of every geometry (inf ones count 0)."""
    return sum(jnp.sum(jnp.where(jnp.isfinite(out[k]), out[k], 0.0)) for k in OUTPUTS)


def _grad_of_sum(p, valid, constellation):
    """The gradient of ``_total``: each geometry's gradient of its HPL + VPL + EMT +
    sigma_acc (the geometries are independent)."""
    return jax.grad(lambda q: _total(_value(q, valid, constellation)))(p)


#: check_grads' coordinates u: p = p0 + scale u, one step eps = 1e-4 in u is the FD step of
#: ``STEPS`` in every kind (relative kinds: scale p0; positions horizontal)
U_SCALE = {k: h / 1e-4 for k, h in STEPS.items()}


def _direction(p, kind, seed):
    """A random direction of the parameter ``kind`` (zero elsewhere), in its unit."""
    rng = np.random.default_rng(seed)
    v = {k: np.zeros(x.shape) for k, x in p.items()}
    d = rng.standard_normal(p[kind].shape)
    if kind in RELATIVE:
        d = d * np.asarray(p[kind])
    if kind == "b_nom_m":
        d = d * (np.asarray(p[kind]) > 0)
    if kind in ("tower_enu_m", "receiver_enu_m"):
        d = d * HORIZONTAL
    v[kind] = d
    return {k: jnp.asarray(x) for k, x in v.items()}


def _shifted(p, v, h):
    return {k: p[k] + h * v[k] for k in p}


def _close(ad, fd, h, what):
    ad, fd = np.asarray(ad), np.asarray(fd)
    err = np.abs(ad - fd)
    bad = err > RTOL * np.abs(fd) + VALUE_NOISE_M / h
    assert not bad.any(), (f"{what}: AD {ad[bad]} FD {fd[bad]} rel err "
                           f"{(err / np.maximum(np.abs(fd), 1e-300))[bad]}")


def test_implicit_root_of_one_term_is_the_hand_derivative():
    """R(x) = c Q((x - b) / s) = rhs has the root x = b + s k, k = Q^-1(rhs / c): dx/db = 1,
    dx/ds = k, dx/drhs = -s / (c phi(k)), dx/dc = s rhs / (c^2 phi(k)) (differentiate
    c Q(k) = rhs). Through ``implicit_root`` on ``solve_pl`` (the kernel's solver), forward
    and reverse; the values to 1e-9 relative (the root solver's 1e-4 m proof tolerance is not
    the issue here: the derivative is taken at the Newton-corrected root); second derivatives
    by ``jax.hessian`` (forward over reverse)."""
    c, b, s, rhs = 2.0, 0.7, 1.3, 1e-7

    def root(theta):
        c, b, s, rhs = theta
        pl, _ = implicit_root(lambda *a: solve_pl(*a[:4], start=a[4], ignore=a[5]),
                              jnp.reshape(c, (1, 1)), jnp.reshape(b, (1, 1)),
                              jnp.reshape(s, (1, 1)), jnp.reshape(rhs, (1,)),
                              jnp.reshape(b + 5.0 * s, (1,)), jnp.zeros((1,), bool))
        return pl[0]

    theta = jnp.array([c, b, s, rhs])
    k = -special.ndtri(rhs / c)
    phi = np.exp(-0.5 * k * k) / np.sqrt(2.0 * np.pi)
    assert float(root(theta)) == pytest.approx(b + s * k, abs=1e-4)
    want = np.array([s * rhs / (c * c * phi), 1.0, k, -s / (c * phi)])
    np.testing.assert_allclose(jax.jit(jax.grad(root))(theta), want, rtol=1e-9)
    np.testing.assert_allclose(jax.jit(jax.jacfwd(root))(theta), want, rtol=1e-9)
    # second order (the rule differentiates its own coefficients): x is linear in b and s,
    # d2x/ds drhs = -1 / (c phi(k)) and d2x/drhs2 = s k / (c^2 phi(k)^2)
    hess = np.asarray(jax.jit(jax.hessian(root))(theta))
    assert hess[1, 1] == pytest.approx(0.0, abs=1e-9) and hess[2, 2] == pytest.approx(
        0.0, abs=1e-9)
    np.testing.assert_allclose(hess[2, 3], -1.0 / (c * phi), rtol=1e-9)
    np.testing.assert_allclose(hess[3, 3], s * k / (c * c * phi * phi), rtol=1e-9)


def test_fault_free_term_alone_matches_the_hand_derivation(case):
    """Row 12: every prior 0, so PL_q = b_q + sigma_q k_q with k_q = Q^-1(rhs_q / 2),
    sigma_q^2 = (N^-1)_qq, N = H^T W H (H with the clock columns, W = C_int^-1), and
    b_q = sum_m |S_qm| b_m, S = N^-1 H^T W. With dW = -e_l e_l^T dvar_l / var_l^2:
    d(N^-1) = -N^-1 dN N^-1 gives dsigma_q / dvar_l = (N^-1 h_l)_q^2 / (2 sigma_q var_l^2),
    and dS = N^-1 H^T dW (I - H S) gives dS_qm / dvar_l = -(N^-1 h_l)_q (I - H S)_lm /
    var_l^2; dPL_q / db_l = |S_ql|; sigma_acc = sqrt(S_u C_acc S_u^T) moves with both
    variances. HPL = hypot(PL_E, PL_N) of the kernel's PLs (roots + the solver's margin,
    ``PL_MARGIN_M``, which enter hypot's chain rule at ~1e-8 relative)."""
    p, valid, constellation = case
    grads = _grad_of_sum(p, valid, constellation)
    src = _sources(p, valid, constellation)
    i = 12
    g, var, var_acc, b = (np.asarray(x[i]) for x in (src.g, src.var_int_m2, src.var_acc_m2,
                                                      src.b_nom_m))
    const = np.asarray(src.constellation[i])
    h = np.concatenate([g, (const[:, None] == np.arange(2)).astype(float)], axis=1)
    n_inv = np.linalg.inv(h.T @ (h / var[:, None]))
    s = n_inv @ h.T / var
    u = (n_inv @ h.T)[:3]  # (N^-1 h_l)_q
    resid = np.eye(len(var)) - h @ s
    sigma = np.sqrt(np.diag(n_inv)[:3])
    k = -special.ndtri(np.array([BUDGET.phmi_h / 4, BUDGET.phmi_h / 4, BUDGET.phmi_v / 2]))
    out = _value(p, valid, constellation)
    pl = np.asarray(out["pl_enu_m"][i])
    np.testing.assert_allclose(pl, np.abs(s[:3]) @ b + sigma * k, atol=1e-3)  # solver tol.
    assert float(out["emt_m"][i]) == 0.0
    d_bias = -u / var ** 2 * ((np.sign(s[:3]) * b) @ resid.T)  # (3, L): db_q / dvar_l
    dpl_dvar = k[:, None] * u ** 2 / (2.0 * sigma[:, None] * var ** 2) + d_bias
    hpl = np.hypot(pl[0], pl[1])
    sigma_acc = np.sqrt(s[2] ** 2 @ var_acc)
    d_acc = s[2] ** 2 / (2.0 * sigma_acc)
    d_acc_int = -u[2] * (resid @ (s[2] * var_acc)) / (var ** 2 * sigma_acc)
    dhpl_dvar = (pl[0] * dpl_dvar[0] + pl[1] * dpl_dvar[1]) / hpl
    np.testing.assert_allclose(grads["var_int_m2"][i], dhpl_dvar + dpl_dvar[2] + d_acc_int,
                               rtol=1e-9)
    np.testing.assert_allclose(grads["var_acc_m2"][i], d_acc, rtol=1e-9)
    db = (pl[0] * np.abs(s[0]) + pl[1] * np.abs(s[1])) / hpl + np.abs(s[2])
    np.testing.assert_allclose(grads["b_nom_m"][i], db, rtol=1e-9)
    # forward mode, VPL alone and sigma_acc alone
    v = _direction(p, "var_int_m2", 0)
    np.testing.assert_allclose(_jvp(p, valid, constellation, v)["vpl_m"][i],
                               dpl_dvar[2] @ np.asarray(v["var_int_m2"][i]), rtol=1e-9)
    v = _direction(p, "var_acc_m2", 0)
    np.testing.assert_allclose(_jvp(p, valid, constellation, v)["sigma_acc_u_m"][i],
                               d_acc @ np.asarray(v["var_acc_m2"][i]), rtol=1e-9)


def test_bench_rows_are_away_from_switches(case):
    """The FD comparisons below need every compared row at least 1e-3 (relative) from a
    decision switch; the failing rows are not compared."""
    p, valid, constellation = case
    flags = np.asarray(araim.switch_flags_kernel(_sources(p, valid, constellation), p["p_const"],
                                                 BUDGET,
                                                 araim.MHSSOptions(1, fault_modes="grouped"),
                                                 rtol=1e-3))
    assert np.all(flags[OK_ROWS] == 0), flags
    # ... and the bench's own GPS P_s (1e-5) sits on the EMT's switch: flagged
    on_edge = dict(p, p_sat=p["p_sat"].at[:, :N_GPS].set(1e-5))
    flags = np.asarray(araim.switch_flags_kernel(_sources(on_edge, valid, constellation),
                                                 p["p_const"], BUDGET,
                                                 araim.MHSSOptions(1, fault_modes="grouped"),
                                                 rtol=1e-3))
    assert np.all(flags[:12] == araim.mhss.SWITCH_EMT), flags
    status = np.asarray(_value(p, valid, constellation)["status"])
    assert np.all(status[OK_ROWS] == Status.OK)
    assert list(status[list(FAILED_ROWS)]) == [Status.TOO_FEW_SOURCES, Status.UNMONITORED_RISK]


@pytest.mark.parametrize("kind", list(STEPS))
def test_jvp_matches_central_differences_of_the_kernel(case, kind):
    """Directional derivatives (``jax.jvp``) of HPL, VPL, EMT and sigma_acc along a random
    direction of one kind of input, against (f(p + h v) - f(p - h v)) / 2h of the kernel."""
    p, valid, constellation = case
    v = _direction(p, kind, 1)
    h = STEPS[kind]
    ad = _jvp(p, valid, constellation, v)
    plus, minus = (_value(_shifted(p, v, s), valid, constellation) for s in (h, -h))
    for k in OUTPUTS:
        with np.errstate(invalid="ignore"):  # inf - inf in the failed rows, not compared
            fd = (np.asarray(plus[k]) - np.asarray(minus[k])) / (2.0 * h)
        _close(np.asarray(ad[k])[OK_ROWS], fd[OK_ROWS], h, f"{kind} -> {k}")
        assert np.all(np.asarray(ad[k])[list(FAILED_ROWS)] == 0.0)


def _oracle(p, valid, constellation):
    """The oracle's (HPL, VPL, EMT, sigma_acc) of the OK rows, each PL root re-solved to
    1e-12 m (brentq on ``reference_mhss.pl_equation``; its own bisection stops at 1e-6 m,
    too coarse for a difference quotient)."""
    src = [np.asarray(x) for x in _sources(p, valid, constellation)]
    pc = np.asarray(p["p_const"])
    out = np.zeros((len(OK_ROWS), 4))
    for n, i in enumerate(OK_ROWS):
        res = ref.protection_levels_reference(tuple(x[i] for x in src), pc[i], BUDGET,
                                              ref.ReferenceOptions(1, fault_modes="grouped"))
        assert res.status == ref.OK
        pl = [optimize.brentq(lambda x, q=q, r=res: np.subtract(*ref.pl_equation(r, BUDGET, q, x)),
                              res.pl_enu_m[q] - 1e-2, res.pl_enu_m[q] + 1e-2, xtol=1e-12,
                              rtol=1e-15) for q in range(3)]
        out[n] = np.hypot(pl[0], pl[1]), pl[2], res.emt_m, res.sigma_acc_u_m
    return out


@pytest.mark.parametrize("kind", ["gps_el_rad", "tower_enu_m", "var_int_m2", "p_sat"])
def test_jvp_matches_central_differences_of_the_oracle(case, kind):
    """The same directional derivatives against central differences of the NumPy oracle
    (plain per-geometry least squares and enumerated modes)."""
    p, valid, constellation = case
    v = _direction(p, kind, 2)
    h = STEPS[kind]
    ad = _jvp(p, valid, constellation, v)
    fd = (_oracle(_shifted(p, v, h), valid, constellation)
          - _oracle(_shifted(p, v, -h), valid, constellation)) / (2.0 * h)
    for j, k in enumerate(OUTPUTS):
        _close(np.asarray(ad[k])[OK_ROWS], fd[:, j], h, f"oracle {kind} -> {k}")


def test_reverse_mode_equals_forward_mode_and_never_nan(case):
    """``jax.grad`` of the sum over the batch (the transposed implicit rule) agrees with the
    forward directional derivatives (<grad, v> = jvp, 1e-10 relative: the same linear rule),
    is finite everywhere, and is exactly 0 for the failed rows and the padding source."""
    p, valid, constellation = case
    grads = _grad_of_sum(p, valid, constellation)
    for k, gk in grads.items():
        gk = np.asarray(gk)
        assert np.all(np.isfinite(gk)), k
        assert np.all(gk[list(FAILED_ROWS)] == 0.0), k
    for kind in ("var_int_m2", "b_nom_m", "p_sat"):
        assert float(grads[kind][13, -1]) == 0.0
    for kind in STEPS:
        v = _direction(p, kind, 3)
        ad = _jvp(p, valid, constellation, v)
        fwd = sum(np.where(np.isfinite(np.asarray(ad[k])), np.asarray(ad[k]), 0.0)
                  for k in OUTPUTS)
        rev = np.sum(np.asarray(grads[kind]) * np.asarray(v[kind]),
                     axis=tuple(range(1, grads[kind].ndim)))
        np.testing.assert_allclose(rev, fwd, rtol=1e-10, atol=1e-12, err_msg=kind)


def test_vmap_of_per_geometry_gradients_matches_the_batch(case):
    """``jax.vmap(jax.grad(...))`` over the 16 geometries (each at batch shape 1 inside) gives
    the per-geometry gradients of the batched one (geometries are independent), to 1e-10
    relative (XLA may round differently at another shape: tests/test_kernels.py)."""
    p, valid, constellation = case

    def one(q, val, const):
        out = _outputs(jax.tree.map(lambda x: x[None], q), val[None], const[None])
        return sum(jnp.where(jnp.isfinite(out[k][0]), out[k][0], 0.0) for k in OUTPUTS)

    per = jax.jit(jax.vmap(jax.grad(one)))(p, valid, constellation)
    batch = _grad_of_sum(p, valid, constellation)
    for k in p:
        np.testing.assert_allclose(per[k], batch[k], rtol=1e-10, atol=1e-14, err_msg=k)


def test_check_grads_forward_and_reverse(case):
    """``jax.test_util.check_grads`` (order 1, modes fwd and rev) on the sum of the finite
    outputs in the coordinates u of ``U_SCALE`` (its eps 1e-4 is then the FD step of every
    kind; relative kinds scaled by their value, so P_s = 0 and b_nom = 0 stay put), along its
    own random direction over every input at once: rtol 1e-5, atol 1e-10 m / 1e-4 (the FD
    noise of the module docstring)."""
    p, valid, constellation = case
    scale = {k: jnp.asarray(U_SCALE[k] * (np.asarray(p[k]) if k in RELATIVE or k == "b_nom_m"
                                           else 1.0)) for k in p}
    scale = {k: v * HORIZONTAL if k in ("tower_enu_m", "receiver_enu_m") else v
             for k, v in scale.items()}

    def total(u):
        q = {k: p[k] + scale[k] * u[k] for k in p}
        return _total(_value(q, valid, constellation))

    u0 = {k: jnp.zeros(x.shape) for k, x in p.items()}
    check_grads(total, (u0,), order=1, modes=("fwd", "rev"), eps=1e-4, rtol=1e-5,
                atol=VALUE_NOISE_M / 1e-4)


def test_bench_table_has_the_gradient_row():
    """``oaraim bench`` stores ``mhss_gradient`` (``oaraim.bench_grad``); the table shows both
    throughputs and their cost ratio beside each other."""
    from oaraim.bench import markdown_table

    entry = {"batch": 16_384, "value_hpl_per_s": 250_000.0, "value_and_grad_hpl_per_s":
             25_000.0, "ratio": 10.0, "host": {"cpus": 2, "jax": "0.10.2", "date": "2026-12-04"}}
    rows = markdown_table({"mhss_gradient": entry}).splitlines()[2:]
    assert len(rows) == 1
    assert "value and gradient of HPL per second" in rows[0]
    assert "25,000 HPL/s (value alone 250,000 HPL/s: 10.0x its cost)" in rows[0]
