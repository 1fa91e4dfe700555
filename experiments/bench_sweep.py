"""A sweep over arms as one batched model vs the same cells evaluated one by one, in one run.

    python experiments/bench_sweep.py [--grid 2] [--episodes 16] [--steps 1000]
                                      [--extrapolate 8 --controllers 4]

The cells: a grid x grid of the shipped arm's (upper-arm length 0.10-0.30 m, gripper mass
0.1-0.6 kg), MBC on the reaching task with the shipped export's env options, `episodes` episodes
of `steps` env steps each. 'sweep' runs them as one batched model (`run.sweep`'s way:
`envs.model_batch.ModelBatchEnv`, one compile); 'one by one' builds each arm as its own variant
(`ArmSpec`) and evaluates it alone (`dpc-mjx eval`'s way: a compile per cell). Compile (the
reset and the first chunk, lowered and compiled ahead of time) is timed apart from the run.
The last rows extrapolate both to an `--extrapolate`^2 grid of `--controllers` controllers: one
by one, the mean per-cell time times the cells; the sweep, one compile per controller and the
run time scaled by the envs (linear in the batch on a CPU; a GPU's is flatter).
"""

from __future__ import annotations

import argparse
import dataclasses

import jax
import numpy as np

from dpc_mjx.envs import rollout
from dpc_mjx.envs.model_batch import ModelBatchEnv
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.io.shipped import SHIPPED, export_cells
from dpc_mjx.robots.arms import ArmSpec
from dpc_mjx.robots.arms.params import batch_arm_params
from dpc_mjx.timing import Stopwatch, run_calls

CHUNK = 50  # env steps per jitted call
SEED = 0


def timed(env, batch: int, steps: int, groups: int = 1) -> tuple[float, float]:
    """(compile s, run s) of `steps` MBC env steps of `batch` envs through the rollout core."""
    with Stopwatch() as compiling:
        carry, key = rollout.start(env, batch, SEED, groups)
        run_chunk = rollout.make_chunk(rollout.batch_fns(env)[1], rollout.zero_policy, CHUNK)
        compiled = run_chunk.lower(carry, key).compile()
        jax.block_until_ready(carry)

    def call(state):
        carry, key = state
        key, k = jax.random.split(key)
        return compiled(carry, k)[0], key

    seconds, _ = run_calls(call, (carry, key), steps // CHUNK)
    return compiling.seconds, seconds


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--grid", type=int, default=2, help="grid x grid cells measured")
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--extrapolate", type=int, default=8, help="to this grid x grid")
    p.add_argument("--controllers", type=int, default=4, help="to this many controllers")
    args = p.parse_args()
    _, (arm,), overrides = export_cells(SHIPPED, None, ["mbc"], DEFAULT_TASK)
    overrides = {**overrides, "engine": "mjx"}  # a batch of models is MJX's; both ways in MJX
    ua, gm = (
        a.ravel()
        for a in np.meshgrid(
            np.linspace(0.10, 0.30, args.grid), np.linspace(0.1, 0.6, args.grid), indexing="ij"
        )
    )
    cells, e = len(ua), args.episodes
    print(f"{cells} cells x {e} episodes x {args.steps} steps, MBC, device {jax.devices()[0]}\n")
    print("| how | compile (s) | run (s) | total (s) |\n|---|---|---|---|")

    base = make(DEFAULT_TASK, arm=arm, controller="mbc", **overrides)
    mx, in_axes = batch_arm_params(
        base.mx, base.model, upper_arm_length=np.repeat(ua, e), gripper_mass=np.repeat(gm, e)
    )
    sweep_c, sweep_r = timed(ModelBatchEnv(base, mx, in_axes), cells * e, args.steps, cells)
    print(f"| sweep, one batched model | {sweep_c:.1f} | {sweep_r:.1f} | {sweep_c + sweep_r:.1f} |")
    one = []
    for length, mass in zip(ua, gm):
        spec = dataclasses.replace(
            ArmSpec(), upper_arm_length=float(length), gripper_mass=float(mass)
        )
        env = make(DEFAULT_TASK, arm=spec, controller="mbc", **overrides)
        one.append(timed(env, e, args.steps))
        c, r = one[-1]
        print(
            f"| one by one: L={length:.3f} m, m={mass:.3f} kg | {c:.1f} | {r:.1f} | {c + r:.1f} |"
        )
    c1, r1 = np.sum(one, axis=0)
    print(f"| one by one, {cells} cells | {c1:.1f} | {r1:.1f} | {c1 + r1:.1f} |")

    n, k = args.extrapolate**2, args.controllers
    one_by_one = k * n * (c1 + r1) / cells
    swept = k * (sweep_c + sweep_r * n / cells)
    print(
        f"\nextrapolated to {args.extrapolate} x {args.extrapolate} arms x {k} controllers: "
        f"one by one {one_by_one / 60:.0f} min, sweep {swept / 60:.0f} min "
        f"({one_by_one / swept:.1f}x)"
    )


if __name__ == "__main__":
    main()
