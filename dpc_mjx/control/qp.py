"""A small QP solver in JAX: fixed-iteration primal-dual interior point (Mehrotra).

Solves, for one problem (vmap it for a batch)::

    min_x  1/2 x' P x + q' x    s.t.  G x <= h           x (n,), P (n, n) sym. PSD, G (m, n)

Equalities can be passed as pairs of opposite inequalities; the method tolerates the empty
interior this creates (slower, with growing duals, and the best iterate is returned).

Method (docs/decisions.md has the choice and the tuning, docs/benchmarks.md the speed):
  * Ruiz equilibration of [P G'; G 0] (variable scaling D, row scaling E, 2 sweeps) and a cost
    scaling c, so that float32 works with entries of order one.
  * Slack form G x + s = h, s >= 0, duals z >= 0, infeasible start. Each iteration forms the
    normal matrix H = P + G' diag(z/s) G, factorises it by an unrolled Cholesky (a pivot floor
    instead of a breakdown), and takes a Mehrotra predictor-corrector step (two solves with the
    one factor) with the fraction-to-boundary rule.
  * float32 safeguards: centring target >= mu_floor; no step once mu < mu_stop (H is then too
    ill-conditioned to factor in float32); a non-finite step is not taken; the iterate with the
    smallest residual-to-tolerance ratio is returned.
  * A fixed number of iterations (lax.scan), no data-dependent control flow: every problem of a
    batch costs the same; jit- and vmap-able; warm-startable from a previous QPResult.

Layout. The method is written once, for arrays whose trailing axes are batch axes (`...`):
P (n, n, ...), q (n, ...), G (m, n, ...), a per-problem scalar (...). Along the small leading
axes it uses static slices only (unrolled matvecs, Cholesky and substitutions, pairwise folds
instead of reductions), so every op is elementwise over the batch. A single call runs it with no
batch axis. Under `jax.vmap`, a batching rule (`jax.custom_batching.custom_vmap`) moves the batch
to the last, contiguous axis and runs the same code on chunks of `_CHUNK` = 64 problems (128 with
a G pattern), one after the other (`lax.map`): each XLA:CPU loop is then a SIMD loop over the
chunk, and a chunk's data (~10 KB per problem dense) stay in the L2 cache. On a GPU the whole
batch is one chunk. Arguments the vmap does not batch are broadcast; nested vmaps are merged
into one batch. `_pin` marks the values that XLA:CPU would otherwise recompute inside every
consumer. `_solve_reference` is the same code vmapped the default way (the batch on the leading
axis), for the benchmark. custom_vmap has no reverse-mode autodiff; nothing differentiates
through the solver.

Sparsity. `g_pattern` (static, (m, n) bool) says which entries of G can be nonzero; the kernel
then stores and multiplies only those (index tables in `_Structure`): G x, G'y and the products
G_ri G_rj of H. P and the Cholesky factor stay dense.

Cost per iteration (n = 12, m = 24): H from the stored row products G_ri G_rj (m n(n+1)/2 = 1872
multiply-adds dense, 56 for the balance QP's pattern), the Cholesky (~n^3/6), two pairs of
triangular solves, six matvecs with P, G or G'. Dense, that is ~11k float ops per problem and
iteration, ~0.35 us at batch 4096 on one core; with the balance pattern ~0.25 us, of which about
half is XLA:CPU's fixed cost per op (docs/benchmarks.md, docs/decisions.md).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jp
import numpy as np

from dpc_mjx.errors import DpcError

_TINY = 1e-30  # keeps divisions finite (fits float32)
_BIG = 1e30  # clamp of z/s (fits float32)
_NORM_MIN = 1e-12  # a zero row or column is left unscaled by the equilibration
# Problems per chunk of the batched kernel on CPU (docs/decisions.md): a chunk's data stay in the
# L2 cache, and each of the ~150 ops of an iteration costs ~50 ns of dispatch whatever its size,
# so the chunk is as large as the cache allows: 64 for a dense G, 128 with a sparse pattern
# (its tables are ~10x smaller).
_CHUNK, _CHUNK_SPARSE = 64, 128


@dataclasses.dataclass(frozen=True)
class QPSettings:
    """Static solver settings (Python scalars; a change retraces).

    iterations: interior-point iterations, all of them always run.
    eps_abs, eps_rel: tolerances of the `converged` flag (OSQP-style, inf-norms, unscaled):
      primal  ||max(Gx - h, 0)|| <= eps_abs + eps_rel max(||Gx||, ||h||)
      dual    ||Px + q + G'z||   <= eps_abs + eps_rel max(||Px||, max_j sum_i |G_ij| ||z||, ||q||)
      gap     s'z / m            <= eps_abs + eps_rel max(|x'Px|, |q'x|) / m.
    ruiz_iterations: equilibration sweeps.
    step_fraction: fraction-to-boundary factor of a step.
    regularization: relative primal regularisation, H += regularization * diag(H).
    pivot_floor: a Cholesky pivot below pivot_floor * H_jj is replaced by it (no breakdown).
    mu_floor: the smallest complementarity target, in the equilibrated units.
    mu_stop: no more steps once the mean complementarity s'z/m (equilibrated) is below this.
    warm_margin: warm-started slacks and duals are lifted off 0 by this, relative (see _start).
    """

    iterations: int = 10
    eps_abs: float = 1e-5
    eps_rel: float = 1e-3
    ruiz_iterations: int = 2
    step_fraction: float = 0.99
    regularization: float = 1e-7
    pivot_floor: float = 1e-6
    mu_floor: float = 1e-10
    mu_stop: float = 1e-8
    warm_margin: float = 1e-2


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class QPResult:
    """Solution and diagnostics of one QP (add a leading batch axis under vmap).

    x: (n,) the solution (0 where valid is False).
    z: (m,) duals of G x <= h, z >= 0 (0 where valid is False).
    s: (m,) slacks h - G x as tracked by the method, s >= 0 (kept for warm starts).
    objective: () 1/2 x'Px + q'x at x.
    primal_residual: () ||max(Gx - h, 0)||_inf, the constraint violation (units of h).
    dual_residual: () ||Px + q + G'z||_inf, the stationarity error (units of q).
    gap: () s'z / m, the mean complementarity (units of the objective / m).
    iterations: () int32, the number of iterations after which all three tolerances first held
      (0: the starting point already met them), or settings.iterations + 1 if they never did.
    converged: () bool, all tolerances met by the returned iterate.
    valid: () bool, the input was finite, nothing broke down, and x satisfies G x <= h within the
      primal tolerance; False means x = 0 and is not to be used.
    """

    x: jax.Array
    z: jax.Array
    s: jax.Array
    objective: jax.Array
    primal_residual: jax.Array
    dual_residual: jax.Array
    gap: jax.Array
    iterations: jax.Array
    converged: jax.Array
    valid: jax.Array


# ---------------------------------------------------------------------------------------------
# Helpers along the small leading axes; the trailing axes (...) are batch axes.


def _pin(x: jax.Array, one: jax.Array) -> jax.Array:
    """x itself (x / 1 is exact), computed once.

    XLA:CPU fuses a cheap expression into every consumer and recomputes it there, once per
    element: a per-problem value broadcast over an (m, ...) vector, or a vector read by a
    matvec, is recomputed m times, and chains of these multiply (up to 100x slower, measured).
    It does not do so with a float divide by a value it cannot fold, so dividing by `one` (a
    runtime array of ones) makes it compute x into memory once. A pinned value must not be
    divided nor divide: XLA rewrites (x / one) / y as x / (one y), which undoes the pin; hence
    the reciprocals in _Scaled.
    """
    return x / one


def _pin_flag(b: jax.Array, one: jax.Array) -> jax.Array:
    """A bool (...) computed once (see _pin)."""
    return _pin(jp.where(b, one, 0.0), one) > 0.5


def _fold(fn, v: jax.Array, axis: int = 0) -> jax.Array:
    """Reduce `axis` of v by the binary fn with a halving tree of static slices.

    XLA:CPU emits a reduction over a non-minor axis as a scalar loop; this stays elementwise
    over the batch (and vectorised).
    """
    while v.shape[axis] > 1:
        k = v.shape[axis]
        half = k // 2
        head = fn(
            jax.lax.slice_in_dim(v, 0, half, axis=axis),
            jax.lax.slice_in_dim(v, half, 2 * half, axis=axis),
        )
        odd = jax.lax.slice_in_dim(v, 2 * half, k, axis=axis)
        v = jp.concatenate([head, odd], axis=axis) if k % 2 else head
    return jp.squeeze(v, axis)


def _sum(v: jax.Array, axis: int = 0) -> jax.Array:
    return _fold(jp.add, v, axis)


def _max(v: jax.Array, axis: int = 0) -> jax.Array:
    return _fold(jp.maximum, v, axis)


def _dot(a: jax.Array, b: jax.Array) -> jax.Array:
    return _sum(a * b)


def _inf_norm(v: jax.Array) -> jax.Array:
    return _max(jp.abs(v))


def _all_finite(v: jax.Array, axes: int = 1) -> jax.Array:
    """(...) bool: all entries of the leading `axes` axes of v are finite.

    v * 0 is 0 where v is finite and NaN where not, so the sum says it; this float formulation
    runs 2x faster on XLA:CPU than folding isfinite with logical_and.
    """
    zeros = v * 0.0
    for _ in range(axes):
        zeros = _sum(zeros)
    return jp.isfinite(zeros)


def _mv(A: jax.Array, x: jax.Array) -> jax.Array:
    """A x for A (m, n, ...), x (n, ...) -> (m, ...), unrolled over n."""
    out = A[:, 0] * x[0]
    for j in range(1, A.shape[1]):
        out = out + A[:, j] * x[j]
    return out


def _take(x: jax.Array, idx: np.ndarray) -> jax.Array:
    """x[idx] along the leading axis for a static index vector idx (k,): a broadcast when all
    indices are equal, a slice when they are consecutive, else a gather."""
    if (idx == idx[0]).all():
        return jp.broadcast_to(x[int(idx[0])], (len(idx),) + x.shape[1:])
    if (np.diff(idx) == 1).all():
        return x[int(idx[0]) : int(idx[0]) + len(idx)]
    return x[idx]


@dataclasses.dataclass(frozen=True)
class _Structure:
    """The static nonzero pattern of G (m, n), or None for a dense G, with the index tables of
    the products the kernel forms from G's entries only (numpy, built once per pattern).

    Entries are addressed in G flattened row-major (r n + j); index m n is an appended zero,
    which pads the tables to rectangles.
    """

    m: int
    n: int
    pattern: tuple[tuple[bool, ...], ...] | None

    @functools.cached_property
    def mask(self) -> np.ndarray:  # (m, n) bool
        if self.pattern is None:
            return np.ones((self.m, self.n), bool)
        return np.array(self.pattern, bool)

    def _padded(self, lists: list[list[int]]) -> np.ndarray:
        """Rows of flat entry indices padded with the zero entry to one width (>= 1)."""
        width = max(1, *(len(x) for x in lists))
        zero = self.m * self.n
        return np.array([x + [zero] * (width - len(x)) for x in lists], np.int64)

    @functools.cached_property
    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """(m, K) flat entries of each row and (m, K) their columns (G x = sum_k of products)."""
        lists = [[r * self.n + j for j in np.flatnonzero(self.mask[r])] for r in range(self.m)]
        flat = self._padded(lists)
        return flat, flat % self.n * (flat < self.m * self.n)

    @functools.cached_property
    def cols(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, L) flat entries of each column and (n, L) their rows (G'y = sum_l of products)."""
        lists = [[r * self.n + j for r in np.flatnonzero(self.mask[:, j])] for j in range(self.n)]
        flat = self._padded(lists)
        return flat, flat // self.n * (flat < self.m * self.n)

    @functools.cached_property
    def normal(self) -> list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray] | None]:
        """Per column j of H = G' diag(w) G: None if G' W G adds nothing to H[j:, j], else
        (lo, hi, a, b, r): entries j + lo .. j + hi - 1 get sum_t G[a_t] G[b_t] w[r_t], where
        a, b, r are (T, hi - lo) flat entries (padded with the zero entry) and rows."""
        out = []
        zero = self.m * self.n
        for j in range(self.n):
            terms = [np.flatnonzero(self.mask[:, i] & self.mask[:, j]) for i in range(j, self.n)]
            hit = [k for k, t in enumerate(terms) if len(t)]
            if not hit:
                out.append(None)
                continue
            lo, hi = hit[0], hit[-1] + 1
            width = max(len(terms[k]) for k in hit)
            a = np.full((width, hi - lo), zero, np.int64)
            b, r = a.copy(), np.zeros((width, hi - lo), np.int64)
            for k in range(lo, hi):
                t = terms[k]
                a[: len(t), k - lo] = t * self.n + j + k
                b[: len(t), k - lo] = t * self.n + j
                r[: len(t), k - lo] = t
            out.append((lo, hi, a, b, r))
        return out


