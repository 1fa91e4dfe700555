"""Every task x every arm variant (slow: one compile per pair, ~25 envs; `make test-all`).

A pair the task can use resets and takes one step finitely with an observation of the advertised
size; a pair it cannot use (a URDF arm for a scripted task, a plate for a grasping task, no arm)
fails in `make` with `DpcError` before anything is built. The default test run covers each task
with its default arm (tests/test_tasks.py) and reaching with regular, none and double
(tests/test_envs.py); the paper's alternates are stepped further in tests/test_tasks.py (slow).
"""

import jax
import jax.numpy as jp
import numpy as np
import pytest
from helpers import FAST_COMPILE

import dpc_mjx
from dpc_mjx import DpcError
from dpc_mjx.envs import known_tasks, registry
from dpc_mjx.robots import VARIANTS, resolve

_BATCH = 2


def _usable(task: str, arm: str) -> bool:
    try:
        registry.TASKS[task].env_class.check_arm(resolve(arm))
    except DpcError:
        return False
    return True


@pytest.mark.slow
@pytest.mark.parametrize("arm", sorted(VARIANTS))
@pytest.mark.parametrize("task", known_tasks())
def test_every_task_and_arm(task, arm):
    if not _usable(task, arm):
        with pytest.raises(DpcError, match="variant"):
            dpc_mjx.make(task, arm=arm)
        return
    env = dpc_mjx.make(task, arm=arm)
    keys = jax.random.split(jax.random.PRNGKey(0), _BATCH)
    reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)
    step = jax.jit(jax.vmap(env.step), compiler_options=FAST_COMPILE)
    state = step(reset(keys), jp.zeros((_BATCH, env.action_size)))
    assert state.obs.shape == (_BATCH, env.observation_size)
    for leaf in jax.tree.leaves((state.obs, state.reward, state.pipeline_state.qpos)):
        assert np.isfinite(np.asarray(leaf)).all(), (task, arm)
    assert not np.asarray(state.metrics["nan_resets"]).any(), (task, arm)
