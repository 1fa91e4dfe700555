"""Arms, on any base: the paper's parametric arm (`ArmSpec`), arms from files (`UrdfArm`: the
SO-100 and the Unitree Z1 shipped, or your own URDF or MJCF, read and checked by `arms.file`), where
an arm meets the base (`arms.mount`: its mount, sensors, servos and name prefix), families of arms
to train over (`arms.family`) and their continuous parameters on a batched `mjx.Model`
(`arms.params`). Nothing here knows a base: `dpc_mjx.robots.assemble` puts arms on one.

    from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
"""

from dpc_mjx.robots.arms.mount import (
    ARM_ARMATURE,
    ARM_DAMPING,
    EE_SITE,
    FORCE_SENSOR,
    MOUNT_SITE,
    REFERENCE_TRUNK_HALF_EXTENTS,
    TORQUE_SENSOR,
    Mount,
    Servo,
    arm_prefix,
)
from dpc_mjx.robots.arms.parametric import (
    EE_SHAPES,
    WIDOWX_RANGES,
    WIDOWX_SERVOS,
    ArmSpec,
    arm_spec,
    box_inertia,
    home_qpos,
    rod_inertia,
)
from dpc_mjx.robots.arms.urdf_arm import URDF_ARMS, UrdfArm

__all__ = [
    "ARM_ARMATURE",
    "ARM_DAMPING",
    "EE_SHAPES",
    "EE_SITE",
    "FORCE_SENSOR",
    "MOUNT_SITE",
    "REFERENCE_TRUNK_HALF_EXTENTS",
    "TORQUE_SENSOR",
    "URDF_ARMS",
    "WIDOWX_RANGES",
    "WIDOWX_SERVOS",
    "ArmSpec",
    "Mount",
    "Servo",
    "UrdfArm",
    "arm_prefix",
    "arm_spec",
    "box_inertia",
    "home_qpos",
    "rod_inertia",
]