@functools.lru_cache(maxsize=None)
def _structure(m: int, n: int, pattern: tuple[tuple[bool, ...], ...] | None) -> _Structure:
    return _Structure(m, n, pattern)


# ---------------------------------------------------------------------------------------------
# The method.


def _diagonal_factor(k: int, regularization: float, like: jax.Array) -> jax.Array:
    """(k, 1, ...) constant of like's dtype: 1 + regularization first (the diagonal), then 1."""
    f = np.ones(k)
    f[0] += regularization
    return jp.asarray(f, like.dtype).reshape((k,) + (1,) * (like.ndim - 1))


def _equilibrate(P: jax.Array, G: jax.Array, sweeps: int, one: jax.Array):
    """Ruiz scaling D (n, ...), E (m, ...) making the columns of [P G'; G 0] of unit inf-norm.

    P and G are finite here, so no NaN can arise and a compare-select maximum (half the cost
    of the NaN-propagating jp.maximum on XLA:CPU) gives the same result.
    """

    def col_max(v, axis=0):
        return _fold(lambda a, b: jp.where(a > b, a, b), v, axis)

    d = jp.ones_like(P[0])
    e = jp.ones_like(G[:, 0])
    for _ in range(sweeps):
        ps = jp.abs(P) * (d[:, None] * d[None, :])
        gs = _pin(jp.abs(G) * (e[:, None] * d[None, :]), one)  # else XLA splits it over threads
        col = jp.maximum(col_max(ps), col_max(gs))  # (n, ...)
        row = col_max(gs, axis=1)  # (m, ...)
        d = _pin(d * jax.lax.rsqrt(jp.where(col > _NORM_MIN, col, 1.0)), one)
        e = _pin(e * jax.lax.rsqrt(jp.where(row > _NORM_MIN, row, 1.0)), one)
    return d, e


