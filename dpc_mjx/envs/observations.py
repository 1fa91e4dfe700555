"""Observation blocks as the paper defines them (§III-B, III-C), from one env's data.

    s_body (11,): roll, pitch (rad); trunk angular velocity (3, rad/s, trunk frame);
                  trunk linear velocity (3, m/s, yaw frame); velocity command (3: v_x, v_y m/s in
                  the yaw frame, yaw rate rad/s)
    s_arm  (2 n,): arm joint positions (rad or m), then velocities, every arm joint in layout order
    p_arm  (n_act,): the arm servos' desired joint positions (the reference motion)

`s_body` has the same layout for every variant; `s_arm`/`p_arm` follow the arm (n = 0 for the
bare A1). Works on `mujoco.MjData` and `mjx.Data` (numpy or jax arrays).
"""

from __future__ import annotations

import jax
import jax.numpy as jp

from dpc_mjx.robots.layout import Layout
from dpc_mjx.rotations import roll_pitch_yaw

S_BODY_SIZE = 11


def yaw_frame_velocity(d) -> jax.Array:
    """(3,) trunk linear velocity (m/s) in the yaw frame (heading-aligned, z up)."""
    yaw = roll_pitch_yaw(d.qpos[3:7])[2]
    c, s = jp.cos(yaw), jp.sin(yaw)
    v = d.qvel[0:3]  # world frame for a free joint
    return jp.stack([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


def s_body(d, command: jax.Array) -> jax.Array:
    """(11,) body state; `command` (3,) [v_x, v_y, yaw rate]."""
    rpy = roll_pitch_yaw(d.qpos[3:7])
    return jp.concatenate([rpy[:2], d.qvel[3:6], yaw_frame_velocity(d), jp.asarray(command)])


def s_arm(lay: Layout, d) -> jax.Array:
    """(2 n,) arm joint positions then velocities."""
    return jp.concatenate([d.qpos[lay.arm_qpos], d.qvel[lay.arm_dof]])


def p_arm(lay: Layout, d) -> jax.Array:
    """(n_act,) the arm servos' targets (ctrl of the arm actuators)."""
    return jp.asarray(d.ctrl[lay.arm_act])
