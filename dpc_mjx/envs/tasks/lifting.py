"""The ball-lifting task (paper §IV, Fig. "ball lifting"): walk a desired trajectory while the arm
lifts a 0.3 kg ball up and down.

Scene (`LiftingEnv.scene_spec(arm)`): one 0.3 kg ball (`BALL_MASS`) per arm, welded between the
jaws from the start (the weld stays on; the finger is shut on it). Gripper arms only.

Script: the body walks at v_x ~ U(0.2, 0.4) m/s, and at `command_switch` ~ U(8, 12) s starts
turning at 0.3 rad/s (`command_after`, v_x 0.3 m/s), so the desired trajectory is a straight line
then an arc. The arm repeats home -> raised -> home with period 2 (`move_time` + `hold_time`) =
4 s of script time from t = 0: up in 1 s, hold 1 s, down in 1 s, hold 1 s; script time runs at
the episode's pace (rate ~ U(`script_rate`)) and each lift goes a fraction ~ U(`lift_gain`) of
the way to the raised pose. The raised pose puts the grasp site `RAISE` (m, trunk frame) from its
home position with the gripper level, solved once per env (`scripts.solve_ik`); for the regular
arm shoulder 0.06, elbow -1.09, wrist 1.03 rad (the ball goes 12 cm up, 6 cm back). Each episode
adds its own weight to the ball (`object_mass`); vertical end-effector pushes (`push_force`); no
payload (the ball is real). Calibration: docs/results-table-one.md (Table I).

On another base the scene moves with the arm's mount by construction: the ball sits at the grasp
site in the home key, `RAISE` is relative to the grasp site's standing position, and the
trajectory is commanded velocities, so nothing in the scene or the script is absolute, and the
mount's offset (`scripts.mount_offset`: (dx, dz) m, world frame, x forward, z up; (0, 0) on the
A1) is never added: relative to the shoulder the ball and the raised pose's IK are the A1's.

Metrics: `ball_gap` (m, largest distance from a grasp site to its ball's centre: the weld's
slack); the task's success measures are the env's own `pos_sq_err` (the body's distance from the
desired path: the paper's trajectory tracking) and `ee_sq_err` (`TASK_MEASURES` is empty).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np

from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.checks import check_number, check_positive, check_range
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.tasks import scripts
from dpc_mjx.envs.tasks.carrying import FINGER_CLOSED
from dpc_mjx.errors import DpcError
from dpc_mjx.robots import objects
from dpc_mjx.robots.arms.mount import arm_prefix
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve

BALL_MASS = 0.3  # kg, the paper's ball
RAISE = np.array([-0.06, 0.0, 0.12])  # m, grasp site raised pose minus home pose
PUSHES = (0.0, 30.0)  # N, vertical pushes at the end effector ~ U (docs/results-table-one.md)


@dataclasses.dataclass(frozen=True)
class LiftingConfig(EnvConfig):
    """`EnvConfig` plus the lifting script."""

    move_time: float = 1.0  # s, home -> raised and back
    hold_time: float = 1.0  # s at each end
    lift_gain: tuple[float, float] = (1.0, 1.0)  # fraction of the raise per episode ~ U

    def validate(self) -> None:
        super().validate()
        check_positive("move_time", self.move_time)
        check_number("hold_time", self.hold_time, low=0.0)
        check_range("lift_gain", self.lift_gain, low=0.0)
        if self.lift_gain[1] > 1.5:
            raise DpcError(f"lift_gain must stay <= 1.5 (joint ranges), got {self.lift_gain!r}.")


def default_config() -> LiftingConfig:
    """v_x ~ 0.3 m/s, turning at 0.3 rad/s from ~10 s; the lift's pace and height and the
    ball's weight per episode; vertical end-effector pushes (calibrated: docs/results-table-one.md,
    Table I); no payload."""
    return LiftingConfig(
        command_vx=(0.2, 0.4),
        command_vy=(0.0, 0.0),
        command_yaw=(0.0, 0.0),
        command_switch=(8.0, 12.0),
        command_after=(0.3, 0.0, 0.3),
        push_force=PUSHES,
        push_axis_weights=(0.0, 0.0, 1.0),
        payload_mass=(0.0, 0.0),
        object_mass=(0.5, 2.0),
        script_rate=(0.8, 1.25),
        lift_gain=(0.7, 1.0),
    )


class LiftingEnv(DpcEnv):
    """Lifting: see the module doc."""

    TASK = "lifting"
    DEFAULT_ARM = "regular"

    def __init__(self, config: LiftingConfig, arm: str | Arm | RobotSpec | None = None):
        super().__init__(config, arm)
        model = self.model
        data = scripts.standing_data(model)
        home = np.asarray(model.key_ctrl[0][self.lay.arm_act], np.float32)
        ends = np.cumsum([len(a.act) for a in self.lay.arms])  # each arm's columns end here
        closed = home.copy()
        closed[ends - 1] = FINGER_CLOSED  # the gripper is each arm's last joint
        raised = closed.copy()
        for k, arm_ in enumerate(self.lay.arms):
            site = int(self.props.grasp_sites[k])
            target = data.site_xpos[site] + RAISE
            q = scripts.solve_ik(model, data, arm_, site, target, 0.0, what="raised pose")
            raised[ends[k] - len(arm_.act) : ends[k] - 1] = q[:-1]
        self.script = scripts.Script.through(
            [closed, raised, closed], 0.0, config.move_time, config.hold_time
        )
        self.period = 2 * (config.move_time + config.hold_time)  # s

    @classmethod
    def scene_spec(cls, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjSpec:
        """The robot (`arm`; None: `DEFAULT_ARM`), ball k centred on arm k's grasp site in the
        home key (oriented with it) and weld k on."""
        robot = resolve(cls.DEFAULT_ARM if arm is None else arm)
        spec = objects.robot_scene(robot, cls.TASK)
        n = len(robot.arms)
        for i, arm_ in enumerate(robot.arms):
            objects.add_grasp_site(spec, i, objects.grasp_offset(arm_, robot.name, cls.TASK))
        pos, quat = objects.home_site_poses(spec, [arm_prefix(i) + "grasp" for i in range(n)])
        for i in range(n):
            objects.add_ball(spec, pos[i], BALL_MASS, name=f"ball{i}", quat=quat[i])
            objects.add_weld(spec, f"ball{i}", i, active=True)
        return spec

    def build_model(self, arm: str | Arm | RobotSpec | None) -> mujoco.MjModel:
        return self.scene_spec(arm).compile()

    @classmethod
    def check_arm(cls, robot: RobotSpec) -> None:
        scripts.check_task_arms(cls.TASK, robot, gripper=True)

    def draw_task(self, key: jax.Array) -> jax.Array:
        """(2,) [script pace, lift gain]."""
        k_rate, k_gain = jax.random.split(key)
        low, high = self.config.lift_gain
        gain = jax.random.uniform(k_gain, (), minval=low, maxval=high)
        return jp.stack([scripts.draw_rate(k_rate, self.config), gain])

    def arm_targets(self, dist, t: jax.Array, d) -> jax.Array:
        del d
        ts = scripts.script_time(t, dist)
        return self.script.targets(jp.mod(ts, self.period), dist.task[1])

    def task_metrics(self, d, dist) -> dict[str, jax.Array]:
        del dist
        return {"ball_gap": jp.max(objects.grasp_gaps(d, self.props))}
