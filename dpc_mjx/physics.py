"""The env's physics engine: MJX (pure JAX) or native MuJoCo C, chosen per env (`EnvConfig.engine`).

Both act on `mjx.Data` inside the jitted env step, so the env, the controller, the policy and the
rollout loop are the same code under either engine (`EnvConfig.engine`):

    'mjx'     `mjx.forward` / `mjx.step` on the device (float32)
    'native'  `mujoco.mj_forward` / `mujoco.mj_step` on the same compiled `MjModel` (float64),
              called through `jax.pure_callback` once per physics tick for the whole env batch:
              one `mujoco.batch.Batch` of the batch's size steps every env in C (its own
              thread pool, the GIL released: `NativePhysics(threads=...)`)
    'auto'    the default (`resolve_engine`): 'native' where JAX runs on one CPU device and the
              model suits it, 'mjx' on an accelerator or over several devices; the env's
              `config.engine` names the one it resolved to

What crosses into MuJoCo C each tick (`INPUTS`): the state (time, qpos, qvel), the solver's warm
start and what the controller and the task set (ctrl, xfrc_applied, eq_active), written into the
Batch's state rows. What comes back (`OUTPUTS`): the new state and warm start, and the quantities
`mj_step` computed at the state it started from, as `mjx.step` leaves them too (body and site
poses, COM-based kinematics, sensors: positions are one step old, velocities new). The other
fields of `mjx.Data` (contacts, constraint forces, ...) are not filled by the native engine;
nothing in the env reads them. The outputs are bit for bit those of a loop of `mj_step` over one
`MjData` per env (tests/test_physics.py keeps that loop as the reference), at any thread count.

The state travels as float32 between ticks (the env's dtype), so a native episode rounds qpos
and qvel to float32 every 4 ms; that is far below the engines' own differences (contact model,
solver), which are what sim-to-sim measures. A step that MuJoCo flags as unstable (its bad
qpos/qvel/qacc warnings, after which it would silently reset the data to qpos0), or one in which
MuJoCo raises an error (`mujoco.batch.SimulationError`, e.g. its arena overflowing; a warning
names it), comes back as NaN, so the env's NaN guard ends that episode as it does for MJX. A
forward, as `mj_forward`, checks and resets nothing.

JAX's persistent compilation cache never stores a native-engine program: jax 0.9.2 refuses to
write any executable that holds host callbacks (`_cache_write` in its compiler module), so these
programs compile afresh in every process.
"""

from __future__ import annotations

import copy
import math
import threading
import warnings

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from mujoco import mjx
from mujoco.batch import Batch, SimulationError

from dpc_mjx.errors import DpcError

