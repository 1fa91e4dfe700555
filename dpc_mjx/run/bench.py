"""Throughput of the full DPC env vs MJX physics alone, at the same batch (`dpc-mjx bench`,
`experiments/bench_env.py`).

Per batch: the env through the rollout core (`envs.rollout.make_chunk` of one step: 5 x
[controller tick + mjx.step], disturbances, obs, reward, NaN guard, the episode tally; zero
actions with the 'policy' controller) and MJX physics alone (`sim.make_rollout`
with 5 steps per call, robot standing on leg servos), both counted in env steps of 20 ms (5
physics steps), one call per env step, after a first call that compiles (timed apart,
`timing.time_calls`).
"""

from __future__ import annotations

import jax
import numpy as np

from dpc_mjx import sim
from dpc_mjx.envs import rollout
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.timing import time_calls  # also imported from here (run.demo)

HEADER = (
    "| batch | env steps/s (full env) | env steps/s (physics only) | env / physics "
    "| compile env (s) | compile physics (s) |\n|---|---|---|---|---|---|"
)


def bench_env(arm: str, batch: int, calls: int, task: str = DEFAULT_TASK, chunk: int = 1) -> dict:
    """{'env_sps', 'phys_sps' (env steps/s), 'env_compile', 'phys_compile' (s)} at `batch`,
    the env `chunk` steps per call (one `lax.scan`; 1: one call per step, as physics)."""
    env = make(task, arm=arm, engine="mjx")  # beside MJX physics alone, on any device
    carry, key = rollout.start(env, batch, seed=0)
    step = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, chunk=chunk)
    c_env, t_env, _ = time_calls(lambda c: step(c, key)[0], carry, calls)
    t_env /= chunk  # s per env step

    servo = with_leg_servos(env.model)
    mx = sim.put_model(servo)
    data = sim.batched_data(mx, perturbed_home(servo, batch), np.tile(home_ctrl(servo), (batch, 1)))
    physics = sim.make_rollout(mx, n_steps=env.n_substeps)
    c_phys, t_phys, _ = time_calls(physics, data, calls)
    return {
        "env_sps": batch / t_env,
        "phys_sps": batch / t_phys,
        "env_compile": c_env,
        "phys_compile": c_phys,
    }


def print_table(arm: str, batches, calls: int, chunk: int = 1) -> list[dict]:
    """Benchmark `arm` at each batch size, printing the markdown table row by row."""
    device = jax.devices()[0].platform
    print(f"arm {arm}, {calls} calls per row, {chunk} env steps per env call, device {device}\n")
    print(HEADER, flush=True)
    rows = []
    for batch in batches:
        rows.append(bench_env(arm, batch, calls, chunk=chunk))
        print(table_row(batch, rows[-1]), flush=True)
    return rows


def table_row(batch: int, r: dict) -> str:
    return (
        f"| {batch} | {r['env_sps']:,.0f} | {r['phys_sps']:,.0f} "
        f"| {r['env_sps'] / r['phys_sps']:.2f} | {r['env_compile']:.1f} "
        f"| {r['phys_compile']:.1f} |"
    )
