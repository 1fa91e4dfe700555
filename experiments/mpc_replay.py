"""The bound of issue 55: the MPC planning against the measured wrench ahead, from a replay of the
same episode (privileged: no robot knows its future wrench), against the same controller with its
u held over the horizon, on the same episodes.

    python experiments/mpc_replay.py [--arm z1] [--episodes 128] [--seed 90000]
        [--controller oracle] [--out runs/mpc_replay]

Two passes of one env (`u_ahead='replay'`, `low_level='mpc'`, the shipped export's env options,
native engine, the reaching task): the first plans against u held (its recording starts at zero)
and records the measured arm-mount wrench at every 4 ms tick; the second replays it, planning at
each tick t against w_k = u(t) + r(t + k dt) - r(t) (`dpc_mjx/envs/ahead.py`). Where the second
pass's robot goes its own way (another step, a fall) the recording is the first pass's, not its
own. Writes `<out>/<arm>-<controller>-held.csv` and `-replay.csv` (per episode, to pair with
`dpc-mjx eval --csv` runs of the same seeds: `experiments/paired_csv.py`) and prints both cells
and the replay minus held, paired.
"""

from __future__ import annotations

import argparse
import pathlib

from dpc_mjx import io
from dpc_mjx.envs import ahead
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.envs.rollout import run_recorded
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.eval import PAIRED_HEADER, cell_result, paired_row, table_row
from dpc_mjx.run.report import write_episodes_csv
from dpc_mjx.timing import Stopwatch


def replay_env(arm: str, controller: str, engine: str = "native"):
    """The reaching env on `arm` under `controller`, the shipped export's options, the MPC as its
    low level planning against a replay (`u_ahead='replay'`)."""
    options = env_overrides(io.load(SHIPPED)) | {"engine": engine, "low_level": "mpc"}
    return make(DEFAULT_TASK, arm=arm, controller=controller, u_ahead="replay", **options)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arm", default="z1")
    ap.add_argument("--episodes", type=int, default=128)
    ap.add_argument("--seed", type=int, default=90000)
    ap.add_argument("--controller", default="oracle", help="mbc, feedforward, oracle, ...")
    ap.add_argument("--out", default="runs/mpc_replay")
    args = ap.parse_args()

    env = replay_env(args.arm, args.controller)
    steps, eps, seed = env.config.episode_length, args.episodes, args.seed
    record = lambda before, after: after.info["u_ticks"]  # noqa: E731  (B, n_substeps, 6)
    cells = {}
    with Stopwatch() as first:
        held, ticks = run_recorded(env, eps, steps, record, seed, progress=True, desc="recorded")
    recordings = ahead.recording(ticks)  # (episodes, steps * n_substeps, 6)
    cells["held"] = cell_result(args.arm, args.controller, held, steps, seed, first.seconds)
    with Stopwatch() as second:
        attach = lambda s: ahead.attach(s, recordings)  # noqa: E731
        replayed, _ = run_recorded(env, eps, steps, None, seed, attach, True, "replayed")
    cells["replay"] = cell_result(args.arm, args.controller, replayed, steps, seed, second.seconds)
    out = pathlib.Path(args.out)
    for name, cell in cells.items():
        write_episodes_csv(out / f"{args.arm}-{args.controller}-{name}.csv", [cell])
        print(f"{name}: {table_row(cell)}", flush=True)
    held_pair, replay_pair = (
        (c.per_episode["fell"], c.per_episode["return"]) for c in cells.values()
    )
    print(PAIRED_HEADER)
    print(paired_row(f"{args.arm} {args.controller}: replay - held", replay_pair, held_pair))


if __name__ == "__main__":
    main()
