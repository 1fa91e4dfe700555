"""DPC environments (brax API): `make("a1_arm/reaching", arm="regular", **overrides)`.

- `base.DpcEnv`: one env, unbatched and pure (`reset(rng)`, `step(state, action)`);
- `config.EnvConfig`: every option, with units and sampling distributions;
- `observations`: s_body, s_arm, p_arm, `ObsLayout` (slices of the flat obs), privileged block;
- `disturbances`: commands, arm reference motions, end-effector pushes, payloads;
- `rewards`: the paper's eqs. 2-4; `wrappers.wrap_for_training`: vmap, episodes, auto-reset;
- `registry`: tasks by name; `reaching`: the training task; `pushing`, `carrying` (and
  `carrying_high`), `lifting`: the paper's test tasks with objects and scripted arm motions
  (`scripts`: waypoints and the IK that finds them).
"""

from dpc_mjx.envs.base import ACTION_SIZE, METRICS, DpcEnv
from dpc_mjx.envs.config import CONTROLLERS, EnvConfig
from dpc_mjx.envs.observations import PRIVILEGED, PRIVILEGED_SIZE, S_BODY_SIZE, ObsLayout
from dpc_mjx.envs.registry import default_arm, get_config, known_tasks, make, register
from dpc_mjx.envs.wrappers import AutoResetWrapper, wrap_for_training

__all__ = [
    "ACTION_SIZE",
    "CONTROLLERS",
    "METRICS",
    "PRIVILEGED",
    "PRIVILEGED_SIZE",
    "S_BODY_SIZE",
    "AutoResetWrapper",
    "DpcEnv",
    "EnvConfig",
    "ObsLayout",
    "default_arm",
    "get_config",
    "known_tasks",
    "make",
    "register",
    "wrap_for_training",
]
