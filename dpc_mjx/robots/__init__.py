"""The A1 with parametric arms or arms from files (named URDFs, or your own URDF/MJCF): specs,
named variants, families of arms to train over (`family`), compiled models, batched params,
and the scene objects (`objects`: boxes, tables, balls, weld grasps; the tasks that place them
own their scenes in `dpc_mjx.envs.tasks`). Whether the A1 can hold an arm up is
`dpc_mjx.control.static_balance`."""

from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.assemble import build, build_spec, robot_spec
from dpc_mjx.robots.family import ArmFamily
from dpc_mjx.robots.layout import Layout, layout, mount_wrench
from dpc_mjx.robots.objects import prop_layout
from dpc_mjx.robots.params import batch_arm_params
from dpc_mjx.robots.spec_json import arm_argument, read_arm_description
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.robots.variants import VARIANTS, RobotSpec, arm_name, resolve

__all__ = [
    "VARIANTS",
    "ArmFamily",
    "ArmSpec",
    "Layout",
    "Mount",
    "RobotSpec",
    "UrdfArm",
    "arm_argument",
    "arm_name",
    "batch_arm_params",
    "build",
    "build_spec",
    "home_ctrl",
    "layout",
    "mount_wrench",
    "perturbed_home",
    "prop_layout",
    "read_arm_description",
    "resolve",
    "robot_spec",
    "with_leg_servos",
]
