"""The A1 with parametric or URDF arms: specs, named variants, compiled models, batched params,
and the task scenes' objects (`props`)."""

from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.assemble import build, build_spec, robot_spec
from dpc_mjx.robots.props import TASKS, build_task_scene, prop_layout, task_spec
from dpc_mjx.robots.variants import VARIANTS, RobotSpec, resolve

__all__ = [
    "TASKS",
    "VARIANTS",
    "ArmSpec",
    "Mount",
    "RobotSpec",
    "UrdfArm",
    "build",
    "build_spec",
    "build_task_scene",
    "prop_layout",
    "resolve",
    "robot_spec",
    "task_spec",
]
