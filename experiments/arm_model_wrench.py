"""How well does the arms' model wrench match the measured mount wrench: R^2 per component and
RMSE, free arm motion (no pushes, no payload), per arm and per input source.

    python experiments/arm_model_wrench.py [--arms regular double so100 z1] [--episodes 16]
        [--steps 500] [--seed 81000] [--engine native] [--controller oracle]

Rollouts of the reaching task with every end-effector force off (`push_force` and
`payload_mass` 0: what the model cannot know is absent), under `--controller` (default the
oracle: the fewest falls, so the most states), seeds `--seed`.. (chose nothing). On every env
step before an episode's end, in the yaw frame (torques about the base's COM), each estimate
against the oracle's u (the measured mount wrench, privileged):

    exact inputs      `arm_model.model_wrench` on the simulator's own state and accelerations
                      (`adapter.data.exact_wrenches`: after `mjx.forward`; privileged), against the
                      oracle of that same forward pass: the model alone
    the others        what the `feedforward` controller computes at its last tick from measured
                      inputs (`EnvConfig.sensor_noise`, the defaults), qdd from the arms' servo
                      targets (`arm_qdd='servo'`) or the encoders' filtered velocity difference
                      ('difference'), the trunk's accelerations those the balance QP asks for
                      (`arm_base_acc='desired'`, the default: not a measurement, so its R^2
                      against the measured wrench says how far the QP's wish is from the
                      trunk's motion) or measured ('measured'); with exact sensors
                      (`sensor_noise=0`) what the sensor errors cost
    gravity           the arms' weight and its moment alone (`DpcEnv.arm_gravity`)

The controller's estimate is the last tick's (a tick, 4 ms, before the oracle's measurement,
as a controller has it). Each source is its own rollout on the same seeds; under the oracle
controller the estimate does not act, so the states are the same.
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from dpc_mjx import stats
from dpc_mjx.adapter.data import exact_wrenches
from dpc_mjx.envs import rollout
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.rotations import roll_pitch_yaw, wrench_to_yaw_frame

COMPONENTS = ("f_x", "f_y", "f_z", "tau_x", "tau_y", "tau_z")
FREE = {"push_force": (0.0, 0.0), "payload_mass": (0.0, 0.0)}  # nothing the model cannot know
SOURCES = {  # row -> env options over FREE
    "servo, desired trunk acc. (default), sensors": {"arm_qdd": "servo"},
    "servo, measured trunk acc., sensors": {"arm_qdd": "servo", "arm_base_acc": "measured"},
    "difference, measured trunk acc., sensors": {
        "arm_qdd": "difference",
        "arm_base_acc": "measured",
    },
    "servo, measured trunk acc., exact sensors": {
        "arm_qdd": "servo",
        "arm_base_acc": "measured",
        "sensor_noise": 0.0,
    },
}


def rollouts(arm: str, options: dict, args, exact: bool = False) -> dict:
    """Per-step records (steps, episodes, ...) on `arm` with env `options` over FREE."""
    env = make(DEFAULT_TASK, arm=arm, controller=args.controller, engine=args.engine, **options)

    def record(before, after):
        del before
        d = after.pipeline_state
        out = {
            "yaw": roll_pitch_yaw(d.qpos[:, 3:7])[:, 2],
            "oracle": after.info["privileged"][:, :6],
            "model": after.info["ctrl"].arm.wrench,
            "gravity": jax.vmap(env.arm_gravity)(d),
            "done": after.done,
        }
        if exact:
            out["exact"], out["exact_oracle"], _ = jax.vmap(lambda x: exact_wrenches(env, x))(d)
        return out

    carry, key = rollout.start(env, args.episodes, args.seed)
    run_chunk = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, 50, record)
    parts = [r for _, r in rollout.chunks(run_chunk, carry, key, args.steps // 50)]
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    alive = (np.cumsum(out["done"], axis=0) - out["done"]) == 0  # no done before this step
    yaw_frame = lambda u: np.asarray(wrench_to_yaw_frame(u, out["yaw"]))[alive]  # noqa: E731
    return {k: yaw_frame(v) for k, v in out.items() if k not in ("yaw", "done")}


def table(arm: str, rows: dict[str, tuple[np.ndarray, np.ndarray]], steps: int) -> None:
    print(f"\n{arm}: {steps:,} steps")
    print(
        "| estimate | "
        + " | ".join(f"R^2 {c}" for c in COMPONENTS)
        + " | RMSE f (N) | RMSE tau (N·m) |"
    )
    print("|---|" + "---|" * 8)
    for name, (u, true) in rows.items():
        r2, rmse = stats.r2(true, u), stats.rmse(true, u)
        f_rmse, t_rmse = np.sqrt((rmse[:3] ** 2).mean()), np.sqrt((rmse[3:] ** 2).mean())
        print(
            f"| {name} | "
            + " | ".join(f"{v:.3f}" for v in r2)
            + f" | {f_rmse:.2f} | {t_rmse:.3f} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arms", nargs="+", default=["regular", "double", "so100", "z1"])
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--steps", type=int, default=500, help="env steps of 20 ms per episode")
    ap.add_argument("--seed", type=int, default=81000)
    ap.add_argument("--engine", default="native", help="native or mjx")
    ap.add_argument("--controller", default="oracle", help="whose states")
    args = ap.parse_args()
    print(
        f"engine {args.engine}, {args.episodes} episodes x {args.steps} steps per arm, seeds "
        f"{args.seed}.., under {args.controller}; free arm motion (no pushes, no payload)"
    )
    for arm in args.arms:
        (name, options), *others = SOURCES.items()
        first = rollouts(arm, FREE | options, args, exact=True)
        rows = {"exact inputs (privileged)": (first["exact"], first["exact_oracle"])}
        rows[name] = (first["model"], first["oracle"])
        for name, options in others:
            rec = rollouts(arm, FREE | options, args)
            rows[name] = (rec["model"], rec["oracle"])
        rows["gravity"] = (first["gravity"], first["oracle"])
        table(arm, rows, len(first["oracle"]))


if __name__ == "__main__":
    main()
