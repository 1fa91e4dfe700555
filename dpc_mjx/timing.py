"""Wall-clock timing for the benchmarks (`time.perf_counter`, seconds): a stopwatch for a block of
code, a call timed to the end of its work (`jax.block_until_ready`: JAX dispatches
asynchronously), and a jitted call's first run (compile included) apart from its steady state.

    with Stopwatch() as sw:             # a block; sw.seconds after it, sw.elapsed() inside
        compiled = fn.lower(x).compile()
    out, seconds = timed(fn, x)         # one call, blocked on
    first, per_call, x = time_calls(step, x, calls=10)   # x = step(x): compile, then steady state
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import jax


class Stopwatch:
    """Seconds since it started (at creation, and again on entering a `with` block); a `with`
    block leaves its duration in `seconds` (NaN until the block ends)."""

    def __init__(self) -> None:
        self.start = time.perf_counter()
        self.seconds = float("nan")

    def __enter__(self) -> Stopwatch:
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self.seconds = time.perf_counter() - self.start

    def elapsed(self) -> float:
        """Seconds since the start, the stopwatch still running."""
        return time.perf_counter() - self.start


def timed(fn: Callable, *args, **kwargs) -> tuple[Any, float]:
    """`fn(*args, **kwargs)` blocked on (`jax.block_until_ready`), and its wall time (s)."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args, **kwargs))
    return out, time.perf_counter() - t0


def run_calls(fn: Callable, x, calls: int) -> tuple[float, Any]:
    """`x = fn(x)` `calls` times back to back (dispatched without waiting), blocked on at the end:
    (the wall time of all the calls (s), the last x)."""
    t0 = time.perf_counter()
    for _ in range(calls):
        x = fn(x)
    jax.block_until_ready(x)
    return time.perf_counter() - t0, x


def time_calls(fn: Callable, x, calls: int) -> tuple[float, float, Any]:
    """Time `x = fn(x)`: (compile + first call s, s per later call of `calls`, the last x)."""
    x, first = timed(fn, x)
    seconds, x = run_calls(fn, x, calls)
    return first, seconds / calls, x
