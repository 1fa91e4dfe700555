"""Tasks by name: `make("reaching", arm="regular", **overrides)`.

A name is `<task>` ("reaching"; any base: `make(..., base=)`), or, as before, "a1_arm/<task>"
(`LEGACY_PREFIX`, an alias: exports written before record it). The task table maps a
name to the task's env class, its default config factory and its default arm, all from the
task's module in `dpc_mjx.envs.tasks` (the class declares `TASK`, `DEFAULT_ARM`, `check_arm`
and `scene_spec`). `make` checks the name, the arm (known variant, one the task can use, one the
base can hold up) and the overrides, raising `DpcError` before anything is built or compiled, then
builds the env; `scene_spec` / `build_scene` give a task's scene alone. On a base other than the
A1, `get_config` scales the task's pushes, payloads and u's bounds by its weight (`WEIGHT_SCALED`);
u's bounds are those of what the policy's u is added to (`RESIDUAL_BOUNDS`).

    task            default arm   scene (on the A1; on another base the objects move with the
                                  arm's mount, `envs.tasks.scripts.mount_offset`)
    reaching        regular       robot on a floor; random arm targets, pushes, payloads
    pushing         pusher        + a free box 0.7 m ahead, pushed with the arm while walking
    carrying        regular       + two tables, a ball per arm carried from one to the other
    carrying_high   longer        the same with 0.45 m tables
    lifting         regular       + a 0.3 kg ball per arm, welded in the gripper, lifted while
                                  walking a trajectory
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import Any

import mujoco

from dpc_mjx.control.static_balance import require_static_balance
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.tasks import carrying, lifting, pushing, reaching
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.bases.file import BaseSpec, read_base
from dpc_mjx.robots.variants import Arm, RobotSpec, on_base, resolve

LEGACY_PREFIX = "a1_arm/"  # tasks' names before any base: "a1_arm/reaching" is "reaching"
DEFAULT_TASK = "reaching"  # the training task: every run, evaluation and export's default


@dataclasses.dataclass(frozen=True)
class Task:
    env_class: type[DpcEnv]
    default_config: Callable[[], EnvConfig]
    default_arm: str  # a name of `dpc_mjx.robots.VARIANTS`


TASKS: dict[str, Task] = {}


def register(
    task: str,
    env_class: type[DpcEnv],
    default_config: Callable[[], EnvConfig],
    default_arm: str = "regular",
) -> None:
    """Make `task` available to `make`."""
    TASKS[task] = Task(env_class, default_config, default_arm)


for _env, _config in (  # each class names its task and default arm
    (reaching.ReachingEnv, reaching.default_config),
    (pushing.PushingEnv, pushing.default_config),
    (carrying.CarryingEnv, carrying.default_config),
    (carrying.CarryingHighEnv, carrying.default_config),
    (lifting.LiftingEnv, lifting.default_config),
):
    register(_env.TASK, _env, _config, _env.DEFAULT_ARM)


def known_tasks() -> list[str]:
    return sorted(TASKS)


# The task's disturbances and u's bounds, drawn for the A1, scaled on another base by the ratio
# m of its trunk + legs mass to the A1's (`base_mass_ratio`; exactly 1 on the A1): the same
# pushes, payloads and u relative to the robot's weight. Fields given as overrides are used as
# given (N, kg, N·m).
WEIGHT_SCALED = ("push_force", "payload_mass", "max_force", "max_torque")

# u's bounds (N, N·m per axis x, y, z; the A1's, scaled as above) where the policy's u is a
# residual of the arms' model (`EnvConfig.u_base`): small loads only, the payload and the model's
# error, so that a push saturates it and is left to the balance QP's feedback
# (docs/results-arm-model.md, "A residual bounded to small loads"). Elsewhere u is the whole
# wrench and `EnvConfig`'s bounds apply. Bounds given as overrides are used as given.
RESIDUAL_BOUNDS = {"model": {"max_force": (6.0, 6.0, 6.0), "max_torque": (3.0, 3.0, 3.0)}}


def get_config(name: str, **overrides: Any) -> EnvConfig:
    """The task's default config with `overrides`, validated; u's bounds those of its `u_base`
    (`RESIDUAL_BOUNDS`) unless given; on a base other than the A1, its `WEIGHT_SCALED` defaults
    scaled by the base's mass ratio."""
    config = _task(name).default_config().replace(**overrides)
    residual = RESIDUAL_BOUNDS.get(config.u_base, {})
    config = config.replace(**{k: v for k, v in residual.items() if k not in overrides})
    m = base_mass_ratio(config.base)
    if m == 1.0:
        return config
    scaled = {
        k: _times(getattr(config, k), m) for k in WEIGHT_SCALED if k not in overrides
    }  # fmt: skip
    return config.replace(**scaled)


