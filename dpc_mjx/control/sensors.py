"""Sensors as a robot has them: what the controller, the observer and the policy read is the true
state plus measurement errors, and the torques act one tick after the measurement.

Measurement errors of one tick (`SensorNoise`), each a per-episode bias (drawn at reset,
~ U(-bias, bias) per component) plus white noise (~ N(0, std^2), drawn every 4 ms tick), scaled
together by `EnvConfig.sensor_noise` (0: exact sensors; 1: the values below):

    quantity (frame)                        std      bias   where the value comes from
    roll, pitch (rad)                       0.002    0.01   an IMU attitude filter's error,
                                                            ~0.5 deg (MEMS AHRS datasheets)
    trunk angular velocity (rad/s, trunk)   0.01     0.01   MEMS gyro (BMI088 class: noise
                                                            0.014 deg/s/sqrt(Hz), turn-on bias
                                                            up to 1 deg/s), plus vibration
    trunk linear velocity (m/s, yaw frame)  0.05     0.02   a kinematic-inertial state
                                                            estimator (Bloesch et al., RSS 2012:
                                                            errors of a few cm/s)
    leg joint positions (rad)               0.001    -      A1 motor encoder (15 bit before a
                                                            9.1:1 gear) and joint compliance
    leg joint velocities (rad/s)            0.05     -      differentiated encoder
    arm joint positions (rad or m)          0.001    -      Dynamixel XM430 class: 4096
                                                            counts/rev (0.0015 rad)
    arm joint velocities (rad/s or m/s)     0.025    -      its velocity unit, 0.229 rpm
    trunk specific acceleration             0.1      0.05   MEMS accelerometer (BMI088 class:
      (m/s^2, trunk frame; what the                         175 ug/sqrt(Hz), 0.02 m/s^2 over
      accelerometer reads)                                  125 Hz) with vibration; bias left
                                                            after calibration (~5 mg)

The accelerometer's errors are drawn from keys of their own (folded from the tick's and the
episode's), so every other error is drawn as before it was measured; it is read by the arms'
model wrench only (`control/arm_estimate.py`).

Delay (`EnvConfig.sensor_delay`, ticks of 4 ms): the ctrl computed from the measurement of tick
k acts from tick k + delay (default 1: 4 ms from measurement to torque, an A1 low-level loop's
communication and computation time). The disturbance observer's known wrench uses the commanded
forces, so the delay is one of the errors it sees.

How each error reaches the controller (`measured`, on its `BodyState`): the trunk orientation is
turned by the roll and pitch errors (R R_x(d_roll) R_y(d_pitch)), the gyro error is added in the
trunk frame, the velocity error in the yaw frame, and the leg encoder errors move the feet
through the leg Jacobians (foot_pos += J dq, foot_vel += J dq_dot). The policy's observation gets
the same errors (`observe`: s_body and s_arm; p_arm, the servo targets, is known exactly; u_obs
comes from the observer, which reads the measured state). Positions are not corrupted: the
controller tracks velocities and holds its height against the measured feet.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from dpc_mjx.control.state import BodyState
from dpc_mjx.rotations import rot_z, yaw_of

# (white-noise std, per-episode bias bound), at sensor_noise = 1; see the module docstring
TILT = (0.002, 0.01)  # rad, roll and pitch
GYRO = (0.01, 0.01)  # rad/s, trunk frame
VELOCITY = (0.05, 0.02)  # m/s, yaw frame
LEG_Q = (0.001, 0.0)  # rad
LEG_QD = (0.05, 0.0)  # rad/s
ARM_Q = (0.001, 0.0)  # rad (m for a finger)
ARM_QD = (0.025, 0.0)  # rad/s (m/s)
ACCEL = (0.1, 0.05)  # m/s^2, trunk frame
_ACCEL_STREAM = 1000  # folded into a key: the accelerometer's own draws


@struct.dataclass
class SensorNoise:
    """One tick's measurement errors (measured - true), frames as in the module docstring."""

    tilt: jax.Array  # (2,) rad, roll and pitch
    gyro: jax.Array  # (3,) rad/s, trunk frame
    velocity: jax.Array  # (3,) m/s, yaw frame
    leg_q: jax.Array  # (12,) rad, leg joints in layout order
    leg_qd: jax.Array  # (12,) rad/s
    arm_q: jax.Array  # (n,) arm joints in layout order
    arm_qd: jax.Array  # (n,)
    accel: jax.Array  # (3,) m/s^2, trunk frame


