"""Array ops along the small leading axes of the QP kernel; trailing axes (...) are batch axes.

The kernel (kernel.py) writes one problem's arithmetic for arrays P (n, n, ...), q (n, ...), G (m,
n, ...) and per-problem scalars (...). Along the leading axes (n = 12, m = 24 for the balance QP)
everything here uses static slices only: unrolled matvecs, Cholesky and substitutions, and pairwise
folds instead of reductions. Every op is then elementwise over the batch, which XLA:CPU vectorises
(batching.py puts the batch on the last axis). `_pin` keeps XLA:CPU from recomputing a fused value
inside each of its consumers. docs/decisions-controller.md ("Implementation: one problem's code, run
batch-minor under vmap") says why each of these forms was chosen.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np

_TINY = 1e-30  # keeps divisions finite (fits float32)


def _pin(x: jax.Array, one: jax.Array) -> jax.Array:
    """x itself (x / 1 is exact), computed once.

    XLA:CPU fuses a cheap expression into every consumer and recomputes it there, once per
    element: a per-problem value broadcast over an (m, ...) vector, or a vector read by a
    matvec, is recomputed m times, and chains of these multiply (docs/decisions-controller.md).
    It does not do so with a float divide by a value it cannot fold, so dividing by `one` (a
    runtime array of ones) makes it compute x into memory once. A pinned value must not be
    divided nor divide: XLA rewrites (x / one) / y as x / (one y), which undoes the pin; hence
    the reciprocals in problem._Scaled.
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

    v * 0 is 0 where v is finite and NaN where not, so the sum says it; on XLA:CPU this float
    formulation is faster than folding isfinite with logical_and.
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


# Above this many variables the factor is dense and batch-major (`_DenseFactor`): the unrolled
# Cholesky emits ~n^2 ops per factor and ~n^2 per solve, and XLA took over 4 minutes (not
# finished) to compile a batch of the MPC's QPs (n = 120: 10 steps x 12 forces, `control/mpc.py`)
# with it, against 10 s dense; LAPACK's potrf and two triangular solves take ~4 ms for a
# (64, 120, 120) batch on one core. The balance QP (n = 12) keeps the unrolled factor; the MPC
# now brings its own (a Riccati recursion, `control/mpc_kkt.py`, through normal.py), ~1 ms.
_UNROLL_MAX = 32


def _cholesky(columns: list[jax.Array], floor: float):
    """The factor of H = L L' from the columns H[j:, j] (n - j, ...): unrolled
    (`_cholesky_unrolled`) up to `_UNROLL_MAX` variables, else dense (`_DenseFactor`)."""
    if len(columns) > _UNROLL_MAX:
        return _DenseFactor.of(columns, floor)
    return _cholesky_unrolled(columns, floor)


@jax.tree_util.register_pytree_node_class
class _DenseFactor:
    """L (..., n, n), lower, batch-major: H + floor diag(H) = L L' for a problem of many
    variables. The floor on the diagonal stands in for the unrolled factor's pivot floor (it
    changes the Newton direction's matrix, not the problem: the residuals are exact)."""

    def __init__(self, L: jax.Array):
        self.L = L

    def tree_flatten(self):
        return (self.L,), None

    @classmethod
    def tree_unflatten(cls, _, children):
        return cls(*children)

    @classmethod
    def of(cls, columns: list[jax.Array], floor: float) -> _DenseFactor:
        pad = [
            jp.concatenate([jp.zeros((j,) + c.shape[1:], c.dtype), c])
            for j, c in enumerate(columns)
        ]
        lower_t = jp.stack(pad)  # (n, n, ...): [j, i] = H[i, j] for i >= j, 0 above
        return cls.of_matrix(jp.moveaxis(lower_t, (0, 1), (-1, -2)), floor)

    @classmethod
    def of_matrix(cls, H: jax.Array, floor: float) -> _DenseFactor:
        """The factor of H (..., n, n), batch-major; only its lower triangle is read."""
        n = H.shape[-1]
        diag = jp.diagonal(H, axis1=-2, axis2=-1)  # (..., n)
        H = H + (floor * diag + _TINY)[..., None] * jp.eye(n, dtype=H.dtype)
        return cls(jax.lax.linalg.cholesky(H, symmetrize_input=False))

    def solve(self, b: jax.Array) -> jax.Array:
        """x (n, ...) of L L' x = b for b (n, ...)."""
        rhs = jp.moveaxis(b, 0, -1)[..., None]  # (..., n, 1)
        solve = jax.lax.linalg.triangular_solve
        y = solve(self.L, rhs, left_side=True, lower=True)
        x = solve(self.L, y, left_side=True, lower=True, transpose_a=True)
        return jp.moveaxis(x[..., 0], -1, 0)


def _cholesky_unrolled(columns: list[jax.Array], floor: float) -> list[tuple[jax.Array, jax.Array]]:
    """Unrolled right-looking Cholesky H = L L' from the columns H[j:, j] (n - j, ...).

    Returns the columns of L as (L_jj (...), L[j+1:, j] (n-j-1, ...)). A pivot below
    floor * H_jj is raised to it, so the factor always exists (a regularised factor of a
    near-singular H). Only the lower triangle is read. The divides here and in _cho_solve
    also pin (see _pin) each entry of the factor and the solution: with reciprocals and
    multiplies instead, XLA:CPU recomputes the chains of updates in every consumer.
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


def _cho_solve(chol, b: jax.Array) -> jax.Array:
    """Solve L L' x = b for b (n, ...), with L from `_cholesky` (column-wise) or any factor with
    a `solve` (`_DenseFactor`, a normal solver's, normal.py)."""
    if not isinstance(chol, list):
        return chol.solve(b)
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
