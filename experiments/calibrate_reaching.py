"""Calibrate the reaching task: MBC (u = 0) vs the oracle (u = measured mount wrench) per arm.

    python experiments/calibrate_reaching.py [--episodes 64] [--steps 500] \
        [--arms regular longer heavier double] [--controllers mbc oracle] [--seed 0] \
        [--set push_force=0,60 payload_mass=0,0.5 ...]

Prints a markdown table: fall rate (95% Wilson CI), mean return (95% normal CI), RMS roll and
pitch and forward-speed RMSE over the steps before a fall. Episodes are fixed-length
(`--steps` env steps of 20 ms), end at the first fall, and use the same seeds for every cell.
The disturbance distributions are the reaching task's defaults unless overridden with --set.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time

import numpy as np

import dpc_mjx
from dpc_mjx.envs.episodes import mean_ci, run_episodes, wilson_ci


def _override(text: str) -> tuple[str, object]:
    name, _, value = text.partition("=")
    parts = [float(v) for v in value.split(",")]
    return name, tuple(parts) if len(parts) > 1 else parts[0]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--episodes", type=int, default=64)
    p.add_argument("--steps", type=int, default=500, help="env steps per episode (20 ms each)")
    p.add_argument("--arms", nargs="+", default=["regular", "longer", "heavier", "double"])
    p.add_argument("--controllers", nargs="+", default=["mbc", "oracle"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", nargs="*", default=[], help="config overrides name=v or name=lo,hi")
    args = p.parse_args()
    overrides = dict(_override(s) for s in args.set)

    print(f"`python {shlex.join(sys.argv)}`\n")
    print(
        f"{args.episodes} episodes of {args.steps} steps ({args.steps * 0.02:g} s) per cell, "
        f"seed {args.seed}, overrides {overrides or 'none'}\n"
    )
    header = (
        "| arm | controller | fall rate [95% CI] | mean return [95% CI] | roll RMS (rad) "
        "| pitch RMS (rad) | v_x RMSE (m/s) | NaN resets | wall (s) |"
    )
    print(header)
    print("|" + "---|" * 9)
    for arm in args.arms:
        for kind in args.controllers:
            env = dpc_mjx.make("a1_arm/reaching", arm=arm, controller=kind, **overrides)
            t0 = time.perf_counter()
            r = run_episodes(env, args.episodes, args.steps, seed=args.seed)
            wall = time.perf_counter() - t0
            n, falls = args.episodes, int(r["fell"].sum())
            lo, hi = wilson_ci(falls, n)
            m, mlo, mhi = mean_ci(r["return"])
            steps = max(float(r["measured"].sum()), 1.0)

            def rms(key, steps=steps, r=r):
                return float(np.sqrt(r[key].sum() / steps))

            print(
                f"| {arm} | {kind} | {falls / n:.2f} [{lo:.2f}, {hi:.2f}] "
                f"| {m:.1f} [{mlo:.1f}, {mhi:.1f}] | {rms('roll_sq'):.3f} "
                f"| {rms('pitch_sq'):.3f} | {rms('vx_sq_err'):.3f} | {int(r['nan'].sum())} "
                f"| {wall:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
