"""Throughput of the full DPC env vs MJX physics alone, at the same batch, in one run.

    python experiments/bench_env.py [--arm regular] [--batches 1 64 256 1024] [--quick]

Rows per batch: the env (jit(vmap(step)): 5 x [controller tick + mjx.step], disturbances, obs,
reward, NaN guard; zero actions with the 'policy' controller) and MJX physics alone
(`sim.make_rollout` with 5 steps per call, robot standing on leg servos), both counted in env
steps of 20 ms (5 physics steps = 1 env step), one call per env step. Compile time apart.
`--quick`: batches 1 and 16, fewer calls.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jp
import numpy as np

import dpc_mjx
from dpc_mjx import sim
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos


def _time(fn, x, calls: int) -> tuple[float, float]:
    """(compile + first call s, s per later call)."""
    t0 = time.perf_counter()
    x = jax.block_until_ready(fn(x))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(calls):
        x = fn(x)
    jax.block_until_ready(x)
    return first, (time.perf_counter() - t0) / calls


def bench(arm: str, batch: int, calls: int) -> dict[str, float]:
    env = dpc_mjx.make("a1_arm/reaching", arm=arm)
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), batch))
    action = jp.zeros((batch, env.action_size))
    step = jax.jit(jax.vmap(env.step))
    c_env, t_env = _time(lambda s: step(s, action), state, calls)

    servo = with_leg_servos(env.model)
    mx = sim.put_model(servo)
    data = sim.batched_data(mx, perturbed_home(servo, batch), np.tile(home_ctrl(servo), (batch, 1)))
    physics = sim.make_rollout(mx, n_steps=env.n_substeps)
    c_phys, t_phys = _time(physics, data, calls)
    return {
        "env_sps": batch / t_env,
        "phys_sps": batch / t_phys,
        "env_compile": c_env,
        "phys_compile": c_phys,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--arm", default="regular")
    p.add_argument("--batches", type=int, nargs="+", default=[1, 64, 256, 1024])
    p.add_argument("--calls", type=int, default=50)
    p.add_argument("--quick", action="store_true", help="batches 1 16, 10 calls")
    args = p.parse_args()
    batches, calls = ([1, 16], 10) if args.quick else (args.batches, args.calls)

    print(f"arm {args.arm}, {calls} calls per row, device {jax.devices()[0].platform}\n")
    print(
        "| batch | env steps/s (full env) | env steps/s (physics only) | env / physics "
        "| compile env (s) | compile physics (s) |"
    )
    print("|---|---|---|---|---|---|")
    for batch in batches:
        r = bench(args.arm, batch, calls)
        print(
            f"| {batch} | {r['env_sps']:,.0f} | {r['phys_sps']:,.0f} "
            f"| {r['env_sps'] / r['phys_sps']:.2f} | {r['env_compile']:.1f} "
            f"| {r['phys_compile']:.1f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
