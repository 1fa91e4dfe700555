"""Throughput of the full DPC env vs MJX physics alone, at the same batch, in one run.

    python experiments/bench_env.py [--arm regular] [--batches 1 64 256 1024] [--quick]

What is measured: `dpc_mjx.run.bench` (also `dpc-mjx bench`). `--quick`: batches 1 and 16, 10 calls.
"""

from __future__ import annotations

import argparse

from dpc_mjx.run.bench import print_table


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--arm", default="regular")
    p.add_argument("--batches", type=int, nargs="+", default=[1, 64, 256, 1024])
    p.add_argument("--calls", type=int, default=50)
    p.add_argument("--quick", action="store_true", help="batches 1 16, 10 calls")
    args = p.parse_args()
    batches, calls = ([1, 16], 10) if args.quick else (args.batches, args.calls)
    print_table(args.arm, batches, calls)


if __name__ == "__main__":
    main()
