"""The MPC's Newton systems by a Riccati recursion: the QP kernel's normal solver for `mpc.py`.

Each interior-point iteration solves Hs y = b (n = 12 N variables, equilibrated units; the kernel's
`qp/normal.py`), with the condensed P = Gamma' Q Gamma + R I of the model x_{k+1} = A_k x_k + B_k
f_k (`mpc.condense`) and the MPC's block-diagonal G::

    Hs = c D P D + Gs' W Gs = c Gh' Q Gh + blockdiag(S_0 .. S_{N-1}),
    Gh = Gamma D (the model with scaled inputs, Bh_k = B_k diag(d_k)),
    S_k = c R diag(d_k)^2 + (Gs' W Gs)_kk (+ floor diag(Hs)_kk)        (12, 12)

with d_k the 12 variable scalings of step k and c the cost scaling. Hs y = b is the stationarity
of the LQR problem

    min_y  sum_{k=1..N} 1/2 x_k' (c Q) x_k + sum_{k=0..N-1} (1/2 y_k' S_k y_k - b_k' y_k),
    x_0 = 0,  x_{k+1} = A_k x_k + Bh_k y_k,

solved by the backward Riccati recursion (V_N = c Q; for k = N-1 .. 0)::

    Hff_k = S_k + Bh_k' V_{k+1} Bh_k = L_k L_k',   Hfx_k = Bh_k' V_{k+1} A_k,
    Li_k = L_k^-1,  M_k = L_k^-1 Hfx_k,   V_k = c Q + A_k' V_{k+1} A_k - M_k' M_k

(the factor: 10 Cholesky eliminations of 12 x 12, `_eliminate`, instead of one of 120 x 120),
then per right-hand side a backward sweep (p_N = 0; z_k = Li_k (Bh_k' p_{k+1} - b_k), p_k = A_k'
p_{k+1} - M_k' z_k) and a forward one (x_0 = 0; y_k = -Li_k' (M_k x_k + z_k), x_{k+1} = A_k x_k +
Bh_k y_k): the feedback y_k = K_k x_k + u_k with K_k = -Hff_k^-1 Hfx_k, u_k = -Hff_k^-1 h_k.

The solver also knows P (`implicit_p`), so that neither the MPC nor the kernel forms the dense
P (120 x 120): P x by rolling the model out and back (`p_matvec`), diag(P) by the recursion
W_N = Q, W_k = Q + A_k' W_{k+1} A_k, block k of Gamma' Q Gamma being B_k' W_{k+1} B_k
(`p_diagonal`).

Arrays carry the kernel's trailing batch axes (...): matrices (12, 12, ...), products unrolled
over the inner index so that every op is elementwise over the batch (as `qp/ops.py`).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jp
import numpy as np

from dpc_mjx.control.qp.normal import NormalParts
from dpc_mjx.control.qp.ops import _TINY, _mv, _pin, _sum
from dpc_mjx.errors import DpcError

NX = 12  # state (Theta, p, omega, v)
NF = 12  # forces of one step (4 feet x 3)


def _mm(a: jax.Array, b: jax.Array) -> jax.Array:
    """a b for a (i, k, ...), b (k, j, ...) -> (i, j, ...), unrolled over k."""
    out = a[:, 0][:, None] * b[0][None]
    for k in range(1, a.shape[1]):
        out = out + a[:, k][:, None] * b[k][None]
    return out


def _mtm(a: jax.Array, b: jax.Array) -> jax.Array:
    """a' b for a (k, i, ...), b (k, j, ...) -> (i, j, ...), unrolled over k."""
    out = a[0][:, None] * b[0][None]
    for k in range(1, a.shape[0]):
        out = out + a[k][:, None] * b[k][None]
    return out


def _mtv(a: jax.Array, x: jax.Array) -> jax.Array:
    """a' x for a (k, i, ...), x (k, ...) -> (i, ...)."""
    out = a[0] * x[0]
    for k in range(1, a.shape[0]):
        out = out + a[k] * x[k]
    return out


