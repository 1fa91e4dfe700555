"""Every base trotting under MBC in the reaching task: falls and forward speed (issue 27's check).

    python experiments/base_trot.py [--bases a1 go1 go2 b1] [--arms none regular]
        [--engines native mjx] [--envs 64] [--seconds 10] [--seed 0]

Each cell: `--envs` envs of `dpc_mjx.make("reaching", arm, base=..., controller="mbc")` with
pushes off (`push_force=(0, 0)`) and the command fixed at 0.3 m/s forward (`command_vx=(0.3,
0.3)`, no lateral speed or turn), the arm's reaching motion as the task draws it, stepped through
`envs.rollout` for `--seconds`. Prints falls (`Tally.fell`), the mean forward speed (yaw frame, m/s,
every env and step after the first second, while not fallen) and its RMS error to the command,
and the compile (first chunk) and run times (`dpc_mjx.timing`).
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

import dpc_mjx
from dpc_mjx.envs import rollout
from dpc_mjx.rotations import roll_pitch_yaw, to_yaw_frame
from dpc_mjx.timing import Stopwatch

COMMAND_VX = 0.3  # m/s
CHUNK = 50  # env steps per compiled chunk


def _forward_speed(before, after):
    """(B,) m/s: forward speed in the yaw frame after the step."""
    del before
    d = after.pipeline_state
    yaw = jax.vmap(roll_pitch_yaw)(d.qpos[:, 3:7])[:, 2]
    return jax.vmap(to_yaw_frame)(d.qvel[:, 0:3], yaw)[:, 0]


def trot_cell(base: str, arm: str, engine: str, envs: int, seconds: float, seed: int) -> dict:
    """One cell of the table (module doc)."""
    env = dpc_mjx.make(
        "reaching", arm=arm, base=base, controller="mbc", engine=engine,
        push_force=(0.0, 0.0), command_vx=(COMMAND_VX, COMMAND_VX), command_vy=(0.0, 0.0),
        command_yaw=(0.0, 0.0),
    )  # fmt: skip
    carry, key = rollout.start(env, envs, seed=seed)
    run = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, CHUNK, _forward_speed)
    speeds, live = [], []
    n_chunks = max(1, round(seconds / env.config.policy_dt / CHUNK))
    with Stopwatch() as first:
        carry, speed = jax.block_until_ready(run(carry, key))
    with Stopwatch() as rest:
        for i in range(n_chunks):
            if i:
                carry, speed = run(carry, jax.random.fold_in(key, i))
            speeds.append(np.asarray(speed))  # (CHUNK, B)
            live.append(np.tile(1.0 - np.asarray(carry[1].ended), (CHUNK, 1)))
    settle = round(1.0 / env.config.policy_dt)  # the first second: starting to walk
    v, w = np.concatenate(speeds)[settle:], np.concatenate(live)[settle:]
    mean = float((v * w).sum() / w.sum())
    rms = float(np.sqrt((((v - COMMAND_VX) ** 2) * w).sum() / w.sum()))
    return {
        "base": base, "arm": arm, "engine": engine, "falls": int(np.asarray(carry[1].fell).sum()),
        "envs": envs, "speed": mean, "rms": rms, "compile_s": first.seconds,
        "steps_per_s": envs * CHUNK * (n_chunks - 1) / max(rest.seconds, 1e-9),
    }  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bases", nargs="*", default=["a1", "go1", "go2", "b1"])
    p.add_argument("--arms", nargs="*", default=["none", "regular"])
    p.add_argument("--engines", nargs="*", default=["native"])
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    print(
        f"| base | arm | engine | falls / {a.envs} | forward speed (m/s) | RMS error (m/s) "
        "| compile + first chunk (s) | env steps/s |\n|---|---|---|---|---|---|---|---|",
        flush=True,
    )
    for base in a.bases:
        for arm in a.arms:
            for engine in a.engines:
                c = trot_cell(base, arm, engine, a.envs, a.seconds, a.seed)
                print(
                    f"| {base} | {arm} | {engine} | {c['falls']} | {c['speed']:.3f} "
                    f"| {c['rms']:.3f} | {c['compile_s']:.1f} | {c['steps_per_s']:.0f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
