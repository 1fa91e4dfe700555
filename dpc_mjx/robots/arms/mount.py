"""What every arm shares where it meets the base: its mount (`Mount`: where its base sits on the
trunk), the mount site with its force and torque sensors, the end-effector site's name, and its
joints' position servos (`Servo`), armature and damping, and the prefix of its names.

A `Mount` is written on the reference trunk box (`REFERENCE_TRUNK_HALF_EXTENTS`, the A1's: the
frame every named variant's mount is written in), and checked against it; `assemble.mount_on`
moves it to the same place of any base's trunk box (each coordinate scaled by the ratio of the
boxes' half extents), so a mount inside the reference box is inside every base's trunk.

MuJoCo's force/torque sensors read the wrench the *trunk exerts on the arm* at the mount site, in
the site frame; `dpc_mjx.robots.layout` turns this into the wrench the arm puts on the trunk.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.urdf import VISUAL_GROUP_SITES

# The reference trunk box every mount is written on: half extents (m) in the trunk frame, the
# A1's trunk collision box (`robots.bases.a1.TRUNK_HALF_EXTENTS`; tests/test_base_file.py checks
# that they agree).
REFERENCE_TRUNK_HALF_EXTENTS = (0.1335, 0.097, 0.057)
_TOP = REFERENCE_TRUNK_HALF_EXTENTS[2]  # m, the reference box's top face
MOUNT_SITE = "mount"
EE_SITE = "ee"
FORCE_SENSOR = "mount_force"  # N, site frame
TORQUE_SENSOR = "mount_torque"  # N·m, site frame

ARM_ARMATURE = 0.01  # kg·m² on every arm joint, keeps stiff position servos stable at dt 4 ms
ARM_DAMPING = 0.05  # N·m·s/rad


@dataclasses.dataclass(frozen=True)
class Mount:
    """Where an arm's base sits on the trunk: position (m) in the trunk frame and yaw (rad)."""

    pos: tuple[float, float, float] = (0.09, 0.0, _TOP)
    yaw: float = 0.0

    def validate(self, what: str = "mount") -> None:
        values = (*self.pos, self.yaw)
        if len(self.pos) != 3 or not all(math.isfinite(float(v)) for v in values):
            raise DpcError(f"{what}: pos must be 3 finite numbers and yaw finite, got {self}.")
        for axis, v, half in zip("xyz", self.pos, REFERENCE_TRUNK_HALF_EXTENTS, strict=True):
            if abs(v) > half + 1e-9:
                raise DpcError(
                    f"{what}: pos {axis}={v:.3f} m is outside the reference trunk box (the A1's, "
                    f"|{axis}| <= {half} m, mapped onto any base's trunk by `mount_on`); mount "
                    f"the arm on the trunk, e.g. on its top face z={_TOP}."
                )


@dataclasses.dataclass(frozen=True)
class Servo:
    """Position servo of one arm joint: gains and force limit."""

    kp: float  # N·m/rad (N/m for the finger)
    kv: float  # N·m·s/rad
    force: float  # N·m (N for the finger)


def arm_prefix(i: int) -> str:
    """Name prefix of everything belonging to arm `i` (joints, actuators, sites, sensors)."""
    return f"arm{i}/"


def add_mount_sensors(spec: mujoco.MjSpec, root: mujoco.MjsBody) -> None:
    """The mount site on the arm's `root` body, with its force and torque sensors."""
    root.add_site(name=MOUNT_SITE, size=[0.01, 0, 0], group=VISUAL_GROUP_SITES)
    for kind, name in (
        (mujoco.mjtSensor.mjSENS_FORCE, FORCE_SENSOR),
        (mujoco.mjtSensor.mjSENS_TORQUE, TORQUE_SENSOR),
    ):
        spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=MOUNT_SITE)


def add_servo(spec: mujoco.MjSpec, joint: str, servo: Servo) -> None:
    """A position servo (`servo`'s gains and force limit) on `joint`, named after it."""
    act = spec.add_actuator(name=joint, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.set_to_position(kp=servo.kp, kv=servo.kv)
    act.forcelimited = True
    act.forcerange = [-servo.force, servo.force]


__all__ = [
    "ARM_ARMATURE",
    "ARM_DAMPING",
    "EE_SITE",
    "FORCE_SENSOR",
    "MOUNT_SITE",
    "REFERENCE_TRUNK_HALF_EXTENTS",
    "TORQUE_SENSOR",
    "Mount",
    "Servo",
    "add_mount_sensors",
    "arm_prefix",
    "add_servo",
]
