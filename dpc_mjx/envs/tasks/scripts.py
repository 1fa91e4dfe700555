"""Scripted arm motions of the object tasks: joint-space waypoints joined by smooth steps, and the
small inverse kinematics that finds the waypoints once per env (MuJoCo C, in `__init__`).

A `Script` is a sequence of moves: move i starts at `start[i]` s, lasts `duration[i]` s and
changes the servo targets by `delta[i]` along the smooth step 3x^2 - 2x^3, so

    p_arm(t) = q_0 + sum_i delta_i * smooth((t - start_i) / duration_i)   (x clipped to [0, 1])

which is continuous, with zero velocity at each waypoint, and jit-friendly (no search).

`solve_ik` is damped least squares on `mujoco.mj_jacSite` over one arm's hinge joints: a site
to a world position and, optionally, the world z-component of the site's x axis (its pitch; the
approach axis of the WidowX-like gripper and the normal of the pusher's plate). The robot is
posed as it stands under the controller (`standing_data`): trunk level at `stand_height`, the
A1's `STAND_HEIGHT` times the base's home height over the A1's (the controller's desired height
scales so: `control.base_scaling`).

The tasks' scenes are drawn for the A1 and move with the arm's mount on another base:
`mount_offset(robot)` is (dx, dz) (m, world frame, x forward, z up), the first arm's mount
standing on `robot`'s base minus the same arm's mount standing on the A1 (exactly (0, 0) on the
A1), and each task adds it to its object and target positions and heights, so that relative to
the arm's shoulder every scene, and every IK solution, is the A1's.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jp
import mujoco
import numpy as np

from dpc_mjx.control.base_scaling import model_scale
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.errors import DpcError
from dpc_mjx.robots import build
from dpc_mjx.robots.arms import ArmSpec
from dpc_mjx.robots.layout import ArmLayout, layout
from dpc_mjx.robots.variants import RobotSpec

# Trunk height (m) of the A1 standing or trotting under the controller (COM height 0.26 m),
# measured in MJX with the regular arm; the keyframe's 0.27 m is 1.5 cm lower.
STAND_HEIGHT = 0.285
MIN_SCENE_HEIGHT = 0.05  # m, lowest a task's shifted height (push pose, table top) may go
IK_TOL = 5e-3  # m, largest position error accepted for a waypoint
_IK_ITERS = 200
_IK_DAMPING = 1e-4  # m², Levenberg-Marquardt damping of J J^T
_IK_AXIS_DAMPING = 1e-2  # of the null-space axis step (it vanishes near singular poses)
_IK_POLISH = 50  # last iterations: position only
_IK_STEP = 0.2  # rad, largest joint change per iteration
_LIMIT_MARGIN = 0.02  # rad, waypoints stay this far inside the joint ranges
# Extra starts of the IK: (shoulder, elbow) rad, the waist aimed at the target, wrist 0.
_SEEDS = [(s, e) for s in (0.4, 1.0, 1.6) for e in (-1.2, -0.4, 0.4, 1.2)]


@dataclasses.dataclass(frozen=True)
class Script:
    """Joint-space waypoints of the arm servos (n = number of arm actuators), static numpy."""

    q0: np.ndarray  # (n,) servo targets at t = 0 (rad, or m for a finger)
    start: np.ndarray  # (m,) s, start of each move
    duration: np.ndarray  # (m,) s
    delta: np.ndarray  # (m, n) change of the servo targets over each move

    @classmethod
    def through(
        cls, waypoints: list[np.ndarray], t0: float, move_time: float, hold_time: float
    ) -> Script:
        """Visit `waypoints` (the first is the start pose) in turn from `t0` s: each move lasts
        `move_time` s and is followed by a `hold_time` s pause."""
        q = np.asarray(waypoints, np.float32)
        m = len(q) - 1
        start = t0 + (move_time + hold_time) * np.arange(m)
        duration = np.full(m, move_time, np.float32)
        return cls(q[0], start.astype(np.float32), duration, np.diff(q, axis=0))

    @property
    def end(self) -> float:
        """s, when the last move ends."""
        return float(self.start[-1] + self.duration[-1]) if len(self.start) else 0.0

    def targets(self, t: jax.Array, gain: jax.Array | float = 1.0) -> jax.Array:
        """(n,) servo targets at script time t (s), every move scaled by `gain` (its amplitude;
        1: the waypoints)."""
        x = jp.clip((t - self.start) / self.duration, 0.0, 1.0)  # (m,)
        return jp.asarray(self.q0) + gain * (smooth(x) @ jp.asarray(self.delta))


def draw_rate(key: jax.Array, config: EnvConfig) -> jax.Array:
    """() the episode's script pace ~ U(config.script_rate): script time = rate x time. A task
    puts it first in its `draw_task` (`Disturbances.task[0]`), where `script_time` reads it."""
    low, high = config.script_rate
    return jax.random.uniform(key, (), minval=low, maxval=high)


def script_time(t: jax.Array, dist) -> jax.Array:
    """() s, the script's time at physics time t (s), at the episode's pace (`draw_rate`)."""
    return t * dist.task[0]


def smooth(x: jax.Array) -> jax.Array:
    """The smooth step 3x^2 - 2x^3 on [0, 1]."""
    return x * x * (3.0 - 2.0 * x)


def stand_height(model: mujoco.MjModel) -> float:
    """m, the trunk's height standing under the controller: `STAND_HEIGHT` (the A1's) times
    h = the model's home trunk height / the A1's (`control.base_scaling.BaseScale.height`, the
    rule the controller's desired height follows); on the A1 h = 1 and this is `STAND_HEIGHT`
    exactly."""
    return STAND_HEIGHT * model_scale(model).height


def standing_data(model: mujoco.MjModel, x: float = 0.0) -> mujoco.MjData:
    """The home keyframe with the trunk level at (x, 0, `stand_height`), kinematics computed."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    data.qpos[:7] = [x, 0.0, stand_height(model), 1.0, 0.0, 0.0, 0.0]
    _kinematics(model, data)
    return data


def mount_offset(robot: RobotSpec) -> tuple[float, float]:
    """(dx, dz) m, world frame (x forward, z up): the first arm's mount site on `robot`'s base
    minus the same arm's mount site on the A1, each robot standing (`standing_data`, trunk at
    x = 0). Exactly (0.0, 0.0) on the A1. Each robot is compiled once per process."""
    if not robot.arms:
        raise DpcError(f"Variant {robot.name!r} has no arm to place a task's scene by; use an arm.")
    x, z = _mount_xz(robot)
    x_a1, z_a1 = _mount_xz(dataclasses.replace(robot, base="a1"))
    return x - x_a1, z - z_a1


@functools.lru_cache(maxsize=32)
def _mount_xz(robot: RobotSpec) -> tuple[float, float]:
    """(x, z) m, world: the first arm's mount site of `robot` standing (`standing_data`)."""
    model = build(robot)
    pos = standing_data(model).site_xpos[layout(model).arms[0].mount_site]
    return float(pos[0]), float(pos[2])


def check_height(task: str, robot: RobotSpec, what: str, height: float) -> float:
    """`height` (m above the floor, a task height shifted by `mount_offset`); raises `DpcError`
    if it is below `MIN_SCENE_HEIGHT` (a base whose arm's mount stands far lower than the
    A1's)."""
    if height < MIN_SCENE_HEIGHT:
        base = getattr(robot.base, "name", robot.base)
        raise DpcError(
            f"Task {task!r} on base {base!r}: its {what} would be {height:.3f} m above the floor "
            f"(below {MIN_SCENE_HEIGHT} m), as the arm's mount stands lower than on the A1. Use a "
            "base whose trunk stands higher, or mount the arm higher on its trunk."
        )
    return height


def solve_ik(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    arm: ArmLayout,
    site: int,
    pos: np.ndarray,
    approach_z: float | None = None,
    what: str = "waypoint",
) -> np.ndarray:
    """Joint positions (len(arm.qpos),) of `arm` that put `site` at world `pos` (3,) m; `data`
    is left in that configuration. With `approach_z`, the site's x axis gets as close as it can
    to that world z-component (-1 points down, 0 horizontal) without giving up position (task
    priority: the axis moves in the position task's null space). Damped least squares from the
    arm's configuration in `data` and from `_SEEDS` (joint limits trap single starts); the best
    result wins. Slide joints (the finger) are kept. Raises `DpcError` if the position error
    stays above `IK_TOL`."""
    hinge = model.jnt_type[model.dof_jntid[arm.dof]] == mujoco.mjtJoint.mjJNT_HINGE
    qadr, dofs = arm.qpos[hinge], arm.dof[hinge]
    joints = model.dof_jntid[dofs]
    lo = model.jnt_range[joints, 0] + _LIMIT_MARGIN
    hi = model.jnt_range[joints, 1] - _LIMIT_MARGIN
    pos = np.asarray(pos, float)
    aim = pos - data.site_xpos[arm.mount_site]
    yaw = np.arctan2(aim[1], aim[0])  # waist seed: towards the target (waist = first joint)
    seeds = [data.qpos[qadr].copy()]
    for shoulder, elbow in _SEEDS:
        q = np.zeros(len(qadr))
        q[: min(3, len(q))] = [yaw, shoulder, elbow][: len(q)]
        seeds.append(np.clip(q, lo, hi))
    best = None
    for q in seeds:
        data.qpos[qadr] = q
        _kinematics(model, data)
        miss, axis_err = _dls(model, data, site, qadr, dofs, lo, hi, pos, approach_z)
        score = (round(miss / IK_TOL), axis_err)  # position first (to IK_TOL), then the axis
        if best is None or score < best[0]:
            best = (score, miss, data.qpos[arm.qpos].copy())
    _, miss, q = best
    data.qpos[arm.qpos] = q
    _kinematics(model, data)
    if miss > IK_TOL:
        raise DpcError(
            f"The arm {arm.prefix!r} cannot reach its {what} at {np.round(pos, 3).tolist()} m "
            f"(closest {miss:.3f} m away); use a longer arm or move the task's objects."
        )
    return q


def _dls(model, data, site, qadr, dofs, lo, hi, pos, approach_z) -> tuple[float, float]:
    """Damped least squares iterations in place; returns (position error m, axis error)."""
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    eye = np.eye(len(dofs))
    for i in range(_IK_ITERS):
        mujoco.mj_jacSite(model, data, jacp, jacr, site)
        err, jac = pos - data.site_xpos[site], jacp[:, dofs]
        pinv = jac.T @ np.linalg.inv(jac @ jac.T + _IK_DAMPING * np.eye(3))
        dq = pinv @ err
        if approach_z is not None and i < _IK_ITERS - _IK_POLISH:  # then position only
            axis = data.site_xmat[site].reshape(3, 3)[:, 0]
            j_axis = np.cross(jacr[:, dofs].T, axis)[:, 2]  # d(axis_z)/dq: (omega_j x axis)_z
            j_null = j_axis @ (eye - pinv @ jac)  # (n,) the axis row in the null space
            rest = approach_z - axis[2] - j_axis @ dq
            dq = dq + j_null * rest / (j_null @ j_null + _IK_AXIS_DAMPING)
        dq = np.clip(dq, -_IK_STEP, _IK_STEP)
        data.qpos[qadr] = np.clip(data.qpos[qadr] + dq, lo, hi)
        _kinematics(model, data)
    miss = float(np.linalg.norm(pos - data.site_xpos[site]))
    axis_z = data.site_xmat[site].reshape(3, 3)[2, 0]
    return miss, 0.0 if approach_z is None else float(abs(axis_z - approach_z))


def _kinematics(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)  # cdof, needed by mj_jacSite


def check_task_arms(task: str, robot: RobotSpec, gripper: bool) -> None:
    """Raise `DpcError` unless `robot` has WidowX-like arms (`ArmSpec`, whose scripted poses
    these tasks solve for), with grippers if `gripper`."""
    if not robot.arms:
        raise DpcError(f"Task {task!r} needs an arm; variant {robot.name!r} has none.")
    for arm in robot.arms:
        if not isinstance(arm, ArmSpec):
            raise DpcError(
                f"Task {task!r} scripts the WidowX-like arms (ArmSpec); variant {robot.name!r} "
                f"has a URDF arm ({arm.urdf}). Use reaching for URDF arms."
            )
        if gripper and arm.ee_shape != "gripper":
            raise DpcError(
                f"Task {task!r} grasps a ball; variant {robot.name!r} has a {arm.ee_shape} end "
                "effector. Use a gripper arm, e.g. regular, longer or double."
            )