def _cholesky(columns: list[jax.Array], floor: float) -> list[tuple[jax.Array, jax.Array]]:
    """Unrolled right-looking Cholesky H = L L' from the columns H[j:, j] (n - j, ...).

    Returns the columns of L as (L_jj (...), L[j+1:, j] (n-j-1, ...)). A pivot below
    floor * H_jj is raised to it, so the factor always exists (a regularised factor of a
    near-singular H). Only the lower triangle is read. The divides here and in _cho_solve
    also pin (see _pin) each entry of the factor and the solution: with reciprocals and
    multiplies instead, XLA:CPU recomputes the chains of updates in every consumer (measured
    5-50x slower).
    """
    n = len(columns)
    h_diag = [c[0] for c in columns]
    trailing = list(columns)  # column k of the trailing Schur complement, rows k: (n - k, ...)
    out = []
    for j in range(n):
        col = trailing[j]
        d = jp.sqrt(jp.maximum(col[0], floor * h_diag[j] + _TINY))
        c = col[1:] / d
        out.append((d, c))
        for k in range(j + 1, n):
            trailing[k] = trailing[k] - c[k - j - 1] * c[k - j - 1 :]
    return out


def _cho_solve(chol: list[tuple[jax.Array, jax.Array]], b: jax.Array) -> jax.Array:
    """Solve L L' x = b for b (n, ...), with L given column-wise by `_cholesky`."""
    n = len(chol)
    y, r = [], b
    for j in range(n):  # forward: L y = b, column-oriented
        d, c = chol[j]
        y.append(r[0] / d)
        r = r[1:] - c * y[j]
    x = [None] * n
    for j in reversed(range(n)):  # backward: L' x = y, row-oriented
        d, c = chol[j]
        acc = y[j]
        for k in range(j + 1, n):
            acc = acc - c[k - j - 1] * x[k]
        x[j] = acc / d
    return jp.stack(x)


