"""Tasks by name: `make("a1_arm/reaching", arm="regular", **overrides)`.

A name is `<robot>/<task>`. Tasks register an env class, a default config factory and a default
arm (`props.TASK_ARMS`); `make` checks the name, the arm (known variant, and one the task can use)
and the overrides, raising `DpcError` before anything is built or compiled, then builds the env.

    task            default arm   scene
    reaching        regular       robot on a floor; random arm targets, pushes, payloads
    pushing         pusher        + a free box 0.7 m ahead, pushed with the arm while walking
    carrying        regular       + two tables, a ball per arm carried from one to the other
    carrying_high   longer        the same with 0.45 m tables
    lifting         regular       + a 0.3 kg ball per arm, welded in the gripper, lifted while
                                  walking a trajectory
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from dpc_mjx.envs import carrying, lifting, pushing, reaching
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.props import TASK_ARMS
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve

ROBOT = "a1_arm"


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
    """Make `f"{ROBOT}/{task}"` available to `make`."""
    TASKS[f"{ROBOT}/{task}"] = Task(env_class, default_config, default_arm)


register("reaching", reaching.ReachingEnv, reaching.default_config, TASK_ARMS["reaching"])
register("pushing", pushing.PushingEnv, pushing.default_config, TASK_ARMS["pushing"])
register("carrying", carrying.CarryingEnv, carrying.default_config, TASK_ARMS["carrying"])
register(
    "carrying_high",
    carrying.CarryingHighEnv,
    carrying.default_config,
    TASK_ARMS["carrying_high"],
)
register("lifting", lifting.LiftingEnv, lifting.default_config, TASK_ARMS["lifting"])


def known_tasks() -> list[str]:
    return sorted(TASKS)


def get_config(name: str, **overrides: Any) -> EnvConfig:
    """The task's default config with `overrides`, validated."""
    return _task(name).default_config().replace(**overrides)


def default_arm(name: str) -> str:
    """The arm variant `make(name)` uses when none is given."""
    return _task(name).default_arm


def make(name: str, arm: str | Arm | RobotSpec | None = None, **overrides: Any) -> DpcEnv:
    """The unbatched env `name` (e.g. "a1_arm/reaching") with arm variant `arm` (a name of
    `dpc_mjx.robots.VARIANTS`, an ArmSpec/UrdfArm or a RobotSpec; None: the task's default arm,
    `default_arm(name)`) and config `overrides`."""
    task = _task(name)
    config = task.default_config().replace(**overrides)
    arm = task.default_arm if arm is None else arm
    task.env_class.check_arm(resolve(arm))  # a bad or unsuitable arm fails here
    return task.env_class(config, arm)


def _task(name: str) -> Task:
    if name not in TASKS:
        raise DpcError(f"Unknown task {name!r}; known tasks: {known_tasks()}.")
    return TASKS[name]
