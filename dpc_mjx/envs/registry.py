"""Tasks by name: `make("a1_arm/reaching", arm="regular", **overrides)`.

A name is `<robot>/<task>`. Tasks register an env class and a default config factory; `make`
checks the name, the arm and the overrides (raising `DpcError` before anything is compiled), then
builds the env. `pushing`, `carrying` and `lifting` (objects in the scene) register the same way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from dpc_mjx.envs import reaching
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve

ROBOT = "a1_arm"


@dataclasses.dataclass(frozen=True)
class Task:
    env_class: type[DpcEnv]
    default_config: Callable[[], EnvConfig]


TASKS: dict[str, Task] = {}


def register(task: str, env_class: type[DpcEnv], default_config: Callable[[], EnvConfig]) -> None:
    """Make `f"{ROBOT}/{task}"` available to `make`."""
    TASKS[f"{ROBOT}/{task}"] = Task(env_class, default_config)


register("reaching", reaching.ReachingEnv, reaching.default_config)


def known_tasks() -> list[str]:
    return sorted(TASKS)


def get_config(name: str, **overrides: Any) -> EnvConfig:
    """The task's default config with `overrides`, validated."""
    return _task(name).default_config().replace(**overrides)


def make(name: str, arm: str | Arm | RobotSpec = "regular", **overrides: Any) -> DpcEnv:
    """The unbatched env `name` (e.g. "a1_arm/reaching") with arm variant `arm` (a name of
    `dpc_mjx.robots.VARIANTS`, an ArmSpec/UrdfArm or a RobotSpec) and config `overrides`."""
    task = _task(name)
    config = task.default_config().replace(**overrides)
    resolve(arm)  # a bad arm fails here, with the known variants
    return task.env_class(config, arm)


def _task(name: str) -> Task:
    if name not in TASKS:
        raise DpcError(f"Unknown task {name!r}; known tasks: {known_tasks()}.")
    return TASKS[name]
