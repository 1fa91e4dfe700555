"""Robots: any quadruped base (`robots.bases`: read from its URDF or MJCF file) carrying zero,
one or two arms (`robots.arms`: the paper's parametric arm, the SO-100, the Unitree Z1, or your
own file), assembled into one MuJoCo model with its scene (`assemble`), indexed (`layout`), named
(`variants`), with scene objects (`objects`: boxes, tables, balls, weld grasps; the tasks that
place them own their scenes in `dpc_mjx.envs.tasks`), arm specs as JSON (`spec_json`), MJCF files
(`mjcf`) and standing servos for tests and benchmarks (`standing`). Whether a base can hold an arm
up is `dpc_mjx.control.static_balance`.

Modules that moved into `bases/` and `arms/` (CHANGELOG, "The house") still import from their
old paths, with a `DeprecationWarning`, until dpc_mjx 0.3."""

from dpc_mjx.deprecation import alias_moved_modules
from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.arms.family import ArmFamily
from dpc_mjx.robots.arms.params import batch_arm_params
from dpc_mjx.robots.assemble import build, build_spec, robot_spec
from dpc_mjx.robots.layout import Layout, layout, mount_wrench
from dpc_mjx.robots.objects import prop_layout
from dpc_mjx.robots.spec_json import arm_argument, read_arm_description
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.robots.variants import VARIANTS, RobotSpec, arm_name, resolve

# Old module paths (dpc_mjx 0.1) -> where they live now.
MOVED = {
    f"dpc_mjx.robots.{old}": f"dpc_mjx.robots.{new}"
    for old, new in {
        "a1": "bases.a1",
        "base_describe": "bases.describe",
        "base_file": "bases.file",
        "base_home": "bases.geometry",
        "base_measure": "bases.measure",
        "base_mjcf": "bases.mjcf_tree",
        "base_model": "bases.model",
        "base_urdf": "bases.urdf_tree",
        "urdf_fuse": "bases.fuse",
        "arm_file": "arms.file",
        "arm_xml": "arms.prepare",
        "family": "arms.family",
        "mount": "arms.mount",
        "params": "arms.params",
        "urdf_arm": "arms.urdf_arm",
    }.items()
}
alias_moved_modules(MOVED, removed_in="0.3")

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
