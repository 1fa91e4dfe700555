"""The pushing task (paper §IV): walk forward and push a free box with the arm.

Scene (`PushingEnv.scene_spec(arm)`): a free 0.2 m, 1 kg cube (`BOX_*`) on the floor 0.7 m
ahead; only the end effector (the `pusher`'s plate, or a gripper's three boxes) touches it. The
default arm is `pusher`, the paper's "heavier but flat" arm (0.5 kg plate); any WidowX-like arm
(`ArmSpec`) can push.

Script: the body walks at a constant command (v_x ~ U(0.15, 0.25) m/s) and stops (command 0) at
`command_switch` ~ U(5, 6) s, when the box is about at its target 1.5 m ahead; the arm moves from
home to a fixed pushing pose during the first `arm_move_time` s (divided by the episode's pace ~
U(`script_rate`)) and holds it, so the plate meets the box after about 1.5 s and pushes it: a steady
contact force on the arm is the disturbance. Each episode draws the box's place (`box_jitter`: x, y,
heading offsets ~ U(-j, j)) and its added weight (`object_mass`), and the end effector gets vertical
pushes (`push_force`; the payload is off). Calibration: docs/results-table-one.md (Table I).

The pushing pose is solved once per env (`scripts.solve_ik`, MuJoCo C): the ee site (the plate's
face centre) `PUSH_REACH` ahead of the trunk at `PUSH_HEIGHT` above the floor, its normal pitched
`PUSH_PITCH` down. A vertical plate cannot go lower than 0.22 m with these arms (shoulder and
wrist limits), above the box's 0.2 m top; pitched 60 deg down, the plate's upper edge leads and
meets the box face at about 0.17 m, below the 0.2 m where a push against floor friction 0.5
would tip the box. For `pusher`: shoulder 1.84, elbow -0.49, wrist -0.31 rad.

On another base the scene moves with the arm's mount (`scripts.mount_offset`: (dx, dz) m, world
frame, x forward, z up, the first arm's mount standing on this base minus on the A1; (0, 0) on
the A1): the push pose is `PUSH_REACH` + dx ahead and `PUSH_HEIGHT` + dz high, and the box,
resting on the floor, grows dz taller (its top 2 * BOX_HALF[2] + dz) and dz deeper, its near
face dx further ahead (`box_geometry`), so that relative to the shoulder the task and its IK pose
are the A1's; the deeper box is what keeps it from tipping (pushed at height c against floor
friction mu, a box of half depth d tips when c > d / mu: on a B1 the plate meets it at 0.41 m).
The goal `push_target` moves with the box's centre.

Metrics (`TASK_MEASURES`, read at the episode's end): `box_dx` (m, the box's displacement
along x since reset), `box_turn` (rad, |change of the box's heading| since reset: a straight push
keeps it) and `box_target_dist` (m, box centre to the target point (`push_target`, 0),
horizontal).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jp
import mujoco
import numpy as np

from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.checks import check_number, check_positive
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.tasks import scripts
from dpc_mjx.errors import DpcError
from dpc_mjx.robots import objects
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve
from dpc_mjx.rotations import roll_pitch_yaw

# The box (m, kg): a light 0.2 m cardboard cube 0.7 m ahead of the trunk.
BOX_HALF = (0.1, 0.1, 0.1)
BOX_MASS = 1.0
BOX_POS = (0.7, 0.0)  # on the floor, world x, y
BOX_FRICTION = 0.5  # box-floor and box-plate (the box has contact priority)
PUSH_REACH = 0.30  # m, ee site ahead of the trunk origin (x, trunk frame)
PUSH_HEIGHT = 0.15  # m, ee site above the floor
PUSH_PITCH = math.radians(60.0)  # plate normal below the horizontal
PUSHES = (0.0, 30.0)  # N, vertical pushes at the end effector ~ U (docs/results-table-one.md)


@dataclasses.dataclass(frozen=True)
class PushingConfig(EnvConfig):
    """`EnvConfig` plus the pushing script."""

    push_target: float = 1.5  # m, world x of the box centre's goal (from 0.7 m); + dx (doc)
    arm_move_time: float = 1.0  # s, home -> pushing pose at the start of the episode
    # the box's place: x, y (m) and heading (rad) offsets from `BOX_POS`, each ~ U(-j, j)
    box_jitter: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def validate(self) -> None:
        super().validate()
        check_number("push_target", self.push_target)
        check_positive("arm_move_time", self.arm_move_time)
        if not (isinstance(self.box_jitter, tuple) and len(self.box_jitter) == 3):
            raise DpcError(f"box_jitter must be an (x, y, heading) tuple, got {self.box_jitter!r}.")
        for v, high in zip(self.box_jitter, (0.1, 0.05, 0.5), strict=True):
            check_number("box_jitter", v, low=0.0, high=high)  # the plate still meets the box


def default_config() -> PushingConfig:
    """Walk at ~0.2 m/s for ~5.5 s then stand (trotting in place); the box placed and weighted
    per episode; vertical end-effector pushes (calibrated: docs/results-table-one.md, Table I)."""
    return PushingConfig(
        command_vx=(0.15, 0.25),
        command_vy=(0.0, 0.0),
        command_yaw=(0.0, 0.0),
        command_switch=(5.0, 6.0),
        command_after=(0.0, 0.0, 0.0),
        push_force=PUSHES,
        push_axis_weights=(0.0, 0.0, 1.0),
        payload_mass=(0.0, 0.0),
        object_mass=(1.0, 4.0),
        script_rate=(0.8, 1.25),
        box_jitter=(0.05, 0.03, 0.2),
        episode_length=500,  # 10 s
    )


def box_geometry(dx: float, dz: float) -> tuple[tuple, tuple]:
    """The box's (x, y) place on the floor (m, world) and half extents (m) on a base whose arm's
    mount stands (dx, dz) from the A1's (module doc): dz taller and dz deeper, its near face dx
    further ahead. (`BOX_POS`, `BOX_HALF`) on the A1."""
    half = (BOX_HALF[0] + dz / 2, BOX_HALF[1], BOX_HALF[2] + dz / 2)
    return (BOX_POS[0] + dx + dz / 2, BOX_POS[1]), half


class PushingEnv(DpcEnv):
    """Pushing: see the module doc."""

    TASK = "pushing"
    DEFAULT_ARM = "pusher"
    TASK_MEASURES = ("box_dx", "box_turn", "box_target_dist")

    def __init__(self, config: PushingConfig, arm: str | Arm | RobotSpec | None = None):
        super().__init__(config, arm)  # sets `self.offset` (`build_model`)
        model, box = self.model, self.props.box
        dx, dz = self.offset
        data = scripts.standing_data(model)
        home = np.asarray(model.key_ctrl[0][self.lay.arm_act], np.float32)
        pose = home.copy()
        cols = np.cumsum([0] + [len(a.act) for a in self.lay.arms])
        for k, arm_ in enumerate(self.lay.arms):
            target = [PUSH_REACH + dx, data.site_xpos[arm_.mount_site][1], PUSH_HEIGHT + dz]
            q = scripts.solve_ik(
                model, data, arm_, arm_.ee_site, target, -math.sin(PUSH_PITCH), what="push pose"
            )
            pose[cols[k] : cols[k + 1]] = q  # a finger (gripper arms) stays at home
        self.script = scripts.Script.through([home, pose], 0.0, config.arm_move_time, 0.0)
        self.pose = pose  # (n_act,) the pushing pose's servo targets
        self._box_qpos = box.qpos  # (7,) x, y, z, quaternion
        self._box_home = np.asarray(model.key_qpos[0][box.qpos], np.float32)

    @classmethod
    def scene_spec(cls, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjSpec:
        """The robot (`arm`; None: `DEFAULT_ARM`) with its end effectors touching the box, and
        the box at rest on the floor (home key), moved and grown by the mount's offset."""
        robot = resolve(cls.DEFAULT_ARM if arm is None else arm)
        spec = objects.robot_scene(robot, cls.TASK)
        dx, dz = scripts.mount_offset(robot)
        scripts.check_height(cls.TASK, robot, "push pose", PUSH_HEIGHT + dz)
        pos, half = box_geometry(dx, dz)
        return objects.add_box(spec, pos, half, BOX_MASS, BOX_FRICTION)

    def build_model(self, arm: str | Arm | RobotSpec) -> mujoco.MjModel:
        """`scene_spec(arm)`; keeps the mount's offset (dx, dz) m as `self.offset`."""
        spec = self.scene_spec(arm)
        self.offset = scripts.mount_offset(resolve(arm))  # cached by `scene_spec`
        return spec.compile()

    @classmethod
    def check_arm(cls, robot: RobotSpec) -> None:
        scripts.check_task_arms(cls.TASK, robot, gripper=False)

    def draw_task(self, key: jax.Array) -> jax.Array:
        """(4,) [script pace, box x offset (m), y offset (m), heading (rad)]."""
        k_rate, k_box = jax.random.split(key)
        j = jp.asarray(self.config.box_jitter)
        box = jax.random.uniform(k_box, (3,), minval=-j, maxval=j)
        return jp.concatenate([scripts.draw_rate(k_rate, self.config)[None], box])

    def place_objects(self, qpos: jax.Array, dist) -> jax.Array:
        dx, dy, heading = dist.task[1], dist.task[2], dist.task[3]
        box = jp.asarray(self._box_home).at[:2].add(jp.stack([dx, dy]))
        box = box.at[3:].set(jp.stack([jp.cos(heading / 2), 0.0, 0.0, jp.sin(heading / 2)]))
        return qpos.at[self._box_qpos].set(box)

    def arm_targets(self, dist, t: jax.Array, d) -> jax.Array:
        del d
        return self.script.targets(scripts.script_time(t, dist))

    def task_metrics(self, d, dist) -> dict[str, jax.Array]:
        box = d.qpos[self._box_qpos]
        shift = box_geometry(*self.offset)[0][0] - BOX_POS[0]  # m, the box centre's, along x
        goal = jp.array([self.config.push_target + shift, 0.0])
        turn = roll_pitch_yaw(box[3:])[2] - dist.task[3]
        return {
            "box_dx": box[0] - self._box_home[0] - dist.task[1],
            "box_turn": jp.abs(jp.arctan2(jp.sin(turn), jp.cos(turn))),
            "box_target_dist": jp.linalg.norm(box[:2] - goal),
        }