def _max_step(v: jax.Array, dv: jax.Array) -> jax.Array:
    """Largest a in [0, 1] with v + a dv >= 0 (v > 0), per problem."""
    neg = dv < 0
    ratio = jp.where(neg, v / jp.where(neg, -dv, 1.0), 1.0)
    return jp.minimum(1.0, _fold(jp.minimum, ratio))


class _Scaled(NamedTuple):
    """The sanitised problem in equilibrated units: x = d * xs, Gs = E G D, cost times c."""

    P: jax.Array  # (n, n, ...) sanitised original P (for the objective)
    q: jax.Array  # (n, ...) sanitised original q
    h: jax.Array  # (m, ...) sanitised original h
    Ps: jax.Array  # (n, n, ...) c D P D
    qs: jax.Array  # (n, ...) c D q
    Gs: jax.Array  # (m, n, ...) E G D (0 outside the pattern)
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
    st: _Structure  # static: the pattern of G and its index tables


def _g_mv(pr: _Scaled, x: jax.Array) -> jax.Array:
    """Gs x (m, ...) for x (n, ...), from the entries of the pattern only."""
    cols = pr.st.rows[1]
    out = pr.g_rows[:, 0] * _take(x, cols[:, 0])
    for k in range(1, cols.shape[1]):
        out = out + pr.g_rows[:, k] * _take(x, cols[:, k])
    return out


def _g_mtv(pr: _Scaled, y: jax.Array) -> jax.Array:
    """Gs'y (n, ...) for y (m, ...), from the entries of the pattern only."""
    rows = pr.st.cols[1]
    out = pr.g_cols[:, 0] * _take(y, rows[:, 0])
    for k in range(1, rows.shape[1]):
        out = out + pr.g_cols[:, k] * _take(y, rows[:, k])
    return out


def _g_tables(Gs: jax.Array, st: _Structure, cfg: QPSettings):
    """The g_rows, g_cols and gg_cols of _Scaled from Gs (m, n, ...). (They need no pin: the
    iterations read them as loop inputs, computed once; pinning them measured the same.)"""
    m, n = st.m, st.n
    if st.pattern is None:  # dense: slices, no gathers
        g_rows, g_cols = Gs, jp.swapaxes(Gs, 0, 1)
        products = [Gs[:, j:] * Gs[:, j : j + 1] for j in range(n)]
    else:
        flat = jp.concatenate([Gs.reshape((m * n,) + Gs.shape[2:]), jp.zeros_like(Gs[:1, 0])])
        g_rows, g_cols = flat[st.rows[0]], flat[st.cols[0]]
        products = [None if t is None else flat[t[2]] * flat[t[3]] for t in st.normal]
    gg_cols = []
    for j, products_j in enumerate(products):
        if products_j is None:
            gg_cols.append(None)
            continue
        if st.normal[j][0] == 0:  # the diagonal entry is first
            diag = _diagonal_factor(products_j.shape[1], cfg.regularization, Gs[0])
            products_j = products_j * diag  # noqa: PLW2901
        gg_cols.append(products_j)
    return g_rows, g_cols, gg_cols


