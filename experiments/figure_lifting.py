"""The paper's Fig. "trajectory tracking ... ball lifting": the body's path under MBC and DPC
against the desired one, while the arm lifts a 0.3 kg ball up and down.

    python experiments/figure_lifting.py [--export DIR] [--episodes 16] [--seed 9000]
        [--out docs/figures/lifting_trajectory.png]

The lifting task (`dpc_mjx.envs.tasks.lifting`: walk at ~0.3 m/s, turn at 0.3 rad/s from
~10 s, the ball, 0.5-2 kg heavier per episode, lifted every ~4 s, vertical end-effector pushes)
for the `regular` arm, MBC and the export's DPC (its `regular` encoder and policy, trained on
reaching; the policy's frame and sensor model carry over), on the same `--episodes` episodes
(seeds `--seed`.., which chose nothing; no episode is picked). The desired path is the env's
(`Disturbances.ref_pose`: the command integrated from the start pose; `pos_sq_err` is the
distance from it). Left: episode 0's path (x, y in m) for both controllers and the desired path,
a cross where a controller fell. Right: the distance from the desired position (m) over time,
mean over the episodes still standing, and the fraction standing. Prints the mean tracking error
and the falls.
"""

from __future__ import annotations

import argparse

import numpy as np

from dpc_mjx import io
from dpc_mjx.envs.registry import make
from dpc_mjx.envs.rollout import record_episodes, zero_policy
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.plots import lifting_trajectory

TASK = "lifting"
DT = 0.02  # s per env step


def record(before, after) -> dict:
    """Per step: body position (m, world), the desired one (`Disturbances.ref_pose`: the command
    integrated from the start pose) and done."""
    del before
    return {
        "pos": after.pipeline_state.qpos[:, :2],
        "desired": after.info["dist"].ref_pose[:, :2],
        "done": after.done,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--export", default=str(SHIPPED))
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=9000)
    ap.add_argument("--out", default="docs/figures/lifting_trajectory.png")
    args = ap.parse_args()

    art = io.load(args.export)
    overrides = env_overrides(art, TASK)
    runs = {}
    for label, controller, policy in (
        ("MBC", "mbc", zero_policy),
        ("DPC", "dpc", art.dpc_policy("regular")),
    ):
        env = make(TASK, arm="regular", controller=controller, **overrides)
        r = record_episodes(env, args.episodes, args.steps, args.seed, record, policy)
        standing = np.cumsum(r["done"], 0) == 0
        err = np.linalg.norm(r["pos"] - r["desired"], axis=-1)
        r["error"], r["standing"] = err, standing
        falls = int((~standing[-1]).sum())
        print(
            f"{label}: {falls} of {args.episodes} episodes fell; tracking error while standing "
            f"{err[standing].mean():.3f} m (mean), {err[-1][standing[-1]].mean():.3f} m at the end",
            flush=True,
        )
        runs[label] = r
    print(f"figure: {lifting_trajectory(runs, DT, args.out)}")


if __name__ == "__main__":
    main()
