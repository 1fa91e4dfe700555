"""Swing legs: Raibert-style footholds, swing trajectories and Cartesian PD (paper eq. 11).

Frames: world, z up, the floor at z = 0. Units: m, m/s, N.
"""

from __future__ import annotations

import jax
import jax.numpy as jp


def raibert_foothold(
    hip_pos: jax.Array,
    com_vel: jax.Array,
    com_vel_des: jax.Array,
    yaw_rate_des: jax.Array,
    com_pos: jax.Array,
    stance_time: jax.Array,
    k_vel: float,
    foot_radius: float,
) -> jax.Array:
    """(4, 3) footholds: below each hip, shifted by half a stance of motion plus velocity feedback.

    p = p_hip + v_des_hip T_st / 2 + k_vel (v - v_des), with v_des_hip the desired velocity of the
    hip (COM velocity plus the yaw rate's tangential part); z is the foot sphere's centre on the
    ground, `foot_radius` (m, the base's). `hip_pos` (4, 3), `com_vel`/`com_vel_des` (3,) world;
    `yaw_rate_des` rad/s; `k_vel` s (`ControllerConfig.raibert_k`).
    """
    lever = hip_pos - com_pos  # (4, 3)
    spin = jp.stack([-lever[:, 1], lever[:, 0], jp.zeros(4)], axis=-1) * yaw_rate_des
    v_des_hip = com_vel_des[None, :] + spin
    feedback = k_vel * (com_vel - com_vel_des)[None, :]
    target = hip_pos + 0.5 * stance_time * v_des_hip + feedback
    return target.at[:, 2].set(foot_radius)


def swing_trajectory(
    start: jax.Array, target: jax.Array, progress: jax.Array, swing_time: jax.Array, height: float
) -> tuple[jax.Array, jax.Array]:
    """Desired (4, 3) position and velocity along each swing.

    Horizontal: smooth-step s(u) = 3u^2 - 2u^3 from start to target. Vertical: start z blended to
    target z plus a raised-cosine bump of `height` m, zero velocity at lift-off and touch-down.
    `progress` (4,) in [0, 1]; `swing_time` s.
    """
    u = progress[:, None]
    s = 3 * u**2 - 2 * u**3
    ds = (6 * u - 6 * u**2) / swing_time  # ds/dt
    pos = start + (target - start) * s
    vel = (target - start) * ds
    bump = height * 0.5 * (1 - jp.cos(2 * jp.pi * progress))
    dbump = height * jp.pi * jp.sin(2 * jp.pi * progress) / swing_time
    pos = pos.at[:, 2].add(bump)
    vel = vel.at[:, 2].add(dbump)
    return pos, vel


def swing_force(
    pos_des: jax.Array,
    vel_des: jax.Array,
    pos: jax.Array,
    vel: jax.Array,
    kp: jax.Array,
    kd: jax.Array,
) -> jax.Array:
    """(4, 3) Cartesian PD force on each foot (eq. 11 with a velocity reference): N.

    f_i = kp (p_d,i - p_i) + kd (v_d,i - v_i); kp, kd (3,) per axis (N/m, N·s/m).
    """
    return kp * (pos_des - pos) + kd * (vel_des - vel)
