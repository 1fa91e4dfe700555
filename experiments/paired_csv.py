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

from dpc_mjx.errors import DpcError
from dpc_mjx.run.eval import PAIRED_HEADER, paired_row
from dpc_mjx.run.report import pair, read_controller


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", help="CSV:CONTROLLER, compared with each of the others")
    ap.add_argument("others", nargs="+", help="CSV:CONTROLLER")
    args = ap.parse_args()
    a = read_controller(args.first)
    print(PAIRED_HEADER)
    for spec in args.others:
        first, second = pair(a, read_controller(spec), (args.first, spec))
        print(paired_row(f"{args.first} - {spec} ({len(first[0])} episodes)", first, second))


if __name__ == "__main__":
    try:
        main()
    except DpcError as e:
        raise SystemExit(f"error: {e}") from None
