"""The wrench the MPC plans against over its horizon, as the env gives it (`EnvConfig.u_ahead`):
the arms' servo targets ahead ('model', for the arms' model wrench's change along them), the
measured wrench's change along a recording of the same episode ('replay': privileged, the bound)
or the pushes' change from their schedule ('pushes', or of those under way only 'push_ends':
privileged, `push_change`).

A replay is two passes over the same episodes (same seed): the first records the measured
arm-mount wrench (the oracle's u) at every control tick (`info['u_ticks']`, (n_substeps, 6) per
env step), the second is given that recording (`attach`) and plans, at each tick t, against

    w_k = u(t) + r(t + k dt) - r(t),  k = 0 .. N - 1

u(t) the controller's present u, r the recording (linear between its ticks, held past its ends)
and dt the MPC's step: the measured wrench's change ahead, as the first pass met it. An env with
`u_ahead='replay'` starts with a zero recording, so its first pass plans against u held.
`experiments/mpc_replay.py` runs both passes.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import State

from dpc_mjx import devices
from dpc_mjx.control.state import forces_u
from dpc_mjx.errors import DpcError
from dpc_mjx.rotations import yaw_of


def horizon(env, info: dict, dist, d) -> tuple[jax.Array | None, jax.Array | None]:
    """(targets_ahead, u_change) of a tick for `LowLevelController.step`, by the env's
    `EnvConfig.u_ahead`: 'model' the servo targets ahead (`servo_targets`), 'replay' the
    recorded wrench's change (`replay_change` of `info['u_replay']`), 'pushes' and
    'push_ends' theirs (`push_change`), 'held' neither."""
    if env.config.u_ahead == "model":
        return servo_targets(env, dist, d), None
    if env.config.u_ahead == "replay":
        mpc = env.controller.config.mpc
        return None, replay_change(info["u_replay"], d.time, env.controller.dt, mpc)
    if env.config.u_ahead in ("pushes", "push_ends"):
        return None, push_change(env, dist, d, begun_only=env.config.u_ahead == "push_ends")
    return None, None


def push_change(env, dist, d, begun_only: bool = False) -> jax.Array:
    """(N, 6) P(t + k dt) - P(t), k = 0 .. N - 1 ('pushes', privileged): P(t) the pushes at the
    grippers at time t from the episode's schedule (`Sampler.pushes`: the push under way and
    the next one, drawn when the last ended) as a wrench about the base's COM, world frame
    (N, N·m): sum_i [f_i, (x_i - c) x f_i], x_i the grippers and c the COM as they are now,
    the heading held. A push reaches the trunk through the arm as this wrench where the arm
    holds still; its servos giving way is what the bound does not know. `begun_only`
    ('push_ends'): only the pushes begun by t, so the change is when they end."""
    mpc = env.controller.config.mpc
    times = d.time + mpc.dt * jp.arange(mpc.steps)  # (N,) s
    yaw = yaw_of(d.xmat[env.controller.idx.trunk])  # () rad, the heading now
    forces = jax.vmap(lambda t: env.sampler.pushes(dist, t, yaw))(times)  # (N, k, 3) N
    if begun_only:
        forces = forces * (dist.push_on <= d.time)[None, :, None]
    grippers, com = d.site_xpos[env.ee_sites], env.com_pos(d)  # (k, 3), (3,) m
    wrench = jax.vmap(lambda f: forces_u(f, grippers, com))(forces)  # (N, 6)
    return wrench - wrench[0]


def servo_targets(env, dist, d) -> jax.Array:
    """(N + 2, n_act) the arms' servo targets at t + k dt for k = -1 .. N (the MPC's step dt,
    t the tick's physics time): what `arm_estimate.planned_change` reads ('model')."""
    mpc = env.controller.config.mpc
    times = d.time + mpc.dt * jp.arange(-1, mpc.steps + 1)  # (N + 2,) s
    return jax.vmap(lambda t: env.arm_targets(dist, t, d))(times)


def replay_change(recording: jax.Array, t: jax.Array, tick_dt: float, mpc) -> jax.Array:
    """(N, 6) r(t + k dt) - r(t), k = 0 .. N - 1 ('replay'): `recording` (T, 6) N and N·m, world,
    the measured wrench at the ticks i * `tick_dt` s (i = 0 .. T - 1), linear between them and
    held past the ends; `mpc` the MPC's config (its step dt and its N)."""
    last = recording.shape[0] - 1
    at = jp.clip((t + mpc.dt * jp.arange(mpc.steps)) / tick_dt, 0.0, last)  # (N,) tick indices
    i0 = jp.minimum(jp.floor(at).astype(jp.int32), max(last - 1, 0))
    frac = (at - i0)[:, None]
    r = (1.0 - frac) * recording[i0] + frac * recording[jp.minimum(i0 + 1, last)]  # (N, 6)
    return r - r[0]


def replay_info(config, n_substeps: int) -> dict[str, jax.Array]:
    """The env's reset info of a 'replay' env (`config` its `EnvConfig`; else {}): 'u_replay'
    (episode_length * n_substeps, 6) the recording replayed, zeros (u held) until `attach`;
    'u_ticks' (n_substeps, 6) the measured wrench at each tick of the last step, recorded."""
    if config.u_ahead != "replay":
        return {}
    return {
        "u_replay": jp.zeros((config.episode_length * n_substeps, 6)),
        "u_ticks": jp.zeros((n_substeps, 6)),
    }


def recording(records: np.ndarray) -> np.ndarray:
    """(B, steps * n_substeps, 6) the recordings of a first pass from its per-step records of
    `info['u_ticks']`, (steps, B, n_substeps, 6), in step order from the first step on."""
    steps, batch, n_sub, _ = records.shape
    return np.asarray(records).transpose(1, 0, 2, 3).reshape(batch, steps * n_sub, 6)


def attach(state: State, recordings: np.ndarray) -> State:
    """The reset batch `state` (B, ...) of a 'replay' env given `recordings` (B, T, 6) (`recording`
    of a first pass on the same seed; padded like the batch on several devices)."""
    if "u_replay" not in state.info:
        raise DpcError(
            "This env keeps no recording to replay: make it with u_ahead='replay' (and "
            "low_level='mpc')."
        )
    want = state.info["u_replay"].shape
    rec = np.asarray(recordings, np.float32)
    if rec.ndim != 3 or rec.shape[1:] != want[1:] or rec.shape[0] > want[0]:
        raise DpcError(
            f"A recording of shape {rec.shape} does not fit this batch's {want} (episodes, "
            "ticks, 6): record the first pass with the same episodes and steps."
        )
    rec = devices.shard(devices.pad(jp.asarray(rec), want[0]), want[0])
    return state.replace(info={**state.info, "u_replay": rec})
