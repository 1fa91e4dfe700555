"""The deciding table of issue 55 from its per-episode CSVs: the balance QP and the MPC under each
controller, the wrench held or predicted over the MPC's horizon, paired on the same episodes.

    python experiments/mpc_decide.py [--dir runs/decide] [--arms regular z1 double]

Reads, per arm, what these wrote (the same `--seed` and `--episodes` for every file of an arm):

    qp-ARM.csv      dpc-mjx eval --controllers mbc feedforward oracle --env low_level=qp
    mpc-ARM.csv     the same with --env low_level=mpc (u held over the horizon)
    ahead-ARM.csv   --controllers feedforward --env low_level=mpc u_ahead=model
    pushes-ARM.csv  --controllers feedforward oracle --env low_level=mpc u_ahead=pushes
    ends-ARM.csv    the same with u_ahead=push_ends
    replay/ARM-oracle-held.csv, replay/ARM-oracle-replay.csv
                    python experiments/mpc_replay.py --arm ARM (the oracle held, then replayed)

and prints, per arm, the fall rates of the cells (95% Wilson) and the paired differences that
decide: MPC - QP per controller, the feedforward ahead - held, the oracle replayed - held
(privileged) and the pushes' part of it (privileged: their whole schedule, or the ends of those
under way). A file that is missing leaves its rows out.
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

from dpc_mjx.run.eval import PAIRED_HEADER, paired_row
from dpc_mjx.run.report import pair, read_controller
from dpc_mjx.stats import wilson_ci


def cells(folder: pathlib.Path, arm: str) -> dict[str, dict]:
    """{cell name: the episodes of `read_controller`} of the files of `arm` that exist."""
    sources = {
        "QP, MBC": (f"qp-{arm}.csv", "mbc"),
        "QP, feedforward": (f"qp-{arm}.csv", "feedforward"),
        "QP, oracle": (f"qp-{arm}.csv", "oracle"),
        "MPC, MBC": (f"mpc-{arm}.csv", "mbc"),
        "MPC, feedforward held": (f"mpc-{arm}.csv", "feedforward"),
        "MPC, feedforward ahead": (f"ahead-{arm}.csv", "feedforward"),
        "MPC, oracle held": (f"mpc-{arm}.csv", "oracle"),
        "MPC, oracle held (replay's first pass)": (f"replay/{arm}-oracle-held.csv", "oracle"),
        "MPC, oracle replayed": (f"replay/{arm}-oracle-replay.csv", "oracle"),
        "MPC, feedforward pushes ahead": (f"pushes-{arm}.csv", "feedforward"),
        "MPC, oracle pushes ahead": (f"pushes-{arm}.csv", "oracle"),
        "MPC, feedforward push ends ahead": (f"ends-{arm}.csv", "feedforward"),
        "MPC, oracle push ends ahead": (f"ends-{arm}.csv", "oracle"),
    }
    found = {}
    for name, (file, controller) in sources.items():
        if (folder / file).exists():
            found[name] = read_controller(f"{folder / file}:{controller}")
    return found


PAIRS = (
    ("MPC, MBC", "QP, MBC"),
    ("MPC, feedforward held", "QP, feedforward"),
    ("MPC, oracle held", "QP, oracle"),
    ("MPC, feedforward ahead", "MPC, feedforward held"),
    ("MPC, feedforward ahead", "QP, feedforward"),
    ("MPC, oracle replayed", "MPC, oracle held (replay's first pass)"),
    ("MPC, oracle replayed", "QP, oracle"),
    ("MPC, feedforward pushes ahead", "MPC, feedforward held"),
    ("MPC, oracle pushes ahead", "MPC, oracle held"),
    ("MPC, oracle replayed", "MPC, oracle pushes ahead"),
    ("MPC, feedforward push ends ahead", "MPC, feedforward held"),
    ("MPC, oracle push ends ahead", "MPC, oracle held"),
    ("MPC, oracle pushes ahead", "MPC, oracle push ends ahead"),
)


def arm_table(folder: pathlib.Path, arm: str) -> list[str]:
    """The markdown lines of one arm: its cells' fall rates, then the paired rows."""
    found = cells(folder, arm)
    if not found:
        return [f"{arm}: no CSVs under {folder}"]
    lines = [f"### {arm}", "", "| cell | episodes | fall rate [95% CI] |", "|---|---|---|"]
    for name, episodes in found.items():
        fell = np.array([v[0] for v in episodes.values()]) > 0
        lo, hi = wilson_ci(int(fell.sum()), len(fell))
        lines.append(f"| {name} | {len(fell)} | {fell.mean():.3f} [{lo:.2f}, {hi:.2f}] |")
    lines += ["", PAIRED_HEADER]
    for a, b in PAIRS:
        if a in found and b in found:
            first, second = pair(found[a], found[b], (a, b))
            lines.append(paired_row(f"{arm}: {a} - {b}", first, second))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dir", default="runs/decide")
    ap.add_argument("--arms", nargs="+", default=["regular", "z1", "double"])
    args = ap.parse_args()
    for arm in args.arms:
        print("\n".join(arm_table(pathlib.Path(args.dir), arm)) + "\n")


if __name__ == "__main__":
    main()
