"""The convex MPC's options screened on the reaching task's pushes: how often it re-solves and
how its state weights are scaled, the controllers evaluated on the same episodes as
`dpc-mjx eval` would (one program).

    python experiments/mpc_options.py [--arm regular] [--episodes 128] [--seed 90000]
        [--every 5] [--q-scale 1.0] [--controllers mbc feedforward] [--out runs/mpc_options]

`--every` K: control ticks of 4 ms between re-solves (`MPCConfig.every`; 5 is one env step, 1
every tick: the plan then never ages, at K times the solves); `--q-scale`: the MPC's state
weights times this (`MPCConfig.Q`; the force weight R unchanged). The shipped export's env
options, native engine, `low_level="mpc"`, u held over the horizon. Writes the per-episode CSV
`<out>/<arm>-every<K>-q<S>.csv`, to pair with `dpc-mjx eval --csv` runs of the same seeds
(`experiments/paired_csv.py`), and prints the cells.
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib

from dpc_mjx import io
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.eval import evaluate_env, table_row
from dpc_mjx.run.report import write_episodes_csv


def mpc_env(arm: str, every: int, q_scale: float, engine: str = "native"):
    """The reaching env on `arm` with the shipped export's options, the MPC as its low level,
    re-solved every `every` ticks, its state weights times `q_scale`."""
    options = env_overrides(io.load(SHIPPED)) | {"engine": engine, "low_level": "mpc"}
    env = make(DEFAULT_TASK, arm=arm, controller="dpc", **options)
    config = env.controller.config
    mpc = config.mpc.replace(every=every, Q=config.mpc.Q * q_scale)
    env.controller = dataclasses.replace(env.controller, config=config.replace(mpc=mpc))
    return env


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arm", default="regular")
    ap.add_argument("--episodes", type=int, default=128)
    ap.add_argument("--seed", type=int, default=90000)
    ap.add_argument("--every", type=int, default=5, help="control ticks between re-solves")
    ap.add_argument("--q-scale", type=float, default=1.0, help="the state weights times this")
    ap.add_argument("--controllers", nargs="+", default=["mbc", "feedforward"])
    ap.add_argument("--out", default="runs/mpc_options")
    args = ap.parse_args()

    env = mpc_env(args.arm, args.every, args.q_scale)
    steps = env.config.episode_length
    cells = evaluate_env(env, args.arm, args.controllers, args.episodes, steps, args.seed, None)
    label = f"{args.arm}-every{args.every}-q{args.q_scale:g}"
    write_episodes_csv(pathlib.Path(args.out) / f"{label}.csv", cells)
    for c in cells:
        print(f"{label}: {table_row(c)}", flush=True)


if __name__ == "__main__":
    main()