def _prepare(P, q, G, h, cfg: QPSettings, st: _Structure) -> _Scaled:
    """Sanitise (a non-finite problem becomes min 1/2|x|^2 s.t. 0 <= 1, flagged) and scale.

    Entries of G outside the pattern st are set to 0, so they are never read.
    """
    n = q.shape[0]
    # a runtime 1 (...) that XLA cannot fold (see _pin), cheap to recompute
    one = 1.0 + 0.0 * jp.isfinite(q[0]).astype(q.dtype)
    if st.pattern is not None:
        G = jp.where(st.mask.reshape(st.mask.shape + (1,) * (q.ndim - 1)), G, 0.0)
    finite = _all_finite(P, 2) & _all_finite(q) & _all_finite(G, 2) & _all_finite(h)
    finite = _pin_flag(finite, one)
    eye = jp.eye(n, dtype=q.dtype).reshape((n, n) + (1,) * (q.ndim - 1))
    P = jp.where(finite, 0.5 * (P + jp.swapaxes(P, 0, 1)), eye)
    q = jp.where(finite, q, 0.0)
    G = jp.where(finite, G, 0.0)
    h = jp.where(finite, h, 1.0)

    d, e = _equilibrate(P, G, cfg.ruiz_iterations, one)
    Ps = P * (d[:, None] * d[None, :])
    qs = q * d
    Gs = _pin(G * (e[:, None] * d[None, :]), one)  # read by every matvec and row product
    cost_norm = jp.maximum(_sum(_max(jp.abs(Ps))) / n, _inf_norm(qs))
    c = _pin(1.0 / jp.clip(cost_norm, 1e-4, 1e6), one)
    # reciprocals, so that no pinned value is divided (XLA would merge the two divides, see _pin)
    inv_d, inv_e, inv_c = (_pin(1.0 / v, one) for v in (d, e, c))
    g_abs = _pin(_max(_sum(jp.abs(Gs)) * inv_d), one)
    norms = _pin(jp.stack([_inf_norm(h), _inf_norm(q)]), one)
    Ps, qs = Ps * c, qs * c
    # H = Ps + Gs' diag(w) Gs is assembled by columns from the products of the rows of Gs.
    p_cols = [Ps[j:, j] * _diagonal_factor(n - j, cfg.regularization, q) for j in range(n)]
    hs = h * e
    inverses = (inv_d, inv_e, inv_c)
    tables = _g_tables(Gs, st, cfg)
    return _Scaled(
        P, q, h, Ps, qs, Gs, hs, d, e, c, *inverses, g_abs, norms, finite, one, p_cols, *tables, st
    )


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


def _start(pr: _Scaled, warm, cfg: QPSettings):
    """Starting (x, s, z) in equilibrated units.

    Cold: x minimises 1/2 x'Px + q'x + 1/2 |Gx - h|^2, s = max(h - Gx, 1), z = 1.
    Warm: the previous x, s = h - Gx lifted to >= warm_margin (1 + |h_i|), the previous z lifted
    to >= warm_margin (1 + max z) (equilibrated units).
    """
    chol = _cholesky(_normal_columns(pr, jp.ones_like(pr.hs)), cfg.pivot_floor)
    x0 = _cho_solve(chol, -pr.qs + _g_mtv(pr, pr.hs))
    s0 = jp.maximum(pr.hs - _g_mv(pr, x0), 1.0)
    z0 = jp.ones_like(pr.hs)
    if warm is None:
        return x0, s0, z0
    wx, wz, wvalid = warm
    use = _pin_flag(wvalid & pr.finite & _all_finite(wx) & _all_finite(wz), pr.one)
    xw = _pin(jp.nan_to_num(wx.astype(x0.dtype)) * pr.inv_d, pr.one)
    zw = jp.nan_to_num(wz.astype(x0.dtype)) * pr.c * pr.inv_e
    # lift both off the boundary, relative to their own scales
    sw = jp.maximum(pr.hs - _g_mv(pr, xw), cfg.warm_margin * (1.0 + jp.abs(pr.hs)))
    zw = jp.maximum(zw, cfg.warm_margin * (1.0 + _pin(_max(zw), pr.one)))
    return tuple(jp.where(use, a, b) for a, b in ((xw, x0), (sw, s0), (zw, z0)))


class _Iterate(NamedTuple):
    """Iterate in equilibrated units: x (n, ...), s (m, ...), z (m, ...) and gx = Gs x (m, ...)."""

    x: jax.Array
    s: jax.Array
    z: jax.Array
    gx: jax.Array


class _Figures(NamedTuple):
    """Residuals of an iterate in original units (...) and merit = max residual / tolerance."""

    primal: jax.Array
    dual: jax.Array
    gap: jax.Array
    primal_tol: jax.Array
    merit: jax.Array


