"""Base state estimator for the deployment loop: a linear Kalman filter fusing the IMU with leg
kinematics (the MIT Cheetah 3's, Bledt et al., IROS 2018; in EKF form Bloesch et al., RSS 2012).

A robot measures its attitude (the IMU's filter), angular rate, specific force and joint angles,
but not its base position and velocity; the controller needs both (the balance QP tracks the
COM height and velocity). Pure JAX, unbatched; `update` runs once per control tick.

State x (18,), world frame: trunk origin position p (3, m), its velocity v (3, m/s), and the
four feet's contact points (4 x 3, m, foot sphere centres).

Process over dt (s): p += v dt + a dt^2 / 2, v += a dt, feet unchanged, with the acceleration
a = R f + g from the accelerometer's specific force f (trunk frame, m/s^2; at rest (0, 0, 9.81))
and the attitude R (trunk -> world).

Measurements, per foot i, with r_i the foot's position from the trunk origin (world frame, from
the joint angles and R) and d_i its velocity relative to the trunk (R (w x r_b + J_i qd_i)):

    foot_i - p = r_i                 leg kinematics
    v = -d_i                         a stance foot does not slide
    foot_i,z = r                     a stance foot is on the ground (flat ground at z = 0; r
                                     the feet's radius, `robots.layout.Layout.foot_radius`)

A foot in swing moves: its process noise and its velocity and height measurements' noise are
multiplied by 1 + (1 - trust) `EstimatorConfig.swing_factor`, with trust in [0, 1] per foot
(1: surely in stance), so it follows the kinematics and informs nothing. Feet land late and lift
early, so a foot's trust in its planned stance ramps up over the first and down over the last
`EstimatorConfig.stance_ramp` of it (`stance_trust`; the Cheetah's), unless the robot has
contact sensors.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

GRAVITY = np.array([0.0, 0.0, -9.81], np.float32)  # m/s^2, world (numpy: no device at import)
N_STATE = 18


def _measurement_matrix() -> np.ndarray:
    """(28, 18) H of the measurements [foot_i - p (12), v (12), foot_i,z (4)] on the state."""
    h = np.zeros((28, N_STATE), np.float32)
    for i in range(4):
        rows = slice(3 * i, 3 * i + 3)
        h[rows, 0:3] = -np.eye(3)  # foot_i - p
        h[rows, 6 + 3 * i : 9 + 3 * i] = np.eye(3)
        h[12 + 3 * i : 15 + 3 * i, 3:6] = np.eye(3)  # v
        h[24 + i, 6 + 3 * i + 2] = 1.0  # foot_i,z
    return h


_MEASUREMENT = _measurement_matrix()  # constant: built once, not in every traced update


@struct.dataclass
class EstimatorConfig:
    """Noise densities of the filter (standard deviations per tick)."""

    accel_std: float = 0.1  # m/s^2, accelerometer noise and model error, drives v
    position_std: float = 0.002  # m per tick, process noise of p
    foot_std: float = 0.002  # m per tick, process noise of a stance foot (slip)
    kinematics_std: float = 0.01  # m, leg kinematics (link lengths, encoder error)
    velocity_std: float = 0.1  # m/s, a stance foot's velocity relative to the trunk
    height_std: float = 0.005  # m, a stance foot's height above the ground
    swing_factor: float = 1e3  # noise multiplier for the feet not in stance
    stance_ramp: float = 0.2  # share of a planned stance at each end where trust ramps


@struct.dataclass
class EstimatorState:
    x: jax.Array  # (18,) [p (3), v (3), feet (4 x 3)], m and m/s, world
    cov: jax.Array  # (18, 18) covariance of x

    @property
    def position(self) -> jax.Array:
        """(3,) m, world: the trunk origin."""
        return self.x[:3]

    @property
    def velocity(self) -> jax.Array:
        """(3,) m/s, world: the trunk origin's velocity."""
        return self.x[3:6]


def init(foot_rel: jax.Array, foot_radius: float, xy: jax.Array | None = None) -> EstimatorState:
    """Standing still with every foot on the ground: p_z from the feet's heights below the trunk
    `foot_rel` (4, 3) (world frame, from the trunk origin) and their radius `foot_radius` (m);
    p_x, p_y = `xy` (default 0)."""
    z = foot_radius - jp.mean(foot_rel[:, 2])
    p = jp.concatenate([jp.zeros(2) if xy is None else jp.asarray(xy), z[None]])
    feet = p + foot_rel
    x = jp.concatenate([p, jp.zeros(3), feet.reshape(-1)])
    return EstimatorState(x=x, cov=jp.eye(N_STATE) * 1e-4)


def update(
    cfg: EstimatorConfig,
    est: EstimatorState,
    rot: jax.Array,
    accel: jax.Array,
    foot_rel: jax.Array,
    foot_rel_vel: jax.Array,
    trust: jax.Array,
    dt: float,
    foot_radius: float,
) -> EstimatorState:
    """One predict + correct step. `rot` (3, 3) trunk -> world; `accel` (3,) specific force,
    trunk frame, m/s^2; `foot_rel` (4, 3) m and `foot_rel_vel` (4, 3) m/s, each foot from /
    relative to the trunk origin, world frame; `trust` (4,) in [0, 1], that each foot is in
    stance (`stance_trust`, or contact sensors); `foot_radius` (m) the feet's."""
    eye3 = jp.eye(3)
    # Predict.
    a = rot @ accel + GRAVITY
    f = jp.eye(N_STATE).at[0:3, 3:6].set(dt * eye3)
    x = f @ est.x + jp.concatenate([0.5 * dt * dt * a, dt * a, jp.zeros(12)])
    weight = 1.0 + (1.0 - trust) * cfg.swing_factor  # (4,) noise multiplier per foot
    q_diag = jp.concatenate(
        [
            jp.full(3, cfg.position_std**2),
            jp.full(3, (cfg.accel_std * dt) ** 2),
            jp.repeat(weight * cfg.foot_std**2, 3),
        ]
    )
    cov = f @ est.cov @ f.T + jp.diag(q_diag)

    # Correct: rows [foot_i - p (12), v (12), foot_i,z (4)].
    h = jp.asarray(_MEASUREMENT)
    y = jp.concatenate([foot_rel.reshape(-1), -foot_rel_vel.reshape(-1), jp.full(4, foot_radius)])
    r_diag = jp.concatenate(
        [
            jp.full(12, cfg.kinematics_std**2),
            jp.repeat(weight * cfg.velocity_std**2, 3),
            weight * cfg.height_std**2,
        ]
    )
    s = h @ cov @ h.T + jp.diag(r_diag)
    gain = jp.linalg.solve(s, h @ cov).T  # (18, 28) = cov h^T s^-1 (s, cov symmetric)
    x = x + gain @ (y - h @ x)
    cov = (jp.eye(N_STATE) - gain @ h) @ cov
    return EstimatorState(x=x, cov=0.5 * (cov + cov.T))


def stance_trust(cfg: EstimatorConfig, phase: jax.Array, duty: float) -> jax.Array:
    """(4,) trust in [0, 1] that each foot is in stance at gait `phase` (4,) in [0, 1) (stance
    while phase < `duty`): 0 in swing, ramping linearly over `cfg.stance_ramp` of the stance at
    each end."""
    s = phase / duty  # progress through the stance, > 1 in swing
    edge = jp.minimum(s, 1.0 - s) / cfg.stance_ramp
    return jp.where(phase < duty, jp.clip(edge, 0.0, 1.0), 0.0)


__all__ = ["EstimatorConfig", "EstimatorState", "init", "stance_trust", "update"]
