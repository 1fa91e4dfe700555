"""What the arms' model wrench costs the env step, side by side in one run.

    python experiments/bench_arm_model.py [--arms regular z1] [--batches 64] [--calls 5]
        [--rounds 3] [--engine native]

Per arm and batch: `jit(vmap(env.step))` through the rollout core (`envs.rollout.make_chunk`, 10
env steps per call, the reaching task, the `feedforward` controller) with the arms' model wrench
computed every tick (`ControllerState.arm`, `control/arm_estimate.py`: the servo accelerations
and the model wrench) and the same env without it (`DpcEnv.use_arm_model(False)`: what the
controllers that do not read it cost), alternating in `--rounds` rounds so
that the shared machine's drift hits both alike; the ratio is the median of the rounds'. One
core (the native engine's `threads=1`). Compile + first call timed apart.
"""

from __future__ import annotations

import argparse
import statistics

import jax

from dpc_mjx.envs import rollout
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.physics import NativePhysics
from dpc_mjx.timing import time_calls

CHUNK = 10  # env steps per call


def runner(arm: str, batch: int, engine: str, with_model: bool):
    """(a call: carry -> carry, its first carry) of the reaching env on `arm`."""
    env = make(DEFAULT_TASK, arm=arm, controller="feedforward", engine=engine)
    if engine == "native":
        env.physics = NativePhysics(env.model, threads=1)
    env.use_arm_model(with_model)
    carry, key = rollout.start(env, batch, seed=0)
    run = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, CHUNK)
    return (lambda c: run(c, key)[0]), carry


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--arms", nargs="+", default=["regular", "z1"])
    p.add_argument("--batches", type=int, nargs="+", default=[64])
    p.add_argument("--calls", type=int, default=5, help="timed calls of 10 env steps per round")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--engine", default="native")
    args = p.parse_args()
    print(f"engine {args.engine}, one core, device {jax.devices()[0].platform}\n")
    print(
        "| arm | batch | compile + first call, with / without (s) | env steps/s with | without "
        "| with / without |"
    )
    print("|---|---|---|---|---|---|", flush=True)
    for arm in args.arms:
        for batch in args.batches:
            fns = {w: runner(arm, batch, args.engine, w) for w in (True, False)}
            first, sps = {}, {True: [], False: []}
            for _ in range(args.rounds):
                for w, (fn, carry) in fns.items():
                    compile_s, per_call, _ = time_calls(fn, carry, args.calls)
                    first.setdefault(w, compile_s)
                    sps[w].append(batch * CHUNK / per_call)
            ratio = statistics.median(a / b for a, b in zip(sps[True], sps[False], strict=True))
            print(
                f"| {arm} | {batch} | {first[True]:.1f} / {first[False]:.1f} | "
                f"{statistics.median(sps[True]):,.0f} | {statistics.median(sps[False]):,.0f} | "
                f"{ratio:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
