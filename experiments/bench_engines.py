"""The full env under MJX and under native MuJoCo C (`EnvConfig.engine`), side by side in one run.

    python experiments/bench_engines.py [--arm regular] [--batches 64 256] [--calls 5]

Per batch: `jit(vmap(env.step))` through the rollout core (`envs.rollout.make_chunk`, 10 env
steps per call, MBC on the reaching task, the shipped export's sensor model), after a first
call that compiles (timed apart), under MJX and under the native engine with 1 thread and with
every usable core. Reported in env steps of 20 ms (5 controller ticks and physics steps) per s.
"""

from __future__ import annotations

import argparse
import os

import jax

from dpc_mjx.envs import rollout
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.physics import NativePhysics
from dpc_mjx.timing import time_calls

CHUNK = 10  # env steps per call

HEADER = (
    "| batch | engine | threads | compile + first call (s) | env steps/s | vs mjx |\n"
    "|---|---|---|---|---|---|"
)


def bench(arm: str, batch: int, calls: int, engine: str, threads: int | None) -> dict:
    """{'compile' (s), 'sps' (env steps/s)} of the reaching env (MBC) at `batch`."""
    env = make(DEFAULT_TASK, arm=arm, controller="mbc", engine=engine)
    if engine == "native":
        env.physics = NativePhysics(env.model, threads=threads)
    carry, key = rollout.start(env, batch, seed=0)
    run = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, CHUNK)
    first, per_call, _ = time_calls(lambda c: run(c, key)[0], carry, calls)
    return {"compile": first, "sps": batch * CHUNK / per_call}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--arm", default="regular")
    p.add_argument("--batches", type=int, nargs="+", default=[64, 256])
    p.add_argument("--calls", type=int, default=5, help="timed calls of 10 env steps per row")
    args = p.parse_args()
    cores = len(os.sched_getaffinity(0))
    print(f"arm {args.arm}, {cores} usable cores, device {jax.devices()[0].platform}\n")
    print(HEADER, flush=True)
    for batch in args.batches:
        base = None
        for engine, threads in (("mjx", None), ("native", 1), ("native", cores)):
            r = bench(args.arm, batch, args.calls, engine, threads)
            base = base or r["sps"]
            print(
                f"| {batch} | {engine} | {threads or '-'} | {r['compile']:.1f} | {r['sps']:,.0f} "
                f"| {r['sps'] / base:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
