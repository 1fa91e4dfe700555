"""A small QP solver in JAX: fixed-iteration primal-dual interior point (Mehrotra).

Solves, for one problem (vmap it for a batch)::

    min_x  1/2 x' P x + q' x    s.t.  G x <= h           x (n,), P (n, n) sym. PSD, G (m, n)

Equalities can be passed as pairs of opposite inequalities; the method tolerates the empty
interior this creates (slower, with growing duals, and the best iterate is returned). Every call
runs the same fixed number of iterations; `solve` is jit- and vmap-able and warm-startable from a
previous QPResult, and under vmap the batch runs batch-minor, in chunks (batching.py).

The modules, in the order a call goes through them:

  api.py        `solve` and `_solve_reference`: argument checks, the static pattern of G.
  settings.py   `QPSettings` (static numbers) and `QPResult` (a pytree).
  batching.py   the custom_vmap rule: the batch on the last axis, in chunks of `_CHUNK`.
  kernel.py     the interior-point iterations: start, Mehrotra steps, best iterate, result.
  problem.py    sanitising, Ruiz equilibration and G's stored products (`_Scaled`).
  normal.py     the hook for a caller's own factor of the Newton systems (`NormalSolver`).
  structure.py  G's static nonzero pattern and its index tables (`_Structure`).
  ops.py        ops along the small leading axes: folds, matvecs, Cholesky, `_pin`.

docs/decisions-controller.md ("Low-level controller: the QP solver") has the method, its tuning and
the reasons for this layout; docs/benchmarks.md has its speed.
"""

from dpc_mjx.control.qp.api import _solve_reference as _solve_reference
from dpc_mjx.control.qp.api import solve
from dpc_mjx.control.qp.batching import _CHUNK as _CHUNK
from dpc_mjx.control.qp.batching import _CHUNK_SPARSE as _CHUNK_SPARSE
from dpc_mjx.control.qp.normal import NormalParts, NormalSolver
from dpc_mjx.control.qp.settings import QPResult, QPSettings

__all__ = ["NormalParts", "NormalSolver", "QPResult", "QPSettings", "solve"]