def _residuals(pr: _Scaled, cfg: QPSettings, it: _Iterate) -> tuple[jax.Array, _Figures]:
    """The scaled dual residual rd = Ps x + qs + Gs'z (n, ...) and the _Figures of the iterate."""
    m = pr.hs.shape[0]
    px = _pin(_mv(pr.Ps, it.x), pr.one)
    rd = _pin(px + pr.qs + _g_mtv(pr, it.z), pr.one)
    primal = _inf_norm(jp.maximum(it.gx - pr.hs, 0.0) * pr.inv_e)
    dual = _inf_norm(rd * pr.inv_d) * pr.inv_c
    gap = _dot(it.s, it.z) * pr.inv_c / m
    primal_tol = cfg.eps_abs + cfg.eps_rel * jp.maximum(_inf_norm(it.gx * pr.inv_e), pr.norms[0])
    # the scale of G'z is bounded via |G|'|z| (large duals of equality pairs cancel in G'z)
    dual_scale = jp.maximum(_inf_norm(px * pr.inv_d), pr.g_abs * _inf_norm(it.z)) * pr.inv_c
    dual_tol = cfg.eps_abs + cfg.eps_rel * jp.maximum(dual_scale, pr.norms[1])
    obj_scale = jp.maximum(jp.abs(_dot(it.x, px)), jp.abs(_dot(it.x, pr.qs))) * pr.inv_c / m
    gap_tol = cfg.eps_abs + cfg.eps_rel * obj_scale
    merit = jp.maximum(jp.maximum(primal / primal_tol, dual / dual_tol), gap / gap_tol)
    merit = jp.where(jp.isfinite(merit), merit, jp.inf)
    figures = _Figures(primal, dual, gap, primal_tol, merit)
    return rd, _Figures(*(_pin(f, pr.one) for f in figures))


def _newton_step(pr: _Scaled, cfg: QPSettings, it: _Iterate, rd: jax.Array) -> _Iterate:
    """One Mehrotra predictor-corrector step from `it`; returns the next _Iterate."""
    m, one = pr.hs.shape[0], pr.one
    x, s, z, gx = it
    rp = gx + s - pr.hs  # primal residual of G x + s = h
    mu = _pin(_dot(s, z) / m, one)
    w = jp.minimum(z / s, _BIG)
    chol = _cholesky(_normal_columns(pr, w), cfg.pivot_floor)

    def direction(rc):  # Newton direction of the KKT system with Z ds + S dz = -rc
        dx = _cho_solve(chol, -rd - _g_mtv(pr, _pin(w * rp - rc / s, one)))
        gdx = _pin(_g_mv(pr, dx), one)
        ds = -rp - gdx
        dz = -(rc + z * ds) / s
        return dx, ds, dz, gdx

    # predictor (affine scaling), then Mehrotra's centring and second-order correction
    dx, ds, dz, _ = direction(s * z)
    a_p, a_d = _pin(_max_step(s, ds), one), _pin(_max_step(z, dz), one)
    mu_aff = _dot(s + a_p * ds, z + a_d * dz) / m
    sigma = jp.clip(mu_aff / jp.maximum(mu, _TINY), 0.0, 1.0) ** 3
    target = _pin(jp.maximum(sigma * mu, cfg.mu_floor), one)
    dx, ds, dz, gdx = direction(s * z + ds * dz - target)
    a = cfg.step_fraction * jp.minimum(_max_step(s, ds), _max_step(z, dz))
    # No step once mu < mu_stop (float32 gains nothing more and H gets too ill-conditioned to
    # factor), nor a non-finite one.
    finite = jp.isfinite(a) & _all_finite(dx) & _all_finite(ds) & _all_finite(dz)
    finite = _pin_flag(finite & _all_finite(gdx), one)
    a = _pin(jp.where(finite & (mu > cfg.mu_stop), a, 0.0), one)
    return _Iterate(
        x=x + a * jp.where(finite, dx, 0.0),
        s=jp.maximum(s + a * jp.where(finite, ds, 0.0), _TINY),
        z=jp.maximum(z + a * jp.where(finite, dz, 0.0), _TINY),
        gx=gx + a * jp.where(finite, gdx, 0.0),
    )


def _kernel(P, q, G, h, warm, cfg: QPSettings, st: _Structure) -> QPResult:
    """The method on arrays with trailing batch axes (...); warm is None or (x, z, valid)."""
    pr = _prepare(P, q, G, h, cfg, st)
    x0, s0, z0 = _start(pr, warm, cfg)
    it0 = _Iterate(x0, s0, z0, _g_mv(pr, x0))
    _, fig0 = _residuals(pr, cfg, it0)
    never = jp.asarray(cfg.iterations + 1, jp.int32)

    def keep_best(best, it, fig):
        better = _pin_flag(fig.merit < best[1].merit, pr.one)
        return jax.tree.map(lambda a, b: jp.where(better, a, b), (it, fig), best)

    def body(carry, k):  # k = iterations done so far
        it, best, first = carry
        rd, fig = _residuals(pr, cfg, it)
        first = jp.where((fig.merit <= 1.0) & (first > k), k, first)
        best = keep_best(best, it, fig)
        return (_newton_step(pr, cfg, it, rd), best, first), None

    carry = (it0, (it0, fig0), jp.full(q.shape[1:], never))
    ks = jp.arange(cfg.iterations, dtype=jp.int32)
    it, best, first = jax.lax.scan(body, carry, ks)[0]
    _, fig = _residuals(pr, cfg, it)
    first = jp.where((fig.merit <= 1.0) & (first == never), cfg.iterations, first)
    it, fig = keep_best(best, it, fig)
    return _result(pr, it, fig, first)


