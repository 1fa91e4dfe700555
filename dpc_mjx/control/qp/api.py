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
from dpc_mjx.control.qp.normal import NormalSolver
from dpc_mjx.control.qp.settings import QPResult, QPSettings
from dpc_mjx.control.qp.structure import _Structure, _structure
from dpc_mjx.errors import DpcError


def solve(  # noqa: PLR0913 (the problem's four arrays plus five options)
    P: jax.Array | None,
    q: jax.Array,
    G: jax.Array,
    h: jax.Array,
    *,
    warm_start: QPResult | None = None,
    settings: QPSettings | None = None,
    g_pattern: np.ndarray | None = None,
    normal_solver: NormalSolver | None = None,
    normal_data: tuple = (),
) -> QPResult:
    """Solve min 1/2 x'Px + q'x s.t. Gx <= h for one problem; see the module doc and QPResult.

    Args:
      P: (n, n) symmetric PSD (its symmetric part is used), or None where `normal_solver`
        knows it (`implicit_p`).  q: (n,).  G: (m, n).  h: (m,).
      warm_start: a previous QPResult of the same shapes; its x and z start the iteration
        (ignored where its `valid` is False).
      settings: QPSettings, defaults if None.
      g_pattern: None (G dense), or a static (m, n) bool array, True where G may be nonzero;
        G's other entries are taken as 0 and never read, and each iteration only forms the
        products of the pattern's entries (e.g. `balance.G_PATTERN`: 40 of 288 entries).
        With a pattern, G may also be given as its K entries (K,), row-major (`G[g_pattern]`).
      normal_solver: None (the kernel factors H = P + G' diag(w) G itself), or a static,
        hashable `NormalSolver` that factors H from structure of P that the kernel cannot see,
        from `normal_data`, a tuple of `normal_solver.n_data` arrays of this problem (normal.py).
    Returns the best iterate seen (smallest residual-to-tolerance ratio). Never raises inside jit:
    non-finite input gives valid False and x = 0 (shapes that are not one problem's raise
    DpcError when traced). Under jax.vmap the batch runs batch-minor (see batching.py); the
    results are the same as one call per problem up to float32 rounding.
    """
    options = (warm_start, settings, g_pattern, normal_solver, normal_data)
    args, cfg, st = _inputs(P, q, G, h, *options)
    return _solver(cfg, st)(*args)


def _solve_reference(P: jax.Array, q: jax.Array, G: jax.Array, h: jax.Array, **options) -> QPResult:
    """`solve` (same arguments and options) without the batching rule: under vmap, the batch is
    the leading axis of every op (the layout before the batch-minor kernel). For benchmarks and
    tests only."""
    return _run_kernel(*_inputs(P, q, G, h, **options))


def _arguments(P, q, G, h, warm_start: QPResult | None, entries: int = -1) -> tuple:
    """(P, q, G, h[, warm x, z, valid]) as arrays of a float dtype, shapes checked; G (m, n), or
    (entries,) the entries of a g_pattern of that many; P None: a placeholder (0,)."""
    dtype = jp.result_type(*(a for a in (P, q, G, h) if a is not None), jp.float32)
    P = jp.zeros(0, dtype) if P is None else P
    P, q, G, h = (jp.asarray(a, dtype) for a in (P, q, G, h))
    n, m = q.shape[0] if q.ndim == 1 else -1, h.shape[0] if h.ndim == 1 else -1
    g_ok = G.shape in ((m, n), (entries,))
    if q.ndim != 1 or h.ndim != 1 or P.shape not in ((n, n), (0,)) or not g_ok:
        raise DpcError(
            f"qp.solve takes one problem: P (n, n), q (n,), G (m, n) (or the K entries of its "
            f"g_pattern, (K,)), h (m,); got P {P.shape}, q {q.shape}, G {G.shape}, h {h.shape}. "
            "For a batch, use jax.vmap(qp.solve)."
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


def _structure_of(m: int, n: int, g_pattern, solver=None) -> _Structure:
    """The static _Structure of G (m, n) for a g_pattern (None or an (m, n) bool array)."""
    if g_pattern is None:
        return _structure(m, n, None, solver)
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
    return _structure(m, n, tuple(map(tuple, pattern.tolist())), solver)


def _normal_arguments(solver, data, dtype) -> tuple:
    """The normal solver's data as arrays of the problem's float dtype, their count checked."""
    data = tuple(data)
    count = 0 if solver is None else solver.n_data
    if len(data) != count:
        raise DpcError(
            f"normal_data must hold the {count} arrays that normal_solver {solver!r} reads; got "
            f"{len(data)}."
        )
    return tuple(jp.asarray(a, dtype) for a in data)


def _inputs(  # noqa: PLR0913, PLR0917
    P, q, G, h, warm_start=None, settings=None, g_pattern=None, normal_solver=None, normal_data=()
) -> tuple:
    """(kernel arguments, QPSettings, _Structure) of a call of solve or _solve_reference; the
    arguments are (P, q, G, h[, warm x, z, valid], *normal_data), G (K,) where it is compact
    (`_Structure.compact`)."""
    concrete = g_pattern is not None and not isinstance(g_pattern, jax.core.Tracer)
    entries = int(np.sum(np.asarray(g_pattern))) if concrete else -1
    args = _arguments(P, q, G, h, warm_start, entries)
    args = args + _normal_arguments(normal_solver, normal_data, args[0].dtype)
    st = _structure_of(args[3].shape[0], args[1].shape[0], g_pattern, normal_solver)
    if (P is None) != st.implicit_p:
        raise DpcError(
            "P = None needs a normal_solver that knows P (`implicit_p`, qp/normal.py), and "
            f"such a solver takes P = None; got P {'None' if P is None else 'an array'} with "
            f"normal_solver {normal_solver!r}."
        )
    G = args[2]
    if st.compact and G.ndim == 2:  # G as its pattern's entries (K,), before the batch moves
        G = G.reshape(-1)[st.entries]
    elif not st.compact and G.ndim == 1:  # the entries given: G (m, n)
        G = jp.zeros(st.m * st.n, G.dtype).at[st.entries].set(G).reshape(st.m, st.n)
    return (*args[:2], G, *args[3:]), settings or QPSettings(), st
