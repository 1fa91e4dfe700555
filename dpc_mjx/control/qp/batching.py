"""How a vmap of `solve` runs: the batch on the last axis, in chunks (custom_vmap rule).

The kernel (kernel.py) is written for arrays whose trailing axes are batch axes: P (n, n, ...), q
(n, ...), G (m, n, ...). A single call runs it with no batch axis. Under `jax.vmap`, a batching rule
(`jax.custom_batching.custom_vmap`) moves the batch to the last, contiguous axis and runs the same
code on chunks of `_CHUNK` = 64 problems (`_CHUNK_SPARSE` = 128 with a G pattern), one after the
other (`lax.map`): each XLA:CPU loop is then a SIMD loop over the chunk, and a chunk's data (~10 KB
per problem dense) stay in the L2 cache. On a GPU the whole batch is one chunk. Arguments the vmap
does not batch are broadcast; nested vmaps are merged into one batch. custom_vmap has no
reverse-mode autodiff; nothing differentiates through the solver. docs/decisions-controller.md
("Implementation: one problem's code, run batch-minor under vmap") has the reasons and what was
tried.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jp
from jax import jit  # bound at import: a later patch of `jax.jit` (tests) does not reach the cache

from dpc_mjx.control.qp.kernel import _run_kernel
from dpc_mjx.control.qp.ops import _pin
from dpc_mjx.control.qp.settings import QPResult, QPSettings
from dpc_mjx.control.qp.structure import _Structure

# Problems per chunk of the batched kernel on CPU (docs/decisions-controller.md): a chunk's data
# stay in the L2 cache, and each op of an iteration has a fixed dispatch cost whatever its size, so
# the chunk is as large as the cache allows: 64 for a dense G, 128 with a sparse pattern (its tables
# are ~10x smaller).
_CHUNK, _CHUNK_SPARSE = 64, 128


def _solve_many(args: tuple, cfg: QPSettings, st: _Structure) -> QPResult:
    """args with a leading batch axis B: the kernel on chunks of problems, batch minor."""
    size = args[0].shape[0]
    # XLA:CPU: chunks that stay in cache, one after the other. An accelerator runs the whole
    # batch at once (the batch-minor layout is also what its memory coalescing wants).
    chunk = _CHUNK if st.pattern is None else _CHUNK_SPARSE
    chunk = min(chunk, size) if jax.default_backend() == "cpu" else size
    n_chunks = -(-size // chunk)
    pad = n_chunks * chunk - size
    if pad:  # repeat the last problem to fill the last chunk
        args = [jp.concatenate([a, jp.repeat(a[-1:], pad, axis=0)]) for a in args]

    def run(chunk_args):  # (chunk, ...) each
        # transpose once: XLA:CPU would otherwise fuse the transpose into every reader (strided)
        one = 1.0 + 0.0 * jp.isfinite(chunk_args[1][:, 0]).astype(chunk_args[1].dtype)
        moved = (jp.moveaxis(a, 0, -1) for a in chunk_args)
        res = _run_kernel(tuple(a if a.dtype == bool else _pin(a, one) for a in moved), cfg, st)
        return jax.tree.map(lambda a: jp.moveaxis(a, -1, 0), res)

    if n_chunks == 1:
        out = run(args)
    else:
        split = [a.reshape((n_chunks, chunk) + a.shape[1:]) for a in args]
        out = jax.tree.map(lambda a: a.reshape((-1,) + a.shape[2:]), jax.lax.map(run, split))
    return jax.tree.map(lambda a: a[:size], out) if pad else out


def _broadcast_unbatched(axis_size: int, in_batched, args) -> list[jax.Array]:
    return [
        a if b else jp.broadcast_to(a, (axis_size,) + a.shape) for a, b in zip(args, in_batched)
    ]


@functools.lru_cache(maxsize=None)
def _batched_solver(cfg: QPSettings, st: _Structure):
    """f(*args with a leading batch axis) -> QPResult with that axis; a vmap of f is merged into
    the same batch axis (nested vmaps become one batch)."""

    # jit: a process traces the kernel once per shape, not once per program that holds it
    solve_many = jit(lambda *args: _solve_many(args, cfg, st))

    @jax.custom_batching.custom_vmap
    def many(*args):
        return solve_many(*args)

    @many.def_vmap
    def _many_vmap(axis_size, in_batched, *args):
        args = _broadcast_unbatched(axis_size, in_batched, args)
        inner = args[0].shape[1]
        out = many(*(a.reshape((-1,) + a.shape[2:]) for a in args))
        out = jax.tree.map(lambda a: a.reshape((axis_size, inner) + a.shape[1:]), out)
        return out, jax.tree.map(lambda _: True, out)

    return many


@functools.lru_cache(maxsize=None)
def _solver(cfg: QPSettings, st: _Structure):
    """f(*args of one problem) -> QPResult, whose vmap runs the batch-minor chunked kernel."""

    run_kernel = jit(lambda *args: _run_kernel(args, cfg, st))  # traced once per shape

    @jax.custom_batching.custom_vmap
    def one(*args):
        return run_kernel(*args)

    @one.def_vmap
    def _one_vmap(axis_size, in_batched, *args):
        out = _batched_solver(cfg, st)(*_broadcast_unbatched(axis_size, in_batched, args))
        return out, jax.tree.map(lambda _: True, out)

    return one
