"""`ControllerBatch`: one batch of envs in which each env has its own controller, so that every
controller's episodes run in one compiled program (one reset, one chunk).

The controller is data, not configuration: each env carries `info['controller']`, a () int32
`Controller.index`, and `DpcEnv.controller_u` selects that env's u among all the controllers'
(MBC's 0, the observer's estimate, the policy's u, the oracle's wrench: each computed for every
env, the others' discarded). With `controllers` (k of them) and a batch of k * E envs, envs
g * E .. g * E + E - 1 run controllers[g]; reset them from `rollout.start(..., groups=k)` and env
g * E + i meets episode i under every controller (the same initial pose and disturbances).

    batch = ControllerBatch(make("reaching", arm="regular"), ["mbc", "observer", "dpc", "oracle"])
    rollout.run_episodes(batch, 4 * E, steps, groups=4, policy=dpc)  # policy acts for every env

The wrapped env is built with controller 'dpc' (its `u_base` says what DPC's u adds to); it may
itself be batched (`model_batch.ModelBatchEnv`: a sweep's grid of arms). Like `ModelBatchEnv`,
its `reset` and `step` act on the whole batch (`batched = True`).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jp
from brax.envs.base import Env, State

from dpc_mjx.controllers import Controller
from dpc_mjx.envs.rollout import batch_fns
from dpc_mjx.errors import DpcError


class ControllerBatch:
    """`env`'s batch in `len(controllers)` equal groups, group g under controllers[g]."""

    batched = True  # reset/step take and return the whole batch (`rollout.batch_fns`)

    def __init__(self, env: Env, controllers: Sequence[str | Controller]):
        self.controllers = Controller.parse_all(controllers)
        if not self.controllers:
            raise DpcError("ControllerBatch needs at least one controller.")
        self.env = env
        dpc = getattr(env, "env", env)  # a ModelBatchEnv's DpcEnv, or the DpcEnv
        dpc.use_arm_model(any(c.adds(env.config.u_base)[1] for c in self.controllers))
        self._reset, self._step = batch_fns(env)
        self.TASK_MEASURES = getattr(env, "TASK_MEASURES", ())
        self.config = env.config

    def ids(self, batch: int) -> jp.ndarray:
        """(batch,) int32 `Controller.index` of each env: `batch / k` of each, in order."""
        k = len(self.controllers)
        if batch % k:
            raise DpcError(
                f"A batch of {batch} envs does not split into the {k} controllers "
                f"{[c.value for c in self.controllers]}: use a multiple of {k}."
            )
        ids = jp.array([c.index for c in self.controllers], jp.int32)
        return jp.repeat(ids, batch // k)

    def reset(self, keys) -> State:
        """Env i reset from keys[i] (B, 2), its controller in `info['controller']`."""
        state = self._reset(keys)
        return state.replace(info={**state.info, "controller": self.ids(keys.shape[0])})

    def step(self, state: State, action) -> State:
        """Every env stepped under its own controller, with action (B, 6) (read by 'dpc')."""
        return self._step(state, action)