def _eliminate(H: jax.Array, rhs: jax.Array, floor: float) -> jax.Array:
    """L^-1 rhs (k, m, ...) for H = L L' (k, k, ...) symmetric positive definite and rhs (k, m,
    ...): Cholesky's elimination carried along the right-hand sides, one rank-1 update of the
    trailing block per column. A pivot below floor H_jj is raised to it (as
    `ops._cholesky_unrolled`), so the factor always exists. The divide pins each row (`ops._pin`);
    the trailing blocks are left to XLA, which fuses them into the rows that read them (a
    left-looking elimination; pinning them measured 1.3x slower)."""
    k = H.shape[0]
    T = jp.concatenate([H, rhs], axis=1)  # (k - j, k - j + m, ...) at column j
    out = []
    for j in range(k):
        d = jp.sqrt(jp.maximum(T[0, 0], floor * H[j, j] + _TINY))
        row = T[0] / d  # (L[j:, j], (L^-1 rhs)_j)
        out.append(row[k - j :])
        T = T[1:, 1:] - row[1 : k - j][:, None] * row[None, 1:]
    return jp.stack(out)


def _diag(v: jax.Array) -> jax.Array:
    """(k, k, ...) with v (k, ...) on the diagonal."""
    eye = jp.eye(v.shape[0], dtype=v.dtype).reshape(v.shape[:1] * 2 + (1,) * (v.ndim - 1))
    return eye * v[:, None]


@functools.cache
def _block_index(steps: int, rows: tuple, cols: tuple) -> np.ndarray:
    """(N, 12, 12) int: where entry (i, j) of diagonal block k of Gs' W Gs lies among the K
    stored entries at (rows, cols) (the lower triangle), K where it is 0."""
    index = np.full((steps, NF, NF), len(rows), np.int64)
    for t, (r, c) in enumerate(zip(rows, cols, strict=True)):
        k, i, j = r // NF, r % NF, c % NF
        if c // NF != k:
            raise DpcError("the MPC's G' W G must be block-diagonal by steps (mpc.g_pattern)")
        index[k, i, j] = index[k, j, i] = t
    return index


@jax.tree_util.register_pytree_node_class
class RiccatiFactor:
    """The factor of Hs (module doc), stacked over the N steps (leading axis): A, Bh, Li = L_k^-1
    and M = L_k^-1 Hfx_k, each (N, 12, 12, ...); one (...) for `ops._pin`."""

    def __init__(self, A, Bh, Li, M, one):  # noqa: PLR0913, PLR0917
        self.A, self.Bh, self.Li, self.M, self.one = A, Bh, Li, M, one

    def tree_flatten(self):
        return (self.A, self.Bh, self.Li, self.M, self.one), None

    @classmethod
    def tree_unflatten(cls, _, children):
        return cls(*children)

    def solve(self, b: jax.Array) -> jax.Array:
        """y (12 N, ...) of Hs y = b for b (12 N, ...): the two sweeps of the module doc."""
        steps = self.A.shape[0]
        r = b.reshape((steps, NF) + b.shape[1:])

        one = self.one

        def backward(p, xs):  # z_k = L_k^-1 h_k, p_k = A_k' p_{k+1} - M_k' z_k
            A, Bh, Li, M, rk = xs
            z = _pin(_mv(Li, _mtv(Bh, p) - rk), one)
            return _pin(_mtv(A, p) - _mtv(M, z), one), z

        p0 = jp.zeros((NX,) + b.shape[1:], b.dtype)
        xs = (self.A, self.Bh, self.Li, self.M, r)
        _, z = jax.lax.scan(backward, p0, xs, reverse=True)

        def forward(x, xs):  # y_k = -L_k^-T (M_k x_k + z_k)
            A, Bh, Li, M, zk = xs
            y = _pin(-_mtv(Li, _mv(M, x) + zk), one)
            return _pin(_mv(A, x) + _mv(Bh, y), one), y

        _, y = jax.lax.scan(forward, p0, (self.A, self.Bh, self.Li, self.M, z))
        return y.reshape(b.shape)


