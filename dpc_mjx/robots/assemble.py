"""Assemble a robot variant (a base + arms) and its scene with `mujoco.MjSpec`, and compile it."""

from __future__ import annotations

import math
import os

import mujoco
import numpy as np

from dpc_mjx.robots import arms
from dpc_mjx.robots.arms import Mount
from dpc_mjx.robots.arms.mount import REFERENCE_TRUNK_HALF_EXTENTS, arm_prefix
from dpc_mjx.robots.bases import model as base_model
from dpc_mjx.robots.bases.file import BaseSpec
from dpc_mjx.robots.urdf import VISUAL_GROUP_SITES
from dpc_mjx.robots.variants import Arm, RobotSpec, on_base, resolve

Base = str | os.PathLike | BaseSpec  # a named base, a file's path or a spec

HOME_KEY = "home"

# Simulation options, chosen for MJX throughput at unchanged stability (docs/decisions-engines.md,
# "MJX").
TIMESTEP = 0.004  # s; the policy's 50 Hz is 5 physics steps
SOLVER_ITERATIONS = 4
LS_ITERATIONS = 8


def robot_spec(arm: str | Arm | RobotSpec, base: Base | None = None) -> mujoco.MjSpec:
    """The robot alone (no floor): base, arms attached at their mounts, options, home keyframe.
    `arm`: a variant's name (`"none"` too), an `ArmSpec`/`UrdfArm` or a `RobotSpec`; `base`: a
    named base, a file's path or a `BaseSpec` (None: the RobotSpec's, the A1)."""
    robot = resolve(arm)
    return assemble(robot if base is None else on_base(robot, _base_argument(base)))


def _base_argument(base: Base) -> str | BaseSpec:
    """`base` as `variants.on_base` takes it (a path object as its string)."""
    return base if isinstance(base, BaseSpec) else os.fspath(base)


def assemble(robot: RobotSpec) -> mujoco.MjSpec:
    """`robot_spec` of a robot already resolved (not validated again: `resolve` checks a file
    arm's static balance on this spec)."""
    base = base_model.as_base(robot.base)
    spec = base_model.base_mjspec(base)
    spec.modelname = f"{base.name}_{robot.name}"
    trunk = spec.body(base.trunk)
    for i, arm in enumerate(robot.arms):
        mount = mount_on(base, arm.mount)
        site = trunk.add_site(
            name=f"{arm_prefix(i)}mount_frame",
            pos=list(mount.pos),
            quat=[math.cos(mount.yaw / 2), 0, 0, math.sin(mount.yaw / 2)],
            group=VISUAL_GROUP_SITES,
        )
        spec.attach(arms.arm_spec(arm), prefix=arm_prefix(i), site=site)

    spec.option.timestep = TIMESTEP
    spec.option.iterations = SOLVER_ITERATIONS
    spec.option.ls_iterations = LS_ITERATIONS
    spec.option.solver = mujoco.mjtSolver.mjSOL_NEWTON
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL

    model = spec.compile()
    qpos, ctrl = _home(robot, base, model)
    spec.add_key(name=HOME_KEY, qpos=list(qpos), ctrl=list(ctrl))
    return spec


# The scene's textures (as MuJoCo Menagerie's scenes): a gradient sky and the floor's checkers.
_SCENE_TEXTURES = {
    "skybox": {
        "type": mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        "builtin": mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        "rgb1": [0.3, 0.5, 0.7],
        "rgb2": [0, 0, 0],
        "width": 512,
        "height": 3072,
    },
    "groundplane": {
        "type": mujoco.mjtTexture.mjTEXTURE_2D,
        "builtin": mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        "rgb1": [0.2, 0.3, 0.4],
        "rgb2": [0.1, 0.2, 0.3],
        "mark": mujoco.mjtMark.mjMARK_EDGE,
        "markrgb": [0.8, 0.8, 0.8],
        "width": 300,
        "height": 300,
    },
}


def add_scene(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """Add the floor, light, sky and a tracking camera to `spec` (in place) and return it."""
    spec.visual.headlight.active = 1  # on, also where MuJoCo 4's "auto" (its default) turns it off
    spec.visual.headlight.diffuse = [0.6, 0.6, 0.6]
    spec.visual.global_.azimuth = 120
    spec.visual.global_.elevation = -20
    for name, texture in _SCENE_TEXTURES.items():
        spec.add_texture(name=name, **texture)
    mat = spec.add_material(name="groundplane", texrepeat=[5, 5], texuniform=True, reflectance=0.2)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "groundplane"
    world = spec.worldbody
    world.add_light(pos=[0, 0, 1.5], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    world.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 0.05],
        material="groundplane",
        contype=base_model.FLOOR_CONTYPE,
        conaffinity=base_model.FLOOR_CONAFFINITY,
    )
    return spec


def build_spec(arm: str | Arm | RobotSpec, base: Base | None = None) -> mujoco.MjSpec:
    """Robot and scene as one spec, ready to compile or edit (`robot_spec`'s arguments)."""
    return add_scene(robot_spec(arm, base))


def build(arm: str | Arm | RobotSpec, base: Base | None = None) -> mujoco.MjModel:
    """Compile a robot: `arm` a variant's name (`"none"` too), an `ArmSpec`/`UrdfArm` or a
    `RobotSpec`, on `base` (a named base, a file's path or a `BaseSpec`; None: the A1, or the
    RobotSpec's), e.g. `build("regular", base="go2")`."""
    return build_spec(arm, base).compile()


def mount_on(base: BaseSpec, mount: Mount) -> Mount:
    """`mount` (written on the A1's trunk box, as the named variants' are) moved to the same
    place of `base`'s trunk box: each coordinate scaled by the ratio of the boxes' half extents,
    about the box's centre. On a base with the A1's box it is `mount` itself."""
    half, center = base.trunk_half_extents, base.trunk_box_center
    if half == REFERENCE_TRUNK_HALF_EXTENTS and not any(center):
        return mount
    pos = tuple(
        c + p * h / h1 for c, p, h, h1 in zip(center, mount.pos, half, REFERENCE_TRUNK_HALF_EXTENTS)
    )
    return Mount(pos, mount.yaw)


def _home(robot: RobotSpec, base: BaseSpec, model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Home qpos (nq,) and ctrl (nu,): standing legs, arms in their home pose as servo targets."""
    height, leg_q = base_model.home_pose(base)
    joint_q = dict(zip(base.leg_joints, leg_q, strict=True))
    for i, arm in enumerate(robot.arms):
        joint_q.update(arms.home_qpos(arm, arm_prefix(i)))
    qpos = model.qpos0.copy()
    qpos[:7] = [0, 0, height, 1, 0, 0, 0]
    for name, q in joint_q.items():
        qpos[model.joint(name).qposadr[0]] = q
    ctrl = np.zeros(model.nu)
    for a in range(model.nu):
        if model.actuator_biastype[a] != mujoco.mjtBias.mjBIAS_NONE:  # position servo
            ctrl[a] = qpos[model.jnt_qposadr[model.actuator_trnid[a, 0]]]
    return qpos, ctrl
