"""Objects for scenes around the robot: free boxes and balls, static tables, weld grasps, and the
object indices (`prop_layout`) the envs close over. It knows no tasks: each task
(`dpc_mjx.envs.tasks`) places these objects with its own sizes, masses and positions.

The robot stands at the origin facing +x (home pose). Builders edit a scene spec (from
`robot_scene` or `assemble.build_spec`) in place and return it.

Objects are real MJX bodies. Contacts stay sparse with these bit masks (a pair collides if
`contype1 & conaffinity2` or `contype2 & conaffinity1`):

    geom                         contype  conaffinity  touches
    floor                           1         0        feet, box, balls
    feet                            0         1        floor
    box                             2         5        floor, table tops, end effectors
    balls                           0         5        floor, table tops
    table tops                      4         0        box, balls
    end effectors (gripper, plate)  0         2        box
    everything else (trunk, legs,   0         0        nothing
    arm links, table pedestals)

Balls are carried by a weld equality (grasp site of arm k <-> centre of ball k), not by
friction in the gripper: the gripper does not touch balls, so switching the weld on near a ball
pulls it into the jaws without a fight against contact forces. A weld starts off or on
(`add_weld(active=...)`); envs switch it in `data.eq_active` with `set_welds`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jp
import mujoco
import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots import arms
from dpc_mjx.robots.arms.mount import arm_prefix
from dpc_mjx.robots.arms.parametric import FINGER_LENGTH
from dpc_mjx.robots.assemble import build_spec
from dpc_mjx.robots.bases import model as base_model
from dpc_mjx.robots.urdf import VISUAL_GROUP_SITES
from dpc_mjx.robots.variants import Arm, RobotSpec

# Contact bits (see the table above).
FLOOR_BIT, EE_BIT, TABLE_BIT = base_model.FLOOR_CONTYPE, 2, 4
BOX_CONTYPE, BOX_CONAFFINITY = EE_BIT, FLOOR_BIT | TABLE_BIT
BALL_CONTYPE, BALL_CONAFFINITY = 0, FLOOR_BIT | TABLE_BIT
TABLE_CONTYPE, TABLE_CONAFFINITY = TABLE_BIT, 0
EE_CONTYPE, EE_CONAFFINITY = 0, EE_BIT

# Defaults that come from the gripper or the builders, not from a task (m).
BALL_RADIUS = 0.02  # fits between the open jaws (0.044 m apart)
BALL_FRICTION = (0.8, 0.005, 0.0005)  # sliding, torsional, rolling (condim 6: balls stop rolling)
GRASP_OFFSET = (-FINGER_LENGTH / 2, 0.0, 0.0)  # ee-body frame, from the ee site: mid-jaw
TABLE_THICKNESS = 0.02  # of a table's top

_BOX_RGBA, _TABLE_RGBA, _BALL_RGBA = [0.7, 0.5, 0.3, 1], [0.55, 0.45, 0.35, 1], [0.9, 0.2, 0.2, 1]


def robot_scene(robot: RobotSpec, scene: str) -> mujoco.MjSpec:
    """The spec of `robot` on the floor, named `<base>_<variant>_<scene>`, with every end effector
    touching boxes (`enable_ee_contacts`); raises `DpcError` if `robot` has no arm."""
    spec = build_spec(robot)
    spec.modelname = f"{spec.modelname}_{scene}"  # `assemble`'s <base>_<variant>
    if not robot.arms:
        raise DpcError(f"Task {scene!r} needs an arm; variant {robot.name!r} has none.")
    for i in range(len(robot.arms)):
        enable_ee_contacts(spec, i)
    return spec


def add_box(
    spec: mujoco.MjSpec,
    pos: tuple[float, float],
    half: tuple[float, float, float],
    mass: float,
    friction: float,
    name: str = "box",
) -> mujoco.MjSpec:
    """A free box of half extents `half` (m) and `mass` (kg) resting on the floor at world
    (x, y) = `pos`; its sliding `friction` wins against the floor's and the plate's. Returns
    `spec`."""
    body = spec.worldbody.add_body(name=name, pos=[pos[0], pos[1], half[2]])
    body.add_freejoint(name=name)
    body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(half),
        mass=mass,
        rgba=_BOX_RGBA,
        contype=BOX_CONTYPE,
        conaffinity=BOX_CONAFFINITY,
        condim=3,
        friction=[friction, 0.005, 0.0001],
        priority=1,  # its friction wins against the floor's and the plate's
    )
    return spec


def add_table(
    spec: mujoco.MjSpec,
    pos: tuple[float, float],
    height: float,
    half: tuple[float, float],
    name: str = "table0",
) -> mujoco.MjSpec:
    """A static table at world (x, y) = `pos`: a colliding top of half extents `half` (m, x, y)
    whose surface is at `height` (m), and a visual pedestal; returns `spec`."""
    world = spec.worldbody
    world.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[half[0], half[1], TABLE_THICKNESS / 2],
        pos=[pos[0], pos[1], height - TABLE_THICKNESS / 2],
        rgba=_TABLE_RGBA,
        contype=TABLE_CONTYPE,
        conaffinity=TABLE_CONAFFINITY,
        condim=3,
    )
    leg = (height - TABLE_THICKNESS) / 2
    world.add_geom(
        name=f"{name}_pedestal",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.03, 0.03, leg],
        pos=[pos[0], pos[1], leg],
        rgba=_TABLE_RGBA,
        contype=0,
        conaffinity=0,
    )
    return spec


def add_ball(
    spec: mujoco.MjSpec,
    pos: tuple[float, float, float],
    mass: float,
    radius: float = BALL_RADIUS,
    name: str = "ball0",
    quat: tuple[float, float, float, float] = (1, 0, 0, 0),
) -> mujoco.MjSpec:
    """A free ball of `mass` (kg) centred at world `pos` (m), with a site `name` at its centre
    (the weld target); returns `spec`."""
    body = spec.worldbody.add_body(name=name, pos=list(pos), quat=list(quat))
    body.add_freejoint(name=name)
    body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[radius, 0, 0],
        mass=mass,
        rgba=_BALL_RGBA,
        contype=BALL_CONTYPE,
        conaffinity=BALL_CONAFFINITY,
        condim=6,
        friction=list(BALL_FRICTION),
    )
    body.add_site(name=name, size=[0.005, 0, 0], group=VISUAL_GROUP_SITES)
    return spec


def enable_ee_contacts(spec: mujoco.MjSpec, arm: int = 0) -> mujoco.MjSpec:
    """Let every geom of arm `arm`'s end-effector body and its children touch the box."""
    ee_body = spec.site(arm_prefix(arm) + arms.EE_SITE).parent
    for geom in ee_body.find_all(mujoco.mjtObj.mjOBJ_GEOM):
        geom.contype, geom.conaffinity = EE_CONTYPE, EE_CONAFFINITY
        geom.condim = 3
    return spec


