"""The problem as the kernel sees it: sanitised, equilibrated, with G's products stored.

`_prepare` replaces a non-finite problem by a harmless flagged one, scales it (Ruiz equilibration of
[P G'; G 0], variable scaling D (n, ...), row scaling E (m, ...), 2 sweeps, and a cost scaling c
(...), so that float32 works with entries of order one) and stores what every iteration reads: the
entries of Gs = E G D by rows and by columns (for Gs x and Gs'y) and the row products Gs_ri Gs_rj
from which `_normal_columns` forms H = Ps + Gs' diag(w) Gs. Only the entries of G's pattern are
stored (structure.py). docs/decisions-controller.md ("Low-level controller: the QP solver") has the
method and the reasons for this layout.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

from dpc_mjx.control.qp.normal import NormalParts
from dpc_mjx.control.qp.ops import (
    _UNROLL_MAX,
    _all_finite,
    _cholesky,
    _DenseFactor,
    _fold,
    _inf_norm,
    _max,
    _mv,
    _pin,
    _pin_flag,
    _sum,
    _take,
)
from dpc_mjx.control.qp.settings import QPSettings
from dpc_mjx.control.qp.structure import _Structure

_NORM_MIN = 1e-12  # a zero row or column is left unscaled by the equilibration


def _diagonal_factor(k: int, regularization: float, like: jax.Array) -> jax.Array:
    """(k, 1, ...) constant of like's dtype: 1 + regularization first (the diagonal), then 1."""
    f = np.ones(k)
    f[0] += regularization
    return jp.asarray(f, like.dtype).reshape((k,) + (1,) * (like.ndim - 1))


def _equilibrate(P: jax.Array, G: jax.Array, sweeps: int, one: jax.Array):
    """Ruiz scaling D (n, ...), E (m, ...) making the columns of [P G'; G 0] of unit inf-norm.

    P and G are finite here, so no NaN can arise and a compare-select maximum (cheaper on
    XLA:CPU than the NaN-propagating jp.maximum) gives the same result.
    """

    d = jp.ones_like(P[0])
    e = jp.ones_like(G[:, 0])
    for _ in range(sweeps):
        ps = jp.abs(P) * (d[:, None] * d[None, :])
        gs = _pin(jp.abs(G) * (e[:, None] * d[None, :]), one)  # else XLA splits it over threads
        col = jp.maximum(_col_max(ps), _col_max(gs))  # (n, ...)
        row = _col_max(gs, axis=1)  # (m, ...)
        d = _pin(d * jax.lax.rsqrt(jp.where(col > _NORM_MIN, col, 1.0)), one)
        e = _pin(e * jax.lax.rsqrt(jp.where(row > _NORM_MIN, row, 1.0)), one)
    return d, e


def _col_max(v: jax.Array, axis: int = 0) -> jax.Array:
    """The max along `axis` of v >= 0 (a compare-select fold, see `_equilibrate`)."""
    return _fold(lambda a, b: jp.where(a > b, a, b), v, axis)


def _equilibrate_entries(P, g: jax.Array, st: _Structure, sweeps: int, one, p_diag=None):  # noqa: PLR0913, PLR0917
    """`_equilibrate` for a compact G (`_Structure.compact`), g (K, ...) its pattern's entries:
    (D (n, ...), E (m, ...), the entries of Gs = E G D (K, ...)), reading only g's entries.
    P None: P's diagonal `p_diag` (n, ...) stands in for its columns' maxima (normal.py)."""
    r_of, c_of = st.entries // st.n, st.entries % st.n  # (K,) row, column of each entry
    by_col, by_row = st.at(st.cols[0]), st.at(st.rows[0])  # (n, L), (m, K_r); K: the zero
    zero = jp.zeros((1,) + g.shape[1:], g.dtype)
    d = jp.ones((st.n,) + g.shape[1:], g.dtype)
    e = jp.ones((st.m,) + g.shape[1:], g.dtype)
    for _ in range(sweeps):
        if P is None:
            p_col = jp.abs(p_diag) * d * d
        else:
            p_col = _col_max(jp.abs(P) * (d[:, None] * d[None, :]))
        gs = jp.concatenate([_pin(jp.abs(g) * (e[r_of] * d[c_of]), one), zero])  # (K + 1, ...)
        col = jp.maximum(p_col, _col_max(gs[by_col], axis=1))  # (n, ...)
        row = _col_max(gs[by_row], axis=1)  # (m, ...)
        d = _pin(d * jax.lax.rsqrt(jp.where(col > _NORM_MIN, col, 1.0)), one)
        e = _pin(e * jax.lax.rsqrt(jp.where(row > _NORM_MIN, row, 1.0)), one)
    return d, e, _pin(g * (e[r_of] * d[c_of]), one)


