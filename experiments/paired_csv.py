"""Paired comparisons from saved per-episode CSVs (`dpc-mjx eval --csv`, `eval_episodes.csv`).

    python experiments/paired_csv.py A.csv:dpc B.csv:mbc B.csv:observer ... [--by-arm]
        [--measure ball_on_target ...]

The first `CSV:CONTROLLER` is compared with each of the others on the episodes they share,
matched by (arm, seed, episode); episodes must be the same set (same `--seed` and `--episodes`),
else the script stops. Prints the rows of `dpc-mjx eval`'s paired table: return difference and
fall-rate difference with paired 95% intervals, discordant falls and the exact McNemar p. Use it
to pair an export evaluated later with controllers already evaluated on the same episodes (the
env is deterministic given the seed: re-running one of them reproduces its rows exactly).
`--by-arm`: one row per arm of the CSVs (the episodes of that arm) instead of one over all.
`--measure COLUMN ...`: also each column's mean difference (a task's measure, e.g.
`ball_on_target`, `pos_rmse`; any numeric column of the CSV) with its paired 95% interval.
"""

from __future__ import annotations

import argparse

from dpc_mjx.errors import DpcError
from dpc_mjx.run.eval import PAIRED_HEADER, paired_row
from dpc_mjx.run.report import pair, paired_text, read_controller


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", help="CSV:CONTROLLER, compared with each of the others")
    ap.add_argument("others", nargs="+", help="CSV:CONTROLLER")
    ap.add_argument("--by-arm", action="store_true", help="one row per arm")
    ap.add_argument("--measure", nargs="+", default=[], help="CSV columns to pair as well")
    args = ap.parse_args()
    a = read_controller(args.first)
    arms = sorted({key[0] for key in a}) if args.by_arm else [None]
    print(PAIRED_HEADER)
    for spec in args.others:
        b = read_controller(spec)
        for arm in arms:
            first, second = pair(*(_of_arm(x, arm) for x in (a, b)), (args.first, spec))
            where = "" if arm is None else f"{arm}: "
            label = f"{where}{args.first} - {spec} ({len(first[0])} episodes)"
            print(paired_row(label, first, second))
    columns = tuple(args.measure)  # each CSV read once for all of them
    if columns:
        measured = read_controller(args.first, columns)
        pairs = {
            spec: pair(measured, read_controller(spec, columns), (args.first, spec))
            for spec in args.others
        }
    for i, column in enumerate(columns):
        print(f"\n| {column}: first - other (same episodes) | difference [95% CI] |\n|---|---|")
        for spec, (first, second) in pairs.items():
            print(f"| {args.first} - {spec} | {paired_text(first[i], second[i])} |")


def _of_arm(episodes: dict, arm: str | None) -> dict:
    """The episodes of `read_controller` of one arm (None: all)."""
    return episodes if arm is None else {k: v for k, v in episodes.items() if k[0] == arm}


if __name__ == "__main__":
    try:
        main()
    except DpcError as e:
        raise SystemExit(f"error: {e}") from None
