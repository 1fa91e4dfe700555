"""Where a cold process's compile time goes: trace, lower and XLA compile of the env's reset and
step, as a new user's first `run_episodes` meets them.

    taskset -c 0 python experiments/bench_compile.py [--engine native] [--batch 64]
        [--controller mbc] [--arm regular]

One fresh process per run (jax's trace caches start empty; the native engine's programs never
reach the persistent compilation cache, docs/decisions-engines.md, and MJX's may: run with
`JAX_COMPILATION_CACHE_DIR` unset or empty for a cold figure). Prints one table: seconds of
`jax.jit(jax.vmap(fn)).trace`, `.lower()` and `.compile()` for the reset and the step at
`--batch`, and the env's build. To compare two commits, run it from each (a `git worktree` and
`PYTHONPATH`) on the same core, back to back.
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jp

import dpc_mjx
from dpc_mjx.timing import Stopwatch


def stages(fn, *args):
    """Seconds of trace, lower and XLA compile of `jax.jit(fn)` on `args`, and the compiled
    program."""
    with Stopwatch() as trace:
        traced = jax.jit(fn).trace(*args)
    with Stopwatch() as lower:
        lowered = traced.lower()
    with Stopwatch() as compile_:
        compiled = lowered.compile()
    return (trace.seconds, lower.seconds, compile_.seconds), compiled


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--engine", default="native", choices=("mjx", "native"))
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--controller", default="mbc")
    p.add_argument("--arm", default="regular")
    args = p.parse_args()
    with Stopwatch() as build:
        env = dpc_mjx.make("reaching", arm=args.arm, controller=args.controller, engine=args.engine)
    keys = jax.random.split(jax.random.PRNGKey(0), args.batch)
    reset, reset_program = stages(jax.vmap(env.reset), keys)
    state = reset_program(keys)  # the states the step is compiled for (no second compile)
    step, _ = stages(jax.vmap(env.step), state, jp.zeros((args.batch, env.action_size)))
    what = f"{args.engine}, {args.controller}, {args.arm}, batch {args.batch}"
    print(f"{what}; env built in {build.seconds:.1f} s")
    print("| program | trace s | lower s | compile s | total s |")
    print("|---|---:|---:|---:|---:|")
    for name, (t, lo, c) in (("reset", reset), ("step", step)):
        print(f"| {name} | {t:.1f} | {lo:.1f} | {c:.1f} | {t + lo + c:.1f} |")


if __name__ == "__main__":
    main()
