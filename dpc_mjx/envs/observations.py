"""Observation blocks as the paper defines them (§III-B, III-C), from one env's data.

    s_body (11,): roll, pitch (rad); trunk angular velocity (3, rad/s, trunk frame);
                  trunk linear velocity (3, m/s, yaw frame); velocity command (3: v_x, v_y m/s in
                  the yaw frame, yaw rate rad/s)
    s_arm  (2 n,): arm joint positions (rad or m), then velocities, every arm joint in layout order
    p_arm  (n_act,): the arm servos' desired joint positions (the reference motion)
    u_obs  (6,): the disturbance observer's estimate of the external wrench on the base
                 (`control/observer.py`: IMU, encoders and the commanded foot forces, no force
                 sensor), in the yaw frame: [f (N), tau (N·m) about the base's COM]

`s_body` has the same layout for every variant; `s_arm`/`p_arm` follow the arm (n = 0 for the
bare A1); `u_obs` is arm-agnostic (what a policy shared by every arm may see). Works on
`mujoco.MjData` and `mjx.Data` (numpy or jax arrays).

An env's observation is `[s_body, s_arm, p_arm, u_obs]` (`ObsLayout` gives the slices); an
encoder reads its first `ObsLayout.encoder_size` entries `[s_body, s_arm, p_arm]`, the paper's
arm observation. The privileged block (never seen by the policy) is `[u_oracle (6), payload (1),
ee_force (3)]` (`PRIVILEGED`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp

from dpc_mjx.robots.layout import Layout
from dpc_mjx.rotations import roll_pitch_yaw, to_yaw_frame, wrench_to_yaw_frame

# s_body's entries, in order (units and frames as in the module docstring); the exports record it
S_BODY_NAMES = (
    *("roll", "pitch"),  # rad
    *("wx", "wy", "wz"),  # rad/s, trunk frame
    *("vx", "vy", "vz"),  # m/s, yaw frame
    *("cmd_vx", "cmd_vy", "cmd_yaw"),  # velocity command: m/s, m/s (yaw frame), rad/s
)
S_BODY_SIZE = len(S_BODY_NAMES)  # 11
# Roll and pitch rate (wx, wy; rad/s, trunk frame) inside s_body: the adapter decoder's target.
S_BODY_DRP = slice(S_BODY_NAMES.index("wx"), S_BODY_NAMES.index("wy") + 1)
# u_obs's entries, in order: force (N), torque about the base's COM (N·m), yaw frame
U_OBS_NAMES = ("obs_fx", "obs_fy", "obs_fz", "obs_tx", "obs_ty", "obs_tz")
U_OBS_SIZE = len(U_OBS_NAMES)  # 6, the last entries of every env observation
# Privileged block: the measured mount wrench u = [f_a (N), tau_a (N·m)] about the base's COM, world
# frame (`state.oracle_u`); total payload mass (kg); total force applied at the end
# effectors by pushes, payload weight excluded (N, world).
PRIVILEGED = {"u_oracle": slice(0, 6), "payload": slice(6, 7), "ee_force": slice(7, 10)}
PRIVILEGED_SIZE = 10


@dataclasses.dataclass(frozen=True)
class ObsLayout:
    """Slices of the flat observation `[s_body (11), s_arm (2 n), p_arm (n_act), u_obs (6)]`."""

    n_arm_joints: int  # n
    n_arm_act: int

    @property
    def s_body(self) -> slice:
        return slice(0, S_BODY_SIZE)

    @property
    def s_arm(self) -> slice:
        return slice(S_BODY_SIZE, S_BODY_SIZE + 2 * self.n_arm_joints)

    @property
    def p_arm(self) -> slice:
        return slice(self.s_arm.stop, self.s_arm.stop + self.n_arm_act)

    @property
    def u_obs(self) -> slice:
        return slice(self.p_arm.stop, self.p_arm.stop + U_OBS_SIZE)

    @property
    def encoder_size(self) -> int:
        """Entries of `[s_body, s_arm, p_arm]`, the encoder's input (a prefix of the obs)."""
        return self.p_arm.stop

    @property
    def size(self) -> int:
        return self.u_obs.stop

    def split(self, obs: jax.Array) -> dict[str, jax.Array]:
        """{'s_body', 's_arm', 'p_arm', 'u_obs'} views of `obs` (..., size)."""
        return {k: obs[..., getattr(self, k)] for k in ("s_body", "s_arm", "p_arm", "u_obs")}

    @classmethod
    def of(cls, lay: Layout) -> ObsLayout:
        return cls(n_arm_joints=len(lay.arm_dof), n_arm_act=len(lay.arm_act))


def yaw_frame_velocity(d) -> jax.Array:
    """(3,) trunk linear velocity (m/s) in the yaw frame (heading-aligned, z up)."""
    return to_yaw_frame(d.qvel[0:3], roll_pitch_yaw(d.qpos[3:7])[2])  # free joint: world frame


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


def u_obs(d, estimate: jax.Array) -> jax.Array:
    """(6,) the observer's `estimate` (6,) (world frame, `ObserverState.estimate`) in the yaw
    frame of the trunk."""
    return wrench_to_yaw_frame(estimate, roll_pitch_yaw(d.qpos[3:7])[2])


def observation(lay: Layout, d, command: jax.Array, estimate: jax.Array) -> jax.Array:
    """The flat observation `[s_body, s_arm, p_arm, u_obs]` (see `ObsLayout`); `estimate` (6,)
    the disturbance observer's, world frame."""
    return jp.concatenate([s_body(d, command), s_arm(lay, d), p_arm(lay, d), u_obs(d, estimate)])


def world_yaw_rate(s_body_: jax.Array) -> jax.Array:
    """Yaw rate (rad/s): the world-z component of the trunk angular velocity, from s_body alone.

    For a ZYX (yaw-pitch-roll) orientation the world z axis in the trunk frame is
    (-sin pitch, cos pitch sin roll, cos pitch cos roll), whatever the yaw.
    """
    roll, pitch, w = s_body_[..., 0], s_body_[..., 1], s_body_[..., 2:5]
    z = jp.stack(
        [-jp.sin(pitch), jp.cos(pitch) * jp.sin(roll), jp.cos(pitch) * jp.cos(roll)], axis=-1
    )
    return jp.sum(z * w, axis=-1)
