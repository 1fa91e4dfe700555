"""Named robot variants: a base (the A1 by default) with zero, one or two arms (the paper's
Table I and more). The arms' mounts are written on the A1's trunk box; on another base
`robots.assemble` moves them to the same place of its trunk box.

none: bare A1. regular/longer/heavier/double: Table I. pusher: the pushing task's heavier, flat
arm (0.5 kg plate end effector, no gripper). so100/z1: URDF arms for transfer.
"""

from __future__ import annotations

import dataclasses
import math

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.arms.mount import REFERENCE_TRUNK_HALF_EXTENTS
from dpc_mjx.robots.bases.file import BaseSpec

MAX_ARMS = 2
MIN_MOUNT_SEPARATION = 0.08  # m between two arm bases (their plates are 0.04 m in radius)

Arm = ArmSpec | UrdfArm


@dataclasses.dataclass(frozen=True)
class RobotSpec:
    """A base and the arms mounted on it (structure: changing it means a new compile). `base`:
    a named base, the path of its file, or a `BaseSpec` (`robots.bases.model.as_base`)."""

    name: str
    arms: tuple[Arm, ...] = ()
    base: str | BaseSpec = "a1"

    def validate(self) -> None:
        if not isinstance(self.arms, tuple):
            raise DpcError(
                f"{self.name}: arms must be a tuple of ArmSpec/UrdfArm, got {self.arms!r}."
            )
        if len(self.arms) > MAX_ARMS:
            raise DpcError(
                f"{self.name}: {len(self.arms)} arms given, a trunk carries at most {MAX_ARMS}."
            )
        for i, arm in enumerate(self.arms):
            if not isinstance(arm, (ArmSpec, UrdfArm)):
                raise DpcError(
                    f"{self.name}: arm {i} is a {type(arm).__name__}, not ArmSpec/UrdfArm."
                )
            arm.validate(f"{self.name}.arms[{i}]")
        if len(self.arms) == 2:
            gap = math.dist(self.arms[0].mount.pos, self.arms[1].mount.pos)
            if gap < MIN_MOUNT_SEPARATION:
                raise DpcError(
                    f"{self.name}: the two arm mounts are {gap:.3f} m apart; move them at least "
                    f"{MIN_MOUNT_SEPARATION} m apart (e.g. y=+-0.06)."
                )

    @property
    def arm_mass(self) -> float:
        """Mass (kg) of the parametric arms; URDF arms are weighed on the compiled model."""
        return sum(arm.mass for arm in self.arms if isinstance(arm, ArmSpec))


_TOP = REFERENCE_TRUNK_HALF_EXTENTS[2]  # m, top face of the trunk

VARIANTS: dict[str, RobotSpec] = {
    spec.name: spec
    for spec in (
        RobotSpec("none"),
        RobotSpec("regular", (ArmSpec(),)),  # Table I: biceps 0.14 m, gripper 0.1 kg
        RobotSpec("longer", (ArmSpec(upper_arm_length=0.28),)),
        RobotSpec("heavier", (ArmSpec(gripper_mass=0.5),)),
        RobotSpec(
            "double",
            (ArmSpec(mount=Mount((0.09, 0.06, _TOP))), ArmSpec(mount=Mount((0.09, -0.06, _TOP)))),
        ),
        # Pushing task: heavier (0.5 kg) flat plate instead of the gripper; 4 arm DOF.
        RobotSpec("pusher", (ArmSpec(gripper_mass=0.5, ee_shape="plate"),)),
        RobotSpec("so100", (UrdfArm("so100"),)),
        RobotSpec("z1", (UrdfArm("z1"),)),
    )
}


def resolve(robot: str | Arm | RobotSpec) -> RobotSpec:
    """A variant name, a single arm or a `RobotSpec`, as a validated `RobotSpec`: a lookup (an arm
    file is read and checked, nothing compiled; whether the A1 can hold it up is
    `control.static_balance`, checked by `envs.registry.resolve_arm`)."""
    if isinstance(robot, str):
        if robot not in VARIANTS:
            raise DpcError(f"Unknown arm variant {robot!r}; known variants: {sorted(VARIANTS)}.")
        spec = VARIANTS[robot]
    elif isinstance(robot, (ArmSpec, UrdfArm)):
        spec = RobotSpec("custom", (robot,))
    elif isinstance(robot, RobotSpec):
        spec = robot
    else:
        raise DpcError(
            f"Expected a variant name, an ArmSpec/UrdfArm or a RobotSpec, "
            f"got {type(robot).__name__}."
        )
    spec.validate()
    return spec


def on_base(robot: RobotSpec, base: str | BaseSpec) -> RobotSpec:
    """`robot` on `base` (a name, a file path or a `BaseSpec`), unless it carries a `BaseSpec`
    object of its own (then that one: `make(..., base=spec)` builds it so)."""
    return robot if isinstance(robot.base, BaseSpec) else dataclasses.replace(robot, base=base)


def arm_name(robot: str | Arm | RobotSpec) -> str:
    """The name an arm goes by in tables and exports: a variant's name, a file arm's file stem
    (`my_arm` for my_arm.urdf), a named URDF arm's name, a RobotSpec's name; "custom" otherwise."""
    if isinstance(robot, str):
        return robot
    if isinstance(robot, UrdfArm):
        return robot.name
    return robot.name if isinstance(robot, RobotSpec) else "custom"
