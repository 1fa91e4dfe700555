"""The paper's reward (eqs. 2-4): velocity and orientation tracking, exp(-8 e^2) terms.

    r_vel = exp(-8 (v_x - v_x^d)^2) + exp(-8 (v_y - v_y^d)^2) + exp(-8 (w_yaw - w_yaw^d)^2)   (2)
    r_orn = exp(-8 (roll - roll^d)^2) + exp(-8 (pitch - pitch^d)^2)                              (3)
    r_total = 0.08 r_vel + 0.05 r_orn                                                            (4)

Velocities are in the yaw frame (m/s) and the yaw rate in rad/s; angles in rad. The maximum
per-step reward is 0.08 * 3 + 0.05 * 2 = 0.34.
"""

from __future__ import annotations

import jax
import jax.numpy as jp

SHARPNESS = 8.0  # the 8.0 of eqs. 2-3
VEL_WEIGHT = 0.08  # eq. 4
ORN_WEIGHT = 0.05  # eq. 4
MAX_REWARD = VEL_WEIGHT * 3 + ORN_WEIGHT * 2


def tracking_term(value: jax.Array, target: jax.Array) -> jax.Array:
    """exp(-8 (value - target)^2), elementwise."""
    return jp.exp(-SHARPNESS * (value - target) ** 2)


def velocity_reward(vel: jax.Array, vel_des: jax.Array) -> jax.Array:
    """Eq. 2. `vel`, `vel_des`: (3,) [v_x, v_y (m/s, yaw frame), w_yaw (rad/s)]."""
    return jp.sum(tracking_term(vel, vel_des), axis=-1)


def orientation_reward(roll_pitch: jax.Array, roll_pitch_des: jax.Array) -> jax.Array:
    """Eq. 3. `roll_pitch`, `roll_pitch_des`: (2,) rad."""
    return jp.sum(tracking_term(roll_pitch, roll_pitch_des), axis=-1)


def total_reward(vel, vel_des, roll_pitch, roll_pitch_des) -> dict[str, jax.Array]:
    """Eq. 4 and its terms, for logging: {'r_vel', 'r_orn', 'r_total'}."""
    r_vel = velocity_reward(vel, vel_des)
    r_orn = orientation_reward(roll_pitch, roll_pitch_des)
    return {"r_vel": r_vel, "r_orn": r_orn, "r_total": VEL_WEIGHT * r_vel + ORN_WEIGHT * r_orn}