def base_mass_ratio(base: str) -> float:
    """m: the trunk + legs mass of `base` (a name or a file's path; `BaseSpec.base_mass`, read
    again when the file changes) over the A1's: `control.base_scaling`'s mass ratio."""
    if base == "a1":
        return 1.0
    return read_base(base).base_mass / read_base("a1").base_mass


def _times(value: float | tuple[float, ...], factor: float) -> float | tuple[float, ...]:
    """`value` x `factor`, per entry, rounded to 0.01 (N, kg, N·m)."""
    if isinstance(value, tuple):
        return tuple(round(float(v) * factor, 2) for v in value)
    return round(float(value) * factor, 2)


def default_arm(name: str) -> str:
    """The arm variant `make(name)` uses when none is given."""
    return _task(name).default_arm


def make(
    name: str,
    arm: str | Arm | RobotSpec | None = None,
    base: str | os.PathLike | BaseSpec | None = None,
    **overrides: Any,
) -> DpcEnv:
    """The unbatched env `name` (e.g. "reaching") with arm variant `arm` (a name of
    `dpc_mjx.robots.VARIANTS`, an ArmSpec/UrdfArm or a RobotSpec; None: the task's default arm,
    `default_arm(name)`) on the quadruped `base` (a name of `robots.bases.file.NAMED_BASES`, the
    path of its .urdf, .xml or .json file, or a BaseSpec; None: the RobotSpec's, the A1) and config
    `overrides`."""
    task = _task(name)
    robot = resolve(task.default_arm if arm is None else arm)
    if isinstance(base, BaseSpec):  # an object: the env builds this very spec
        robot, base = dataclasses.replace(robot, base=base), str(base.path)
    if base is not None:
        overrides = {**overrides, "base": os.fspath(base)}
    config = get_config(name, **overrides)
    robot = on_base(robot, config.base)
    task.env_class.check_arm(resolve_arm(robot))  # a bad or unsuitable arm fails here
    return task.env_class(config, robot)


def resolve_arm(arm: str | Arm | RobotSpec) -> RobotSpec:
    """`robots.resolve(arm)`, then the A1 holding its arm files up (`control.static_balance`):
    where an arm comes in (`make`, `scene_spec`, transfer, eval, sweep), before any compile."""
    spec = resolve(arm)
    require_static_balance(spec)
    return spec


def scene_spec(name: str, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjSpec:
    """Task `name`'s scene with arm variant `arm` (None: `default_arm(name)`) as an uncompiled
    spec: the robot at the origin in its home key, the task's objects at rest. The env may edit
    it further (carrying moves the robot to `robot_x`); use `make(name).model` for the env's."""
    task = _task(name)
    scene = getattr(task.env_class, "scene_spec", None)
    if scene is None:
        raise DpcError(
            f"Task {name!r} ({task.env_class.__name__}) has no `scene_spec`; build its env with "
            "`make` and read `env.model`."
        )
    arm = task.default_arm if arm is None else arm
    resolve_arm(arm)
    return scene(arm)


def build_scene(name: str, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjModel:
    """Compile `scene_spec(name, arm)`."""
    return scene_spec(name, arm).compile()


def task_name(name: str) -> str:
    """The name of task `name` ("a1_arm/reaching" -> "reaching"), to compare names."""
    return name.removeprefix(LEGACY_PREFIX)


def _task(name: str) -> Task:
    """The task `name`, by its name ("reaching") or its old one ("a1_arm/reaching")."""
    task = TASKS.get(task_name(name))
    if task is None:
        raise DpcError(
            f"Unknown task {name!r}; known tasks: {known_tasks()} (the old names "
            f"'{LEGACY_PREFIX}<task>' work too)."
        )
    return task
