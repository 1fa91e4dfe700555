"""DPC environments (brax API): `make("reaching", arm="regular", **overrides)`.

- `base.DpcEnv`: one env, unbatched and pure (`reset(rng)`, `step(state, action)`);
- `config.EnvConfig`: every option, with units and sampling distributions;
- `observations`: s_body, s_arm, p_arm, `ObsLayout` (slices of the flat obs), privileged block;
- `disturbances`: commands, arm reference motions, end-effector pushes, payloads;
- `rewards`: the paper's eqs. 2-4; `outcome`: the per-step metrics and the NaN guard's test;
- `wrappers.wrap_for_training`: vmap, episodes, auto-reset;
- `rollout`: the one rollout core (a batch stepped with a policy in jitted chunks, episode
  tallies, per-step records): evaluation, data collection, SAC's evaluation, benchmarks;
- `registry`: the task table (name -> env class, default config, default arm), `make`, and each
  task's scene alone (`build_scene`);
- `tasks`: one module per task, each owning its scene, arms and script: `reaching` (the training
  task); `pushing`, `carrying` (and `carrying_high`), `lifting` (the paper's test tasks with
  objects and scripted arm motions; `tasks.scripts`: waypoints and the IK that finds them).
"""

from dpc_mjx.envs.base import ACTION_SIZE, METRICS, DpcEnv
from dpc_mjx.envs.config import CONTROLLERS, EnvConfig
from dpc_mjx.envs.observations import PRIVILEGED, PRIVILEGED_SIZE, S_BODY_SIZE, ObsLayout
from dpc_mjx.envs.registry import (
    DEFAULT_TASK,
    build_scene,
    default_arm,
    get_config,
    known_tasks,
    make,
    register,
)
from dpc_mjx.envs.rollout import Policy, Tally, run_episodes, zero_policy
from dpc_mjx.envs.wrappers import AutoResetWrapper, wrap_for_training

__all__ = [
    "ACTION_SIZE",
    "CONTROLLERS",
    "DEFAULT_TASK",
    "METRICS",
    "PRIVILEGED",
    "PRIVILEGED_SIZE",
    "S_BODY_SIZE",
    "AutoResetWrapper",
    "DpcEnv",
    "EnvConfig",
    "ObsLayout",
    "Policy",
    "Tally",
    "build_scene",
    "default_arm",
    "get_config",
    "known_tasks",
    "make",
    "register",
    "run_episodes",
    "wrap_for_training",
    "zero_policy",
]