@struct.dataclass
class _Scaled:
    """The sanitised problem in equilibrated units: x = d * xs, Gs = E G D, cost times c."""

    P: jax.Array | None  # (n, n, ...) sanitised original P (for the objective); None: implicit
    q: jax.Array  # (n, ...) sanitised original q
    h: jax.Array  # (m, ...) sanitised original h
    Ps: jax.Array | None  # (n, n, ...) c D P D; None where P is implicit (normal.py)
    qs: jax.Array  # (n, ...) c D q
    Gs: jax.Array  # (m, n, ...) E G D (0 outside the pattern); (K, ...) its entries if compact
    hs: jax.Array  # (m, ...) E h
    d: jax.Array  # (n, ...) variable scaling D
    e: jax.Array  # (m, ...) row scaling E
    c: jax.Array  # (...) cost scaling
    inv_d: jax.Array  # (n, ...) 1 / d
    inv_e: jax.Array  # (m, ...) 1 / e
    inv_c: jax.Array  # (...) 1 / c
    g_abs: jax.Array  # (...) max_j sum_i |Gs_ij| / d_j, bounds |G|'|z| in original units (times c)
    norms: jax.Array  # (2, ...) ||h||_inf, ||q||_inf (original units)
    finite: jax.Array  # (...) bool, the input was finite
    one: jax.Array  # (...) ones, for _pin
    p_cols: list  # columns Ps[j:, j] (n - j, ...), the diagonal entry times (1 + reg)
    g_rows: jax.Array  # (m, K, ...) the entries of each row of Gs (st.rows), for Gs x
    g_cols: jax.Array  # (n, L, ...) the entries of each column of Gs (st.cols), for Gs'y
    gg_cols: list  # per column j of H: None or the products Gs_ri Gs_rj (T, hi - lo, ...) of
    #   st.normal[j], the diagonal entry times (1 + reg)
    p_major: jax.Array | None  # over _UNROLL_MAX variables: Ps batch-major (..., n, n), the
    #   diagonal times (1 + reg), for the dense factor (`_normal_factor`; p_cols is then empty)
    p_diag: jax.Array | None  # with a normal solver (st.solver): (n, ...) the diagonal of Ps
    normal_data: tuple  # the normal solver's arrays (normal.py), () without one
    st: _Structure = struct.field(pytree_node=False)  # the pattern of G and its index tables


def _pattern_mv(values: jax.Array, index: np.ndarray, x: jax.Array) -> jax.Array:
    """sum_k values[:, k] * x[index[:, k]] (r, ...): a product with a matrix stored as its
    pattern's entries per row (`values` (r, k_max, ...)) and their column indices (r, k_max)."""
    out = values[:, 0] * _take(x, index[:, 0])
    for k in range(1, index.shape[1]):
        out = out + values[:, k] * _take(x, index[:, k])
    return out


def _g_mv(pr: _Scaled, x: jax.Array) -> jax.Array:
    """Gs x (m, ...) for x (n, ...), from the entries of the pattern only."""
    return _pattern_mv(pr.g_rows, pr.st.rows[1], x)


def _g_mtv(pr: _Scaled, y: jax.Array) -> jax.Array:
    """Gs'y (n, ...) for y (m, ...), from the entries of the pattern only."""
    return _pattern_mv(pr.g_cols, pr.st.cols[1], y)


def _g_tables(Gs: jax.Array, st: _Structure, cfg: QPSettings):
    """The g_rows, g_cols and gg_cols of _Scaled from Gs (m, n, ...), or (K, ...) where G is
    compact. (They need no pin: the iterations read them as loop inputs, computed once; pinning
    them measured the same.)"""
    m, n = st.m, st.n
    if st.pattern is None:  # dense: slices, no gathers
        g_rows, g_cols = Gs, jp.swapaxes(Gs, 0, 1)
        products = [Gs[:, j:] * Gs[:, j : j + 1] for j in range(n)]
    elif st.compact:  # Gs (K, ...) the pattern's entries; st.at: where an entry lies in it
        flat = jp.concatenate([Gs, jp.zeros((1,) + Gs.shape[1:], Gs.dtype)])
        g_rows, g_cols = flat[st.at(st.rows[0])], flat[st.at(st.cols[0])]
        products = [None if t is None else flat[st.at(t[2])] * flat[st.at(t[3])]
                    for t in st.normal]  # fmt: skip
    else:
        flat = jp.concatenate([Gs.reshape((m * n,) + Gs.shape[2:]), jp.zeros_like(Gs[:1, 0])])
        g_rows, g_cols = flat[st.rows[0]], flat[st.cols[0]]
        products = [None if t is None else flat[t[2]] * flat[t[3]] for t in st.normal]
    like = Gs if st.compact else Gs[0]  # (k, ...): for the shape of the diagonal factor
    gg_cols = []
    for j, products_j in enumerate(products):
        if products_j is None:
            gg_cols.append(None)
            continue
        if st.normal[j][0] == 0:  # the diagonal entry is first
            diag = _diagonal_factor(products_j.shape[1], cfg.regularization, like)
            products_j = products_j * diag  # noqa: PLW2901
        gg_cols.append(products_j)
    return g_rows, g_cols, gg_cols


