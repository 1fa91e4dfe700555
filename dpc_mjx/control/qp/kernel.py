"""The interior-point iterations: start, Newton steps, best iterate, result.

Fixed-iteration primal-dual interior point method (Mehrotra) on the problem prepared by
problem.py, for arrays with trailing batch axes (...):

  * Slack form G x + s = h, s >= 0, duals z >= 0, infeasible start (or warm start). Each
    iteration forms the normal matrix H = P + G' diag(z/s) G, factorises it by an unrolled
    Cholesky (a pivot floor instead of a breakdown) and takes a Mehrotra predictor-corrector step
    (two solves with the one factor) with the fraction-to-boundary rule.
  * float32 safeguards: centring target >= mu_floor; no step once mu < mu_stop (H is then too
    ill-conditioned to factor in float32); a non-finite step is not taken; the iterate with the
    smallest residual-to-tolerance ratio is returned.
  * A fixed number of iterations (lax.scan), no data-dependent control flow: every problem of a
    batch costs the same.

Cost per iteration (n = 12, m = 24): H from the stored row products G_ri G_rj (m n(n+1)/2 = 1872
multiply-adds dense, 56 for the balance QP's pattern), the Cholesky (~n^3/6), two pairs of
triangular solves, six matvecs with P, G or G'; ~11k float ops per problem dense. The method and
its tuning are in docs/decisions-controller.md ("Low-level controller: the QP solver"), its speed in
docs/benchmarks.md.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from dpc_mjx.control.qp.ops import (
    _TINY,
    _all_finite,
    _cho_solve,
    _dot,
    _fold,
    _inf_norm,
    _max,
    _pin,
    _pin_flag,
)
from dpc_mjx.control.qp.problem import (
    _g_mtv,
    _g_mv,
    _normal_factor,
    _p_mv,
    _prepare,
    _ps_mv,
    _Scaled,
)
from dpc_mjx.control.qp.settings import QPResult, QPSettings
from dpc_mjx.control.qp.structure import _Structure

_BIG = 1e30  # clamp of z/s (fits float32)


@struct.dataclass
class _Iterate:
    """Iterate in equilibrated units: x (n, ...), s (m, ...), z (m, ...) and gx = Gs x (m, ...)."""

    x: jax.Array
    s: jax.Array
    z: jax.Array
    gx: jax.Array


@struct.dataclass
class _Figures:
    """Residuals of an iterate in original units (...) and merit = max residual / tolerance."""

    primal: jax.Array
    dual: jax.Array
    gap: jax.Array
    primal_tol: jax.Array
    merit: jax.Array


def _max_step(v: jax.Array, dv: jax.Array) -> jax.Array:
    """Largest a in [0, 1] with v + a dv >= 0 (v > 0), per problem."""
    neg = dv < 0
    ratio = jp.where(neg, v / jp.where(neg, -dv, 1.0), 1.0)
    return jp.minimum(1.0, _fold(jp.minimum, ratio))


def _start(pr: _Scaled, warm, cfg: QPSettings):
    """Starting (x, s, z) in equilibrated units.

    Cold: x minimises 1/2 x'Px + q'x + 1/2 |Gx - h|^2, s = max(h - Gx, 1), z = 1.
    Warm: the previous x, s = h - Gx lifted to >= warm_margin (1 + |h_i|), the previous z lifted
    to >= warm_margin (1 + max z) (equilibrated units).
    """
    chol = _normal_factor(pr, jp.ones_like(pr.hs), cfg.pivot_floor)
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


def _residuals(pr: _Scaled, cfg: QPSettings, it: _Iterate) -> tuple[jax.Array, _Figures]:
    """The scaled dual residual rd = Ps x + qs + Gs'z (n, ...) and the _Figures of the iterate."""
    m = pr.hs.shape[0]
    px = _pin(_ps_mv(pr, it.x), pr.one)
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
    return rd, jax.tree.map(lambda f: _pin(f, pr.one), figures)


def _newton_step(pr: _Scaled, cfg: QPSettings, it: _Iterate, rd: jax.Array) -> _Iterate:
    """One Mehrotra predictor-corrector step from `it`; returns the next _Iterate."""
    m, one = pr.hs.shape[0], pr.one
    x, s, z, gx = it.x, it.s, it.z, it.gx
    rp = gx + s - pr.hs  # primal residual of G x + s = h
    mu = _pin(_dot(s, z) / m, one)
    w = jp.minimum(z / s, _BIG)
    chol = _normal_factor(pr, w, cfg.pivot_floor)

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


def _kernel(P, q, G, h, warm, cfg: QPSettings, st: _Structure, data=()) -> QPResult:  # noqa: PLR0913, PLR0917
    """The method on arrays with trailing batch axes (...); warm is None or (x, z, valid); data
    the normal solver's arrays (normal.py)."""
    pr = _prepare(P, q, G, h, cfg, st, data)
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
    objective = 0.5 * _dot(x_out, _p_mv(pr, x_out)) + _dot(pr.q, x_out)
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


def _run_kernel(args: tuple, cfg: QPSettings, st: _Structure) -> QPResult:
    """args = (P, q, G, h[, warm x, warm z, warm valid], *normal data), trailing batch axes."""
    n_data = 0 if st.solver is None else st.solver.n_data
    args, data = tuple(args[: len(args) - n_data]), tuple(args[len(args) - n_data :])
    warm = tuple(args[4:]) or None
    return _kernel(*args[:4], warm, cfg, st, data)
