"""What the MPC costs the env step against the balance QP, side by side in one run (issue 55).

    python experiments/bench_mpc.py [--batches 64 256] [--calls 5] [--rounds 3] [--arm regular]
        [--engine native]

Per batch: `jit(vmap(env.step))` through the rollout core (`envs.rollout.make_chunk`, 10 env steps
per call, the reaching task, the MBC controller) with `low_level='qp'` (the balance QP at every
4 ms tick) and `low_level='mpc'` (the MPC re-solved every `MPCConfig.every` ticks, the QP
tracking its plan), alternating in `--rounds` rounds so that the shared machine's drift hits
both alike; the ratio is the median of the rounds'. `--engine native` (the default): one core,
the process restarts pinned to one core with XLA single-threaded (`bench_limit.one_core`), the
native engine's `threads=1`; `--engine mjx`: MJX on the device JAX runs on (a GPU's check,
`experiments/gpu_check.sh`), no pinning. Compile + first call timed apart.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(__file__))
import jax  # noqa: E402
from bench_arm_model import CHUNK  # noqa: E402
from bench_limit import one_core  # noqa: E402

from dpc_mjx.envs import rollout  # noqa: E402
from dpc_mjx.envs.registry import DEFAULT_TASK, make  # noqa: E402
from dpc_mjx.physics import NativePhysics  # noqa: E402
from dpc_mjx.timing import time_calls  # noqa: E402

LOW_LEVELS = ("qp", "mpc")


def runner(arm: str, batch: int, low_level: str, engine: str):
    """(a call: carry -> carry, its first carry) of the reaching env on `arm` under MBC."""
    env = make(DEFAULT_TASK, arm=arm, controller="mbc", engine=engine, low_level=low_level)
    if engine == "native":
        env.physics = NativePhysics(env.model, threads=1)
    carry, key = rollout.start(env, batch, seed=0)
    run = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, CHUNK)
    return (lambda c: run(c, key)[0]), carry


def row(arm: str, batch: int, calls: int, rounds: int, engine: str) -> str:
    """One markdown row: compile times, env steps/s and ms per env step of both, MPC / QP."""
    fns = {name: runner(arm, batch, name, engine) for name in LOW_LEVELS}
    first, sps = {}, {name: [] for name in LOW_LEVELS}
    for _ in range(rounds):
        for name, (fn, carry) in fns.items():
            compile_s, per_call, _ = time_calls(fn, carry, calls)
            first.setdefault(name, compile_s)
            sps[name].append(batch * CHUNK / per_call)
    cost = statistics.median(q / m for q, m in zip(sps["qp"], sps["mpc"], strict=True))
    rate = {name: statistics.median(v) for name, v in sps.items()}
    ms = {name: 1e3 * batch / r for name, r in rate.items()}  # ms per env step of the batch
    return (
        f"| {batch} | {first['qp']:.1f} / {first['mpc']:.1f} | {rate['qp']:,.0f} | "
        f"{rate['mpc']:,.0f} | {ms['qp']:.1f} | {ms['mpc']:.1f} | {cost:.2f} |"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--arm", default="regular")
    p.add_argument("--batches", type=int, nargs="+", default=[64, 256])
    p.add_argument("--calls", type=int, default=5, help="timed calls of 10 env steps per round")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--engine", choices=("native", "mjx"), default="native")
    args = p.parse_args()
    where = "one core"
    if args.engine == "native":
        one_core()
    else:
        where = "the device's own threads"
    print(f"{DEFAULT_TASK}, {args.arm}, MBC, {args.engine}, {where}, {jax.devices()[0].platform}\n")
    print(
        "| batch | compile + first call, QP / MPC (s) | env steps/s QP | MPC | ms per env step "
        "(batch) QP | MPC | MPC / QP cost |"
    )
    print("|---|---|---|---|---|---|---|", flush=True)
    for batch in args.batches:
        print(row(args.arm, batch, args.calls, args.rounds, args.engine), flush=True)


if __name__ == "__main__":
    main()