def grasp_offset(arm: Arm, variant: str, task: str) -> tuple[float, float, float]:
    """The grasp site's offset (m, ee-body frame) from arm `arm`'s ee site: mid-jaw for a gripper
    (`GRASP_OFFSET`), the ee site itself for a URDF arm. Raises `DpcError` for other end
    effectors (`variant` and `task` name the caller in the message)."""
    if isinstance(arm, arms.UrdfArm):
        return (0.0, 0.0, 0.0)  # the ball centre at the ee site
    if arm.ee_shape != "gripper":
        raise DpcError(
            f"Task {task!r} grasps a ball; variant {variant!r} has a {arm.ee_shape} end effector. "
            "Use a gripper arm, e.g. regular, longer or double."
        )
    return GRASP_OFFSET


def add_grasp(
    spec: mujoco.MjSpec,
    ball: str,
    arm: int = 0,
    offset: tuple[float, float, float] = GRASP_OFFSET,
    active: bool = False,
) -> mujoco.MjSpec:
    """A grasp site on arm `arm`'s end effector and a weld `grasp<arm>` of the site `ball` to it.

    See `add_grasp_site` and `add_weld`.
    """
    return add_weld(add_grasp_site(spec, arm, offset), ball, arm, active)


def add_grasp_site(
    spec: mujoco.MjSpec,
    arm: int = 0,
    offset: tuple[float, float, float] = GRASP_OFFSET,
) -> mujoco.MjSpec:
    """Site `arm<i>/grasp` on the end-effector body, `offset` (m, ee-body frame) from the ee site;
    the default is between the gripper's jaws."""
    ee = spec.site(arm_prefix(arm) + arms.EE_SITE)
    ee.parent.add_site(
        name=arm_prefix(arm) + "grasp",
        pos=list(np.asarray(ee.pos) + offset),
        size=[0.005, 0, 0],
        group=VISUAL_GROUP_SITES,
    )
    return spec


def add_weld(spec: mujoco.MjSpec, ball: str, arm: int = 0, active: bool = False) -> mujoco.MjSpec:
    """Weld `grasp<arm>` between arm `arm`'s grasp site and the site `ball` (the ball's centre).

    A site weld holds the two site frames together (position and orientation; MuJoCo ignores
    relpose for site welds), so switching it on pulls the ball's centre to the grasp site.
    """
    spec.add_equality(
        name=f"grasp{arm}",
        type=mujoco.mjtEq.mjEQ_WELD,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        name1=arm_prefix(arm) + "grasp",
        name2=ball,
        active=active,
    )
    return spec


