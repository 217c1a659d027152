"""The linear tangent of every fault mode's weighted least squares (seed 004 eqs. 9-11), the
derivative rule of ``projection.project``'s C_int-weighted modes (docs/gradients.md).

Automatic differentiation of the projection as ``project`` computes it (unrolled Cholesky
factors, rank-one downdates, sums over sources written out slice by slice) transposes every
slice into a pad of the whole array and every stored intermediate into a replay of its
producer: reverse mode cost 9-10x the value. The rule here is the derivative of the
mathematical function instead, written from the position rows S^(i) the forward pass returns,
with every sum over sources a vectorised reduction (whose transpose is a broadcast).

Per mode (weights w_l = C_int^-1(l, l) where kept, 0 where excluded; S the position rows of
N^-1 H^T W, N the normal matrix with one clock per constellation; M^-1 = (N^-1)_pos,pos =
S W^-1 S^T; u_l = S_:l / w_l = M^-1 g~_l, with g~_l the row centred on its constellation's
w-weighted mean row and s_c that constellation's weight sum): from
dS = N^-1 dH^T W R + N^-1 H^T dW R - S dH S, R = I - H S, and
h_l^T N^-1 h_m = g~_l^T M^-1 g~_m + [c(l) = c(m)] / s_c,

    dS_:l = w_l M^-1 (dg_l - Z u_l - v_c(l) / s_c(l)) + dw_l u_l
    d(sigma_q^2) = -(M^-1 Z M^-1)_qq

with Z = D + D^T + sum_m dw_m g~_m g~_m^T, D = sum_m w_m dg_m g~_m^T (3 x 3), and
v_c = sum_(m in c) (w_m dg_m + dw_m g~_m). Then eqs. (10) and (11):
db_q = sum_l sign(S_ql) b_l dS_ql + |S_ql| db_l and d(sigma_ss,q^2) = sum_l 2 (S - S^(0))_ql
C_acc,l (dS - dS^(0))_ql + (S - S^(0))_ql^2 dC_acc,l. Only the position columns of H vary;
a clock dropped for an absent constellation (1 on its diagonal) changes nothing. The rule
needs no factorisation: M^-1 and u come from the S the forward pass returns.
"""

import jax.numpy as jnp

from oaraim.araim import linalg

__all__ = ["mode_centering", "separation_tangents", "wls_tangents"]


def _safe_inverse(x):
    """1 / x where x > 0, else 0 (finite either way, for reverse mode's zero cotangents)."""
    pos = x > 0
    return jnp.where(pos, 1.0 / jnp.where(pos, x, 1.0), 0.0)


def mode_centering(g_rows, w, memf):
    """Every mode's centred rows and inverse constellation weight sums.

    g_rows (3, L, B) the rows' components; w (K, L, B) each mode's weights; memf (L, C, B)
    float constellation membership. Returns g~, a list of 3 (K, L, B) arrays (the rows' east,
    north and up components minus their constellation's w-weighted mean in each mode), and
    1/s_c(l) (K, L, B), the inverse weight sum of each source's constellation (0 where that
    constellation has no weight)."""
    g_centred = [g_rows[a][None] for a in range(3)]
    inv_s = 0.0
    for c in range(memf.shape[1]):
        wc = w * memf[:, c]
        inv_c = linalg.materialize(_safe_inverse(_summed_over_sources(wc)))
        for a in range(3):
            g_centred[a] = g_centred[a] - memf[:, c] * linalg.materialize(
                _summed_over_sources(wc * g_rows[a]) * inv_c)
        inv_s = inv_s + memf[:, c] * inv_c
    return [linalg.materialize(x) for x in g_centred], linalg.materialize(inv_s)


def _stored(x, one):
    """x / one for an array ``one`` of ones known only at run time: x, computed once and
    stored. Like ``linalg.materialize`` (XLA never duplicates a division into the consumers
    that broadcast it) but linear in x, so the transposed rule stores its cotangent too."""
    return x / one


def _over_sources(x):
    """sum over the source axis (1) of a (K, L, B) array, kept as (K, 1, B)."""
    return jnp.sum(x, axis=1, keepdims=True)


def _summed_over_sources(x):
    """The same sum as ``_over_sources`` for a value that is not a tangent, written out
    source by source (``linalg.sum_axis``: XLA vectorises it along the batch axis; a
    reduction over a non-minor axis ran several times slower). Not for tangents: the
    transpose of its slices is a pad of the whole array each."""
    return linalg.sum_axis(x, 1)[:, None]


