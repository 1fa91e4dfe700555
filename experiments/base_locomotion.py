"""The locomotion table per base: stand, trot and turn under MBC, the observer and the oracle.

    python experiments/base_locomotion.py [--bases a1 go1 go2 b1] [--arm regular]
        [--motions stand trot turn] [--controllers mbc observer oracle] [--episodes 64]
        [--steps 500] [--seed 32000] [--engine native] [--set NAME=VALUE ...]

Each cell is `dpc_mjx.run.eval.evaluate` on the reaching task with the arm's reaching motion,
the task's pushes and payloads (on a base other than the A1 scaled by its weight,
`dpc_mjx.envs.registry.WEIGHT_SCALED`) and the velocity command fixed for the whole episode:

    stand   v_x = 0,        yaw rate = 0
    trot    v_x = 0.3 m/s,  yaw rate = 0
    turn    v_x = 0,        yaw rate = 0.5 rad/s

Every controller runs the same episodes (seeds `--seed` .. `--seed + episodes - 1`). Prints a
markdown table: fall rate with its 95% Wilson interval, RMS roll and pitch, the forward-speed
and yaw-rate RMS errors to the command (over the steps before a fall), wall time.
`--set push_force=[0,0]` turns the pushes off (values as JSON).
"""

from __future__ import annotations

import argparse
import shlex
import sys

from dpc_mjx.run.cli_tools import parse_sets
from dpc_mjx.run.eval import evaluate

MOTIONS = {  # name: (v_x m/s, yaw rate rad/s), held for the whole episode
    "stand": (0.0, 0.0),
    "trot": (0.3, 0.0),
    "turn": (0.0, 0.5),
}


def motion_overrides(motion: str) -> dict:
    """The env options that hold `motion`'s command for the whole episode."""
    vx, yaw = MOTIONS[motion]
    return {
        "command_vx": (vx, vx), "command_vy": (0.0, 0.0), "command_yaw": (yaw, yaw),
        "command_switch": (1e6, 1e6),
    }  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--bases", nargs="+", default=["a1", "go1", "go2", "b1"])
    p.add_argument("--arm", default="regular")
    p.add_argument("--motions", nargs="+", default=list(MOTIONS), choices=list(MOTIONS))
    p.add_argument("--controllers", nargs="+", default=["mbc", "observer", "oracle"])
    p.add_argument("--episodes", type=int, default=64)
    p.add_argument("--steps", type=int, default=500, help="env steps per episode (20 ms each)")
    p.add_argument("--seed", type=int, default=32000)
    p.add_argument("--engine", default="native")
    p.add_argument("--set", nargs="*", default=[], help="env options, values as JSON")
    a = p.parse_args()
    extra = parse_sets(a.set)
    print(f"`python {shlex.join(sys.argv)}`\n")
    print(
        f"{a.episodes} episodes of {a.steps} steps ({a.steps * 0.02:g} s) per cell, seeds "
        f"{a.seed}-{a.seed + a.episodes - 1}, arm {a.arm}, engine {a.engine}, "
        f"overrides {extra or 'none'}\n"
    )
    print(
        "| base | motion | controller | fall rate [95% CI] | roll RMS (rad) | pitch RMS (rad) "
        "| v_x RMSE (m/s) | yaw-rate RMSE (rad/s) | wall (s) |\n" + "|---" * 9 + "|",
        flush=True,
    )
    for base in a.bases:
        for motion in a.motions:
            overrides = {"base": base, "engine": a.engine, **motion_overrides(motion), **extra}

            def row(c, base=base, motion=motion):
                print(
                    f"| {base} | {motion} | {c.controller} | {c.fall_rate:.2f} "
                    f"[{c.fall_ci[0]:.2f}, {c.fall_ci[1]:.2f}] | {c.roll_rms:.3f} "
                    f"| {c.pitch_rms:.3f} | {c.vx_rmse:.3f} | {c.yaw_rate_rmse:.3f} "
                    f"| {c.seconds:.0f} |",
                    flush=True,
                )

            evaluate(
                [a.arm], a.controllers, episodes=a.episodes, steps=a.steps, seed=a.seed,
                overrides=overrides, on_result=row, progress=False,
            )  # fmt: skip


if __name__ == "__main__":
    main()