ENGINES = ("mjx", "native")
AUTO = "auto"  # `resolve_engine` picks one of ENGINES
ENGINE_CHOICES = (AUTO, *ENGINES)
ENGINE_NAMES = {"mjx": "MJX", "native": "native MuJoCo C"}  # for tables and progress lines

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
    """MuJoCo C on the host: each tick, the whole env batch in one `mujoco.batch.Batch` (one per
    batch size seen), stepped in C on `threads` threads with the GIL released (Batch's nthread).

    One thread by default (results are bit-identical at any count). On the 2-core machine of
    docs/benchmarks-cpu.md (`experiments/bench_limit.py`, the reaching env) two threads paid when it
    was idle, 1,979 vs 1,434 env steps/s at batch 64 and 3,196 vs 2,876 at batch 256, and not
    when other jobs loaded it (468 vs 466 at batch 64): pass `threads` where cores are free. One
    thread is what a process pinned to one core (issue 26's target) runs."""

    def __init__(self, model: mujoco.MjModel, threads: int = 1):
        if not native_suits(model):
            raise DpcError(
                "The native engine copies time, qpos and qvel as the state; this model also has "
                f"actuator activations ({model.na}), mocap bodies ({model.nmocap}) or plugins "
                f"({model.nplugin}). Use engine='mjx' for it."
            )
        if threads < 1:
            raise DpcError(f"NativePhysics needs threads >= 1, got {threads}.")
        self.model = model
        self.threads = threads
        # Batch.forward checks qpos and qvel as mj_step does (mj_forward does not) and resets a
        # bad state: forward runs on a copy of the model that does not reset, as mj_forward
        self._no_reset = copy.copy(model)
        self._no_reset.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
        # (batch size, advance) -> its Batch and bound fields, each (n, *MjData's shape) float64:
        # INPUTS are views of the state rows, the derived OUTPUTS are refreshed by every call
        self._batches: dict[tuple[int, bool], tuple[Batch, dict[str, np.ndarray]]] = {}
        self._lock = threading.Lock()  # a Batch and its bound arrays serve one call at a time
        template = mjx.make_data(model, impl="jax")
        # per env shapes and dtypes of the mjx.Data fields (xmat: (nbody, 3, 3) as in MJX)
        self._shapes = {k: getattr(template, k).shape for k in set(INPUTS) | set(OUTPUTS)}
        self._dtypes = {k: getattr(template, k).dtype for k in set(INPUTS) | set(OUTPUTS)}
        self._dtype = template.qpos.dtype  # of the packed arrays (float32 unless x64)
        # where each field lies in the packed arrays (`_call`): field -> slice of the last axis
        self._in_slices, self._in_size = _packing(self._shapes, INPUTS)
        self._out_slices, self._out_size = _packing(self._shapes, OUTPUTS)

    def forward(self, d: mjx.Data) -> mjx.Data:
        return self._call(d, advance=False)

    def step(self, d: mjx.Data) -> mjx.Data:
        return self._call(d, advance=True)

    def _call(self, d: mjx.Data, advance: bool) -> mjx.Data:
        """`OUTPUTS` of mj_step (advance) or mj_forward for `d`, any batch shape (vmap).

        One packed array each way, (*batch, `_in_size`) in and (*batch, `_out_size`) out, the fields
        end to end in `INPUTS` / `OUTPUTS` order: a callback pays a cost per array it passes (jax
        puts each input on the device and checks each output). At batch 64 a no-op callback costs
        0.79 ms a call with one array per field and 0.23 ms packed, and the env steps ~25 % faster
        (experiments/bench_callback.py, bench_limit.py; docs/benchmarks-cpu.md)."""
        packed_in = jp.concatenate([jp.ravel(getattr(d, k)).astype(self._dtype) for k in INPUTS])
        packed_out = jax.pure_callback(
            lambda x: self._host(advance, x),
            jax.ShapeDtypeStruct((self._out_size,), self._dtype),
            packed_in,
            vmap_method="broadcast_all",
        )
        return d.replace(
            **{
                k: packed_out[..., sl].reshape(self._shapes[k]).astype(self._dtypes[k])
                for k, sl in self._out_slices.items()
            }
        )

    def _batch(self, n: int, advance: bool) -> tuple[Batch, dict[str, np.ndarray]]:
        """The Batch of `n` simulations for steps (`advance`) or forwards and its bound `INPUTS`
        and `OUTPUTS`, made once."""
        if (n, advance) not in self._batches:
            batch = Batch(self.model if advance else self._no_reset, n, self.threads)
            fields = {k: batch.bind(k) for k in (*INPUTS, *OUTPUTS)}
            self._batches[n, advance] = batch, fields
        return self._batches[n, advance]

    def _host(self, advance: bool, packed: np.ndarray) -> np.ndarray:
        """Host side of one tick: `INPUTS` packed (*batch, `_in_size`) -> `OUTPUTS` packed
        (*batch, `_out_size`), both in the env's float dtype (`_call`)."""
        packed = np.asarray(packed)
        shape = packed.shape[:-1]  # the batch's
        n = math.prod(shape)
        out = np.empty((n, self._out_size), self._dtype)
        if n == 0:  # an empty batch (a Batch needs a simulation)
            return out.reshape(shape + (self._out_size,))
        rows = packed.reshape(n, self._in_size)
        with self._lock:
            batch, fields = self._batch(n, advance)
            for k, sl in self._in_slices.items():  # float32 (bool as 0/1) -> float64, in place
                fields[k][...] = rows[:, sl].reshape(fields[k].shape)
            batch.warning[:, _BAD_STATE, 1] = 0  # the counts (warning: (n, mjNWARNING, 2))
            failed = _run(batch, advance)
            # a step that MuJoCo found unstable reset the sim's data to qpos0, and a sim in which
            # it raised kept its state: report either as NaN (a forward resets nothing)
            bad = np.any(batch.warning[:, _BAD_STATE, 1] > 0, axis=1) & advance
            bad[failed] = True
            for k, sl in self._out_slices.items():  # float64 -> the env's dtype, as astype
                out[:, sl] = fields[k].reshape(n, sl.stop - sl.start)
            if bad.any():
                for k in ("qpos", "qvel"):
                    out[bad, self._out_slices[k]] = np.nan
        return out.reshape(shape + (self._out_size,))


