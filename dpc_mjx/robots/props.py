"""Task scenes: the boxes, tables and balls of the pushing, carrying and lifting tasks (paper §IV).

The robot stands at the origin facing +x (home pose). Builders edit a scene spec from
`assemble.build_spec` in place and return it; `build_task_scene(task, arm)` compiles one task.

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
pulls it into the jaws without a fight against contact forces. Carrying starts with the welds off
(`data.eq_active`, see `set_welds`); lifting starts with the 0.3 kg ball welded in the gripper.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jp
import mujoco
import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots import a1, arms
from dpc_mjx.robots.assemble import arm_prefix, build_spec
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve

# Contact bits (see the table above).
FLOOR_BIT, EE_BIT, TABLE_BIT = a1.FLOOR_CONTYPE, 2, 4
BOX_CONTYPE, BOX_CONAFFINITY = EE_BIT, FLOOR_BIT | TABLE_BIT
BALL_CONTYPE, BALL_CONAFFINITY = 0, FLOOR_BIT | TABLE_BIT
TABLE_CONTYPE, TABLE_CONAFFINITY = TABLE_BIT, 0
EE_CONTYPE, EE_CONAFFINITY = 0, EE_BIT

# Defaults (m, kg). Pushing: a light 0.2 m cardboard box 0.7 m ahead of the trunk.
BOX_HALF = (0.1, 0.1, 0.1)
BOX_MASS = 1.0
BOX_POS = (0.7, 0.0)  # on the floor, world x, y
BOX_FRICTION = 0.5  # box-floor and box-plate (the box has contact priority)
# Carrying: ball from the source table (left, +y) to the target table (right, -y).
TABLE_HEIGHT = 0.3  # top surface above the floor
TABLE_HEIGHT_HIGH = 0.45  # `carrying_high`, for the longer arm
TABLE_HALF = (0.15, 0.15)  # top, half extents in x, y
TABLE_THICKNESS = 0.02
TABLE_POS = ((0.55, 0.3), (0.55, -0.3))  # source, target: top centres, world x, y
BALL_RADIUS = 0.02  # fits between the open jaws (0.044 m apart)
BALL_MASS = 0.1  # carrying
LIFT_BALL_MASS = 0.3  # lifting (the paper's 0.3 kg ball)
BALL_EDGE_INSET = 0.05  # ball centre from the source table's near (-x) edge
BALL_SPACING = 0.12  # between two balls along y (the double arm's mounts are 0.12 apart)
GRASP_OFFSET = (-arms.FINGER_LENGTH / 2, 0.0, 0.0)  # ee-body frame, from the ee site: mid-jaw
BALL_FRICTION = (0.8, 0.005, 0.0005)  # sliding, torsional, rolling (condim 6: balls stop rolling)

_BOX_RGBA, _TABLE_RGBA, _BALL_RGBA = [0.7, 0.5, 0.3, 1], [0.55, 0.45, 0.35, 1], [0.9, 0.2, 0.2, 1]

TASK_ARMS = {  # task -> default arm variant
    "reaching": "regular",
    "pushing": "pusher",
    "carrying": "regular",
    "carrying_high": "longer",
    "lifting": "regular",
}
TASKS = tuple(TASK_ARMS)


def add_box(
    spec: mujoco.MjSpec,
    pos: tuple[float, float] = BOX_POS,
    half: tuple[float, float, float] = BOX_HALF,
    mass: float = BOX_MASS,
    friction: float = BOX_FRICTION,
    name: str = "box",
) -> mujoco.MjSpec:
    """A free box resting on the floor at world (x, y) = `pos`; returns `spec`."""
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
    height: float = TABLE_HEIGHT,
    half: tuple[float, float] = TABLE_HALF,
    name: str = "table0",
) -> mujoco.MjSpec:
    """A static table: a colliding top whose surface is at `height`, and a visual pedestal."""
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
    mass: float = LIFT_BALL_MASS,
    radius: float = BALL_RADIUS,
    name: str = "ball0",
    quat: tuple[float, float, float, float] = (1, 0, 0, 0),
) -> mujoco.MjSpec:
    """A free ball centred at world `pos`, with a site `name` at its centre (the weld target)."""
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
    body.add_site(name=name, size=[0.005, 0, 0], group=a1.VISUAL_GROUP_SITES)
    return spec


def add_tables_and_balls(
    spec: mujoco.MjSpec,
    table_height: float = TABLE_HEIGHT,
    n_balls: int = 1,
    ball_mass: float = BALL_MASS,
    table_pos: tuple[tuple[float, float], ...] = TABLE_POS,
) -> mujoco.MjSpec:
    """Source and target tables (`table0`, `table1`) and `n_balls` (1 or 2) balls on the source."""
    if n_balls not in (1, 2):
        raise DpcError(f"n_balls must be 1 or 2 (one per arm), got {n_balls}.")
    for i, xy in enumerate(table_pos):
        add_table(spec, xy, table_height, name=f"table{i}")
    x = table_pos[0][0] - TABLE_HALF[0] + BALL_EDGE_INSET
    for k in range(n_balls):
        y = table_pos[0][1] + (0.5 - k) * BALL_SPACING * (n_balls - 1)  # ball k near arm k
        add_ball(spec, (x, y, table_height + BALL_RADIUS), ball_mass, name=f"ball{k}")
    return spec


def enable_ee_contacts(spec: mujoco.MjSpec, arm: int = 0) -> mujoco.MjSpec:
    """Let every geom of arm `arm`'s end-effector body and its children touch the box."""
    ee_body = spec.site(arm_prefix(arm) + arms.EE_SITE).parent
    for geom in ee_body.find_all(mujoco.mjtObj.mjOBJ_GEOM):
        geom.contype, geom.conaffinity = EE_CONTYPE, EE_CONAFFINITY
        geom.condim = 3
    return spec


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
        group=a1.VISUAL_GROUP_SITES,
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


