"""A second identical evaluation in a fresh process, with the command line's persistent
compilation cache (`dpc_mjx/compile_cache.py`), against the first one that filled it.

    python experiments/bench_cache.py [--engine mjx] [--episodes 8] [--steps 50]

Runs `dpc-mjx eval` of the four controllers twice, each in its own process, with one new, empty
cache folder; prints the wall time of each (process start to exit: imports, model build, compile
or cache read, the episodes), their ratio and the cache's entries. The native engine's env
programs hold host callbacks, which jax does not persist: under `--engine native` only the
small programs are served from the cache.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys
import tempfile

from dpc_mjx.timing import Stopwatch


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--engine", default="mjx", choices=("mjx", "native"))
    p.add_argument("--episodes", type=int, default=8)
    p.add_argument("--steps", type=int, default=50)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cache = pathlib.Path(tmp) / "jax"
        env = {**os.environ, "JAX_COMPILATION_CACHE_DIR": str(cache)}
        command = [sys.executable, "-m", "dpc_mjx.run.cli", "eval", "--engine", args.engine]
        command += ["--episodes", str(args.episodes), "--steps", str(args.steps)]
        command += ["--csv", str(pathlib.Path(tmp) / "episodes.csv")]
        walls, entries = [], []
        for _ in range(2):
            with Stopwatch() as sw:
                subprocess.run(command, env=env, check=True, capture_output=True)
            walls.append(sw.seconds)
            entries.append(len(list(cache.glob("*"))))
    print(
        f"dpc-mjx eval --engine {args.engine}: 4 controllers x {args.episodes} episodes x "
        f"{args.steps} steps, each run a fresh process, one cache folder\n"
    )
    print("| run | wall (s) | cache entries after |\n|---|---|---|")
    for name, wall, n in zip(("first (cache empty)", "second (same programs)"), walls, entries):
        print(f"| {name} | {wall:.1f} | {n} |")
    print(f"\nsecond / first: {walls[1] / walls[0]:.2f}")


if __name__ == "__main__":
    main()
