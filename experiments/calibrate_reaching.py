"""Calibrate the reaching task: MBC (u = 0) vs the oracle (u = measured mount wrench) per arm.

    python experiments/calibrate_reaching.py [--episodes 64] [--steps 1000] \
        [--arms regular longer heavier double] [--controllers mbc oracle] [--seed 0] \
        [--base a1] [--engine native] [--set push_force=[0,60] push_axis_weights=[0.3,0.3,1] ...]

Prints a markdown table (`dpc_mjx.run.eval`: fall rate with a 95% Wilson interval, mean return with
a 95% normal interval, RMS roll and pitch, speed and yaw-rate RMSE over the steps before a fall).
The disturbance distributions are the reaching task's defaults unless overridden with --set (on a
base other than the A1, scaled by its weight: `dpc_mjx.envs.registry.WEIGHT_SCALED`); --set values
are JSON, read as `dpc-mjx` reads them (`dpc_mjx.run.cli_tools.parse_sets`: lists as tuples).
"""

from __future__ import annotations

import argparse
import shlex
import sys

from dpc_mjx.run.cli_tools import parse_sets
from dpc_mjx.run.eval import TABLE_HEADER, evaluate, table_row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--episodes", type=int, default=64)
    p.add_argument("--steps", type=int, default=1000, help="env steps per episode (20 ms each)")
    p.add_argument("--arms", nargs="+", default=["regular", "longer", "heavier", "double"])
    p.add_argument("--controllers", nargs="+", default=["mbc", "oracle"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--base", default="a1", help="a named base or a base file's path")
    p.add_argument("--engine", default=None, help="native or mjx (default: the library's)")
    p.add_argument("--set", nargs="*", default=[], help="env options name=value, values as JSON")
    args = p.parse_args()
    overrides = parse_sets(args.set)
    overrides["base"] = args.base
    if args.engine is not None:
        overrides["engine"] = args.engine

    print(f"`python {shlex.join(sys.argv)}`\n")
    print(
        f"{args.episodes} episodes of {args.steps} steps ({args.steps * 0.02:g} s) per cell, "
        f"seed {args.seed}, overrides {overrides or 'none'}\n"
    )
    print(TABLE_HEADER, flush=True)
    evaluate(
        args.arms,
        args.controllers,
        episodes=args.episodes,
        steps=args.steps,
        seed=args.seed,
        overrides=overrides,
        on_result=lambda cell: print(table_row(cell), flush=True),
    )


if __name__ == "__main__":
    main()
