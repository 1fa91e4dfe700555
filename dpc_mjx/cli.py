"""The `dpc-mjx` command line."""

from __future__ import annotations

import argparse
import sys

from dpc_mjx.errors import DpcError


def _demo(args: argparse.Namespace) -> None:
    from dpc_mjx.demo import run_demo
    from dpc_mjx.robots import VARIANTS

    run_demo(args.variants or tuple(VARIANTS), batch=args.batch, seconds=args.seconds)


def _mjcf(args: argparse.Namespace) -> None:
    from dpc_mjx.robots.mjcf import write_mjcf

    for path in write_mjcf(args.out_dir):
        print(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="dpc-mjx", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="build every arm variant and stand a batch of each in MJX")
    demo.add_argument("--variants", nargs="*", help="variant names (default: all)")
    demo.add_argument("--batch", type=int, default=16, help="envs per variant (default 16)")
    demo.add_argument("--seconds", type=float, default=1.0, help="simulated time (default 1)")
    demo.set_defaults(run=_demo)

    mjcf = sub.add_parser("mjcf", help="write every variant's robot and scene MJCF")
    mjcf.add_argument("out_dir", nargs="?", default="mjcf")
    mjcf.set_defaults(run=_mjcf)

    args = parser.parse_args(argv)
    try:
        args.run(args)
    except DpcError as e:
        print(f"dpc-mjx: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