def task_spec(task: str, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjSpec:
    """Robot, scene and the objects of `task` (one of `TASKS`) as one spec.

    `arm` defaults to the task's variant in `TASK_ARMS`. The home keyframe holds every object at
    rest (pushing, carrying) or the ball in the gripper (lifting).
    """
    if task not in TASK_ARMS:
        raise DpcError(f"Unknown task {task!r}; known tasks: {sorted(TASK_ARMS)}.")
    robot = resolve(TASK_ARMS[task] if arm is None else arm)
    spec = build_spec(robot)
    spec.modelname = f"a1_{robot.name}_{task}"
    if task == "reaching":
        return spec
    if not robot.arms:
        raise DpcError(f"Task {task!r} needs an arm; variant {robot.name!r} has none.")
    for i in range(len(robot.arms)):
        enable_ee_contacts(spec, i)
    if task == "pushing":
        return add_box(spec)

    offsets = [_grasp_offset(task, robot.name, a) for a in robot.arms]
    if task == "lifting":
        for i, off in enumerate(offsets):
            add_grasp_site(spec, i, off)
        pos, quat = _home_site_poses(spec, [arm_prefix(i) + "grasp" for i in range(len(offsets))])
        for i in range(len(offsets)):
            add_ball(spec, pos[i], LIFT_BALL_MASS, name=f"ball{i}", quat=quat[i])
            add_weld(spec, f"ball{i}", i, active=True)
        return spec

    height = TABLE_HEIGHT_HIGH if task == "carrying_high" else TABLE_HEIGHT
    add_tables_and_balls(spec, height, n_balls=len(robot.arms))
    for i, off in enumerate(offsets):
        add_grasp(spec, f"ball{i}", i, off, active=False)
    return spec


def build_task_scene(task: str, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjModel:
    """Compile `task_spec(task, arm)`."""
    return task_spec(task, arm).compile()


def _grasp_offset(task: str, name: str, arm: Arm) -> tuple[float, float, float]:
    if isinstance(arm, arms.UrdfArm):
        return (0.0, 0.0, 0.0)  # the ball centre at the ee site
    if arm.ee_shape != "gripper":
        raise DpcError(
            f"Task {task!r} grasps a ball; variant {name!r} has a {arm.ee_shape} end effector. "
            "Use a gripper arm, e.g. regular, longer or double."
        )
    return GRASP_OFFSET


def _home_site_poses(spec: mujoco.MjSpec, sites: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """World positions (n, 3) and quaternions (n, 4) of `sites` in the home keyframe."""
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
    """A free body (box or ball) of a task scene."""

    name: str
    body: int
    geom: int
    qpos: np.ndarray  # (7,) qpos addresses: position (3,) m world, then quaternion (4,)
    dof: np.ndarray  # (6,) qvel addresses: linear (3,) m/s world, then angular (3,) rad/s


@dataclasses.dataclass(frozen=True)
class PropLayout:
    """A task scene's object indices (see `prop_layout`); static, safe to close over in jit."""

    box: FreeObject | None
    balls: tuple[FreeObject, ...]
    ball_sites: np.ndarray  # (n_balls,) site ids at the ball centres
    grasp_sites: np.ndarray  # (n_welds,) site ids between each arm's jaws
    welds: np.ndarray  # (n_welds,) equality ids; weld k holds ball k at arm k's grasp site
    table_geoms: np.ndarray  # (n_tables,) geom ids of the table tops: source, target
    table_tops: np.ndarray  # (n_tables, 3) m, world centre of each table's top surface

    @property
    def objects(self) -> tuple[FreeObject, ...]:
        return ((self.box,) if self.box else ()) + self.balls


def prop_layout(model: mujoco.MjModel) -> PropLayout:
    """Indices of the objects in a model from `build_task_scene` (empty for reaching)."""

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
