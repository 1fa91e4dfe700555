"""The paper's parametric arm (`ArmSpec`) and the one builder of every arm's spec (`arm_spec`).

`ArmSpec` is a WidowX-like parametric arm built from primitives: waist (yaw), shoulder, elbow and
wrist (pitch) hinges plus a one-finger parallel gripper (built here). `UrdfArm` is an arm from a
file: the SO-100 and Unitree Z1 (the example-robot-data wheel's URDFs, shipped in
`dpc_mjx/descriptions/`; structurally different, used to test transfer) or a user's own URDF or
MJCF file (`dpc_mjx.robots.arms.urdf_arm`, read by `dpc_mjx.robots.arms.file`; another of the
optional wheel's: `dpc_mjx.assets.wheel_urdf`).

Every arm is built as its own `MjSpec` whose root body (the arm's base, fixed to the trunk) holds a
site `mount` with a force and a torque sensor (`dpc_mjx.robots.arms.mount`), and is attached to the
trunk with a name prefix `arm<i>/`. MuJoCo's force/torque sensors read the wrench the *trunk
exerts on the arm* at that site, in the site frame; `dpc_mjx.robots.layout` turns this into the
wrench the arm puts on the trunk.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms.mount import (
    ARM_ARMATURE,
    ARM_DAMPING,
    EE_SITE,
    Mount,
    Servo,
    add_mount_sensors,
    add_servo,
)
from dpc_mjx.robots.arms.urdf_arm import UrdfArm, urdf_arm_spec
from dpc_mjx.robots.urdf import VISUAL_GROUP_SITES, make_visual

# Fixed geometry of the parametric arm (m).
BASE_HEIGHT = 0.03  # mount plate to waist joint
PALM_LENGTH = 0.05  # gripper palm along the wrist axis
FINGER_LENGTH = 0.04
FINGER_TRAVEL = 0.03  # slide range of the moving finger
FINGER_MASS_FRACTION = 0.2  # of gripper_mass; the palm carries the rest

# End effectors: a one-finger gripper, or a flat plate for pushing (no finger, 4 arm DOF).
EE_SHAPES = ("gripper", "plate")
PLATE_OFFSET = 0.01  # wrist end to the plate's back face
PLATE_HALF = (0.005, 0.06, 0.04)  # half extents: thickness (along the wrist), width, height

# Joint name -> servo, in kinematic order.
WIDOWX_SERVOS = {
    "waist": Servo(20.0, 1.0, 10.0),
    "shoulder": Servo(40.0, 2.0, 20.0),
    "elbow": Servo(30.0, 1.5, 15.0),
    "wrist": Servo(10.0, 0.5, 5.0),
    "gripper": Servo(100.0, 2.0, 10.0),
}
WIDOWX_RANGES = {  # rad (m for the finger)
    "waist": (-math.pi, math.pi),
    "shoulder": (-1.9, 1.9),
    "elbow": (-1.6, 2.1),
    "wrist": (-1.8, 2.1),
    "gripper": (0.0, FINGER_TRAVEL),
}


@dataclasses.dataclass(frozen=True)
class ArmSpec:
    """A WidowX-like arm: 4 DOF (waist, shoulder, elbow, wrist pitch) + a gripper, from primitives.

    At zero joint angles the upper arm points up (+z) and the forearm, wrist and gripper point
    forward (+x of the mount): the WidowX "home" L-pose. Positive shoulder/elbow/wrist angles pitch
    the arm forward/down. Lengths in m, masses in kg.
    """

    upper_arm_length: float = 0.14  # the paper's "biceps": shoulder axis to elbow axis
    forearm_length: float = 0.14  # elbow axis to wrist axis
    wrist_length: float = 0.07  # wrist axis to gripper palm
    shoulder_height: float = 0.06  # mount plate to shoulder axis
    link_radius: float = 0.018
    base_mass: float = 0.25  # fixed to the trunk
    turret_mass: float = 0.15  # rotates with the waist
    upper_arm_mass: float = 0.2
    forearm_mass: float = 0.15
    wrist_mass: float = 0.08
    gripper_mass: float = 0.1  # palm + finger, or the plate (+ any payload you add here)
    mount: Mount = Mount()
    ee_shape: str = "gripper"  # one of EE_SHAPES

    @property
    def joints(self) -> tuple[str, ...]:
        """Joint names in kinematic order (the plate has no finger joint)."""
        names = tuple(WIDOWX_SERVOS)
        return names if self.ee_shape == "gripper" else names[:-1]

    @property
    def mass(self) -> float:
        """Total arm mass (kg), base included."""
        return (
            self.base_mass
            + self.turret_mass
            + self.upper_arm_mass
            + self.forearm_mass
            + self.wrist_mass
            + self.gripper_mass
        )

    def validate(self, what: str = "arm") -> None:
        if self.ee_shape not in EE_SHAPES:
            raise DpcError(f"{what}: ee_shape must be one of {EE_SHAPES}, got {self.ee_shape!r}.")
        for f in dataclasses.fields(self):
            if f.name in ("mount", "ee_shape"):
                continue
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise DpcError(
                    f"{what}: {f.name} must be a positive finite number (m or kg), got {v!r}."
                )
        if self.shoulder_height <= BASE_HEIGHT:
            raise DpcError(
                f"{what}: shoulder_height={self.shoulder_height} m must exceed the base plate "
                f"height {BASE_HEIGHT} m."
            )
        if self.link_radius * 2 >= min(self.upper_arm_length, self.forearm_length):
            raise DpcError(f"{what}: link_radius={self.link_radius} m is too thick for its links.")
        self.mount.validate(f"{what}.mount")


def arm_spec(arm: ArmSpec | UrdfArm) -> mujoco.MjSpec:
    """The arm alone as a spec: one root body at the origin (to attach at a trunk site)."""
    if isinstance(arm, ArmSpec):
        return _widowx_spec(arm)
    return urdf_arm_spec(arm)


def home_qpos(arm: ArmSpec | UrdfArm, prefix: str) -> dict[str, float]:
    """Home joint value (rad or m) per joint name of an attached arm (names with `prefix`)."""
    if isinstance(arm, ArmSpec):
        return {prefix + name: 0.0 for name in arm.joints}
    return {prefix + name: q for name, q in arm.home_pose().items()}


def _set_inertia(body: mujoco.MjsBody, mass: float, com: tuple, inertia: np.ndarray) -> None:
    body.explicitinertial = True
    body.mass = mass
    body.ipos = list(com)
    body.inertia = list(inertia)


def rod_inertia(mass, length, radius, axis: int):
    """Diagonal inertia (kg·m²) about the COM of a solid cylinder along `axis` (0=x, 1=y, 2=z).

    Works on numpy or jax arrays, so batched link lengths use the same formula as the compiler.
    """
    across = mass * (3 * radius**2 + length**2) / 12
    along = mass * radius**2 / 2
    return [along if i == axis else across for i in range(3)]


def box_inertia(mass, half):
    """Diagonal inertia (kg·m²) of a solid box with half extents `half` (3,)."""
    hx, hy, hz = half
    return [mass * (hy**2 + hz**2) / 3, mass * (hx**2 + hz**2) / 3, mass * (hx**2 + hy**2) / 3]


def _widowx_spec(arm: ArmSpec) -> mujoco.MjSpec:
    spec = mujoco.MjSpec()
    spec.compiler.degree = False  # every angle here is in rad (MjSpec's default is degrees)
    spec.modelname = "widowx"
    r = arm.link_radius
    capsule = mujoco.mjtGeom.mjGEOM_CAPSULE
    rgba = [0.15, 0.15, 0.15, 1]

    base = spec.worldbody.add_body(name="base")
    base.fuse = 0  # keep the welded base apart from the trunk: the mount sensors live in it
    _add_post(base, arm.base_mass, BASE_HEIGHT, 0.04, rgba)
    add_mount_sensors(spec, base)

    turret = base.add_body(name="turret", pos=[0, 0, BASE_HEIGHT])
    turret_h = arm.shoulder_height - BASE_HEIGHT
    _add_post(turret, arm.turret_mass, turret_h, 0.03, rgba)

    upper = turret.add_body(name="upper_arm", pos=[0, 0, turret_h])
    L1 = arm.upper_arm_length
    _set_inertia(
        upper, arm.upper_arm_mass, (0, 0, L1 / 2), rod_inertia(arm.upper_arm_mass, L1, r, 2)
    )
    upper.add_geom(name="upper_arm", type=capsule, size=[r, 0, 0], fromto=[0, 0, 0, 0, 0, L1])

    fore = upper.add_body(name="forearm", pos=[0, 0, L1])
    L2 = arm.forearm_length
    _set_inertia(fore, arm.forearm_mass, (L2 / 2, 0, 0), rod_inertia(arm.forearm_mass, L2, r, 0))
    fore.add_geom(name="forearm", type=capsule, size=[r, 0, 0], fromto=[0, 0, 0, L2, 0, 0])

    wrist = fore.add_body(name="wrist", pos=[L2, 0, 0])
    L3 = arm.wrist_length
    _set_inertia(wrist, arm.wrist_mass, (L3 / 2, 0, 0), rod_inertia(arm.wrist_mass, L3, 0.8 * r, 0))
    wrist.add_geom(type=capsule, size=[0.8 * r, 0, 0], fromto=[0, 0, 0, L3, 0, 0])

    gripper = wrist.add_body(name="gripper", pos=[L3, 0, 0])
    gripper.fuse = 0  # welded, but kept as its own body so its mass can be batched
    joints = [
        (turret, "waist", [0, 0, 1]),
        (upper, "shoulder", [0, 1, 0]),
        (fore, "elbow", [0, 1, 0]),
        (wrist, "wrist", [0, 1, 0]),
    ]
    if arm.ee_shape == "gripper":
        finger = _add_gripper(gripper, arm.gripper_mass, rgba)
        joints.append((finger, "gripper", [0, -1, 0]))  # positive closes onto the fixed jaw
    else:
        _add_plate(gripper, arm.gripper_mass, rgba)

    for body, name, axis in joints:
        kind = mujoco.mjtJoint.mjJNT_SLIDE if name == "gripper" else mujoco.mjtJoint.mjJNT_HINGE
        body.add_joint(
            name=name,
            type=kind,
            axis=axis,
            range=list(WIDOWX_RANGES[name]),
            armature=ARM_ARMATURE,
            damping=[ARM_DAMPING, 0, 0],
        )
        add_servo(spec, name, WIDOWX_SERVOS[name])

    for geom in spec.geoms:
        make_visual(geom)
    return spec


def _add_post(body: mujoco.MjsBody, mass: float, height: float, radius: float, rgba: list) -> None:
    """A vertical cylinder (m) from the body's origin up: its mass, inertia and geom."""
    _set_inertia(body, mass, (0, 0, height / 2), rod_inertia(mass, height, radius, 2))
    body.add_geom(
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[radius, height / 2, 0],
        pos=[0, 0, height / 2],
        rgba=rgba,
    )