def home_site_poses(spec: mujoco.MjSpec, sites: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """World positions (n, 3) m and quaternions (n, 4) of `sites` in the home keyframe (compiles
    a copy of the scene so far; `spec` is unchanged)."""
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_kinematics(model, data)
    ids = [model.site(s).id for s in sites]
    quats = np.zeros((len(ids), 4))
    for k, i in enumerate(ids):
        mujoco.mju_mat2Quat(quats[k], data.site_xmat[i])
    return data.site_xpos[ids].copy(), quats


# --- indices for the envs ----------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class FreeObject:
    """A free body (box or ball) of a scene."""

    name: str
    body: int
    geom: int
    qpos: np.ndarray  # (7,) qpos addresses: position (3,) m world, then quaternion (4,)
    dof: np.ndarray  # (6,) qvel addresses: linear (3,) m/s world, then angular (3,) rad/s


@dataclasses.dataclass(frozen=True)
class PropLayout:
    """A scene's object indices (see `prop_layout`); static, safe to close over in jit."""

    box: FreeObject | None
    balls: tuple[FreeObject, ...]
    ball_sites: np.ndarray  # (n_balls,) site ids at the ball centres
    grasp_sites: np.ndarray  # (n_welds,) site ids between each arm's jaws
    welds: np.ndarray  # (n_welds,) equality ids; weld k holds ball k at arm k's grasp site
    table_geoms: np.ndarray  # (n_tables,) geom ids of the table tops, in name order
    table_tops: np.ndarray  # (n_tables, 3) m, world centre of each table's top surface

    @property
    def objects(self) -> tuple[FreeObject, ...]:
        return ((self.box,) if self.box else ()) + self.balls


def prop_layout(model: mujoco.MjModel) -> PropLayout:
    """Indices of the objects these builders named in `model` (`box`, `ball<k>`, `grasp<k>`,
    `table<k>`); empty for a scene without objects."""

    def find(kind: mujoco.mjtObj, name: str) -> int:
        return mujoco.mj_name2id(model, kind, name)

    def free(name: str) -> FreeObject | None:
        body = find(mujoco.mjtObj.mjOBJ_BODY, name)
        if body < 0:
            return None
        joint = model.body_jntadr[body]
        if model.body_jntnum[body] != 1 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
            raise DpcError(f"Body {name!r} is not a free object of a task scene.")
        q, v = model.jnt_qposadr[joint], model.jnt_dofadr[joint]
        return FreeObject(
            name,
            body,
            find(mujoco.mjtObj.mjOBJ_GEOM, name),
            np.arange(q, q + 7),
            np.arange(v, v + 6),
        )

    balls, welds, grasps, tables = [], [], [], []
    while (ball := free(f"ball{len(balls)}")) is not None:
        balls.append(ball)
    while (eq := find(mujoco.mjtObj.mjOBJ_EQUALITY, f"grasp{len(welds)}")) >= 0:
        welds.append(eq)
        grasps.append(find(mujoco.mjtObj.mjOBJ_SITE, arm_prefix(len(grasps)) + "grasp"))
    while (geom := find(mujoco.mjtObj.mjOBJ_GEOM, f"table{len(tables)}")) >= 0:
        tables.append(geom)
    tables = np.array(tables, int)
    tops = model.geom_pos[tables] + np.array([0.0, 0.0, 1.0]) * model.geom_size[tables, 2:3]
    return PropLayout(
        box=free("box"),
        balls=tuple(balls),
        ball_sites=np.array([find(mujoco.mjtObj.mjOBJ_SITE, b.name) for b in balls], int),
        grasp_sites=np.array(grasps, int),
        welds=np.array(welds, int),
        table_geoms=tables,
        table_tops=tops.reshape(-1, 3),
    )


def set_welds(data, props: PropLayout, active):
    """`data` (mjx.Data) with weld k switched on where `active[k]` (n_welds,) bool. Jit-safe."""
    return data.replace(eq_active=data.eq_active.at[props.welds].set(jp.asarray(active, bool)))


def grasp_gaps(data, props: PropLayout):
    """(n_welds,) m from each grasp site to its ball's centre (switch the weld on when small)."""
    gap = data.site_xpos[props.grasp_sites] - data.site_xpos[props.ball_sites[: len(props.welds)]]
    return jp.linalg.norm(gap, axis=-1)
