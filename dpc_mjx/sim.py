"""Small MJX helpers: put a model on the device, batch initial states, roll out many steps.

A pitfall these helpers avoid: data built with `mjx.make_data` holds some uncommitted arrays; the
first jitted step returns them committed to the device, so the *second* call of the same jitted
function sees a different argument signature and compiles again (seconds to minutes, easily taken
for a hang). We commit every leaf with `jax.device_put` up front.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from mujoco import mjx


def put_model(model: mujoco.MjModel) -> mjx.Model:
    """The model on this process's first device (in a run of several processes,
    `jax.devices()[0]` is process 0's), with MJX's pure-JAX implementation."""
    return mjx.put_model(model, impl="jax", device=jax.local_devices()[0])


def commit(tree):
    """Commit every array of a pytree to this process's first device (the module docstring)."""
    return jax.device_put(tree, jax.local_devices()[0])


def batched_data(
    mx: mjx.Model,
    qpos: np.ndarray,
    ctrl: np.ndarray | None = None,
    qvel: np.ndarray | None = None,
) -> mjx.Data:
    """A batch of data from (B, nq) qpos, optional (B, nu) ctrl and (B, nv) qvel.

    Derived quantities (positions, sensors) are zero until the first `mjx.step`/`mjx.forward`.
    """
    qpos = jp.asarray(qpos, jp.float32)
    batch = qpos.shape[0]
    ctrl = jp.zeros((batch, mx.nu)) if ctrl is None else jp.asarray(ctrl, jp.float32)
    qvel = jp.zeros((batch, mx.nv)) if qvel is None else jp.asarray(qvel, jp.float32)

    d0 = mjx.make_data(mx)
    return commit(jax.vmap(lambda q, v, u: d0.replace(qpos=q, qvel=v, ctrl=u))(qpos, qvel, ctrl))


def make_rollout(mx: mjx.Model, n_steps: int, model_axes=None) -> Callable[[mjx.Data], mjx.Data]:
    """jit(vmap(n_steps x mjx.step)) over a batch of data (ctrl held constant).

    With `model_axes` (an in_axes tree from `dpc_mjx.robots.arms.params`), `mx` is a batched model
    and the returned function takes `(data)` with the model closed over per batch element.
    """

    def steps(m, d):
        return jax.lax.scan(lambda d, _: (mjx.step(m, d), None), d, None, length=n_steps)[0]

    if model_axes is None:
        return jax.jit(jax.vmap(lambda d: steps(mx, d)))
    return jax.jit(lambda d: jax.vmap(steps, in_axes=(model_axes, 0))(mx, d))
