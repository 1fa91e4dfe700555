"""A small dense QP solver in JAX: fixed-iteration primal-dual interior point (Mehrotra).

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

Cost per iteration (n = 12, m = 24): H (m n(n+1)/2 = 1872 MACs), the Cholesky (~n^3/6), two pairs
of triangular solves, seven matvecs with P, G or G'. Matvecs are written as multiply + reduce and
the linear algebra as unrolled static slices, which XLA:CPU runs faster under vmap than batched
dots, gathers or LAPACK calls at this size.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jp
import numpy as np

_TINY = 1e-30  # keeps divisions finite (fits float32)
_BIG = 1e30  # clamp of z/s (fits float32)
_NORM_MIN = 1e-12  # a zero row or column is left unscaled by the equilibration


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


def _equilibrate(P: jax.Array, G: jax.Array, sweeps: int) -> tuple[jax.Array, jax.Array]:
    """Ruiz scaling D (n,), E (m,) making the columns of [P G'; G 0] of unit inf-norm."""
    n, m = P.shape[0], G.shape[0]
    d, e = jp.ones(n, P.dtype), jp.ones(m, P.dtype)
    for _ in range(sweeps):
        ps = jp.abs(P) * (d[:, None] * d[None, :])
        gs = jp.abs(G) * (e[:, None] * d[None, :])
        col = jp.maximum(jp.max(ps, axis=0), jp.max(gs, axis=0))  # (n,)
        row = jp.max(gs, axis=1)  # (m,)
        d = d / jp.sqrt(jp.where(col > _NORM_MIN, col, 1.0))
        e = e / jp.sqrt(jp.where(row > _NORM_MIN, row, 1.0))
    return d, e


def _cholesky(H: jax.Array, floor: float) -> list[tuple[jax.Array, jax.Array]]:
    """Unrolled right-looking Cholesky H = L L' of an (n, n) matrix.

    Returns the columns of L as (L_jj (), L[j+1:, j] (n-j-1,)). A pivot below floor * H_jj is
    raised to it, so the factor always exists (a regularised factor of a near-singular H).
    """
    n = H.shape[0]
    h_diag = jp.diagonal(H)
    cols = []
    S = H  # trailing Schur complement, shrinks by one each step
    for j in range(n):
        d = jp.sqrt(jp.maximum(S[0, 0], floor * h_diag[j] + _TINY))
        c = S[1:, 0] / d
        cols.append((d, c))
        if j < n - 1:
            S = S[1:, 1:] - c[:, None] * c[None, :]
    return cols


def _cho_solve(cols: list[tuple[jax.Array, jax.Array]], b: jax.Array) -> jax.Array:
    """Solve L L' x = b for b (n,), with L given column-wise by `_cholesky`."""
    n = len(cols)
    y, r = [], b
    for j in range(n):  # forward: L y = b, column-oriented
        d, c = cols[j]
        y.append(r[0] / d)
        r = r[1:] - c * y[j]
    x = [None] * n
    for j in reversed(range(n)):  # backward: L' x = y, row-oriented
        d, c = cols[j]
        x[j] = y[j] / d if j == n - 1 else (y[j] - jp.sum(c * jp.stack(x[j + 1 :]))) / d
    return jp.stack(x)


def _max_step(v: jax.Array, dv: jax.Array) -> jax.Array:
    """Largest a in [0, 1] with v + a dv >= 0 (v > 0)."""
    neg = dv < 0
    ratio = jp.where(neg, v / jp.where(neg, -dv, 1.0), 1.0)
    return jp.minimum(1.0, jp.min(ratio))


def _inf_norm(v: jax.Array) -> jax.Array:
    return jp.max(jp.abs(v))


def _mv(A: jax.Array, x: jax.Array) -> jax.Array:
    """A x as multiply + reduce: XLA:CPU fuses this; a batched dot of this size is slower."""
    return jp.sum(A * x[None, :], axis=1)


def _mtv(A: jax.Array, y: jax.Array) -> jax.Array:
    """A' y as multiply + reduce."""
    return jp.sum(A * y[:, None], axis=0)


class _Scaled(NamedTuple):
    """The sanitised problem in equilibrated units: x = d * xs, Gs = E G D, cost times c."""

    P: jax.Array  # (n, n) sanitised original P (for the objective)
    q: jax.Array  # (n,) sanitised original q
    h: jax.Array  # (m,) sanitised original h
    Ps: jax.Array  # (n, n) c D P D
    qs: jax.Array  # (n,) c D q
    Gs: jax.Array  # (m, n) E G D
    hs: jax.Array  # (m,) E h
    d: jax.Array  # (n,) variable scaling D
    e: jax.Array  # (m,) row scaling E
    c: jax.Array  # () cost scaling
    g_abs: jax.Array  # () max_j sum_i |Gs_ij| / d_j, bounds |G|'|z| in original units (times c)
    finite: jax.Array  # () bool, the input was finite


def _prepare(P, q, G, h, cfg: QPSettings) -> _Scaled:
    """Sanitise (a non-finite problem becomes min 1/2|x|^2 s.t. 0 <= 1, flagged) and scale."""
    dtype = jp.result_type(P, q, G, h, jp.float32)
    P, q, G, h = (jp.asarray(a, dtype) for a in (P, q, G, h))
    finite = jp.all(jp.isfinite(P)) & jp.all(jp.isfinite(q))
    finite &= jp.all(jp.isfinite(G)) & jp.all(jp.isfinite(h))
    P = jp.where(finite, 0.5 * (P + P.T), jp.eye(q.shape[0], dtype=dtype))
    q = jp.where(finite, q, 0.0)
    G = jp.where(finite, G, 0.0)
    h = jp.where(finite, h, 1.0)

    d, e = _equilibrate(P, G, cfg.ruiz_iterations)
    Ps = P * (d[:, None] * d[None, :])
    qs = q * d
    Gs = G * (e[:, None] * d[None, :])
    cost_norm = jp.maximum(jp.mean(jp.max(jp.abs(Ps), axis=0)), _inf_norm(qs))
    c = 1.0 / jp.clip(cost_norm, 1e-4, 1e6)
    g_abs = jp.max(jp.sum(jp.abs(Gs), axis=0) / d)
    return _Scaled(P, q, h, Ps * c, qs * c, Gs, h * e, d, e, c, g_abs, finite)


def _normal_matrix_fn(pr: _Scaled, cfg: QPSettings):
    """w (m,) -> the lower triangle of H = Ps + Gs' diag(w) Gs, times (1 + reg) on the diagonal.

    Column j below the diagonal is Ps[j:, j] + Gs[:, j:]' (w * Gs[:, j]): m n(n+1)/2 MACs in all,
    with static slices only (a gather is slow under vmap on XLA:CPU; a stored table of the row
    products G_ri G_rj costs more memory traffic than it saves). `_cholesky` reads only the lower
    triangle, so the upper one is left zero.
    """
    n = pr.qs.shape[0]
    diag = 1.0 + cfg.regularization * jp.eye(n, dtype=pr.Ps.dtype)
    offs = np.concatenate([[0], np.cumsum(np.arange(n, 0, -1))])
    Pc = jp.concatenate([pr.Ps[j:, j] for j in range(n)])

    def normal_matrix(w: jax.Array) -> jax.Array:
        wg = w[:, None] * pr.Gs  # (m, n)
        Hp = Pc + jp.concatenate([jp.sum(pr.Gs[:, j:] * wg[:, j : j + 1], 0) for j in range(n)])
        H = jp.stack([jp.pad(Hp[offs[j] : offs[j] + n - j], (j, 0)) for j in range(n)], axis=1)
        return H * diag

    return normal_matrix


def _start(pr: _Scaled, normal_matrix, warm_start: QPResult | None, cfg: QPSettings):
    """Starting (x, s, z) in equilibrated units.

    Cold: x minimises 1/2 x'Px + q'x + 1/2 |Gx - h|^2, s = max(h - Gx, 1), z = 1.
    Warm: the previous x, s = h - Gx lifted to >= warm_margin (1 + |h_i|), the previous z lifted
    to >= warm_margin (1 + max z) (equilibrated units).
    """
    m = pr.hs.shape[0]
    chol = _cholesky(normal_matrix(jp.ones(m, pr.hs.dtype)), cfg.pivot_floor)
    x0 = _cho_solve(chol, -pr.qs + _mtv(pr.Gs, pr.hs))
    s0 = jp.maximum(pr.hs - _mv(pr.Gs, x0), 1.0)
    z0 = jp.ones(m, pr.hs.dtype)
    if warm_start is None:
        return x0, s0, z0
    use = warm_start.valid & pr.finite
    use &= jp.all(jp.isfinite(warm_start.x)) & jp.all(jp.isfinite(warm_start.z))
    xw = jp.nan_to_num(warm_start.x.astype(x0.dtype)) / pr.d
    zw = jp.nan_to_num(warm_start.z.astype(x0.dtype)) * pr.c / pr.e
    # lift both off the boundary, relative to their own scales
    sw = jp.maximum(pr.hs - _mv(pr.Gs, xw), cfg.warm_margin * (1.0 + jp.abs(pr.hs)))
    zw = jp.maximum(zw, cfg.warm_margin * (1.0 + jp.max(zw)))
    return tuple(jp.where(use, a, b) for a, b in ((xw, x0), (sw, s0), (zw, z0)))


class _Iterate(NamedTuple):
    """Interior-point iterate in equilibrated units: x (n,), s (m,), z (m,) and gx = Gs x (m,)."""

    x: jax.Array
    s: jax.Array
    z: jax.Array
    gx: jax.Array


class _Figures(NamedTuple):
    """Residuals of an iterate in original units (scalars) and merit = max residual / tolerance."""

    primal: jax.Array
    dual: jax.Array
    gap: jax.Array
    primal_tol: jax.Array
    merit: jax.Array


def _residuals(pr: _Scaled, cfg: QPSettings, it: _Iterate) -> tuple[jax.Array, _Figures]:
    """The scaled dual residual rd = Ps x + qs + Gs'z (n,) and the _Figures of the iterate."""
    m = pr.hs.shape[0]
    px = _mv(pr.Ps, it.x)
    rd = px + pr.qs + _mtv(pr.Gs, it.z)
    primal = _inf_norm(jp.maximum(it.gx - pr.hs, 0.0) / pr.e)
    dual = _inf_norm(rd / pr.d) / pr.c
    gap = jp.dot(it.s, it.z) / (pr.c * m)
    primal_tol = cfg.eps_abs + cfg.eps_rel * jp.maximum(_inf_norm(it.gx / pr.e), _inf_norm(pr.h))
    # the scale of G'z is bounded via |G|'|z| (large duals of equality pairs cancel in G'z)
    dual_scale = jp.maximum(_inf_norm(px / pr.d), pr.g_abs * _inf_norm(it.z)) / pr.c
    dual_tol = cfg.eps_abs + cfg.eps_rel * jp.maximum(dual_scale, _inf_norm(pr.q))
    obj_scale = jp.maximum(jp.abs(jp.dot(it.x, px)), jp.abs(jp.dot(it.x, pr.qs))) / (pr.c * m)
    gap_tol = cfg.eps_abs + cfg.eps_rel * obj_scale
    merit = jp.maximum(jp.maximum(primal / primal_tol, dual / dual_tol), gap / gap_tol)
    merit = jp.where(jp.isfinite(merit), merit, jp.inf)
    return rd, _Figures(primal, dual, gap, primal_tol, merit)


def _newton_step(pr: _Scaled, cfg: QPSettings, normal_matrix, it: _Iterate, rd: jax.Array):
    """One Mehrotra predictor-corrector step from `it`; returns the next _Iterate."""
    Gs, m = pr.Gs, pr.hs.shape[0]
    x, s, z, gx = it
    rp = gx + s - pr.hs  # primal residual of G x + s = h
    mu = jp.dot(s, z) / m
    w = jp.minimum(z / s, _BIG)
    chol = _cholesky(normal_matrix(w), cfg.pivot_floor)

    def direction(rc):  # Newton direction of the KKT system with Z ds + S dz = -rc
        dx = _cho_solve(chol, -rd - _mtv(Gs, w * rp - rc / s))
        gdx = _mv(Gs, dx)
        ds = -rp - gdx
        dz = -(rc + z * ds) / s
        return dx, ds, dz, gdx

    # predictor (affine scaling), then Mehrotra's centring and second-order correction
    dx, ds, dz, _ = direction(s * z)
    a_p, a_d = _max_step(s, ds), _max_step(z, dz)
    mu_aff = jp.dot(s + a_p * ds, z + a_d * dz) / m
    sigma = jp.clip(mu_aff / jp.maximum(mu, _TINY), 0.0, 1.0) ** 3
    target = jp.maximum(sigma * mu, cfg.mu_floor)
    dx, ds, dz, gdx = direction(s * z + ds * dz - target)
    a = cfg.step_fraction * jp.minimum(_max_step(s, ds), _max_step(z, dz))
    # No step once mu < mu_stop (float32 gains nothing more and H gets too ill-conditioned to
    # factor), nor a non-finite one.
    finite = jp.isfinite(a) & jp.all(jp.isfinite(dx)) & jp.all(jp.isfinite(ds))
    finite &= jp.all(jp.isfinite(dz)) & jp.all(jp.isfinite(gdx))
    a = jp.where(finite & (mu > cfg.mu_stop), a, 0.0)
    return _Iterate(
        x=x + a * jp.where(finite, dx, 0.0),
        s=jp.maximum(s + a * jp.where(finite, ds, 0.0), _TINY),
        z=jp.maximum(z + a * jp.where(finite, dz, 0.0), _TINY),
        gx=gx + a * jp.where(finite, gdx, 0.0),
    )


def solve(  # noqa: PLR0913 (the problem's four arrays plus two options)
    P: jax.Array,
    q: jax.Array,
    G: jax.Array,
    h: jax.Array,
    *,
    warm_start: QPResult | None = None,
    settings: QPSettings | None = None,
) -> QPResult:
    """Solve min 1/2 x'Px + q'x s.t. Gx <= h for one problem; see the module doc and QPResult.

    Args:
      P: (n, n) symmetric PSD (its symmetric part is used).  q: (n,).  G: (m, n).  h: (m,).
      warm_start: a previous QPResult of the same shapes; its x and z start the iteration
        (ignored where its `valid` is False).
      settings: QPSettings, defaults if None.
    Returns the best iterate seen (smallest residual-to-tolerance ratio). Never raises inside jit:
    non-finite input gives valid False and x = 0.
    """
    cfg = settings or QPSettings()
    pr = _prepare(P, q, G, h, cfg)
    normal_matrix = _normal_matrix_fn(pr, cfg)
    x0, s0, z0 = _start(pr, normal_matrix, warm_start, cfg)
    it0 = _Iterate(x0, s0, z0, _mv(pr.Gs, x0))
    _, fig0 = _residuals(pr, cfg, it0)
    never = jp.asarray(cfg.iterations + 1, jp.int32)

    def keep_best(best, it, fig):
        better = fig.merit < best[1].merit
        return jax.tree.map(lambda a, b: jp.where(better, a, b), (it, fig), best)

    def body(carry, k):  # k = iterations done so far
        it, best, first = carry
        rd, fig = _residuals(pr, cfg, it)
        first = jp.where((fig.merit <= 1.0) & (first > k), k, first)
        best = keep_best(best, it, fig)
        return (_newton_step(pr, cfg, normal_matrix, it, rd), best, first), None

    carry = (it0, (it0, fig0), never)
    ks = jp.arange(cfg.iterations, dtype=jp.int32)
    it, best, first = jax.lax.scan(body, carry, ks)[0]
    _, fig = _residuals(pr, cfg, it)
    first = jp.where((fig.merit <= 1.0) & (first == never), cfg.iterations, first)
    it, fig = keep_best(best, it, fig)
    return _result(pr, it, fig, first)


def _result(pr: _Scaled, it: _Iterate, fig: _Figures, first: jax.Array) -> QPResult:
    """Back to the original units, with the flags; x = z = s = 0 where not valid."""
    x_out, z_out, s_out = pr.d * it.x, pr.e * it.z / pr.c, it.s / pr.e
    finite = jp.all(jp.isfinite(x_out)) & jp.all(jp.isfinite(z_out)) & jp.all(jp.isfinite(s_out))
    valid = pr.finite & finite & (fig.primal <= fig.primal_tol)
    x_out, z_out, s_out = (jp.where(valid, v, 0.0) for v in (x_out, z_out, s_out))
    objective = 0.5 * jp.dot(x_out, _mv(pr.P, x_out)) + jp.dot(pr.q, x_out)
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