def _sanitise(P, q, G, h, st: _Structure, data: tuple, one: jax.Array) -> tuple:  # noqa: PLR0913, PLR0917
    """(P, q, G, h, data, diag(P) or None, finite): a non-finite problem becomes min 1/2|x|^2
    s.t. 0 <= 1 (where P is implicit, normal.py: its data zeroed), flagged by finite (...)."""
    n = q.shape[0]
    if st.pattern is not None and not st.compact:
        G = jp.where(st.mask.reshape(st.mask.shape + (1,) * (q.ndim - 1)), G, 0.0)
    g_axes = 1 if st.compact else 2  # G (K, ...) or (m, n, ...)
    finite = _all_finite(q) & _all_finite(G, g_axes) & _all_finite(h)
    if st.implicit_p:  # P (0, ...): the normal solver's data say it
        finite = functools.reduce(jp.logical_and, (_all_finite(a, a.ndim - q.ndim + 1)
                                                   for a in data), finite)  # fmt: skip
    finite = _pin_flag(finite if st.implicit_p else _all_finite(P, 2) & finite, one)
    q = jp.where(finite, q, 0.0)
    G = jp.where(finite, G, 0.0)
    h = jp.where(finite, h, 1.0)
    if st.implicit_p:
        data = tuple(jp.where(finite, a, 0.0) for a in data)
        return None, q, G, h, data, st.solver.p_diagonal(data), finite
    eye = jp.eye(n, dtype=q.dtype).reshape((n, n) + (1,) * (q.ndim - 1))
    P = jp.where(finite, 0.5 * (P + jp.swapaxes(P, 0, 1)), eye)
    return P, q, G, h, data, None, finite


def _p_parts(Ps, ps_diag, c, cfg: QPSettings, st: _Structure, one: jax.Array) -> tuple:  # noqa: PLR0913, PLR0917
    """(Ps, p_cols, p_major, p_diag) of _Scaled from D P D (n, n, ...) (None where P is
    implicit: its diagonal ps_diag (n, ...)) and the cost scaling c (...)."""
    if st.implicit_p:  # the caller's solver factors H (normal.py): it needs only diag(Ps)
        return None, [], None, _pin(ps_diag * c, one)
    n = Ps.shape[0]
    Ps = Ps * c
    if st.solver is not None:
        return Ps, [], None, _pin(jp.stack([Ps[j, j] for j in range(n)]), one)
    if n > _UNROLL_MAX:  # H is formed batch-major from Ps (`_normal_factor`)
        reg = 1.0 + cfg.regularization * jp.eye(n, dtype=Ps.dtype)
        reg = reg.reshape(reg.shape + (1,) * (Ps.ndim - 2))
        return Ps, [], jp.moveaxis(Ps * reg, (0, 1), (-2, -1)), None
    like = Ps[0]  # (n, ...)
    p_cols = [Ps[j:, j] * _diagonal_factor(n - j, cfg.regularization, like) for j in range(n)]
    return Ps, p_cols, None, None


