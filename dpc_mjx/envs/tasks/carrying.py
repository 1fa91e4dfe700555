"""The carrying task (paper §IV): move a ball from one table to another with the arm while the
body keeps steady; `carrying_high` uses 0.45 m tables (default arm `longer`), and the `double`
arm carries two balls, one per arm.

Scene (`CarryingEnv.scene_spec(arm)`, `add_tables_and_balls`): source table at (0.55, 0.3) m
(+y, left), target table at (0.55, -0.3) m, top surface 0.30 m (0.45 m high), one 0.1 kg ball
per arm on the source table. Gripper arms only (`ArmSpec` with `ee_shape="gripper"`).
The regular arm cannot reach the ball from the origin (0.47 m from the shoulder, 0.42 m reach),
so the robot starts `robot_x` = 0.15 m closer to the tables (its feet do not touch them).

Script (joint space, `scripts.Script`): after `start_time` s, moves of `move_time` s each followed
by `hold_time` s, through

    home -> above the ball (+6 cm) -> at the ball -> close (finger shut, weld on) -> lift (+10 cm)
    -> swing the waist over the target table -> lower (ball 1 cm above its rest height)
    -> release (weld off, finger open) -> retreat (+6 cm) -> home

The waypoints are solved once per env (`scripts.solve_ik`, MuJoCo C) for the grasp site (between
the jaws), gripper pitched about 45 deg down, robot standing level at `scripts.STAND_HEIGHT`;
ball k goes from its place on the source table to the same place on the target table
(translated by -0.6 m in y), so the two arms of `double` never cross.

Each episode runs the script at its own pace (script time = rate x time, rate ~
U(`script_rate`)) and adds its own weight to each ball (`object_mass`); the body stands (trot in
place, command 0) and the end effectors get vertical pushes (`push_force`; no payload).
Calibration: docs/results-table-one.md (Table I).

On another base the scene moves with the arm's mount (`scripts.mount_offset`: (dx, dz) m, world
frame, x forward, z up, the first arm's mount standing on this base minus on the A1; (0, 0) on
the A1): both tables, and the balls on them, move dx along x, and their tops rise dz (the tables
grow dz taller), while `robot_x` (the trunk's place) stays; relative to the shoulder the scene and
every waypoint's IK solution are the A1's.

Grasp: a weld, not friction (see `robots.objects`). During the close move and its hold, weld k
switches on as soon as the grasp site is within `grasp_threshold` of ball k
(`objects.grasp_gaps`), and stays on until the release move starts (`task_physics`, every
physics step, via `objects.set_welds`).

Metrics (`TASK_MEASURES`, read at the episode's end): `ball_on_target` (fraction of balls
resting on the target table, weld off: delivered), `ball_target_dist` (m, mean over balls of ball
centre to its rest point on the target table); per step also `grasped` (fraction of welds on).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np

from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.checks import check_number, check_positive
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.disturbances import NEVER
from dpc_mjx.envs.tasks import scripts
from dpc_mjx.errors import DpcError
from dpc_mjx.robots import objects
from dpc_mjx.robots.assemble import HOME_KEY
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve

# Scene (m, kg): a ball from the source table (left, +y) to the target table (right, -y).
TABLE_HEIGHT = 0.3  # top surface above the floor
TABLE_HEIGHT_HIGH = 0.45  # `carrying_high`, for the longer arm
TABLE_HALF = (0.15, 0.15)  # top, half extents in x, y
TABLE_POS = ((0.55, 0.3), (0.55, -0.3))  # source, target: top centres, world x, y
BALL_MASS = 0.1  # kg, per ball
BALL_EDGE_INSET = 0.05  # ball centre from the source table's near (-x) edge
BALL_SPACING = 0.12  # between two balls along y (the double arm's mounts are 0.12 apart)
# Script:
APPROACH_HEIGHT = 0.06  # m, grasp site above the ball before grasping and after releasing
LIFT_HEIGHT = 0.10  # m, ball above its rest height while carried
PLACE_CLEARANCE = 0.01  # m, ball above its rest height when released
APPROACH_Z = -0.7  # world z of the gripper's approach axis (about 45 deg down), soft
FINGER_CLOSED = 0.004  # m: jaws 0.044 - 0.004 = 0.04 m apart, the ball's diameter
REST_TOL = 0.01  # m, ball centre from its rest height on the target table for `ball_on_target`
PUSHES = (0.0, 15.0)  # N, vertical pushes at the end effector ~ U (docs/results-table-one.md)
# Move indices of the script (see the module doc).
_CLOSE, _LIFT, _RELEASE = 2, 3, 6


@dataclasses.dataclass(frozen=True)
class CarryingConfig(EnvConfig):
    """`EnvConfig` plus the carrying script."""

    grasp_threshold: float = 0.03  # m, grasp site to ball centre to switch the weld on
    robot_x: float = 0.15  # m, world x of the trunk at reset (tables span x 0.40-0.70, + dx)
    start_time: float = 0.5  # s standing before the first move
    move_time: float = 1.0  # s per move
    hold_time: float = 0.25  # s pause after each move

    def validate(self) -> None:
        super().validate()
        check_number("robot_x", self.robot_x, low=-0.5, high=0.3)
        check_number("start_time", self.start_time, low=0.0)
        check_number("hold_time", self.hold_time, low=0.0)
        for name in ("grasp_threshold", "move_time"):
            check_positive(name, getattr(self, name))


def default_config() -> CarryingConfig:
    """Stand (trot in place, command 0) while the arm carries at its episode's pace, the balls
    weighted per episode, vertical end-effector pushes (calibrated: docs/results-table-one.md, Table
    I); no payload; 13 s."""
    return CarryingConfig(
        command_vx=(0.0, 0.0),
        command_vy=(0.0, 0.0),
        command_yaw=(0.0, 0.0),
        command_switch=(NEVER, NEVER),
        push_force=PUSHES,
        push_axis_weights=(0.0, 0.0, 1.0),
        payload_mass=(0.0, 0.0),
        object_mass=(0.3, 1.0),
        script_rate=(0.9, 1.1),
        episode_length=650,
    )


class CarryingEnv(DpcEnv):
    """Carrying: see the module doc."""

    TASK = "carrying"
    DEFAULT_ARM = "regular"
    TASK_MEASURES = ("ball_on_target", "ball_target_dist")
    TABLE_HEIGHT = TABLE_HEIGHT  # m, top surface above the floor (the module's 0.3)

    def __init__(self, config: CarryingConfig, arm: str | Arm | RobotSpec | None = None):
        super().__init__(config, arm)
        model, p = self.model, self.props
        shift = p.table_tops[1] - p.table_tops[0]  # source -> target table
        rest = np.array([model.key_qpos[0][b.qpos[:3]] for b in p.balls])  # (k, 3) m
        self.place = (rest + shift).astype(np.float32)  # (k, 3) rest points on the target
        data = scripts.standing_data(model, config.robot_x)
        home = np.asarray(model.key_ctrl[0][self.lay.arm_act], np.float32)
        per_arm = [self._waypoints(data, k, rest[k], self.place[k]) for k in range(len(p.balls))]
        waypoints = [home] + [np.concatenate(w) for w in zip(*per_arm, strict=True)] + [home]
        self.script = scripts.Script.through(
            waypoints, config.start_time, config.move_time, config.hold_time
        )
        # s: the grasp window [t_close, t_lift) and the release (weld off from t_release)
        self.t_close = float(self.script.start[_CLOSE])
        self.t_lift = float(self.script.start[_LIFT])
        self.t_release = float(self.script.start[_RELEASE])
        self._ball_qpos = np.array([b.qpos[:3] for b in p.balls])  # (k, 3)
        self._target_lo = p.table_tops[1, :2] - TABLE_HALF  # (2,) m, target top, x-y box
        self._target_hi = p.table_tops[1, :2] + TABLE_HALF

    def _waypoints(self, data, k: int, ball: np.ndarray, place: np.ndarray) -> list[np.ndarray]:
        """Servo targets of arm k at the 8 waypoints between home and home (see the module doc)."""
        arm, site = self.lay.arms[k], int(self.props.grasp_sites[k])
        up = np.array([0.0, 0.0, 1.0])
        poses = []
        for name, pos in (
            ("pre-grasp", ball + APPROACH_HEIGHT * up),
            ("grasp", ball),
            ("lift", ball + LIFT_HEIGHT * up),
            ("carry", place + LIFT_HEIGHT * up),
            ("place", place + PLACE_CLEARANCE * up),
            ("retreat", place + APPROACH_HEIGHT * up),
        ):
            poses.append(scripts.solve_ik(self.model, data, arm, site, pos, APPROACH_Z, what=name))
        finger = np.zeros(len(arm.act), np.float32)
        finger[-1] = FINGER_CLOSED  # the gripper is the arm's last joint
        pre, grasp, lift, carry, place_, retreat = poses
        return [
            pre,
            grasp,
            grasp + finger,
            lift + finger,
            carry + finger,
            place_ + finger,
            place_,
            retreat,
        ]

    @classmethod
    def scene_spec(cls, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjSpec:
        """The robot (`arm`; None: `DEFAULT_ARM`) at the origin, the tables `TABLE_HEIGHT` high,
        ball k on the source table and weld k (off) from it to arm k's grasp site; the tables
        moved by the mount's offset (module doc)."""
        robot = resolve(cls.DEFAULT_ARM if arm is None else arm)
        spec = objects.robot_scene(robot, cls.TASK)
        offsets = [objects.grasp_offset(a, robot.name, cls.TASK) for a in robot.arms]
        dx, dz = scripts.mount_offset(robot)
        height = scripts.check_height(cls.TASK, robot, "table top", cls.TABLE_HEIGHT + dz)
        tables = tuple((x + dx, y) for x, y in TABLE_POS)
        add_tables_and_balls(spec, height, n_balls=len(robot.arms), table_pos=tables)
        for i, off in enumerate(offsets):
            objects.add_grasp(spec, f"ball{i}", i, off, active=False)
        return spec

    def build_model(self, arm: str | Arm | RobotSpec | None) -> mujoco.MjModel:
        """`scene_spec(arm)` with the trunk at x = `config.robot_x` in the home key."""
        spec = self.scene_spec(arm)
        key = spec.key(HOME_KEY)
        qpos = list(key.qpos)
        qpos[0] = self.config.robot_x  # the trunk's x
        key.qpos = qpos
        return spec.compile()

    @classmethod
    def check_arm(cls, robot: RobotSpec) -> None:
        scripts.check_task_arms(cls.TASK, robot, gripper=True)

    def draw_task(self, key: jax.Array) -> jax.Array:
        """(1,) [script pace]."""
        return scripts.draw_rate(key, self.config)[None]

    def arm_targets(self, dist, t: jax.Array, d) -> jax.Array:
        del d
        return self.script.targets(scripts.script_time(t, dist))

    def task_physics(self, d, t: jax.Array, dist):
        ts = scripts.script_time(t, dist)
        gaps = objects.grasp_gaps(d, self.props)  # (k,) m
        window = (ts >= self.t_close) & (ts < self.t_lift)
        held = d.eq_active[self.props.welds] | (window & (gaps < self.config.grasp_threshold))
        return objects.set_welds(d, self.props, held & (ts < self.t_release))

    def task_metrics(self, d, dist) -> dict[str, jax.Array]:
        del dist
        balls = d.qpos[self._ball_qpos]  # (k, 3) m
        held = d.eq_active[self.props.welds]
        inside = jp.all((balls[:, :2] >= self._target_lo) & (balls[:, :2] <= self._target_hi), 1)
        resting = jp.abs(balls[:, 2] - self.place[:, 2]) < REST_TOL
        return {
            "ball_target_dist": jp.mean(jp.linalg.norm(balls - self.place, axis=1)),
            "ball_on_target": jp.mean(inside & resting & ~held),
            "grasped": jp.mean(held.astype(jp.float32)),
        }


class CarryingHighEnv(CarryingEnv):
    """Carrying between 0.45 m tables (`TABLE_HEIGHT_HIGH`); default arm `longer`."""

    TASK = "carrying_high"
    DEFAULT_ARM = "longer"
    TABLE_HEIGHT = TABLE_HEIGHT_HIGH


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
        objects.add_table(spec, xy, table_height, TABLE_HALF, name=f"table{i}")
    x = table_pos[0][0] - TABLE_HALF[0] + BALL_EDGE_INSET
    for k in range(n_balls):
        y = table_pos[0][1] + (0.5 - k) * BALL_SPACING * (n_balls - 1)  # ball k near arm k
        pos = (x, y, table_height + objects.BALL_RADIUS)
        objects.add_ball(spec, pos, ball_mass, name=f"ball{k}")
    return spec
