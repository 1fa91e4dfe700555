"""A caller's own factor of the normal matrix: the kernel's hook for structure it cannot see.

Each interior-point iteration solves H dx = b with H = Ps + Gs' diag(w) Gs (kernel.py). By default
the kernel forms H and factors it by Cholesky (ops.py): unrolled up to `ops._UNROLL_MAX`
variables, dense (LAPACK) above. A problem whose P has a structure that G's pattern does not
show (the MPC's condensed P = Gamma' Q Gamma + R of a linear model, `control/mpc_kkt.py`) can
pass `qp.solve(..., normal_solver=..., normal_data=...)`: the kernel then never forms H and calls
`normal_solver.factor` instead, with the `NormalParts` below and the problem's own `normal_data`
(a tuple of arrays, batched as P is). The solver must factor exactly this H (plus a
regularisation of its diagonal): the residuals, computed from P and G, are what the method
converges on.

A solver that also knows P from its data (`implicit_p`: `p_matvec`, `p_diagonal`) lets the caller
pass P = None: the kernel then never holds the dense P (n, n). Its equilibration reads P's
diagonal instead of its columns' maxima (for a PSD P, |P_ij| <= sqrt(P_ii P_jj)), and the
kernel's sanitising of a non-finite problem zeroes the data (P of zero data is the solver's).
"""

from __future__ import annotations

from typing import Protocol

import jax
import numpy as np
from flax import struct


@struct.dataclass
class NormalParts:
    """What the kernel knows of H = Ps + Gs' diag(w) Gs at an iteration (trailing batch axes).

    d: (n, ...) the variable scaling (x = d xs): Ps = c D P D, Gs = E G D.
    c: (...) the cost scaling.
    p_diag: (n, ...) the diagonal of Ps.
    gwg: (K, ...) the entries of Gs' diag(w) Gs at (rows, cols) (G's pattern; lower triangle, the
      diagonal included).
    one: (...) ones that XLA cannot fold, to compute a value once (`ops._pin`).
    rows, cols: (K,) static numpy indices of those entries.
    """

    d: jax.Array
    c: jax.Array
    p_diag: jax.Array
    gwg: jax.Array
    one: jax.Array
    rows: np.ndarray = struct.field(pytree_node=False)
    cols: np.ndarray = struct.field(pytree_node=False)


class Factor(Protocol):
    def solve(self, b: jax.Array) -> jax.Array:
        """x (n, ...) of H x = b for b (n, ...)."""


class NormalSolver(Protocol):
    """A static, hashable object (it is part of the compiled solver's cache key)."""

    n_data: int  # the number of arrays in `normal_data`
    implicit_p: bool  # P = None allowed: `p_matvec` and `p_diagonal` give what the kernel reads

    def p_matvec(self, data: tuple, x: jax.Array) -> jax.Array:
        """P x (n, ...) for x (n, ...), original units (only where `implicit_p`)."""

    def p_diagonal(self, data: tuple) -> jax.Array:
        """The diagonal of P (n, ...) (only where `implicit_p`)."""

    def factor(self, data: tuple, parts: NormalParts, floor: float) -> Factor:
        """The factor of H + floor diag(H) (the dense factor's pivot floor, `ops._DenseFactor`)
        from the problem's `data` (arrays with trailing batch axes) and the kernel's `parts`,
        whose `gwg` carries on its diagonal the kernel's relative regularisation, as the kernel's
        own H does."""
