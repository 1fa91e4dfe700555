"""The entry points `solve` and `_solve_reference`: argument checks, then the kernel.

`solve` checks one problem's shapes, turns `g_pattern` into its static `_Structure` and calls the
kernel through the batching rule of batching.py; `_solve_reference` calls the same kernel without
that rule (under vmap, the batch is then the leading axis of every op), for benchmarks and tests.
docs/decisions-controller.md ("Low-level controller: the QP solver") describes the method.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np

from dpc_mjx.control.qp.batching import _solver
from dpc_mjx.control.qp.kernel import _run_kernel
from dpc_mjx.control.qp.settings import QPResult, QPSettings
from dpc_mjx.control.qp.structure import _Structure, _structure
from dpc_mjx.errors import DpcError


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
    DpcError when traced). Under jax.vmap the batch runs batch-minor (see batching.py); the
    results are the same as one call per problem up to float32 rounding.
    """
    args, cfg, st = _inputs(P, q, G, h, warm_start, settings, g_pattern)
    return _solver(cfg, st)(*args)


def _solve_reference(P: jax.Array, q: jax.Array, G: jax.Array, h: jax.Array, **options) -> QPResult:
    """`solve` (same arguments and options) without the batching rule: under vmap, the batch is
    the leading axis of every op (the layout before the batch-minor kernel). For benchmarks and
    tests only."""
    return _run_kernel(*_inputs(P, q, G, h, **options))


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


def _inputs(P, q, G, h, warm_start=None, settings=None, g_pattern=None) -> tuple:  # noqa: PLR0913, PLR0917
    """(kernel arguments, QPSettings, _Structure) of a call of solve or _solve_reference."""
    args = _arguments(P, q, G, h, warm_start)
    return args, settings or QPSettings(), _structure_of(args[2], g_pattern)