def _result(pr: _Scaled, it: _Iterate, fig: _Figures, first: jax.Array) -> QPResult:
    """Back to the original units, with the flags; x = z = s = 0 where not valid."""
    x_out, z_out, s_out = pr.d * it.x, pr.e * it.z * pr.inv_c, it.s * pr.inv_e
    finite = _all_finite(x_out) & _all_finite(z_out) & _all_finite(s_out)
    valid = _pin_flag(pr.finite & finite & (fig.primal <= fig.primal_tol), pr.one)
    x_out, z_out, s_out = (_pin(jp.where(valid, v, 0.0), pr.one) for v in (x_out, z_out, s_out))
    objective = 0.5 * _dot(x_out, _mv(pr.P, x_out)) + _dot(pr.q, x_out)
    zero = jp.zeros((), x_out.dtype)
    return QPResult(
        x=x_out,
        z=z_out,
        s=s_out,
        objective=objective,
        primal_residual=jp.where(finite, fig.primal, zero),
        dual_residual=jp.where(finite, fig.dual, zero),
        gap=jp.where(finite, fig.gap, zero),
        iterations=first,
        converged=valid & (fig.merit <= 1.0),
        valid=valid,
    )


# ---------------------------------------------------------------------------------------------
# Entry points and batching.


def _run_kernel(args: tuple, cfg: QPSettings, st: _Structure) -> QPResult:
    """args = (P, q, G, h) or (P, q, G, h, warm x, warm z, warm valid), trailing batch axes."""
    warm = tuple(args[4:]) or None
    return _kernel(*args[:4], warm, cfg, st)


