"""The low-level controller's own test bench: the controller alone on MJX physics (or MuJoCo C's,
`physics=NativePhysics(model)`), with locomotion metrics.

This is not a second environment. Envs (`dpc_mjx.envs`, stepped by `dpc_mjx.envs.rollout`) are
what policies, evaluation and data collection use: they add the policy rate (50 Hz), the arm's
reference motions, pushes, payloads, rewards and observations. The bench runs the controller at
the physics rate with none of that: a fixed command and an optional external trunk wrench, u
chosen per tick (mbc / oracle / observer / given). It measures what the controller achieves by
itself (tests/test_controller.py, experiments/locomotion.py, experiments/bench_controller.py)
and uses the library's one fall test (`control.state.has_fallen`).

One tick = read state, pick u, controller step, one physics step. A chunk of ticks runs under
`lax.scan` inside one jitted, vmapped call.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import jax
import jax.numpy as jp
import numpy as np
from flax import struct
from mujoco import mjx

from dpc_mjx import sim
from dpc_mjx.control import gait
from dpc_mjx.control.controller import ControllerState, LowLevelController, make_controller
from dpc_mjx.control.state import has_fallen, oracle_u, read_state
from dpc_mjx.controllers import Controller
from dpc_mjx.errors import DpcError
from dpc_mjx.physics import MjxPhysics, NativePhysics
from dpc_mjx.robots import build
from dpc_mjx.robots.standing import perturbed_home
from dpc_mjx.rotations import roll_pitch_yaw, to_yaw_frame

# The bench's u: a `Controller` but DPC (no policy runs here), or GIVEN: u as the caller passes it
GIVEN = "given"
CONTROLLERS = (Controller.MBC, Controller.ORACLE, Controller.OBSERVER, GIVEN)


@struct.dataclass
class LocoMetrics:
    """Running sums over the ticks before a fall (per env)."""

    ticks: jax.Array  # () ticks measured
    speed_sq_err: jax.Array  # () sum of (forward speed in the yaw frame - command)^2, (m/s)^2
    lateral_sq_err: jax.Array  # () same for lateral speed
    yaw_rate_sq_err: jax.Array  # () (rad/s)^2
    roll_sq: jax.Array  # () rad^2
    pitch_sq: jax.Array  # () rad^2
    fallen: jax.Array  # () bool, latched

    @classmethod
    def zeros(cls) -> LocoMetrics:
        z = jp.zeros(())
        return cls(z, z, z, z, z, z, jp.zeros((), bool))


@struct.dataclass
class LoopState:
    ctrl: ControllerState
    data: mjx.Data
    metrics: LocoMetrics


def make_chunk(
    mx: mjx.Model,
    controller: LowLevelController,
    n_ticks: int,
    kind: str = Controller.MBC,
    measure_after: float = 1.0,
    physics: MjxPhysics | NativePhysics | None = None,
) -> Callable:
    """jit(vmap) of `n_ticks` ticks: `(loop_state, command (B,3), wrench (B,6), u (B,6)) -> state`.

    `kind`: 'mbc' (u = 0), 'oracle' (u = measured mount wrench + the known external wrench),
    'observer' (u = the momentum observer's estimate, `step(..., u=None)`) or 'given' (u as
    passed). `wrench` is an external [force N, torque N·m] applied to the trunk at
    its COM (world frame) in the simulation. Metrics start after `measure_after` s. `physics`:
    what steps the simulation (default `MjxPhysics(mx)`; `dpc_mjx.physics.NativePhysics(model)`
    for MuJoCo C).
    """
    if kind not in CONTROLLERS:
        raise DpcError(
            f"Unknown controller {kind!r} for the bench; choose one of "
            f"{[str(c) for c in CONTROLLERS]} ('dpc': evaluate an env, `run.eval`)."
        )
    idx, lay = controller.idx, controller.lay
    trunk = idx.trunk
    physics = physics or MjxPhysics(mx)

    def tick(ls: LoopState, command, wrench, u_given):
        d = ls.data
        s = read_state(idx, d)
        known = jp.concatenate(  # the external wrench moved to the base's COM
            [wrench[:3], wrench[3:] + jp.cross(d.xipos[trunk] - s.com_pos, wrench[:3])]
        )
        if kind == Controller.MBC:
            u = jp.zeros(6)
        elif kind == Controller.ORACLE:
            u = oracle_u(lay, d, s.com_pos) + known
        elif kind == Controller.OBSERVER:
            u = None  # the controller's own observer estimate of this tick
        else:
            u = u_given
        cs, ctrl = controller.step(ls.ctrl, d, command, u)
        xfrc = d.xfrc_applied.at[trunk].set(wrench)
        d = physics.step(d.replace(ctrl=ctrl, xfrc_applied=xfrc))
        m = _update_metrics(ls.metrics, d, cs.t, command, measure_after, controller)
        return LoopState(cs, d, m)

    def chunk(ls, command, wrench, u):
        def body(carry, _):
            return tick(carry, command, wrench, u), None

        return jax.lax.scan(body, ls, None, length=n_ticks)[0]

    return jax.jit(jax.vmap(chunk))


def _update_metrics(m: LocoMetrics, d, t, command, measure_after, ctl) -> LocoMetrics:
    rpy = roll_pitch_yaw(d.qpos[3:7])
    fwd, lat, _ = to_yaw_frame(d.qvel[0:3], rpy[2])  # m/s, yaw frame
    yaw_rate = (d.xmat[ctl.idx.trunk] @ d.qvel[3:6])[2]
    fallen = has_fallen(d.qpos[2], rpy[:2], ctl.fall_height)
    fallen = m.fallen | fallen | ~jp.all(jp.isfinite(d.qpos))
    w = ((t >= measure_after) & ~fallen).astype(jp.float32)
    return LocoMetrics(
        ticks=m.ticks + w,
        speed_sq_err=m.speed_sq_err + w * (fwd - command[0]) ** 2,
        lateral_sq_err=m.lateral_sq_err + w * (lat - command[1]) ** 2,
        yaw_rate_sq_err=m.yaw_rate_sq_err + w * (yaw_rate - command[2]) ** 2,
        roll_sq=m.roll_sq + w * rpy[0] ** 2,
        pitch_sq=m.pitch_sq + w * rpy[1] ** 2,
        fallen=fallen,
    )


def init_loop(controller: LowLevelController, data: mjx.Data) -> LoopState:
    """Batched loop state from batched data (committed to the device)."""
    ctrl = jax.jit(jax.vmap(controller.init))(data)
    metrics = jax.vmap(lambda _: LocoMetrics.zeros())(jp.arange(data.qpos.shape[0]))
    return sim.commit(LoopState(ctrl, data, metrics))


def summarize(m: LocoMetrics) -> dict[str, float]:
    """Batch summary: fall rate, and RMS errors over the envs that did not fall."""
    m = jax.device_get(m)
    ok = ~np.asarray(m.fallen)
    ticks = max(float(np.sum(m.ticks[ok])), 1.0)

    def rms(x):
        return float(np.sqrt(np.sum(np.asarray(x)[ok]) / ticks)) if ok.any() else float("nan")

    return {
        "fall_rate": float(np.mean(~ok)),
        "speed_rmse": rms(m.speed_sq_err),
        "lateral_rmse": rms(m.lateral_sq_err),
        "yaw_rate_rmse": rms(m.yaw_rate_sq_err),
        "roll_rms": rms(m.roll_sq),
        "pitch_rms": rms(m.pitch_sq),
    }


def run_locomotion(
    variant: str,
    gait_name: str,
    commands,
    n_envs: int = 32,
    seconds: float = 20.0,
    kind: str = Controller.MBC,
    seed: int = 0,
    chunk_ticks: int = 250,
) -> list[dict[str, float]]:
    """Run `n_envs` perturbed robots of `variant` for each command (forward m/s, lateral m/s,
    yaw rate rad/s) with one compiled chunk; return one `summarize` dict per command, plus the
    measured env-steps/s and compile time."""
    gaits = {"trot": gait.trot, "stand": gait.stand}
    if gait_name not in gaits:
        raise DpcError(f"Unknown gait {gait_name!r}; choose one of {sorted(gaits)}.")
    model = build(variant)
    mx = sim.put_model(model)
    controller = make_controller(model, gait_=gaits[gait_name]())
    chunk = make_chunk(mx, controller, chunk_ticks, kind)
    n_chunks = max(1, round(seconds / model.opt.timestep / chunk_ticks))
    rows = []
    for i, command in enumerate(commands):
        data = sim.batched_data(
            mx,
            perturbed_home(model, n_envs, seed=seed + i),
            np.tile(model.key_ctrl[0], (n_envs, 1)),
        )
        ls = init_loop(controller, data)
        cmd = jp.tile(jp.asarray(command, jp.float32), (n_envs, 1))
        zeros = jp.zeros((n_envs, 6))
        t0 = time.perf_counter()
        ls = jax.block_until_ready(chunk(ls, cmd, zeros, zeros))
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        for k in range(1, n_chunks):
            ls = chunk(ls, cmd, zeros, zeros)
            if k % 10 == 0:
                print(
                    f"  {variant} {gait_name} {kind} cmd={tuple(command)}: "
                    f"{k * chunk_ticks * model.opt.timestep:.0f}/{seconds:.0f} s",
                    flush=True,
                )
        jax.block_until_ready(ls)
        run = time.perf_counter() - t0
        row = summarize(ls.metrics)
        row["steps_per_s"] = n_envs * chunk_ticks * (n_chunks - 1) / max(run, 1e-9)
        row["first_call_s"] = first  # compile (first command only) + one chunk
        rows.append(row)
    return rows
