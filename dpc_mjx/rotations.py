"""Rotation helpers on (..., 4) wxyz quaternions (MuJoCo's convention), numpy or jax input."""

from __future__ import annotations

import jax.numpy as jp


def roll_pitch_yaw(quat):
    """(..., 3) ZYX Euler angles (rad): roll about x, pitch about y, yaw about z, of a body->world
    rotation given as a (..., 4) wxyz quaternion."""
    w, x, y, z = (quat[..., i] for i in range(4))
    roll = jp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = jp.arcsin(jp.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = jp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return jp.stack([roll, pitch, yaw], axis=-1)
