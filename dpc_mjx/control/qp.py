"""A small dense QP solver in JAX: fixed-iteration primal-dual interior point (Mehrotra).

Solves, for one problem (vmap it for a batch)::

    min_x  1/2 x' P x + q' x    s.t.  G x <= h           x (n,), P (n, n) sym. PSD, G (m, n)

Equalities can be written as pairs of opposite inequalities (the balance QP does this for swing
feet); the method tolerates the empty interior that this creates.

Method (see docs/qp_notes.md for the choice and the tuning):
  * Modified Ruiz equilibration of [P G'; G 0] (variable scaling D, row scaling E) and a cost
    scaling c, so that float32 sees entries of order one.
  * Slack form G x + s = h, s >= 0, duals z >= 0, infeasible start. Each iteration forms the
    normal matrix H = P + G' diag(z/s) G, Cholesky-factorises it (n x n, unrolled, with a pivot
    floor instead of a breakdown), and takes a Mehrotra predictor-corrector step with the
    fraction-to-boundary rule. The target complementarity never goes below `mu_floor`, which keeps
    z/s finite in float32.
  * A fixed number of iterations (lax.scan), no data-dependent control flow: every problem of a
    batch costs the same, and the function is jit- and vmap-able.

Costs per iteration, n = 12, m = 24: forming H (m n(n+1)/2 = 1872 MACs from precomputed row
products), one Cholesky (~n^3/6) and two pairs of triangular solves, six matvecs with G, G' or P.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import numpy as np

_TINY = 1e-30  # keeps divisions finite (fits float32)
_BIG = 1e30  # clamp of z/s (fits float32, its square does not overflow a float32 sum of 24 terms)


@dataclasses.dataclass(frozen=True)
class QPSettings:
    """Static solver settings (Python scalars; a change retraces).

    iterations: interior-point iterations, all of them always run.
    eps_abs, eps_rel: tolerances of the `converged` flag (OSQP-style, inf-norms, unscaled):
      primal  ||max(Gx - h, 0)|| <= eps_abs + eps_rel max(||Gx||, ||h||)
      dual    ||Px + q + G'z||   <= eps_abs + eps_rel max(||Px||, ||G'z||, ||q||)
      gap     s'z / m            <= eps_abs + eps_rel max(|x'Px|, |q'x|) / m.
    ruiz_iterations: equilibration sweeps.
    step_fraction: fraction-to-boundary factor of a step.
    regularization: relative primal regularisation, H += regularization * diag(H).
    pivot_floor: a Cholesky pivot below pivot_floor * H_jj is replaced by it (no breakdown).
    mu_floor: the smallest complementarity target, in the equilibrated units.
    warm_margin: warm-started slacks and duals are lifted to at least this (equilibrated units).
    """

    iterations: int = 10
    eps_abs: float = 1e-5
    eps_rel: float = 1e-3
    ruiz_iterations: int = 5
    step_fraction: float = 0.99
    regularization: float = 1e-7
    pivot_floor: float = 1e-6
    mu_floor: float = 1e-10
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
        d = d / jp.sqrt(jp.where(col > 1e-12, col, 1.0))
        e = e / jp.sqrt(jp.where(row > 1e-12, row, 1.0))
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
        x[j] = y[j] / d if j == n - 1 else (y[j] - c @ jp.stack(x[j + 1 :])) / d
    return jp.stack(x)


def _max_step(v: jax.Array, dv: jax.Array) -> jax.Array:
    """Largest a in [0, 1] with v + a dv >= 0 (v > 0)."""
    neg = dv < 0
    ratio = jp.where(neg, v / jp.where(neg, -dv, 1.0), 1.0)
    return jp.minimum(1.0, jp.min(ratio))


def _inf_norm(v: jax.Array) -> jax.Array:
    return jp.max(jp.abs(v))


def solve(
    P: jax.Array,
    q: jax.Array,
    G: jax.Array,
    h: jax.Array,
    warm_start: QPResult | None = None,
    settings: QPSettings | None = None,
) -> QPResult:
    """Solve min 1/2 x'Px + q'x s.t. Gx <= h for one problem; see the module doc and QPResult.

    Args:
      P: (n, n) symmetric PSD (its symmetric part is used).  q: (n,).  G: (m, n).  h: (m,).
      warm_start: a previous QPResult of the same shapes; its x, z, s start the iteration (ignored
        where its `valid` is False).
      settings: QPSettings, defaults if None.
    Never raises inside jit: non-finite input gives valid False and x = 0.
    """
    cfg = settings or QPSettings()
    dtype = jp.result_type(P, q, G, h, jp.float32)
    P, q, G, h = (jp.asarray(a, dtype) for a in (P, q, G, h))
    n, m = q.shape[0], h.shape[0]
    eye = jp.eye(n, dtype=dtype)

    # --- sanitise: a non-finite problem is replaced by a benign one and flagged ---------------
    finite_in = jp.all(jp.isfinite(P)) & jp.all(jp.isfinite(q))
    finite_in &= jp.all(jp.isfinite(G)) & jp.all(jp.isfinite(h))
    P = jp.where(finite_in, 0.5 * (P + P.T), eye)
    q = jp.where(finite_in, q, 0.0)
    G = jp.where(finite_in, G, 0.0)
    h = jp.where(finite_in, h, 1.0)

    # --- equilibrate: x = D xs, rows scaled by E, cost by c ------------------------------------
    d, e = _equilibrate(P, G, cfg.ruiz_iterations)
    Ps = P * (d[:, None] * d[None, :])
    qs = q * d
    Gs = G * (e[:, None] * d[None, :])
    hs = h * e
    cost_norm = jp.maximum(jp.mean(jp.max(jp.abs(Ps), axis=0)), _inf_norm(qs))
    c = 1.0 / jp.clip(cost_norm, 1e-4, 1e6)
    Ps, qs = Ps * c, qs * c

    # H = Ps + Gs' diag(w) Gs in packed lower-triangular form: Hp = Pp + w @ GG, with the row
    # products GG[r, k] = Gs[r, i_k] Gs[r, j_k] formed once (k runs over the n(n+1)/2 pairs).
    il, jl = np.tril_indices(n)
    unpack = np.zeros((n, n), np.int32)
    unpack[il, jl] = unpack[jl, il] = np.arange(il.size)
    GG = Gs[:, il] * Gs[:, jl]  # (m, n(n+1)/2)
    Pp = Ps[il, jl]

    def normal_matrix(w: jax.Array) -> jax.Array:
        import os
        mode = os.environ.get("HMODE", "packed")
        if mode == "packed":
            Hp = Pp + jp.sum(w[:, None] * GG, axis=0)
            H = Hp[unpack]  # (n, n) symmetric
        elif mode == "dense":
            H = Ps + (Gs.T * w) @ Gs
        elif mode == "mulsum":
            H = Ps + jp.sum(Gs[:, :, None] * (w[:, None] * Gs)[:, None, :], axis=0)
        elif mode == "take":
            Hp = Pp + jp.sum(w[:, None] * GG, axis=0)
            H = jp.take(Hp, jp.asarray(unpack.reshape(-1)), mode="clip").reshape(n, n)
        elif mode == "fixed":
            H = Ps + jp.eye(n) * jp.sum(w)
        return H + cfg.regularization * jp.diag(jp.diagonal(H))

    # --- starting point --------------------------------------------------------------------
    # Cold: x minimises 1/2 x'Px + q'x + 1/2 |Gx - h|^2; s = h - Gx and z lifted to >= 1.
    chol0 = _cholesky(normal_matrix(jp.ones(m, dtype)), cfg.pivot_floor)
    x0 = _cho_solve(chol0, -qs + Gs.T @ hs)
    s0 = jp.maximum(hs - Gs @ x0, 1.0)
    z0 = jp.ones(m, dtype)
    if warm_start is not None:
        use = warm_start.valid & finite_in
        xw = jp.nan_to_num(warm_start.x.astype(dtype)) / d
        sw = jp.maximum(jp.nan_to_num(warm_start.s.astype(dtype)) * e, cfg.warm_margin)
        zw = jp.maximum(jp.nan_to_num(warm_start.z.astype(dtype)) * c / e, cfg.warm_margin)
        x0, s0, z0 = (jp.where(use, a, b) for a, b in ((xw, x0), (sw, s0), (zw, z0)))

    # --- residuals and the convergence test in the original units ------------------------------
    def residuals(x, s, z, gx):
        rd = Ps @ x + qs + Gs.T @ z  # scaled dual residual
        px = Ps @ x
        prim = _inf_norm(jp.maximum(gx - hs, 0.0) / e)
        dual = _inf_norm(rd / d) / c
        gap = jp.dot(s, z) / (c * m)
        prim_tol = cfg.eps_abs + cfg.eps_rel * jp.maximum(_inf_norm(gx / e), _inf_norm(h))
        dual_tol = cfg.eps_abs + cfg.eps_rel * jp.maximum(
            jp.maximum(_inf_norm(px / d), _inf_norm((Gs.T @ z) / d)), _inf_norm(q * c)
        ) / c
        obj_scale = jp.maximum(jp.abs(jp.dot(x, px)), jp.abs(jp.dot(x, qs))) / (c * m)
        gap_tol = cfg.eps_abs + cfg.eps_rel * obj_scale
        ok = (prim <= prim_tol) & (dual <= dual_tol) & (gap <= gap_tol)
        return rd, prim, dual, gap, ok

    def step(carry, k):
        x, s, z, gx, first = carry
        rd, _, _, _, ok = residuals(x, s, z, gx)
        first = jp.where(ok & (first > k), k, first)
        rp = gx + s - hs
        mu = jp.dot(s, z) / m
        w = jp.minimum(z / s, _BIG)
        chol = _cholesky(normal_matrix(w), cfg.pivot_floor)

        def direction(rc):  # Newton step for Z ds + S dz = -rc
            dx = _cho_solve(chol, -rd - Gs.T @ (w * rp - rc / s))
            gdx = Gs @ dx
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
        x = x + a * dx
        s = jp.maximum(s + a * ds, _TINY)
        z = jp.maximum(z + a * dz, _TINY)
        return (x, s, z, gx + a * gdx, first), None

    never = jp.asarray(cfg.iterations + 1, jp.int32)
    carry = (x0, s0, z0, Gs @ x0, never)
    x, s, z, gx, first = jax.lax.scan(
        step, carry, jp.arange(cfg.iterations, dtype=jp.int32)
    )[0]
    _, prim, dual, gap, ok = residuals(x, s, z, gx)
    first = jp.where(ok & (first == never), cfg.iterations, first)

    # --- back to the original units, flags ----------------------------------------------------
    x_out, z_out, s_out = d * x, e * z / c, s / e
    finite_out = jp.all(jp.isfinite(x_out)) & jp.all(jp.isfinite(z_out)) & jp.all(jp.isfinite(s_out))
    prim_tol = cfg.eps_abs + cfg.eps_rel * jp.maximum(_inf_norm(gx / e), _inf_norm(h))
    valid = finite_in & finite_out & (prim <= prim_tol)
    converged = valid & ok
    x_out = jp.where(valid, x_out, 0.0)
    z_out = jp.where(valid, z_out, 0.0)
    s_out = jp.where(valid, s_out, 0.0)
    objective = 0.5 * jp.dot(x_out, P @ x_out) + jp.dot(q, x_out)
    nan0 = jp.asarray(0.0, dtype)
    return QPResult(
        x=x_out,
        z=z_out,
        s=s_out,
        objective=objective,
        primal_residual=jp.where(finite_out, prim, nan0),
        dual_residual=jp.where(finite_out, dual, nan0),
        gap=jp.where(finite_out, gap, nan0),
        iterations=first,
        converged=converged,
        valid=valid,
    )
