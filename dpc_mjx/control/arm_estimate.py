"""The arms' model wrench as a robot measures it: `arm_model.model_wrench` fed, at every control
tick, with what the sensors give (`control/sensors.py`), never the simulator's state.

Inputs at tick k (world frame; `BodyState` after the sensor model):

    trunk rotation R, angular velocity w  the IMU's attitude and gyro (measured `BodyState`)
    trunk accelerations                   by `ArmEstimateConfig.base_acc`:
        'desired'     those the balance QP asks for this tick (`balance.desired_acceleration`:
                      the COM's and the angular, eq. 9): the arms' reaction to the trunk's
                      acceleration as the QP's own model would have it with the arms' mass and
                      inertia added to the base's (a composite rigid body), not a measurement
        'measured'    the accelerometer (trunk frame, its errors) turned by R, and the gyro's
                      difference (w_k - w_{k-1}) / dt, low-passed
    q, qd                                 the arm encoders (with their errors)
    qdd                                   by `ArmEstimateConfig.qdd`:
        'servo'       what the arms' position servos do to the measured state toward this tick's
                      targets (`arm_model.servo_motion`: the arm's own dynamics, its servo law)
        'difference'  the encoders' velocity difference (qd_k - qd_{k-1}) / dt, low-passed

Each low-pass is first order, discrete at the tick: y_k = y_{k-1} + dt / (tau + dt) (x_k -
y_{k-1}), tau = `ArmEstimateConfig.filter_s`. The state it carries (`ArmEstimate`) is the last
tick's gyro and arm velocities and the filtered accelerations; its `wrench` is the last estimate
(6,) [f (N), tau (N·m) about the base's COM], the sign and point of `state.oracle_u`.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from dpc_mjx.control import arm_model
from dpc_mjx.control.balance import GRAVITY
from dpc_mjx.control.sensors import SensorNoise
from dpc_mjx.control.state import BodyState
from dpc_mjx.errors import DpcError

QDD_SOURCES = ("servo", "difference")
BASE_ACC_SOURCES = ("desired", "measured")


@struct.dataclass
class ArmEstimateConfig:
    """How the arms' joint and trunk accelerations are estimated (module docstring)."""

    qdd: str = struct.field(pytree_node=False, default="servo")  # one of QDD_SOURCES
    base_acc: str = struct.field(pytree_node=False, default="desired")  # of BASE_ACC_SOURCES
    filter_s: float = 0.02  # s, time constant of the differences' low-pass

    def validate(self) -> None:
        if self.qdd not in QDD_SOURCES:
            raise DpcError(f"ArmEstimateConfig.qdd={self.qdd!r}: use one of {QDD_SOURCES}.")
        if self.base_acc not in BASE_ACC_SOURCES:
            raise DpcError(
                f"ArmEstimateConfig.base_acc={self.base_acc!r}: use one of {BASE_ACC_SOURCES}."
            )
        if not (isinstance(self.filter_s, (int, float)) and 0.0 <= self.filter_s <= 1.0):
            raise DpcError(
                f"ArmEstimateConfig.filter_s={self.filter_s!r}: a time constant in [0, 1] s "
                "(0: the raw difference)."
            )


@struct.dataclass
class ArmEstimate:
    """One env's estimator state (unbatched)."""

    ang_vel: jax.Array  # (3,) rad/s, world: the gyro of the last tick
    arm_qd: jax.Array  # (n,) rad/s: the arm encoders' velocities of the last tick
    ang_acc: jax.Array  # (3,) rad/s^2, world: filtered difference
    arm_qdd: jax.Array  # (n,) rad/s^2: filtered difference
    wrench: jax.Array  # (6,) the last model wrench, N and N·m, world, about the base's COM


def init(s: BodyState, arm_qd: jax.Array) -> ArmEstimate:
    """At rest on the measured state `s` with the arm velocities `arm_qd` (n,)."""
    return ArmEstimate(
        ang_vel=s.ang_vel,
        arm_qd=arm_qd,
        ang_acc=jp.zeros(3),
        arm_qdd=jp.zeros_like(arm_qd),
        wrench=jp.zeros(6),
    )


def _low_pass(previous: jax.Array, x: jax.Array, dt: float, tau) -> jax.Array:
    return previous + dt / (tau + dt) * (x - previous)


