"""What the arms' model leaves, given exactly: the privileged bounds of DPC on the model.

    python experiments/model_bounds.py [--export DIR] [--arm regular] [--episodes 128]
        [--seed 85000] [--engine native] [--bounds all payload push] [--out runs/model_bounds]

DPC on the model (`EnvConfig.u_base` 'model') gives the balance QP the arms' model wrench (the
`feedforward` controller's u) plus the policy's estimate of what the model cannot know: on the
reaching task the end-effector pushes and the payload's weight. Each bound replaces the policy's
estimate by the true external force at the end effectors, at every 4 ms tick (privileged: no
robot measures it), as the wrench about the base's COM, world frame:

    all       pushes + payload weight  (DPC's shipped target, `Dataset.u_unmodelled`)
    payload   the payload's weight only (the slow part: constant over an episode)
    push      the pushes only (the sudden part)
    felt      what the arms' model, given the exact state, accelerations and the servos' targets,
              leaves of the measured wrench: u_oracle - the model wrench of the servos'
              motion (`arm_model.servo_motion`) on one `mjx.forward` of the tick's data (the
              push as the mount feels it beyond the arm's deflection, which the model sees)
    ramped    payload + each push ramped in as 1 - exp(-(t - t_on) / tau) (`--tau` s; a push
              felt through a lag of time constant tau, its tail after it ends dropped)

u_ext = [sum_k F_k, sum_k (p_k - c) x F_k], F_k (N) the force on end effector k at its site
p_k (m, world), c the base's COM. Each bound runs with `feedforward` in one program (the
pairing's check: its rows must equal those of the export's program), and the export's DPC with
`feedforward` in another, all on the same episodes (seeds `--seed`..). Per-episode CSVs to
`--out` (`<bound>.csv`, `dpc.csv`); pair them with `experiments/paired_csv.py`.
"""

from __future__ import annotations

import argparse
import pathlib

import jax.numpy as jp

from dpc_mjx import io
from dpc_mjx.adapter.data import felt_u
from dpc_mjx.control.state import forces_u
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.eval import evaluate_env, table_row
from dpc_mjx.run.report import write_episodes_csv

BOUNDS = ("all", "payload", "push", "felt", "ramped")


def bounded(env, part: str, tau: float = 0.1):
    """`env` (u_base 'model') whose DPC u is the true external end-effector wrench `part`
    (`BOUNDS`) instead of the policy's: a subclass made for this experiment."""
    base = type(env)

    class Bound(base):
        def _ticks(self, d0, info, dist, u_policy, tick_keys):
            self._dist = dist  # read by `_dpc_u` in the same trace (the ticks' scan)
            return base._ticks(self, d0, info, dist, u_policy, tick_keys)

        def _dpc_u(self, d, u_policy):
            if part == "felt":
                return felt_u(self, d)
            dist, yaw = self._dist, self._yaw(d)
            weight = self.sampler.payload_weights(dist)
            push = self.sampler.pushes(dist, d.time, yaw)
            ramp = 1.0 - jp.exp(-jp.maximum(d.time - dist.push_on, 0.0) / tau)  # (k,)
            ramped = weight + push * ramp[:, None]
            forces = {"all": push + weight, "payload": weight, "push": push, "ramped": ramped}
            forces = forces[part]  # (k, 3) N
            return forces_u(forces, d.site_xpos[self.ee_sites], self.com_pos(d))

    env.__class__ = Bound
    return env


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--export", default=str(SHIPPED))
    ap.add_argument("--arm", default="regular")
    ap.add_argument("--episodes", type=int, default=128)
    ap.add_argument("--seed", type=int, default=85000)
    ap.add_argument("--engine", default="native")
    ap.add_argument("--bounds", nargs="+", default=list(BOUNDS), choices=BOUNDS)
    ap.add_argument("--tau", type=float, default=0.1, help="s, the 'ramped' bound's lag")
    ap.add_argument("--no-dpc", action="store_true", help="the bounds only")
    ap.add_argument("--out", default="runs/model_bounds")
    args = ap.parse_args()

    artefacts = io.load(args.export)
    options = env_overrides(artefacts) | {"engine": args.engine, "u_base": "model"}
    out = pathlib.Path(args.out)
    runs = [] if args.no_dpc else [("dpc", None)]
    runs += [(b, b) for b in args.bounds]
    for name, part in runs:
        env = make(DEFAULT_TASK, arm=args.arm, controller="dpc", **options)
        policy = artefacts.dpc_policy(args.arm) if part is None else None
        if part is not None:
            env = bounded(env, part, args.tau)
        steps = env.config.episode_length
        cells = evaluate_env(
            env, args.arm, ["feedforward", "dpc"], args.episodes, steps, args.seed, policy
        )
        label = f"{name}-{args.tau:g}" if part == "ramped" else name
        write_episodes_csv(out / f"{label}.csv", cells)
        for c in cells:
            print(f"{label}: {table_row(c)}", flush=True)


if __name__ == "__main__":
    main()
