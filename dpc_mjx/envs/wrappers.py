"""Batching, episode limits and auto-reset around an unbatched `DpcEnv`.

brax's own `AutoResetWrapper` puts back the *first* pipeline state and observation of each env but
keeps `info`, where a `DpcEnv` carries its controller state and disturbance schedule; after a
reset the controller would plan from the old episode's desired pose and the same schedule would
never be redrawn. Ours resets a done env *freshly* (a new `reset` from a new key): physics,
observation and every env-owned `info` entry. Use `wrap_for_training` wherever brax would call
`envs.training.wrap`, e.g. `sac.train(environment=env, wrap_env_fn=wrap_for_training, ...)`.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jp
from brax.envs.base import Env, State, Wrapper
from brax.envs.wrappers.training import EpisodeWrapper, VmapWrapper

from dpc_mjx.errors import DpcError

# info keys owned by wrappers: a reset must not overwrite them.
_WRAPPER_KEYS = ("steps", "truncation", "episode_done", "episode_metrics", "eval_metrics")
_RESET_KEY = "reset_rng"


class AutoResetWrapper(Wrapper):
    """Resets done envs of a batch with a fresh `reset` (new key per env); the others unchanged.

    The step that ends an episode returns its own reward, done = 1 and metrics, with the physics,
    obs and env info of the new episode (brax's convention). The fresh resets are computed only
    when some env is done (`lax.cond`), for the whole batch, and selected per env.
    """

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        keys = jax.vmap(lambda k: jax.random.fold_in(k, 1))(rng)  # independent of env keys
        return state.replace(info={**state.info, _RESET_KEY: keys})

    def step(self, state: State, action: jax.Array) -> State:
        if "steps" in state.info:  # as brax: the step counter restarts after a done step
            steps = jp.where(state.done, jp.zeros_like(state.info["steps"]), state.info["steps"])
            state = state.replace(info={**state.info, "steps": steps})
        state = self.env.step(state.replace(done=jp.zeros_like(state.done)), action)
        split = jax.vmap(jax.random.split)(state.info[_RESET_KEY])  # (B, 2, 2)
        reset_keys, carry = split[:, 0], split[:, 1]

        def fresh(s: State) -> State:
            new = self.env.reset(reset_keys)
            done = s.done

            def pick(a, b):
                return jp.where(done.reshape(done.shape + (1,) * (a.ndim - 1)), a, b)

            keys = [k for k in new.info if k not in _WRAPPER_KEYS and k != _RESET_KEY]
            info = {**s.info, **{k: jax.tree.map(pick, new.info[k], s.info[k]) for k in keys}}
            return s.replace(
                pipeline_state=jax.tree.map(pick, new.pipeline_state, s.pipeline_state),
                obs=jax.tree.map(pick, new.obs, s.obs),
                info=info,
            )

        state = jax.lax.cond(jp.any(state.done > 0), fresh, lambda s: s, state)
        return state.replace(info={**state.info, _RESET_KEY: carry})


def wrap_for_training(
    env: Env,
    episode_length: int | None = None,
    action_repeat: int = 1,
    randomization_fn: Callable | None = None,
) -> Env:
    """vmap + episode limit + fresh auto-reset: the drop-in for brax's `envs.training.wrap`.

    `episode_length` defaults to the env's `config.episode_length`. The batch size is the number
    of keys given to `reset`: `(B, 2)`.
    """
    if randomization_fn is not None:
        raise DpcError(
            "randomization_fn is not supported by DpcEnv (it has no brax `sys`); vary arm "
            "parameters with a batched mjx.Model (dpc_mjx.robots.arms.params) instead."
        )
    if episode_length is None:
        episode_length = env.unwrapped.config.episode_length
    env = VmapWrapper(env)
    env = EpisodeWrapper(env, episode_length, action_repeat)
    return AutoResetWrapper(env)
