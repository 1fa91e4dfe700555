"""The Unitree A1, assembled with `mujoco.MjSpec` from its URDF (example-robot-data's, shipped in
`dpc_mjx/descriptions/`: no wheel needed).

Floating base, 12 torque-controlled leg joints (URDF limits and effort), a home keyframe
(added by `dpc_mjx.robots.build` once the arms are on), foot and IMU sites, IMU-like sensors, and
contacts only between the 4 foot spheres and the floor (the MJX-friendly "feet only" layout).
"""

from __future__ import annotations

import mujoco
import numpy as np

from dpc_mjx.robots.urdf import load_urdf

LEGS = ("FR", "FL", "RR", "RL")  # MuJoCo/URDF order: front-right, front-left, rear-right, rear-left
LEG_JOINTS = tuple(f"{leg}_{part}_joint" for leg in LEGS for part in ("hip", "thigh", "calf"))
FOOT_SITES = tuple(f"{leg}_foot" for leg in LEGS)
TRUNK = "trunk"
IMU_SITE = "imu"

# Home pose: trunk height (m) above the floor and leg joint angles (rad) per leg (hip, thigh, calf).
HOME_HEIGHT = 0.27
HOME_LEG = (0.0, 0.9, -1.8)

# Trunk collision box of the URDF: half extents (m) in the trunk frame; arm mounts must lie in it.
TRUNK_HALF_EXTENTS = (0.1335, 0.097, 0.057)

VISUAL_GROUP_SITES = 4  # sites are hidden by default in the viewer

FOOT_RADIUS = 0.02  # m, the URDF's foot sphere
FOOT_FRICTION = 0.8

# Leg joint dynamics not given by the URDF (its damping and friction are 0).
LEG_DAMPING = 0.1  # N·m·s/rad
LEG_ARMATURE = 0.01  # kg·m², reflected rotor inertia

# Contact bit masks: a pair collides if (contype1 & conaffinity2) or (contype2 & conaffinity1).
FLOOR_CONTYPE, FLOOR_CONAFFINITY = 1, 0
FOOT_CONTYPE, FOOT_CONAFFINITY = 0, 1  # feet touch the floor but never each other


def a1_spec() -> mujoco.MjSpec:
    """The A1 as a spec: trunk with a free joint, leg motors, sites, sensors; no floor."""
    spec = load_urdf("a1", drop_links=("base",))
    spec.modelname = "a1"
    trunk = spec.body(TRUNK)
    trunk.add_freejoint(name="root")
    trunk.add_site(name=IMU_SITE, pos=[0, 0, 0], group=VISUAL_GROUP_SITES)

    for leg in LEGS:
        foot = spec.body(f"{leg}_foot")
        foot.add_site(
            name=f"{leg}_foot", pos=[0, 0, 0], size=[0.005, 0, 0], group=VISUAL_GROUP_SITES
        )
        sphere = next(g for g in foot.geoms if g.type == mujoco.mjtGeom.mjGEOM_SPHERE)
        sphere.name = f"{leg}_foot"
        sphere.contype, sphere.conaffinity = FOOT_CONTYPE, FOOT_CONAFFINITY
        sphere.condim = 3
        sphere.friction = [FOOT_FRICTION, 0.02, 0.01]
        sphere.size = [FOOT_RADIUS, 0, 0]

    for name in LEG_JOINTS:
        joint = spec.joint(name)
        joint.damping = [LEG_DAMPING, 0, 0]
        joint.armature = LEG_ARMATURE
        effort = float(joint.actfrcrange[1])  # N·m, the URDF's <limit effort=...>
        act = spec.add_actuator(name=name.removesuffix("_joint"), target=name)
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


def home_leg_qpos() -> np.ndarray:
    """(12,) leg joint angles of the home pose, rad, in `LEG_JOINTS` order."""
    return np.tile(np.asarray(HOME_LEG), len(LEGS))
