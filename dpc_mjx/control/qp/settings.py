"""The solver's settings and result types.

`QPSettings` holds static Python numbers: they shape the traced program, so a change retraces.
`QPResult` is the per-problem output, a pytree (`flax.struct`) that vmap and scan carry like any
array; a controller keeps it as the warm start of its next solve. docs/decisions-controller.md
(section "the QP solver") explains the tolerances and safeguards that these settings tune.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
from flax import struct


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
    warm_margin: warm-started slacks and duals are lifted off 0 by this, relative (kernel._start).
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


@struct.dataclass
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

    @classmethod
    def zeros(cls, n: int, m: int, dtype=jp.float32) -> QPResult:
        """A not-valid result of zeros for n variables and m rows, shaped and typed as `solve`'s
        for float `dtype` inputs: a warm start that starts cold (built without tracing a
        solve)."""
        scalar = jp.zeros((), dtype)
        return cls(
            x=jp.zeros(n, dtype),
            z=jp.zeros(m, dtype),
            s=jp.zeros(m, dtype),
            objective=scalar,
            primal_residual=scalar,
            dual_residual=scalar,
            gap=scalar,
            iterations=jp.zeros((), jp.int32),
            converged=jp.zeros((), bool),
            valid=jp.zeros((), bool),
        )
