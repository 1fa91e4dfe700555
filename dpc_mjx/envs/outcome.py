"""What one env step reports besides the observation: the per-step metrics (`METRICS`) and the
test for a bad step (non-finite or exploded), which `DpcEnv.step` then undoes (the NaN guard).

A bad step keeps the previous physics and controller state, returns obs = 0 and reward = 0 with
done = 1 and reports 0 for every metric but `nan_resets` (1).
"""

from __future__ import annotations

import jax
import jax.numpy as jp

# Per-step metrics (summed over an episode by brax's EpisodeWrapper):
METRICS = (
    "r_vel",  # eq. 2
    "r_orn",  # eq. 3
    "r_total",  # eq. 4 (without the fall penalty)
    "fall",  # 1 on the step that falls
    "nan_resets",  # 1 on a non-finite/exploded step
    "vx_sq_err",  # (m/s)^2, yaw-frame forward speed minus command
    "vy_sq_err",  # (m/s)^2
    "yaw_rate_sq_err",  # (rad/s)^2
    "roll_sq",  # rad^2
    "pitch_sq",  # rad^2
    "pos_sq_err",  # m^2, trunk (x, y) minus the desired path (`Disturbances.ref_pose`)
    "ee_sq_err",  # m^2, end-effector tracking error, first order, mean over arms (`_ee_sq_err`)
)


def finite(*arrays: jax.Array) -> jax.Array:
    """() bool: every entry of every array is finite."""
    return jp.all(jp.array([jp.all(jp.isfinite(a)) for a in arrays]))


def is_bad(
    d, obs: jax.Array, privileged: jax.Array, cs, r_total: jax.Array, explode_speed: float
) -> jax.Array:
    """() bool: the step left a non-finite value (physics `d`, obs, privileged values, the
    controller state `cs`'s forces and QP solution, reward) or a speed |qvel| over
    `explode_speed` (rad/s, m/s)."""
    return ~(
        finite(d.qpos, d.qvel, d.ctrl, obs, privileged, cs.forces, cs.qp.x, r_total)
        & jp.all(jp.abs(d.qvel) <= explode_speed)
    )


def step_metrics(
    r: dict, err: jax.Array, sb: jax.Array, fall: jax.Array, bad: jax.Array
) -> dict[str, jax.Array]:
    """The reward and tracking terms of `METRICS` (all but `pos_sq_err`, `ee_sq_err`): `r` the
    reward terms, `err` (3,) [vx, vy, yaw rate] minus the command, `sb` the true s_body."""
    return {
        "r_vel": r["r_vel"],
        "r_orn": r["r_orn"],
        "r_total": r["r_total"],
        "fall": fall.astype(jp.float32),
        "nan_resets": bad.astype(jp.float32),
        "vx_sq_err": err[0] ** 2,
        "vy_sq_err": err[1] ** 2,
        "yaw_rate_sq_err": err[2] ** 2,
        "roll_sq": sb[0] ** 2,
        "pitch_sq": sb[1] ** 2,
    }


def zero_if_bad(metrics: dict[str, jax.Array], bad: jax.Array) -> dict[str, jax.Array]:
    """A bad step reports 0 for every term but `nan_resets`."""
    return {k: jp.where(bad & (k != "nan_resets"), 0.0, v) for k, v in metrics.items()}


__all__ = ["METRICS", "finite", "is_bad", "step_metrics", "zero_if_bad"]