@dataclasses.dataclass(frozen=True)
class RiccatiSolver:
    """`qp.solve`'s normal solver for the MPC (`qp/normal.py`); normal_data = (A (N, 12, 12),
    B (N, 12, 12), Q (12,), R ()) of P = Gamma' diag(Q tiled) Gamma + R I (`mpc.build_mpc_qp`)."""

    steps: int
    n_data: int = 4
    implicit_p: bool = True

    def p_matvec(self, data: tuple, x: jax.Array) -> jax.Array:
        """P x (12 N, ...) = Gamma' Q Gamma x + R x for x (12 N, ...): the model rolled out from
        x_0 = 0 (s_{k+1} = A_k s_k + B_k x_k), then back (mu_{k+1} = Q s_{k+1} + A_{k+1}'
        mu_{k+2}, (Gamma' Q Gamma x)_k = B_k' mu_{k+1})."""
        A, B, Q, R = data
        xk = x.reshape((self.steps, NF) + x.shape[1:])

        def forward(s, xs):
            Ak, Bk, fk = xs
            s = _mv(Ak, s) + _mv(Bk, fk)
            return s, s

        zero = jp.zeros((NX,) + x.shape[1:], x.dtype)
        _, states = jax.lax.scan(forward, zero, (A, B, xk))

        def backward(carry, xs):  # carry A_{k+1}' mu_{k+2}
            Ak, Bk, sk = xs
            mu = Q * sk + carry
            return _mtv(Ak, mu), _mtv(Bk, mu)

        _, out = jax.lax.scan(backward, zero, (A, B, states), reverse=True)
        return out.reshape(x.shape) + R * x

    def p_diagonal(self, data: tuple) -> jax.Array:
        """diag(P) (12 N, ...): block k of Gamma' Q Gamma is B_k' W_{k+1} B_k with W_N = Q,
        W_k = Q + A_k' W_{k+1} A_k."""
        A, B, Q, R = data
        Qm = _diag(Q)

        def step(W, xs):
            Ak, Bk = xs
            diag = _sum(Bk * _mm(W, Bk))  # (12, ...) the diagonal of B_k' W B_k
            return Qm + _mtm(Ak, _mm(W, Ak)), diag

        _, out = jax.lax.scan(step, Qm, (A, B), reverse=True)
        return out.reshape((self.steps * NF,) + out.shape[2:]) + R

    def factor(self, data: tuple, parts: NormalParts, floor: float) -> RiccatiFactor:
        """The RiccatiFactor of Hs + floor diag(Hs) (module doc) at this iteration's weights
        (in `parts.gwg`)."""
        A, B, Q, R = data
        batch = parts.d.shape[1:]
        d = parts.d.reshape((self.steps, NF) + batch)  # (N, 12, ...)
        index = _block_index(self.steps, tuple(parts.rows), tuple(parts.cols))
        values = jp.concatenate([parts.gwg, jp.zeros((1,) + batch, parts.gwg.dtype)])
        S = values[index]  # (N, 12, 12, ...) the diagonal blocks of Gs' W Gs
        on_diag = values[index[:, np.arange(NF), np.arange(NF)]]  # (N, 12, ...)
        p_diag = parts.p_diag.reshape(d.shape)
        shift = parts.c * R * d * d + floor * (p_diag + on_diag)  # (N, 12, ...)
        S = S + _stacked_diag(shift)
        Bh = B * d[:, None]  # (N, 12, 12, ...) the inputs in the kernel's units
        cq = _diag(Q * parts.c)  # (12, 12, ...)

        def step(V, xs):  # V_{k+1} -> V_k (module doc)
            Ak, Bk, Sk = xs
            VB, VA = _pin(_mm(V, Bk), one), _pin(_mm(V, Ak), one)
            hff = _pin(Sk + _mtm(Bk, VB), one)
            hfx = _mtm(Bk, VA)
            X = _eliminate(hff, jp.concatenate([eye, hfx], axis=1), floor)
            Li, M = _pin(X[:, :NF], one), _pin(X[:, NF:], one)  # L^-1, L^-1 Hfx
            return _pin(cq + _mtm(Ak, VA) - _mtm(M, M), one), (Li, M)

        one = parts.one
        eye = jp.broadcast_to(_diag(jp.ones((NF,) + batch, A.dtype)), (NF, NF) + batch)
        _, (Li, M) = jax.lax.scan(step, cq, (A, _pin(Bh, one), _pin(S, one)), reverse=True)
        return RiccatiFactor(A, Bh, Li, M, one)


def _stacked_diag(v: jax.Array) -> jax.Array:
    """(N, k, k, ...) with v (N, k, ...) on the diagonals."""
    k = v.shape[1]
    eye = jp.eye(k, dtype=v.dtype).reshape((1, k, k) + (1,) * (v.ndim - 2))
    return eye * v[:, :, None]
