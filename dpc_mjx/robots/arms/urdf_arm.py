"""`UrdfArm`: an arm from a file, the SO-100 and Unitree Z1 (the example-robot-data wheel's URDFs,
shipped in `dpc_mjx/descriptions/`; structurally different, used to test transfer) or a user's own
URDF or MJCF file (`dpc_mjx.robots.arms.file` reads and checks it), and its spec with the mount's
sensors, the end-effector site and servos capped in gain (`urdf_arm_spec`).
"""

from __future__ import annotations

import dataclasses
import math
import pathlib

import mujoco
import numpy as np

from dpc_mjx import assets
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms import file as arm_file
from dpc_mjx.robots.arms import mount as arm_mount
from dpc_mjx.robots.urdf import VISUAL_GROUP, VISUAL_GROUP_SITES, inside, make_visual


@dataclasses.dataclass(frozen=True)
class UrdfArm:
    """An arm from a file, attached at `mount`: a name the library knows ('so100', 'z1', shipped
    copies of the example-robot-data wheel's URDFs) or the path of your own URDF or MJCF file
    (`dpc_mjx.robots.arms.file` says what the file needs and what is inferred).

    ee_body and ee_offset (m, in ee_body's frame): where the end effector is; home: (joint, value)
    pairs of the home pose (rad, m for a slide), joints not named at 0 (clipped into their range).
    None or () takes the named arm's values, or for a file what `arm_file` infers. The body welded
    to the trunk is always inferred (the file's root link).
    """

    urdf: str  # a name of URDF_ARMS, or the path of a .urdf or MJCF .xml file
    mount: arm_mount.Mount = arm_mount.Mount()
    ee_body: str | None = None
    ee_offset: tuple[float, float, float] | None = None
    home: tuple[tuple[str, float], ...] = ()

    @property
    def is_file(self) -> bool:
        """Whether this arm is a user's file rather than a named arm."""
        return self.urdf not in URDF_ARMS

    @property
    def name(self) -> str:
        """The arm's short name: the named arm's, or the file's stem (`my_arm` for my_arm.urdf)."""
        return pathlib.Path(self.urdf).stem if self.is_file else self.urdf

    def read(self) -> arm_file.ArmFile:
        """The arm's file read and checked (cached per file); `DpcError` if it cannot be used."""
        if not self.is_file:
            info = URDF_ARMS[self.urdf]
            return arm_file.read(
                assets.urdf_path(self.urdf),
                ee_body=self.ee_body or info.ee_body,
                keep_meshes=False,
            )
        return arm_file.read(self.urdf, ee_body=self.ee_body)

    def home_pose(self) -> dict[str, float]:
        """Home value (rad, m) per joint of the arm (names without the attach prefix)."""
        read = self.read()
        home = arm_file.default_home(read)
        if not self.is_file:
            for name, q in URDF_ARMS[self.urdf].home.items():
                home[name] = float(np.clip(q, *inside(read.joints[name])))
        return {**home, **dict(self.home)}

    @property
    def offset(self) -> tuple[float, float, float]:
        """ee_offset, or the named arm's (m, in ee_body's frame; a file's default is 0)."""
        if self.ee_offset is not None:
            return self.ee_offset
        return (0.0, 0.0, 0.0) if self.is_file else URDF_ARMS[self.urdf].ee_offset

    def validate(self, what: str = "arm") -> None:
        if self.is_file and pathlib.Path(self.urdf).suffix.lower() not in arm_file.SUFFIXES:
            raise DpcError(
                f"{what}: unknown URDF arm {self.urdf!r}; known: {sorted(URDF_ARMS)}, or give the "
                "path of a .urdf or MJCF .xml file."
            )
        offset = self.offset
        if len(offset) != 3 or not all(math.isfinite(float(v)) for v in offset):
            raise DpcError(f"{what}: ee_offset must be 3 finite numbers (m), got {offset!r}.")
        names = [pair[0] for pair in self.home]
        if len(set(names)) != len(names) or not all(len(pair) == 2 for pair in self.home):
            raise DpcError(
                f"{what}: home must be (joint, value) pairs, each joint once: {self.home}"
            )
        arm_file.check_home(self.read(), dict(self.home), what)
        self.mount.validate(f"{what}.mount")


@dataclasses.dataclass(frozen=True)
class _UrdfArmInfo:
    ee_body: str
    ee_offset: tuple[float, float, float]  # m, in ee_body's frame
    home: dict[str, float]  # rad; joints not named start at 0 clipped into their range


URDF_ARMS = {
    # SO-100 (5 DOF + jaw). Its URDF <limit effort=35> is far above the real servos; we cap gains.
    "so100": _UrdfArmInfo("gripper", (0.0, -0.09, 0.0), {"shoulder_lift": 0.3}),
    # Unitree Z1 (6 DOF + gripper), folded in its URDF zero pose; its massless `world` link is
    # skipped as the root (`arm_file`).
    "z1": _UrdfArmInfo("link06", (0.15, 0.0, 0.0), {}),
}
_URDF_KP_CAP = 40.0  # N·m/rad


def urdf_arm_spec(arm: UrdfArm) -> mujoco.MjSpec:
    """The arm alone as a spec (its root body at the origin), with the mount's sensors, the
    end-effector site, capsules where it has no geometry, and a servo on every joint."""
    read = arm.read()
    spec = read.spec
    spec.modelname = arm.name
    root = spec.body(read.root)
    root.fuse = 0  # keep the root body apart from the trunk: the mount sensors live in it
    arm_mount.add_mount_sensors(spec, root)
    spec.body(read.ee_body).add_site(
        name=arm_mount.EE_SITE, pos=list(arm.offset), size=[0.01, 0, 0], group=VISUAL_GROUP_SITES
    )
    if not arm.is_file or not read.has_geometry:
        # Capsules between successive joint origins, so the arm is visible without its meshes.
        for body in spec.bodies:
            if body.name in ("world", read.root):
                continue
            if np.linalg.norm(body.pos) > 1e-3:
                body.parent.add_geom(
                    type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                    size=[0.012, 0, 0],
                    fromto=[0, 0, 0, *body.pos],
                )
    for joint in spec.joints:
        joint.armature = arm_mount.ARM_ARMATURE
        joint.damping = [max(joint.damping[0], arm_mount.ARM_DAMPING), 0, 0]
        effort = float(joint.actfrcrange[1]) or _URDF_KP_CAP
        kp = min(effort, _URDF_KP_CAP)
        arm_mount.add_servo(spec, joint.name, arm_mount.Servo(kp=kp, kv=0.05 * kp, force=effort))
    for geom in spec.geoms:
        make_visual(geom)
        geom.group = VISUAL_GROUP
    return spec


__all__ = ["URDF_ARMS", "UrdfArm", "urdf_arm_spec"]
