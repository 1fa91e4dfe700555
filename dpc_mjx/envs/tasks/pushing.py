"""The pushing task (paper §IV): walk forward and push a free box with the arm.

Scene (`PushingEnv.scene_spec(arm)`): a free 0.2 m, 1 kg cube (`BOX_*`) on the floor 0.7 m
ahead; only the end effector (the `pusher`'s plate, or a gripper's three boxes) touches it. The
default arm is `pusher`, the paper's "heavier but flat" arm (0.5 kg plate); any WidowX-like arm
(`ArmSpec`) can push.

Script: the body walks at a constant command (v_x 0.2 m/s) and stops (command 0) at
`command_switch` = 5.5 s, when the box is about at its target 1.5 m ahead; the arm moves from
home to a fixed pushing pose during the first `arm_move_time` s and holds it, so the plate meets
the box after about 1.5 s and pushes it: a steady contact force on the arm is the disturbance;
the random end-effector pushes and the payload are off.

The pushing pose is solved once per env (`scripts.solve_ik`, MuJoCo C): the ee site (the plate's
face centre) `PUSH_REACH` ahead of the trunk at `PUSH_HEIGHT` above the floor, its normal pitched
`PUSH_PITCH` down. A vertical plate cannot go lower than 0.22 m with these arms (shoulder and
wrist limits), above the box's 0.2 m top; pitched 60 deg down, the plate's upper edge leads and
meets the box face at about 0.17 m, below the 0.2 m where a push against floor friction 0.5
would tip the box. For `pusher`: shoulder 1.84, elbow -0.49, wrist -0.31 rad.

Metrics: `box_dx` (m, box displacement along x since reset) and `box_target_dist` (m, box centre
to the target point (`push_target`, 0), horizontal).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jp
import mujoco
import numpy as np

from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.config import EnvConfig, _number, _positive
from dpc_mjx.envs.tasks import scripts
from dpc_mjx.robots import objects
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve

# The box (m, kg): a light 0.2 m cardboard cube 0.7 m ahead of the trunk.
BOX_HALF = (0.1, 0.1, 0.1)
BOX_MASS = 1.0
BOX_POS = (0.7, 0.0)  # on the floor, world x, y
BOX_FRICTION = 0.5  # box-floor and box-plate (the box has contact priority)
PUSH_REACH = 0.30  # m, ee site ahead of the trunk origin (x, trunk frame)
PUSH_HEIGHT = 0.15  # m, ee site above the floor
PUSH_PITCH = math.radians(60.0)  # plate normal below the horizontal


@dataclasses.dataclass(frozen=True)
class PushingConfig(EnvConfig):
    """`EnvConfig` plus the pushing script."""

    push_target: float = 1.5  # m, world x of the box centre's goal (it starts at 0.7 m)
    arm_move_time: float = 1.0  # s, home -> pushing pose at the start of the episode

    def validate(self) -> None:
        super().validate()
        _number("push_target", self.push_target)
        _positive("arm_move_time", self.arm_move_time)


def default_config() -> PushingConfig:
    """Walk at 0.2 m/s for 5.5 s then stand (trotting in place); no pushes, no payload."""
    return PushingConfig(
        command_vx=(0.2, 0.2),
        command_vy=(0.0, 0.0),
        command_yaw=(0.0, 0.0),
        command_switch=(5.5, 5.5),
        command_after=(0.0, 0.0, 0.0),
        push_force=(0.0, 0.0),
        payload_mass=(0.0, 0.0),
        episode_length=500,  # 10 s
    )


class PushingEnv(DpcEnv):
    """Pushing: see the module doc."""

    TASK = "pushing"
    DEFAULT_ARM = "pusher"

    def __init__(self, config: PushingConfig, arm: str | Arm | RobotSpec | None = None):
        super().__init__(config, arm)
        model, box = self.model, self.props.box
        data = scripts.standing_data(model)
        home = np.asarray(model.key_ctrl[0][self.lay.arm_act], np.float32)
        pose = home.copy()
        cols = np.cumsum([0] + [len(a.act) for a in self.lay.arms])
        for k, arm_ in enumerate(self.lay.arms):
            target = [PUSH_REACH, data.site_xpos[arm_.mount_site][1], PUSH_HEIGHT]
            q = scripts.solve_ik(
                model, data, arm_, arm_.ee_site, target, -math.sin(PUSH_PITCH), what="push pose"
            )
            pose[cols[k] : cols[k + 1]] = q  # a finger (gripper arms) stays at home
        self.script = scripts.Script.through([home, pose], 0.0, config.arm_move_time, 0.0)
        self.pose = pose  # (n_act,) the pushing pose's servo targets
        self._box_qpos = box.qpos[:2]
        self._box_start = np.asarray(model.key_qpos[0][box.qpos[:2]], np.float32)

    @classmethod
    def scene_spec(cls, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjSpec:
        """The robot (`arm`; None: `DEFAULT_ARM`) with its end effectors touching the box, and
        the box at rest on the floor (home key)."""
        robot = resolve(cls.DEFAULT_ARM if arm is None else arm)
        spec = objects.robot_scene(robot, cls.TASK)
        return objects.add_box(spec, BOX_POS, BOX_HALF, BOX_MASS, BOX_FRICTION)

    def build_model(self, arm: str | Arm | RobotSpec | None) -> mujoco.MjModel:
        return self.scene_spec(arm).compile()

    @classmethod
    def check_arm(cls, robot: RobotSpec) -> None:
        scripts.check_task_arms(cls.TASK, robot, gripper=False)

    def arm_targets(self, dist, t: jax.Array, d) -> jax.Array:
        del dist, d
        return self.script.targets(t)

    def task_metrics(self, d) -> dict[str, jax.Array]:
        xy = d.qpos[self._box_qpos]
        goal = jp.array([self.config.push_target, 0.0])
        return {
            "box_dx": xy[0] - self._box_start[0],
            "box_target_dist": jp.linalg.norm(xy - goal),
        }
