"""Paired comparisons from saved per-episode CSVs (`dpc-mjx eval --csv`, `eval_episodes.csv`).

    python experiments/paired_csv.py A.csv:dpc B.csv:mbc B.csv:observer ...

The first `CSV:CONTROLLER` is compared with each of the others on the episodes they share,
matched by (arm, seed, episode); episodes must be the same set (same `--seed` and `--episodes`),
else the script stops. Prints the rows of `dpc-mjx eval`'s paired table: return difference and
fall-rate difference with paired 95% intervals, discordant falls and the exact McNemar p. Use it
to pair an export evaluated later with controllers already evaluated on the same episodes (the
env is deterministic given the seed: re-running one of them reproduces its rows exactly).
"""

from __future__ import annotations

import argparse
import csv

import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.run.eval import PAIRED_HEADER, paired_row


def episodes(spec: str) -> dict[tuple, tuple[float, float]]:
    """{(arm, seed, episode): (fell, return)} of one controller in one CSV (`PATH:CONTROLLER`)."""
    path, sep, controller = spec.rpartition(":")
    if not sep:
        raise DpcError(f"Give CSV:CONTROLLER, got {spec!r} (e.g. runs/eval/x.csv:dpc).")
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["controller"] == controller]
    if not rows:
        raise DpcError(f"{path} has no rows of controller {controller!r}.")
    return {
        (r["arm"], r["seed"], r["episode"]): (float(r["fell"]), float(r["return"])) for r in rows
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", help="CSV:CONTROLLER, compared with each of the others")
    ap.add_argument("others", nargs="+", help="CSV:CONTROLLER")
    args = ap.parse_args()
    a = episodes(args.first)
    print(PAIRED_HEADER)
    for spec in args.others:
        b = episodes(spec)
        if set(a) != set(b):
            raise DpcError(f"{args.first} and {spec} hold different episodes; pair the same ones.")
        keys = sorted(a)
        first, second = ([np.array([x[k][i] for k in keys]) for i in (0, 1)] for x in (a, b))
        print(paired_row(f"{args.first} - {spec} ({len(keys)} episodes)", first, second))


if __name__ == "__main__":
    try:
        main()
    except DpcError as e:
        raise SystemExit(f"error: {e}") from None