def _prepare(P, q, G, h, cfg: QPSettings, st: _Structure, data: tuple = ()) -> _Scaled:  # noqa: PLR0913, PLR0917
    """Sanitise (`_sanitise`) and scale.

    Entries of G outside the pattern st are set to 0, so they are never read; a compact G (K,
    ...) holds only the pattern's entries (`_Structure.compact`). P is None where the normal
    solver knows it (`_Structure.implicit_p`).
    """
    n = q.shape[0]
    # a runtime 1 (...) that XLA cannot fold (see _pin), cheap to recompute
    one = 1.0 + 0.0 * jp.isfinite(q[0]).astype(q.dtype)
    P, q, G, h, data, p_diag, finite = _sanitise(P, q, G, h, st, data, one)
    if st.compact:
        d, e, Gs = _equilibrate_entries(P, G, st, cfg.ruiz_iterations, one, p_diag)
    else:
        d, e = _equilibrate(P, G, cfg.ruiz_iterations, one)
        Gs = _pin(G * (e[:, None] * d[None, :]), one)  # read by every matvec and row product
    qs = q * d
    if P is None:  # Ps's diagonal stands in for its columns' maxima
        Ps, ps_diag = None, p_diag * d * d
        cost_norm = jp.maximum(_sum(jp.abs(ps_diag)) / n, _inf_norm(qs))
    else:
        Ps, ps_diag = P * (d[:, None] * d[None, :]), None
        cost_norm = jp.maximum(_sum(_max(jp.abs(Ps))) / n, _inf_norm(qs))
    c = _pin(1.0 / jp.clip(cost_norm, 1e-4, 1e6), one)
    # reciprocals, so that no pinned value is divided (XLA would merge the two divides, see _pin)
    inv_d, inv_e, inv_c = (_pin(1.0 / v, one) for v in (d, e, c))
    tables = _g_tables(Gs, st, cfg)
    col_abs = _sum(jp.abs(tables[1]), axis=1) if st.compact else _sum(jp.abs(Gs))  # (n, ...)
    g_abs = _pin(_max(col_abs * inv_d), one)
    norms = _pin(jp.stack([_inf_norm(h), _inf_norm(q)]), one)
    qs = qs * c
    # H = Ps + Gs' diag(w) Gs is assembled by columns from the products of the rows of Gs.
    Ps, p_cols, p_major, p_diag = _p_parts(Ps, ps_diag, c, cfg, st, one)
    hs = h * e
    inverses = (inv_d, inv_e, inv_c)
    return _Scaled(
        P, q, h, Ps, qs, Gs, hs, d, e, c, *inverses, g_abs, norms, finite, one, p_cols, *tables,
        p_major, p_diag, tuple(data), st,
    )  # fmt: skip


def _ps_mv(pr: _Scaled, x: jax.Array) -> jax.Array:
    """Ps x (n, ...) for x (n, ...): from the stored Ps, or the normal solver's P x (P None)."""
    if pr.Ps is not None:
        return _mv(pr.Ps, x)
    return pr.c * pr.d * pr.st.solver.p_matvec(pr.normal_data, pr.d * x)


def _p_mv(pr: _Scaled, x: jax.Array) -> jax.Array:
    """P x (n, ...) for x (n, ...) in the original units, as `_ps_mv`."""
    if pr.P is not None:
        return _mv(pr.P, x)
    return pr.st.solver.p_matvec(pr.normal_data, x)


def _normal_columns(pr: _Scaled, w: jax.Array) -> list[jax.Array]:
    """w (m, ...) -> the columns H[j:, j] (n - j, ...) of H = Ps + Gs' diag(w) Gs, with the
    diagonal times (1 + regularization), from the stored row products: m n(n+1)/2
    multiply-adds for a dense G, only the pattern's products for a sparse one."""
    columns = []
    for p_col, gg, spec in zip(pr.p_cols, pr.gg_cols, pr.st.normal, strict=True):
        if gg is None:
            columns.append(p_col)
            continue
        lo, hi, _, _, rows = spec
        part = p_col[lo:hi]
        for t in range(rows.shape[0]):
            part = part + gg[t] * _take(w, rows[t])
        whole = hi - lo == len(p_col)
        columns.append(part if whole else jp.concatenate([p_col[:lo], part, p_col[hi:]]))
    return columns


def _normal_factor(pr: _Scaled, w: jax.Array, floor: float):
    """The factor (`ops._cholesky`) of H = Ps + Gs' diag(w) Gs for w (m, ...). Up to _UNROLL_MAX
    variables from `_normal_columns`; above, H is Ps batch-major (`p_major`) plus G's products
    added at their K entries (st.normal_entries), then factored dense: no (n, n, ...) columns
    to assemble and transpose every iteration. With a normal solver (st.solver, normal.py),
    its factor from G's products and the scalings."""
    if pr.p_major is None and pr.st.solver is None:
        return _cholesky(_normal_columns(pr, w), floor)
    values = []  # (hi - lo, ...) per column j of H that G' W G adds to
    for gg, spec in zip(pr.gg_cols, pr.st.normal, strict=True):
        if gg is not None:
            rows = spec[4]
            part = gg[0] * _take(w, rows[0])
            for t in range(1, rows.shape[0]):
                part = part + gg[t] * _take(w, rows[t])
            values.append(part)
    rows, cols = pr.st.normal_entries
    if pr.st.solver is not None:
        gwg = jp.concatenate(values) if values else jp.zeros((0,) + w.shape[1:], w.dtype)
        parts = NormalParts(pr.d, pr.c, pr.p_diag, gwg, pr.one, rows, cols)
        return pr.st.solver.factor(pr.normal_data, parts, floor)
    H = pr.p_major
    if values:
        H = H.at[..., rows, cols].add(jp.moveaxis(jp.concatenate(values), 0, -1))  # (..., K)
    return _DenseFactor.of_matrix(H, floor)
