"""Every quadruped URDF of the example-robot-data wheel: read, then trotted under MBC (issue 47).

    python experiments/wheel_bases.py [--robots anymal_c solo12 ...] [--arms none regular]
        [--envs 16] [--seconds 10] [--seed 0] [--engine native]

Each file is read by `dpc_mjx.robots.bases.file.read_base` (fixed links whose inertia MuJoCo
refuses fused, `robots.bases.fuse`, named under "fused"); one it refuses is listed with the
refusal. One it reads is trotted as `experiments/base_trot.py` trots a named base (`trot_cell`:
`--envs` envs of the reaching task, pushes off, 0.3 m/s forward, the arm's reaching motion,
`--seconds` of MBC) with each of `--arms`: falls of `--envs` and the forward speed's RMS error to
the command, "does not trot" unless 0 falls and an error below SPEED_TOL (tests/test_bases.py's
check). Prints a markdown table.

The files are the wheel's robots that stand on four legs (`QUADRUPEDS`, picked by hand from
its `robots/` folder: the rest are arms, hands, humanoids, bipeds, drones and pendulums).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import warnings

from base_trot import trot_cell

from dpc_mjx import DpcError, assets
from dpc_mjx.robots.bases.file import read_base

SPEED_TOL = 0.1  # m/s: a cell trots with 0 falls and a v_x RMSE below this (tests/test_bases.py)
QUADRUPEDS = {  # name: the URDF under the wheel's robots/ folder
    "a1": "a1_description/urdf/a1.urdf",
    "anymal_b": "anymal_b_simple_description/robots/anymal.urdf",
    "anymal_b_kinova": "anymal_b_simple_description/robots/anymal-kinova.urdf",
    "anymal_c": "anymal_c_simple_description/urdf/anymal.urdf",
    "b1": "b1_description/urdf/b1.urdf",
    "b1_z1": "b1_description/urdf/b1-z1.urdf",
    "go1": "go1_description/urdf/go1.urdf",
    "go2": "go2_description/urdf/go2.urdf",
    "hyq": "hyq_description/robots/hyq_no_sensors.urdf",
    "laikago": "laikago_description/urdf/laikago.urdf",
    "quadruped": "quadruped_description/urdf/quadruped.urdf",
    "solo": "solo_description/robots/solo.urdf",
    "solo12": "solo_description/robots/solo12.urdf",
}


def _short(message: str, robots: str) -> str:
    """A refusal without the file's path (the table names the file) and with the wheel's
    `robots` folder, where it names another of its files, as `robots/`."""
    first = message.split(": ", 1)[-1] if message.startswith(("Base ", "MuJoCo")) else message
    return " ".join(first.replace(robots, "robots/").split()).replace("|", "/")


def _fused(f) -> str:
    """A `bases.fuse.Fused` in a cell: how many links into which, and whose inertia was refused."""
    return f"{len(f.links)} link(s) into {f.into} (refused: {', '.join(f.refused)})"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", nargs="*", default=list(QUADRUPEDS), choices=list(QUADRUPEDS))
    p.add_argument("--arms", nargs="*", default=["none", "regular"])
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--engine", default="native")
    a = p.parse_args()
    print(f"`python {shlex.join(sys.argv)}`\n")
    arms = " | ".join(f"falls / {a.envs}, arm {arm} (v_x RMSE m/s)" for arm in a.arms)
    print(f"| robot | file | mass (kg) | fused | {arms} |\n" + "|---" * (4 + len(a.arms)) + "|")
    for name in a.robots:
        path = assets.wheel_urdf(QUADRUPEDS[name])
        robots = str(path)[: -len(QUADRUPEDS[name])]  # the wheel's robots/ folder
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the fusion's warning: the table's "fused"
                spec = read_base(str(path))
        except DpcError as e:
            refusal = f"refused: {_short(str(e), robots)}"
            print(f"| {name} | {QUADRUPEDS[name]} | | | {refusal} |" + " |" * (len(a.arms) - 1))
            continue
        fused = "; ".join(_fused(f) for f in spec.fused)
        cells = []
        for arm in a.arms:
            try:
                c = trot_cell(str(path), arm, a.engine, a.envs, a.seconds, a.seed)
                trots = c["falls"] == 0 and c["rms"] < SPEED_TOL
                cells.append(f"{c['falls']} ({c['rms']:.3f}){'' if trots else ': does not trot'}")
            except DpcError as e:
                cells.append(f"refused: {_short(str(e), robots)}")
        print(
            f"| {name} | {QUADRUPEDS[name]} | {spec.mass:.2f} | {fused or 'none'} | "
            + " | ".join(cells) + " |",
            flush=True,
        )  # fmt: skip


if __name__ == "__main__":
    main()