def _add_gripper(gripper: mujoco.MjsBody, mass: float, rgba: list) -> mujoco.MjsBody:
    """Palm, fixed jaw and ee site on the `gripper` body; returns the moving finger's body."""
    palm_half = (PALM_LENGTH / 2, 0.03, 0.015)
    palm_mass = (1 - FINGER_MASS_FRACTION) * mass
    _set_inertia(gripper, palm_mass, (palm_half[0], 0, 0), box_inertia(palm_mass, palm_half))
    gripper.add_geom(
        type=mujoco.mjtGeom.mjGEOM_BOX, size=list(palm_half), pos=[palm_half[0], 0, 0], rgba=rgba
    )
    jaw_half = (FINGER_LENGTH / 2, 0.004, 0.012)
    gripper.add_geom(
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(jaw_half),
        pos=[PALM_LENGTH + jaw_half[0], -0.026, 0],
    )
    gripper.add_site(
        name=EE_SITE,
        pos=[PALM_LENGTH + FINGER_LENGTH, 0, 0],
        size=[0.01, 0, 0],
        group=VISUAL_GROUP_SITES,
    )

    finger = gripper.add_body(name="finger", pos=[PALM_LENGTH, 0.026, 0])
    finger_mass = FINGER_MASS_FRACTION * mass
    _set_inertia(finger, finger_mass, (jaw_half[0], 0, 0), box_inertia(finger_mass, jaw_half))
    finger.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=list(jaw_half), pos=[jaw_half[0], 0, 0])
    return finger


def _add_plate(gripper: mujoco.MjsBody, mass: float, rgba: list) -> None:
    """A flat pushing plate across the wrist axis, all of `mass` (kg); ee site on its face."""
    centre = PLATE_OFFSET + PLATE_HALF[0]
    _set_inertia(gripper, mass, (centre, 0, 0), box_inertia(mass, PLATE_HALF))
    gripper.add_geom(
        name="plate",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(PLATE_HALF),
        pos=[centre, 0, 0],
        rgba=rgba,
    )
    gripper.add_site(
        name=EE_SITE,
        pos=[PLATE_OFFSET + 2 * PLATE_HALF[0], 0, 0],
        size=[0.01, 0, 0],
        group=VISUAL_GROUP_SITES,
    )


__all__ = [
    "EE_SHAPES",
    "WIDOWX_RANGES",
    "WIDOWX_SERVOS",
    "ArmSpec",
    "arm_spec",
    "box_inertia",
    "home_qpos",
    "rod_inertia",
]
