"""The env's physics engine: MJX (pure JAX, the default) or native MuJoCo C (sim-to-sim).

Both act on `mjx.Data` inside the jitted env step, so the env, the controller, the policy and the
rollout loop are the same code under either engine (`EnvConfig.engine`):

    'mjx'     `mjx.forward` / `mjx.step` on the device (float32)
    'native'  `mujoco.mj_forward` / `mujoco.mj_step` on the same compiled `MjModel` (float64),
              called through `jax.pure_callback` once per physics tick for the whole env batch
              (optionally split over threads: `NativePhysics(threads=...)`)

What crosses into MuJoCo C each tick (`INPUTS`): the state (time, qpos, qvel), the solver's warm
start and what the controller and the task set (ctrl, xfrc_applied, eq_active). What comes back
(`OUTPUTS`): the new state and warm start, and the quantities `mj_step` computed at the state it
started from, as `mjx.step` leaves them too (body and site poses, COM-based kinematics, sensors:
positions are one step old, velocities new). The other fields of `mjx.Data` (contacts,
constraint forces, ...) are not filled by the native engine; nothing in the env reads them.

The state travels as float32 between ticks (the env's dtype), so a native episode rounds qpos
and qvel to float32 every 4 ms; that is far below the engines' own differences (contact model,
solver), which are what sim-to-sim measures. A step that MuJoCo flags as unstable (its bad
qpos/qvel/qacc warnings, after which it would silently reset the data to qpos0) comes back as
NaN, so the env's NaN guard ends that episode as it does for MJX.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor

import jax
import mujoco
import numpy as np
from mujoco import mjx

from dpc_mjx.errors import DpcError

ENGINES = ("mjx", "native")

# mjx.Data fields handed to MuJoCo C each tick, and those it hands back
INPUTS = ("time", "qpos", "qvel", "qacc_warmstart", "ctrl", "xfrc_applied", "eq_active")
OUTPUTS = (
    *("time", "qpos", "qvel", "qacc_warmstart"),  # the state after the step
    *("xpos", "xquat", "xmat", "xipos", "ximat", "site_xpos", "site_xmat"),  # at the start
    *("subtree_com", "cdof", "sensordata"),  # at the start
)
# MuJoCo's warnings for a non-finite or huge qpos, qvel or qacc (it then resets the data)
_BAD_STATE = tuple(
    int(getattr(mujoco.mjtWarning, w))
    for w in ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")
)


class MjxPhysics:
    """MJX on the JAX device."""

    def __init__(self, mx: mjx.Model):
        self.mx = mx

    def forward(self, d: mjx.Data) -> mjx.Data:
        return mjx.forward(self.mx, d)

    def step(self, d: mjx.Data) -> mjx.Data:
        return mjx.step(self.mx, d)


class NativePhysics:
    """MuJoCo C on the host, one `MjData` per thread. One thread by default: on the 2-core
    machine of docs/benchmarks.md two threads were 0.7x as fast (the field copies hold the GIL,
    and a pool costs its own dispatch every tick)."""

    def __init__(self, model: mujoco.MjModel, threads: int = 1):
        if model.na or model.nmocap or model.nplugin:
            raise DpcError(
                "The native engine copies time, qpos and qvel as the state; this model also has "
                f"actuator activations ({model.na}), mocap bodies ({model.nmocap}) or plugins "
                f"({model.nplugin}). Use engine='mjx' for it."
            )
        self.model = model
        if threads < 1:
            raise DpcError(f"NativePhysics needs threads >= 1, got {threads}.")
        self.threads = threads
        self._datas = [mujoco.MjData(model) for _ in range(self.threads)]
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        template = mjx.make_data(model, impl="jax")
        # per env shapes and dtypes of the mjx.Data fields (xmat: (nbody, 3, 3) as in MJX)
        self._shapes = {k: getattr(template, k).shape for k in set(INPUTS) | set(OUTPUTS)}
        self._dtypes = {k: getattr(template, k).dtype for k in set(INPUTS) | set(OUTPUTS)}

    def forward(self, d: mjx.Data) -> mjx.Data:
        return self._call(d, advance=False)

    def step(self, d: mjx.Data) -> mjx.Data:
        return self._call(d, advance=True)

    def _call(self, d: mjx.Data, advance: bool) -> mjx.Data:
        """`OUTPUTS` of mj_step (advance) or mj_forward for `d`, any batch shape (vmap)."""
        shapes = [jax.ShapeDtypeStruct(self._shapes[k], self._dtypes[k]) for k in OUTPUTS]
        out = jax.pure_callback(
            lambda *x: self._host(advance, *x),
            shapes,
            *[getattr(d, k) for k in INPUTS],
            vmap_method="broadcast_all",
        )
        return d.replace(**dict(zip(OUTPUTS, out, strict=True)))

    def _host(self, advance: bool, *inputs: np.ndarray) -> list[np.ndarray]:
        """Host side of one tick: `inputs` (`INPUTS`, each (*batch, *field)) -> `OUTPUTS`."""
        x = dict(zip(INPUTS, inputs, strict=True))
        batch = np.shape(x["qpos"])[:-1]
        n = math.prod(batch)
        x = {k: np.asarray(v).reshape((n, *self._shapes[k])) for k, v in x.items()}
        out = {k: np.empty((n, *self._shapes[k]), self._dtypes[k]) for k in OUTPUTS}

        def run(thread: int, envs: np.ndarray) -> None:
            m, d = self.model, self._datas[thread]
            for i in envs:
                d.time = x["time"][i]
                d.qpos[:] = x["qpos"][i]
                d.qvel[:] = x["qvel"][i]
                d.qacc_warmstart[:] = x["qacc_warmstart"][i]
                d.ctrl[:] = x["ctrl"][i]
                d.xfrc_applied[:] = x["xfrc_applied"][i]
                d.eq_active[:] = x["eq_active"][i]
                for w in _BAD_STATE:
                    d.warning[w].number = 0
                (mujoco.mj_step if advance else mujoco.mj_forward)(m, d)
                unstable = any(d.warning[w].number > 0 for w in _BAD_STATE)
                for k in OUTPUTS:
                    out[k][i] = np.reshape(getattr(d, k), self._shapes[k])
                if unstable:  # MuJoCo reset the data to qpos0: report the step as NaN
                    out["qpos"][i] = np.nan
                    out["qvel"][i] = np.nan

        parts = np.array_split(np.arange(n), self.threads)
        if self._pool is None or n < 2:
            run(0, np.arange(n))
        else:
            list(self._pool.map(run, range(self.threads), parts))
        return [out[k].reshape(batch + self._shapes[k]) for k in OUTPUTS]


def make_physics(engine: str, model: mujoco.MjModel, mx: mjx.Model) -> MjxPhysics | NativePhysics:
    """The engine named `engine` (`ENGINES`) for a compiled model and its MJX copy."""
    if engine == "mjx":
        return MjxPhysics(mx)
    if engine == "native":
        return NativePhysics(model)
    raise DpcError(f"engine={engine!r} is not valid; choose one of {list(ENGINES)}.")


__all__ = ["ENGINES", "INPUTS", "OUTPUTS", "MjxPhysics", "NativePhysics", "make_physics"]