def _packing(shapes: dict[str, tuple], keys: tuple[str, ...]) -> tuple[dict[str, slice], int]:
    """The fields `keys` end to end in one flat array: ({field: its slice}, the array's size)."""
    slices, offset = {}, 0
    for k in keys:
        size = math.prod(shapes[k])
        slices[k], offset = slice(offset, offset + size), offset + size
    return slices, offset


def _run(batch: Batch, advance: bool) -> np.ndarray:
    """`batch.step()` (advance) or `batch.forward()`: the ids of the sims in which MuJoCo raised
    (they kept their state; the others ran to the end), with one warning that says so."""
    try:
        batch.step() if advance else batch.forward()
    except SimulationError as e:
        warnings.warn(
            f"The native engine reports these sims as NaN (the env resets them): {e}",
            RuntimeWarning,
            stacklevel=2,
        )
        return np.asarray(e.ids, int)
    return np.zeros(0, int)


def native_suits(model: mujoco.MjModel) -> bool:
    """Whether the native engine's copied state (time, qpos, qvel) is the whole of `model`'s:
    no actuator activations, mocap bodies or plugins."""
    return not (model.na or model.nmocap or model.nplugin)


def resolve_engine(engine: str, model: mujoco.MjModel | None = None) -> str:
    """`engine` ('mjx' or 'native') as given; 'auto' resolved to 'native' where JAX runs on a
    CPU with one device (it steps the env 1.6-2.4x as fast as MJX there and compiles about 3x
    faster: docs/benchmarks-cpu.md, "The env against MuJoCo C's physics alone") and `model`, if
    given, `native_suits`; else to 'mjx' (an accelerator, or several devices or processes, over
    which a run shards MJX's batch: `dpc_mjx.devices`). Starts JAX's backend: call it where the
    env is built, not at import."""
    if engine not in ENGINE_CHOICES:
        raise DpcError(f"engine={engine!r} is not valid; choose one of {list(ENGINE_CHOICES)}.")
    if engine != AUTO:
        return engine
    on_one_cpu = jax.default_backend() == "cpu" and jax.device_count() == 1
    return "native" if on_one_cpu and (model is None or native_suits(model)) else "mjx"


def make_physics(engine: str, model: mujoco.MjModel, mx: mjx.Model) -> MjxPhysics | NativePhysics:
    """The engine named `engine` (`ENGINES`) for a compiled model and its MJX copy."""
    if engine == "mjx":
        return MjxPhysics(mx)
    if engine == "native":
        return NativePhysics(model)
    raise DpcError(f"engine={engine!r} is not valid; choose one of {list(ENGINES)}.")


__all__ = [
    "AUTO",
    "ENGINES",
    "ENGINE_CHOICES",
    "ENGINE_NAMES",
    "INPUTS",
    "OUTPUTS",
    "MjxPhysics",
    "NativePhysics",
    "make_physics",
    "native_suits",
    "resolve_engine",
]
