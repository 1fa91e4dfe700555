"""Helpers shared by the test modules (pytest puts this folder on the import path)."""

import contextlib
import functools

import jax
import mujoco
import numpy as np
from brax.envs.base import Wrapper

# XLA's backend optimisation off: compiles ~40% shorter, steps ~10x slower. For tests that compile
# a program to take a handful of steps (compile time dominates the test run), never for timing.
FAST_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True}

# The physics of the envs in tests that do not test MJX itself (issue 26: "tests that do not test
# MJX itself use the faster path"): MuJoCo C through `mujoco.batch` (`dpc_mjx/physics.py`), whose
# env programs compile about 3x faster (experiments/bench_limit.py in docs/benchmarks-cpu.md: a
# 10-step chunk, batch 64, 37 s native against 103 s under MJX). MJX keeps its own tests:
# test_mjx, test_objects, test_controller, test_eval_regression, test_sweep, test_physics,
# test_devices.
ENGINE = "native"


# Env options of a robot standing still: standing gait, no commands, no pushes, exact sensors
STANDING_STILL = {
    "gait": "stand",
    "push_force": (0.0, 0.0),
    "sensor_noise": 0.0,
    "sensor_delay": 0,
    **{k: (0.0, 0.0) for k in ("command_vx", "command_vy", "command_yaw")},
}

_JIT = jax.jit


def fast_jit(fun=None, **kwargs):
    """`jax.jit` with FAST_COMPILE unless told otherwise: monkeypatched over `jax.jit` by tests
    that run a library entry point (transfer, evaluation, render) for a few steps."""
    kwargs.setdefault("compiler_options", FAST_COMPILE)
    if fun is None:
        return functools.partial(fast_jit, **kwargs)
    return _JIT(fun, **kwargs)


class CountTraces(Wrapper):
    """Counts how often `step` is traced (a Python side effect runs only while tracing)."""

    def __init__(self, env):
        super().__init__(env)
        self.traces = 0

    def step(self, state, action):
        self.traces += 1
        return self.env.step(state, action)


@contextlib.contextmanager
def _duration_events(pick):
    """Yields a list of `pick(event, fun_name)` for each JAX duration event of the block for
    which it is not None."""
    seen = []

    def listener(event, duration, fun_name="", **_):
        del duration
        item = pick(event, fun_name)
        if item is not None:
            seen.append(item)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield seen
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def recorded_compiles():
    """Yields a list that collects the JAX compile events of the block."""
    return _duration_events(lambda event, _: event if "compile" in event else None)


def lowered_programs():
    """Yields a list of the name of every function the block lowers to a program (JAX's
    jaxpr-to-MLIR event, which fires whether or not the persistent cache then holds it)."""
    lowering = "/jax/core/compile/jaxpr_to_mlir_module_duration"
    return _duration_events(lambda event, name: name if event == lowering else None)


def model_bytes(model: mujoco.MjModel) -> bytes:
    """A compiled model's bytes (`mj_saveModel`), to compare two models exactly."""
    buffer = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()
