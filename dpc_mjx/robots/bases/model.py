"""A quadruped base (`robots.bases.file.BaseSpec`) as a MuJoCo spec, and the names the library gives
its parts on every base.

`base_mjspec(base)`: the base's URDF (meshes dropped, as `robots.urdf` does for every shipped
file) or MJCF (its own actuators, sensors, sites, keyframes and options dropped too:
`robots.bases.mjcf_tree.load_mjcf`), its trunk given the free joint `ROOT_JOINT`, an IMU site on the
trunk's origin, a foot site and a foot sphere per leg (the file's sphere, or one of the spec's
radius where the file has none), a torque motor per leg joint (range: the file's effort),
IMU-like sensors, and contacts only between the feet and the floor (the MJX-friendly "feet only"
layout). An actuated subtree of the file that is not a leg (`base.others`: B1's Z1) is left out:
it is mounted as an arm.

Whatever the file calls them, the library's names are the same on every base: actuators
`<place>_<part>` (`FR_hip`, ..., `RL_calf`; places `bases.file.LEGS`, parts `LEG_PARTS`), foot sites
and spheres `<place>_foot`, the trunk is the body of the `ROOT_JOINT`. `robots.layout` finds
everything by these names; the A1's own file names agree with them, so its model is unchanged.

Leg joint damping and rotor armature (the files give none) scale with the joint's torque limit
from the A1's values (`LEG_DAMPING`, `LEG_ARMATURE` at `A1_EFFORT`): a stronger motor, a larger
rotor.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.bases.file import LEGS, BaseSpec, base_file_path, read_base
from dpc_mjx.robots.bases.fuse import apply_to_spec
from dpc_mjx.robots.bases.mjcf_tree import is_mjcf, load_mjcf
from dpc_mjx.robots.bases.urdf_tree import UrdfTree
from dpc_mjx.robots.urdf import VISUAL_GROUP_SITES, load_urdf, make_visual

ROOT_JOINT = "root"  # the trunk's free joint
IMU_SITE = "imu"
LEG_PARTS = ("hip", "thigh", "calf")  # a leg's joints from the trunk out (actuator names)

FOOT_FRICTION = 0.8
A1_EFFORT = 33.5  # N·m, the A1's joint torque limit, at which the two values below hold
LEG_DAMPING = 0.1  # N·m·s/rad
LEG_ARMATURE = 0.01  # kg·m², reflected rotor inertia

# Contact bit masks: a pair collides if (contype1 & conaffinity2) or (contype2 & conaffinity1).
FLOOR_CONTYPE, FLOOR_CONAFFINITY = 1, 0
FOOT_CONTYPE, FOOT_CONAFFINITY = 0, 1  # feet touch the floor but never each other

# The A1's home pose, as the library has always stood it (its recorded results rest on it): trunk
# height (m) and per leg (hip, thigh, calf) angles (rad). Every other base: `BaseSpec`'s.
A1_HOME_HEIGHT = 0.27
A1_HOME_LEG = (0.0, 0.9, -1.8)


def as_base(base: str | os.PathLike | BaseSpec) -> BaseSpec:
    """A base given by name, file path or spec, as a `BaseSpec` (read and checked once)."""
    if isinstance(base, BaseSpec):
        return base
    if not isinstance(base, (str, os.PathLike)):
        raise DpcError(
            "base must be a base's name, the path of its .urdf/.xml/.json file or a BaseSpec, "
            f"got {type(base).__name__}."
        )
    return read_base(base)


def actuator_name(place: str, part: str) -> str:
    """The torque motor of `part` (one of LEG_PARTS) of the leg at `place` (one of LEGS)."""
    return f"{place}_{part}"


def foot_name(place: str) -> str:
    """The foot site and foot sphere of the leg at `place`."""
    return f"{place}_foot"


def is_shipped_a1(base: BaseSpec) -> bool:
    """The A1 the library ships (its file, its inferred home height not overridden)."""
    return base.path == base_file_path("a1") and base.home_from != "given"


def home_pose(base: BaseSpec) -> tuple[float, np.ndarray]:
    """(trunk height above the floor, m; (12,) leg joint angles, rad, legs in LEGS order)."""
    if is_shipped_a1(base):
        return A1_HOME_HEIGHT, np.tile(np.asarray(A1_HOME_LEG), len(LEGS))
    return base.home_height, base.home_qpos


def base_mjspec(base: BaseSpec) -> mujoco.MjSpec:
    """The base as a spec: trunk with a free joint, leg motors, feet, sites, sensors; no floor."""
    if is_mjcf(base.path):
        spec = load_mjcf(base.path, base.trunk, base.skipped_roots, base.others)
    else:
        spec = load_urdf(base.path, drop_links=base.skipped_roots + _other_links(base))
        apply_to_spec(spec, base.fused)  # fixed links whose inertia MuJoCo refuses, fused
    spec.modelname = base.name
    trunk = spec.body(base.trunk)
    trunk.add_freejoint(name=ROOT_JOINT)
    trunk.add_site(name=IMU_SITE, pos=[0, 0, 0], group=VISUAL_GROUP_SITES)
    for leg in base.legs:
        _add_foot(spec.body(leg.foot), foot_name(leg.place), leg.foot_center, leg.foot_radius)
        for part, name, effort in zip(LEG_PARTS, leg.joints, leg.torque_limits, strict=True):
            joint = spec.joint(name)
            joint.damping = [LEG_DAMPING * (effort / A1_EFFORT), 0, 0]
            joint.armature = LEG_ARMATURE * (effort / A1_EFFORT)
            act = spec.add_actuator(name=actuator_name(leg.place, part), target=name)
            act.trntype = mujoco.mjtTrn.mjTRN_JOINT
            act.set_to_motor()
            act.ctrllimited = True
            act.ctrlrange = [-effort, effort]  # N·m
    for kind, name in (
        (mujoco.mjtSensor.mjSENS_FRAMEQUAT, "trunk_quat"),  # world orientation of the trunk
        (mujoco.mjtSensor.mjSENS_GYRO, "gyro"),  # rad/s, trunk frame
        (mujoco.mjtSensor.mjSENS_ACCELEROMETER, "accelerometer"),  # m/s², trunk frame
        (mujoco.mjtSensor.mjSENS_VELOCIMETER, "local_linvel"),  # m/s, trunk frame
    ):
        spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE)
    return spec


def _add_foot(body: mujoco.MjsBody, name: str, center, radius: float) -> None:
    """The foot site and the colliding foot sphere (the file's sphere if it has one there)."""
    body.add_site(name=name, pos=list(center), size=[0.005, 0, 0], group=VISUAL_GROUP_SITES)
    spheres = [g for g in body.geoms if g.type == mujoco.mjtGeom.mjGEOM_SPHERE]
    if spheres:
        sphere = spheres[0]
    else:
        sphere = body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=list(center))
        make_visual(sphere)  # massless: the file's inertias stay the base's
    sphere.name = name
    sphere.contype, sphere.conaffinity = FOOT_CONTYPE, FOOT_CONAFFINITY
    sphere.condim = 3
    sphere.friction = [FOOT_FRICTION, 0.02, 0.01]
    sphere.size = [radius, 0, 0]


def _other_links(base: BaseSpec) -> tuple[str, ...]:
    """The links of the base file's actuated subtrees that are not legs (mounted as arms)."""
    if not base.others:
        return ()
    tree = UrdfTree.parse(base.path)
    return tuple(link for limb in base.others for link in tree.subtree_links(limb.root))


__all__ = [
    "A1_HOME_HEIGHT",
    "A1_HOME_LEG",
    "FLOOR_CONAFFINITY",
    "FLOOR_CONTYPE",
    "IMU_SITE",
    "LEG_PARTS",
    "ROOT_JOINT",
    "actuator_name",
    "as_base",
    "base_mjspec",
    "foot_name",
    "home_pose",
    "is_shipped_a1",
]
