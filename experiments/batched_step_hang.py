"""Does a batched env step finish on this jax? `jax.jit(jax.vmap(env.step))` at one batch size.

    python experiments/batched_step_hang.py [--batch 1024] [--calls 20] [--hang-after 300]

Prints one markdown row: jax version, XLA_FLAGS, batch, compile times, the median and the slowest
later call, and how many calls finished. A call that takes longer than `--hang-after` seconds
counts as hung: the row says so and the script exits with status 3. dpc_mjx sets
`--xla_cpu_enable_concurrency_optimized_scheduler=false` itself where XLA_FLAGS is unset, on the
jaxlib versions measured to need it (dpc_mjx/xla_flags.py: 0.10.2); to see the step without it,
start with
`XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=true` (docs/decisions.md, "Packaging
and versions").
"""

from __future__ import annotations

import argparse
import os
import statistics
import threading

import jax
import jax.numpy as jp

from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.timing import timed

HEADER = (
    "| jax | XLA_FLAGS | batch | compile reset (s) | first step (s) | later steps: median (s) "
    "| slowest (s) | calls done |\n|---|---|---|---|---|---|---|---|"
)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--task", default=DEFAULT_TASK)
    p.add_argument("--batch", type=int, default=1024)
    p.add_argument("--calls", type=int, default=20, help="env steps after the first")
    p.add_argument("--hang-after", type=float, default=300.0, help="seconds for one call")
    args = p.parse_args()

    times: list[float] = []  # later calls, s
    first = {"reset": float("nan"), "step": float("nan")}

    def row(done: str) -> str:
        later = (statistics.median(times), max(times)) if times else (float("nan"),) * 2
        return (
            f"| {jax.__version__} | {os.environ.get('XLA_FLAGS', '')} | {args.batch} "
            f"| {first['reset']:.1f} | {first['step']:.1f} | {later[0]:.2f} | {later[1]:.2f} "
            f"| {done} |"
        )

    def watched(fn, *xs):
        """(fn(*xs) blocked on, s); a watchdog ends the process if it exceeds --hang-after."""
        finished = threading.Event()

        def watchdog():
            if not finished.wait(args.hang_after):
                print(row(f"{len(times)}, then hung (> {args.hang_after:.0f} s)"), flush=True)
                os._exit(3)

        threading.Thread(target=watchdog, daemon=True).start()
        out, seconds = timed(fn, *xs)
        finished.set()
        return out, seconds

    print(HEADER, flush=True)
    env = make(args.task)
    keys = jax.random.split(jax.random.PRNGKey(0), args.batch)
    state, first["reset"] = watched(jax.jit(jax.vmap(env.reset)), keys)
    step = jax.jit(jax.vmap(env.step))
    action = jp.zeros((args.batch, env.action_size))
    state, first["step"] = watched(step, state, action)  # compile and one call
    for _ in range(args.calls):
        state, seconds = watched(step, state, action)
        times.append(seconds)
    print(row(f"{len(times)} of {args.calls}"), flush=True)


if __name__ == "__main__":
    main()