def update(
    config: ArmEstimateConfig,
    arm: arm_model.ArmModel,
    est: ArmEstimate,
    s: BodyState,
    measured: tuple[jax.Array, jax.Array, jax.Array],
    targets: jax.Array,
    com: jax.Array,
    desired: jax.Array,
    dt: float,
) -> ArmEstimate:
    """One tick: `s` the measured body state; `measured` = (accelerometer (3,) m/s^2 trunk
    frame, arm q (n,), arm qd (n,)) as read; `targets` (n,) the arm servo targets of this
    tick; `com` (3,) m, world, the base's COM minus the trunk's origin; `desired` (6,) the
    accelerations the balance QP asks for (COM m/s^2, angular rad/s^2, world); `dt` s."""
    accel, q, qd = measured
    ang_acc = _low_pass(est.ang_acc, (s.ang_vel - est.ang_vel) / dt, dt, config.filter_s)
    qdd_diff = _low_pass(est.arm_qdd, (qd - est.arm_qd) / dt, dt, config.filter_s)
    if config.base_acc == "desired":  # the trunk origin's, from the COM's: a_o = a_c - dw x r...
        dw, w = desired[3:], s.ang_vel
        a_origin = desired[:3] - jp.cross(dw, com) - jp.cross(w, jp.cross(w, com))
        motion = (dw, a_origin + jp.array([0.0, 0.0, GRAVITY]))  # a - g, g = (0, 0, -9.81)
    else:
        motion = (ang_acc, s.rot @ accel)
    base = arm_model.BaseMotion(
        rot=s.rot, ang_vel=s.ang_vel, ang_acc=motion[0], lin_acc=motion[1], com=com
    )
    if config.qdd == "servo":
        wrench, _ = arm_model.servo_motion(arm, base, q, qd, targets)
    else:
        wrench = arm_model.model_wrench(arm, base, q, qd, qdd_diff)
    return ArmEstimate(
        ang_vel=s.ang_vel, arm_qd=qd, ang_acc=ang_acc, arm_qdd=qdd_diff, wrench=wrench
    )


def planned_change(
    arm: arm_model.ArmModel, s: BodyState, com: jax.Array, targets: jax.Array, dt: float
) -> jax.Array:
    """(N, 6) how the arms' model wrench changes along their planned motion, over the MPC's
    horizon: W_k - W_0 for k = 0 .. N-1 (so row 0 is 0), W_k the model wrench of the arms at
    their servo targets for t + k dt, moving at those targets' central differences:

        q_k = T_k,  qd_k = (T_{k+1} - T_{k-1}) / (2 dt),  qdd_k = (T_{k+1} - 2 T_k + T_{k-1}) / dt^2

    `targets` (N + 2, n) the servo targets at t + k dt for k = -1 .. N (the arm's planner's;
    the servos assumed to track them), `dt` s the horizon's step; the base as measured now
    (`s`: rotation, angular velocity), not accelerating (the MPC plans its motion), `com` (3,)
    m, world, the base's COM minus the trunk's origin. Added to the present u, the wrench the
    MPC plans against (`EnvConfig.u_ahead` 'model'): the arm's own motion ahead, not privileged."""
    q = targets[1:-1]
    qd = (targets[2:] - targets[:-2]) / (2.0 * dt)
    qdd = (targets[2:] - 2.0 * targets[1:-1] + targets[:-2]) / dt**2
    base = arm_model.BaseMotion(
        rot=s.rot,
        ang_vel=s.ang_vel,
        ang_acc=jp.zeros(3),
        lin_acc=jp.array([0.0, 0.0, GRAVITY]),  # a - g at rest, g = (0, 0, -9.81)
        com=com,
    )
    wrench = jax.vmap(lambda *x: arm_model.model_wrench(arm, base, *x))(q, qd, qdd)  # (N, 6)
    return wrench - wrench[0]


def read_sensors(lay, d, noise: SensorNoise | None) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(accelerometer (3,) m/s^2 trunk frame, arm q (n,), arm qd (n,)) as the robot reads them
    from the data `d`, with the errors `noise` (None: exact)."""
    adr = lay.sensor_adr["accelerometer"]
    accel = d.sensordata[adr : adr + 3]
    q, qd = d.qpos[lay.arm_qpos], d.qvel[lay.arm_dof]
    if noise is None:
        return accel, q, qd
    return accel + noise.accel, q + noise.arm_q, qd + noise.arm_qd


__all__ = [
    "BASE_ACC_SOURCES",
    "QDD_SOURCES",
    "ArmEstimate",
    "ArmEstimateConfig",
    "init",
    "planned_change",
    "read_sensors",
    "update",
]
