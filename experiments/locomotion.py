"""MBC (and the oracle) standing and trotting in MJX: fall rate, speed RMSE, roll/pitch RMS.

    python experiments/locomotion.py [--envs 32] [--seconds 20] [--out docs/results_locomotion.md]

Every cell is `--envs` robots from perturbed home poses (joint offsets U(-0.05, 0.05) rad, a seed
per command), metrics after the first second and before any fall.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import dpc_mjx  # noqa: F401
from dpc_mjx.control.closed_loop import run_locomotion
from dpc_mjx.timing import Stopwatch

CONDITIONS = [  # (gait, command: forward m/s, lateral m/s, yaw rate rad/s)
    ("stand", (0.0, 0.0, 0.0)),
    ("trot", (0.0, 0.0, 0.0)),
    ("trot", (0.3, 0.0, 0.0)),
    ("trot", (0.5, 0.0, 0.0)),
    ("trot", (0.0, 0.0, 0.5)),
]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--envs", type=int, default=32)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--variants", nargs="*", default=["none", "regular"])
    p.add_argument("--controllers", nargs="*", default=["mbc"])
    p.add_argument("--out", type=pathlib.Path, default=None, help="also write the table here")
    a = p.parse_args()
    lines = [
        f"| variant | controller | gait | command (vx, vy, wz) | falls / {a.envs} "
        "| speed RMSE (m/s) "
        "| yaw-rate RMSE (rad/s) | roll RMS (rad) | pitch RMS (rad) | env-steps/s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    clock = Stopwatch()
    for variant in a.variants:
        for kind in a.controllers:
            for gait_name in ("stand", "trot"):
                cmds = [c for g, c in CONDITIONS if g == gait_name]
                rows = run_locomotion(variant, gait_name, cmds, a.envs, a.seconds, kind)
                for cmd, r in zip(cmds, rows, strict=True):
                    line = (
                        f"| {variant} | {kind} | {gait_name} | {cmd} | "
                        f"{round(r['fall_rate'] * a.envs)} | {r['speed_rmse']:.3f} | "
                        f"{r['yaw_rate_rmse']:.3f} | {r['roll_rms']:.3f} | "
                        f"{r['pitch_rms']:.3f} | {r['steps_per_s']:,.0f} |"
                    )
                    print(line, flush=True)
                    lines.append(line)
    table = "\n".join(lines)
    print(f"\n{table}\n\n({clock.elapsed():.0f} s, command: {' '.join(sys.argv)})")
    if a.out:
        a.out.write_text(table + "\n")


if __name__ == "__main__":
    main()
