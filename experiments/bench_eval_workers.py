"""Evaluation cells one at a time against two at a time (`run.eval.evaluate(workers=...)`).

    .venv/bin/python -u experiments/bench_eval_workers.py [--episodes 64] [--workers 1 2 1]

In one run: the shipped export's four cells (MBC, observer, DPC, oracle on `regular`, with the
export's env options and the default engine: native MuJoCo C on a CPU), `--episodes` episodes of
`--steps` env steps from seed `--seed`, evaluated once per `--workers` entry (default 1, then 2,
then 1 again; each a fresh compile: every cell builds its env and jits anew, and the native
engine's programs never reach JAX's persistent cache). Printed: the wall time of the whole
evaluation per row and whether every per-episode figure of every cell equals the first row's,
bit for bit.
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from dpc_mjx import io
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.eval import evaluate
from dpc_mjx.timing import Stopwatch

CONTROLLERS = ("mbc", "observer", "dpc", "oracle")


def run(workers: int, args: argparse.Namespace, art) -> tuple[float, list]:
    """(wall s, cells) of the four cells with `workers` cells at a time."""
    with Stopwatch() as clock:
        cells = evaluate(
            ["regular"],
            list(CONTROLLERS),
            episodes=args.episodes,
            steps=args.steps,
            seed=args.seed,
            dpc_policy_for=art.dpc_policy,
            overrides=env_overrides(art),  # the export's env options, as `dpc-mjx eval`
            progress=False,
            workers=workers,
        )
    return clock.seconds, cells


def same(a: list, b: list) -> bool:
    """Every per-episode array of every cell equal, bit for bit."""
    return all(
        np.array_equal(x.per_episode[k], y.per_episode[k], equal_nan=True)
        for x, y in zip(a, b, strict=True)
        for k in x.per_episode
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--episodes", type=int, default=64)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--seed", type=int, default=1000)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2, 1], help="one run each")
    args = p.parse_args()
    art = io.load(SHIPPED)
    print(f"4 cells x {args.episodes} episodes x {args.steps} steps, {jax.devices()[0]}\n")
    print("| run | workers | wall (s) | cells as the first run's |\n|---|---|---|---|")
    first = None
    for i, workers in enumerate(args.workers):
        wall, cells = run(workers, args, art)
        first = first or cells
        print(f"| {i + 1} | {workers} | {wall:.1f} | {'yes' if same(cells, first) else 'NO'} |")


if __name__ == "__main__":
    main()