def _own_constellation_sum(x, memf, one):
    """sum over the sources m of source l's constellation of x_m, for every l: x (K, L, B),
    memf (L, C, B) -> (K, L, B)."""
    return sum(memf[:, c] * _stored(_over_sources(x * memf[:, c]), one)
               for c in range(memf.shape[1]))


def wls_tangents(s_pos, w, g_centred, inv_s, memf, dg_rows, dw):
    """The tangents of every mode's position rows and variances (module docstring).

    s_pos (K, 3, L, B) the modes' position rows S (0 at excluded sources); w (K, L, B) the
    modes' weights; g_centred, inv_s from ``mode_centering``; memf (L, C, B); dg_rows
    (3, L, B) the tangent of the rows' components; dw (K, L, B) that of the modes' weights.
    Returns dS (a list of the 3 components' (K, L, B) tangents) and dsigma^2 (K, 3, B);
    linear in (dg_rows, dw).

    Written component by component ((K, L, B) arrays, the 3 x 3 products unrolled) with the
    sums over sources as reductions: its transpose (reverse mode) is then broadcasts and the
    same products, not the (K, 3, 3, L, B) broadcasts and nested reductions of a vectorised
    3 x 3 product (measured: 8x the value's time)."""
    one = (w[:, :1] == w[:, :1]).astype(w.dtype)  # (K, 1, B) ones
    gt = g_centred
    positive = w > 0
    w_inv = jnp.where(positive, 1.0 / jnp.where(positive, w, 1.0), 0.0)
    u = [linalg.materialize(s_pos[:, a] * w_inv) for a in range(3)]
    m_inv = [[None] * 3 for _ in range(3)]
    for a in range(3):
        for b in range(a + 1):
            m_inv[a][b] = m_inv[b][a] = linalg.materialize(
                _summed_over_sources(s_pos[:, a] * u[b]))
    # broadcast over the modes once: each broadcast is a sum over the modes in reverse mode
    dg = [jnp.broadcast_to(dg_rows[a][None], w.shape) for a in range(3)]
    wdg = [w * x for x in dg]
    dwg = [dw * x for x in gt]
    # Z = D + D^T + sum_m dw_m g~_m g~_m^T (symmetric), D = sum_m w_m dg_m g~_m^T
    z_mat = [[None] * 3 for _ in range(3)]
    for a in range(3):
        for b in range(a + 1):
            z_mat[a][b] = z_mat[b][a] = _stored(_over_sources(
                wdg[a] * gt[b] + wdg[b] * gt[a] + dwg[a] * gt[b]), one)
    inner = [dg[a] - sum(z_mat[a][b] * u[b] for b in range(3))
             - inv_s * _own_constellation_sum(wdg[a] + dwg[a], memf, one) for a in range(3)]
    ds = [w * sum(m_inv[a][b] * inner[b] for b in range(3)) + dw * u[a] for a in range(3)]
    d_var = [-sum(m_inv[a][b] * z_mat[b][c] * m_inv[c][a] for b in range(3) for c in range(3))
             for a in range(3)]
    return ds, jnp.concatenate(d_var, axis=1)


def separation_tangents(s_pos, sigma_ss, ds, b_nom, var_acc, db_nom, dvar_acc):
    """The tangents of eqs. (10) and (11) from the rows' tangents ``ds`` (``wls_tangents``: 3
    (K, L, B) arrays), mode 0 the all-in-view solution: b_q^(i) = sum_l |S_ql| b_l and
    sigma_ss,q^(i) = sqrt(sum_l (S^(i) - S^(0))_ql^2 C_acc,l) (derivative 0 where it is 0, as
    ``linalg.sqrt0``). b_nom, var_acc, their tangents (L, B). Returns (dbias, dsigma_ss),
    (K, 3, B) each."""
    shape = ds[0].shape
    # broadcast over the modes once (one sum over the modes each in reverse mode)
    db_nom, dvar_acc = (jnp.broadcast_to(x[None], shape) for x in (db_nom, dvar_acc))
    d_bias, d_ss = [], []
    for a in range(3):
        rows, d_rows = s_pos[:, a], ds[a]
        d_bias.append(_over_sources(jnp.sign(rows) * b_nom * d_rows
                                    + jnp.abs(rows) * db_nom)[:, 0])
        sep = rows - rows[:1]
        d_ss2 = _over_sources(2.0 * sep * var_acc * (d_rows - d_rows[:1])
                              + sep * sep * dvar_acc)[:, 0]
        d_ss.append(0.5 * d_ss2 * _safe_inverse(sigma_ss[:, a]))
    return jnp.stack(d_bias, axis=1), jnp.stack(d_ss, axis=1)
