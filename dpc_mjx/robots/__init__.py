"""The A1 with parametric or URDF arms: specs, named variants, compiled models, batched params."""

from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.assemble import build, build_spec, robot_spec
from dpc_mjx.robots.variants import VARIANTS, RobotSpec, resolve

__all__ = [
    "VARIANTS",
    "ArmSpec",
    "Mount",
    "RobotSpec",
    "UrdfArm",
    "build",
    "build_spec",
    "resolve",
    "robot_spec",
]
