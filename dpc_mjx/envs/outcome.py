"""What one env step reports besides the observation: the per-step metrics (`METRICS`) and the
test for a bad step (non-finite or exploded), which `DpcEnv.step` then undoes (the NaN guard).

A bad step keeps the previous physics and controller state, returns obs = 0 and reward = 0 with
done = 1 and reports 0 for every metric but `nan_resets` (1).
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from mujoco import mjx

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
    "ee_sq_err",  # m^2, end-effector tracking error, first order, mean over arms (`ee_sq_err`)
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


def ee_sq_err(mx: mjx.Model, lay, d, targets: jax.Array) -> jax.Array:
    """() m^2: the squared distance of each end effector (`ee` site) from where the servo
    targets `targets` (n_act,) would put it, to first order, |J_arm (p_arm - q_arm)|^2 with
    J_arm the site's position Jacobian (world) over the arm's joints, mean over arms of the
    layout `lay` (`robots.layout`); 0 without arms. (The servos' tracking error in joint space,
    seen at the end effector.)"""
    if not lay.arms:
        return jp.zeros(())
    errs, col = [], 0
    for arm in lay.arms:
        body = int(np.asarray(mx.site_bodyid)[arm.ee_site])
        jacp, _ = mjx.jac(mx, d, d.site_xpos[arm.ee_site], body)  # (nv, 3)
        dq = targets[col : col + len(arm.act)] - d.qpos[arm.qpos]  # (n_k,) rad (m for a finger)
        errs.append(jp.sum((dq @ jacp[arm.dof]) ** 2))
        col += len(arm.act)  # each arm's servo targets follow the last arm's
    return jp.mean(jp.stack(errs))


def zero_if_bad(metrics: dict[str, jax.Array], bad: jax.Array) -> dict[str, jax.Array]:
    """A bad step reports 0 for every term but `nan_resets`."""
    return {k: jp.where(bad & (k != "nan_resets"), 0.0, v) for k, v in metrics.items()}


__all__ = ["METRICS", "ee_sq_err", "finite", "is_bad", "step_metrics", "zero_if_bad"]