def _solve_many(args: tuple, cfg: QPSettings, st: _Structure) -> QPResult:
    """args with a leading batch axis B: the kernel on chunks of problems, batch minor."""
    size = args[0].shape[0]
    # XLA:CPU: chunks that stay in cache, one after the other. An accelerator runs the whole
    # batch at once (the batch-minor layout is also what its memory coalescing wants).
    chunk = _CHUNK if st.pattern is None else _CHUNK_SPARSE
    chunk = min(chunk, size) if jax.default_backend() == "cpu" else size
    n_chunks = -(-size // chunk)
    pad = n_chunks * chunk - size
    if pad:  # repeat the last problem to fill the last chunk
        args = [jp.concatenate([a, jp.repeat(a[-1:], pad, axis=0)]) for a in args]

    def run(chunk_args):  # (chunk, ...) each
        # transpose once: XLA:CPU would otherwise fuse the transpose into every reader (strided)
        one = 1.0 + 0.0 * jp.isfinite(chunk_args[1][:, 0]).astype(chunk_args[1].dtype)
        moved = (jp.moveaxis(a, 0, -1) for a in chunk_args)
        res = _run_kernel(tuple(a if a.dtype == bool else _pin(a, one) for a in moved), cfg, st)
        return jax.tree.map(lambda a: jp.moveaxis(a, -1, 0), res)

    if n_chunks == 1:
        out = run(args)
    else:
        split = [a.reshape((n_chunks, chunk) + a.shape[1:]) for a in args]
        out = jax.tree.map(lambda a: a.reshape((-1,) + a.shape[2:]), jax.lax.map(run, split))
    return jax.tree.map(lambda a: a[:size], out) if pad else out


def _broadcast_unbatched(axis_size: int, in_batched, args) -> list[jax.Array]:
    return [
        a if b else jp.broadcast_to(a, (axis_size,) + a.shape) for a, b in zip(args, in_batched)
    ]


@functools.lru_cache(maxsize=None)
def _batched_solver(cfg: QPSettings, st: _Structure):
    """f(*args with a leading batch axis) -> QPResult with that axis; a vmap of f is merged into
    the same batch axis (nested vmaps become one batch)."""

    @jax.custom_batching.custom_vmap
    def many(*args):
        return _solve_many(args, cfg, st)

    @many.def_vmap
    def _many_vmap(axis_size, in_batched, *args):
        args = _broadcast_unbatched(axis_size, in_batched, args)
        inner = args[0].shape[1]
        out = many(*(a.reshape((-1,) + a.shape[2:]) for a in args))
        out = jax.tree.map(lambda a: a.reshape((axis_size, inner) + a.shape[1:]), out)
        return out, jax.tree.map(lambda _: True, out)

    return many


@functools.lru_cache(maxsize=None)
def _solver(cfg: QPSettings, st: _Structure):
    """f(*args of one problem) -> QPResult, whose vmap runs the batch-minor chunked kernel."""

    @jax.custom_batching.custom_vmap
    def one(*args):
        return _run_kernel(args, cfg, st)

    @one.def_vmap
    def _one_vmap(axis_size, in_batched, *args):
        out = _batched_solver(cfg, st)(*_broadcast_unbatched(axis_size, in_batched, args))
        return out, jax.tree.map(lambda _: True, out)

    return one


def _arguments(P, q, G, h, warm_start: QPResult | None) -> tuple:
    """(P, q, G, h[, warm x, z, valid]) as arrays of a float dtype, shapes checked."""
    dtype = jp.result_type(P, q, G, h, jp.float32)
    P, q, G, h = (jp.asarray(a, dtype) for a in (P, q, G, h))
    n, m = q.shape[0] if q.ndim == 1 else -1, h.shape[0] if h.ndim == 1 else -1
    if q.ndim != 1 or h.ndim != 1 or P.shape != (n, n) or G.shape != (m, n):
        raise DpcError(
            f"qp.solve takes one problem: P (n, n), q (n,), G (m, n), h (m,); got P {P.shape}, "
            f"q {q.shape}, G {G.shape}, h {h.shape}. For a batch, use jax.vmap(qp.solve)."
        )
    if warm_start is None:
        return (P, q, G, h)
    warm = (jp.asarray(warm_start.x), jp.asarray(warm_start.z), jp.asarray(warm_start.valid))
    if warm[0].shape != (n,) or warm[1].shape != (m,) or warm[2].shape != ():
        raise DpcError(
            f"warm_start must be a QPResult of this problem's shapes (x ({n},), z ({m},), valid "
            f"()); got x {warm[0].shape}, z {warm[1].shape}, valid {warm[2].shape}."
        )
    return (P, q, G, h, *warm)


def _structure_of(G: jax.Array, g_pattern) -> _Structure:
    """The static _Structure of G (m, n) for a g_pattern (None or an (m, n) bool array)."""
    m, n = G.shape
    if g_pattern is None:
        return _structure(m, n, None)
    if isinstance(g_pattern, jax.core.Tracer):
        raise DpcError(
            "g_pattern must be a concrete (static) array, e.g. a numpy constant; got a traced "
            "value. Build it outside jit/vmap (it describes the problem's structure, not data)."
        )
    pattern = np.asarray(g_pattern)
    if pattern.shape != (m, n) or pattern.dtype != bool:
        raise DpcError(
            f"g_pattern must be a bool array of G's shape {(m, n)} (True where G may be nonzero); "
            f"got {pattern.dtype} {pattern.shape}."
        )
    return _structure(m, n, tuple(map(tuple, pattern.tolist())))


def _inputs(P, q, G, h, warm_start, settings, g_pattern) -> tuple:  # noqa: PLR0913, PLR0917
    """(kernel arguments, QPSettings, _Structure) of a call of solve or _solve_reference."""
    args = _arguments(P, q, G, h, warm_start)
    return args, settings or QPSettings(), _structure_of(args[2], g_pattern)


def solve(  # noqa: PLR0913 (the problem's four arrays plus three options)
    P: jax.Array,
    q: jax.Array,
    G: jax.Array,
    h: jax.Array,
    *,
    warm_start: QPResult | None = None,
    settings: QPSettings | None = None,
    g_pattern: np.ndarray | None = None,
) -> QPResult:
    """Solve min 1/2 x'Px + q'x s.t. Gx <= h for one problem; see the module doc and QPResult.

    Args:
      P: (n, n) symmetric PSD (its symmetric part is used).  q: (n,).  G: (m, n).  h: (m,).
      warm_start: a previous QPResult of the same shapes; its x and z start the iteration
        (ignored where its `valid` is False).
      settings: QPSettings, defaults if None.
      g_pattern: None (G dense), or a static (m, n) bool array, True where G may be nonzero;
        G's other entries are taken as 0 and never read, and each iteration only forms the
        products of the pattern's entries (e.g. `balance.G_PATTERN`: 40 of 288 entries).
    Returns the best iterate seen (smallest residual-to-tolerance ratio). Never raises inside jit:
    non-finite input gives valid False and x = 0 (shapes that are not one problem's raise
    DpcError when traced). Under jax.vmap the batch runs batch-minor (see the module doc); the
    results are the same as one call per problem up to float32 rounding.
    """
    args, cfg, st = _inputs(P, q, G, h, warm_start, settings, g_pattern)
    return _solver(cfg, st)(*args)


def _solve_reference(  # noqa: PLR0913 (as solve)
    P: jax.Array,
    q: jax.Array,
    G: jax.Array,
    h: jax.Array,
    *,
    warm_start: QPResult | None = None,
    settings: QPSettings | None = None,
    g_pattern: np.ndarray | None = None,
) -> QPResult:
    """`solve` without the batching rule: under vmap, the batch is the leading axis of every op
    (the layout before the batch-minor kernel). For benchmarks and tests only."""
    return _run_kernel(*_inputs(P, q, G, h, warm_start, settings, g_pattern))
