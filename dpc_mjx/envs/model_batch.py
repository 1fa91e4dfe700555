"""`ModelBatchEnv`: one env stepped on a batch of models, env i on model i, in one compile.

The models differ only in continuous values (an arm's upper-arm length and gripper mass:
`robots.arms.params.batch_arm_params`), so `jax.vmap` runs the unbatched `DpcEnv` over the batched
fields of one `mjx.Model` and the unbatched rest; a sweep over a grid of arms is one program:

    mx, in_axes = batch_arm_params(env.mx, env.model, upper_arm_length=L, gripper_mass=m)
    grid = ModelBatchEnv(env, mx, in_axes)      # (B,) models, B = len(L)
    rollout.run_episodes(grid, B, steps)        # env i on model i

Unlike `DpcEnv`, its `reset` and `step` act on the whole batch (`batched = True`, which the
rollout core reads): reset keys (B, 2) -> State (B, ...), step (State (B, ...), action (B, 6)).
"""

from __future__ import annotations

import copy
import dataclasses

import jax
from brax.envs.base import State
from mujoco import mjx

from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.errors import DpcError
from dpc_mjx.physics import make_physics


class ModelBatchEnv:
    """`env` on each of the (B,) models of `mx` (batched along the fields `in_axes` marks 0)."""

    batched = True  # reset/step take and return the whole batch (`rollout.batch_fns`)

    def __init__(self, env: DpcEnv, mx: mjx.Model, in_axes: mjx.Model):
        batch_size = lambda axis, x: None if axis is None else x.shape[axis]  # noqa: E731
        sizes = set(jax.tree.leaves(jax.tree.map(batch_size, in_axes, mx, is_leaf=_none)))
        if len(sizes) != 1:
            raise DpcError(
                f"ModelBatchEnv needs one batch size across the batched model fields, got "
                f"{sorted(sizes)}; build the batch with robots.arms.params.batch_arm_params."
            )
        self.env, self.mx, self.in_axes = env, mx, in_axes
        self.size = sizes.pop()  # B
        self.TASK_MEASURES = env.TASK_MEASURES
        self.config = env.config

    def reset(self, keys: jax.Array) -> State:
        """Env i reset from keys[i] (B, 2) on model i."""
        self._check(keys.shape[0])
        one = lambda m, k: on_model(self.env, m).reset(k)  # noqa: E731
        return jax.vmap(one, in_axes=(self.in_axes, 0))(self.mx, keys)

    def step(self, state: State, action: jax.Array) -> State:
        """Env i stepped on model i with action[i] (B, 6)."""
        one = lambda m, s, a: on_model(self.env, m).step(s, a)  # noqa: E731
        return jax.vmap(one, in_axes=(self.in_axes, 0, 0))(self.mx, state, action)

    def _check(self, batch: int) -> None:
        if batch != self.size:
            raise DpcError(
                f"This ModelBatchEnv holds {self.size} models but was given a batch of {batch} "
                "envs; run exactly one env per model (repeat a model to run it more often)."
            )


def on_model(env: DpcEnv, mx: mjx.Model) -> DpcEnv:
    """`env` on `mx`, a model of the same structure with other continuous values (one element
    of `robots.arms.params.batch_arm_params`'s batch, inside `jax.vmap`). Physics, the data, the
    end-effector Jacobians and what the env and its controller know of the arms (their masses,
    their rigid-body model: `control.arm_model`) use `mx`; the controller keeps its model of the
    bare base, which an arm's parameters do not touch. MJX engine only (the native engine steps
    the one compiled `MjModel`)."""
    if env.config.engine != "mjx":
        raise DpcError(
            f"A batch of models runs on the MJX engine only (this env has engine="
            f"{env.config.engine!r}); build the env with engine='mjx'."
        )
    env = copy.copy(env)
    env.mx = mx
    env.physics = make_physics("mjx", env.model, mx)
    env._arm_masses = mx.body_mass[env.lay.arm_bodies]  # kg, `DpcEnv.arm_gravity`'s
    if env.controller.arm is not None:
        env.controller = dataclasses.replace(env.controller, arm=env.controller.arm.on(mx))
    return env


def _none(x) -> bool:
    return x is None