_SPECS = {  # field -> (std, bias) at scale 1
    "tilt": TILT,
    "gyro": GYRO,
    "velocity": VELOCITY,
    "leg_q": LEG_Q,
    "leg_qd": LEG_QD,
    "arm_q": ARM_Q,
    "arm_qd": ARM_QD,
}


def _sizes(n_arm: int) -> dict[str, int]:
    return {
        "tilt": 2,
        "gyro": 3,
        "velocity": 3,
        "leg_q": 12,
        "leg_qd": 12,
        "arm_q": n_arm,
        "arm_qd": n_arm,
    }


def zeros(n_arm: int) -> SensorNoise:
    """No errors (exact sensors), for an arm of `n_arm` joints."""
    sizes = _sizes(n_arm)
    return SensorNoise(**{name: jp.zeros(sizes[name]) for name in _SPECS}, accel=jp.zeros(3))


def draw_bias(key: jax.Array, n_arm: int, scale: float) -> SensorNoise:
    """A per-episode bias ~ U(-bias, bias) per component, times `scale`."""
    keys = jax.random.split(key, len(_SPECS))
    sizes = _sizes(n_arm)
    return SensorNoise(
        **{
            name: scale * bound * jax.random.uniform(k, (sizes[name],), minval=-1.0, maxval=1.0)
            for k, (name, (_, bound)) in zip(keys, _SPECS.items(), strict=True)
        },
        accel=scale * ACCEL[1] * jax.random.uniform(_accel_key(key), (3,), minval=-1, maxval=1),
    )


def draw(key: jax.Array, bias: SensorNoise, scale: float) -> SensorNoise:
    """One tick's errors: `bias` plus white noise ~ N(0, (scale std)^2) per component."""
    keys = jax.random.split(key, len(_SPECS))
    return SensorNoise(
        **{
            name: getattr(bias, name)
            + scale * std * jax.random.normal(k, getattr(bias, name).shape)
            for k, (name, (std, _)) in zip(keys, _SPECS.items(), strict=True)
        },
        accel=bias.accel + scale * ACCEL[0] * jax.random.normal(_accel_key(key), (3,)),
    )


def _accel_key(key: jax.Array) -> jax.Array:
    """The accelerometer's key, apart from the other errors' (module docstring)."""
    return jax.random.fold_in(key, _ACCEL_STREAM)


def measured(s: BodyState, noise: SensorNoise) -> BodyState:
    """The body state the controller reads: `s` (true) with the errors `noise`."""
    c, sn = jp.cos(noise.tilt), jp.sin(noise.tilt)
    one, zero = jp.ones(()), jp.zeros(())
    r_x = jp.array([[one, zero, zero], [zero, c[0], -sn[0]], [zero, sn[0], c[0]]])
    r_y = jp.array([[c[1], zero, sn[1]], [zero, one, zero], [-sn[1], zero, c[1]]])
    rot = s.rot @ r_x @ r_y  # (3, 3) body -> world, measured
    w_body = s.rot.T @ s.ang_vel + noise.gyro  # rad/s, trunk frame, what the gyro reads
    dq = noise.leg_q.reshape(4, 3)
    dqd = noise.leg_qd.reshape(4, 3)
    return s.replace(
        rot=rot,
        ang_vel=rot @ w_body,
        com_vel=s.com_vel + rot_z(yaw_of(s.rot)) @ noise.velocity,
        foot_pos=s.foot_pos + jp.einsum("fcj,fj->fc", s.foot_jac, dq),
        foot_vel=s.foot_vel + jp.einsum("fcj,fj->fc", s.foot_jac, dqd),
    )


def observe(s_body: jax.Array, s_arm: jax.Array, noise: SensorNoise) -> tuple:
    """(s_body (11,), s_arm (2 n,)) as measured: roll, pitch, the trunk-frame angular velocity
    and the yaw-frame velocity of s_body, and the arm's joint positions and velocities, with
    the errors `noise` (the command entries are exact)."""
    body = jp.concatenate([noise.tilt, noise.gyro, noise.velocity, jp.zeros(3)])
    arm = jp.concatenate([noise.arm_q, noise.arm_qd])
    return s_body + body, s_arm + arm


__all__ = ["SensorNoise", "draw", "draw_bias", "measured", "observe", "zeros"]
