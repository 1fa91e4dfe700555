"""Shared test set-up: XLA:CPU's older fusion emitters, a persistent JAX compilation cache, and
the test files ordered longest first so that `make test`'s two workers (`-n 2 --dist loadfile`: a
file at a time) finish together instead of one waiting on the other's last long file."""

import os
import pathlib
from importlib import metadata

# XLA:CPU's loop-fusion code from its older emitters instead of the MLIR fusion emitters (XLA's
# default): the env and QP programs, which are many small fusions, compile ~30% faster with the
# same steps/s (docs/benchmarks.md, "Compile time with the older fusion emitters"). The same
# HLO, so the same arithmetic up to rounding (how a loop is vectorised, where FMA contracts),
# the spread the recordings already allow between CPUs. Set before jax starts its CPU backend
# (this module runs first), only for the jaxlib it was measured on (XLA aborts on a flag it does
# not know) and only where XLA_FLAGS is unset: a set XLA_FLAGS is left as it is, as
# `dpc_mjx.xla_flags` leaves it, and subprocesses inherit this one.
_OLDER_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
_OLDER_EMITTERS_JAXLIB = ("0.9.2",)
if "XLA_FLAGS" not in os.environ and metadata.version("jaxlib") in _OLDER_EMITTERS_JAXLIB:
    os.environ["XLA_FLAGS"] = _OLDER_EMITTERS

import jax  # noqa: E402  (after XLA_FLAGS)

_CACHE = pathlib.Path(__file__).resolve().parents[1] / ".cache" / "jax"
jax.config.update("jax_compilation_cache_dir", os.environ.get("DPC_JAX_CACHE", str(_CACHE)))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

# The files that compile most, longest first, from `pytest --durations` of a cold `make test`
# (README, "make test"; 2026-12-03); every other file runs after them in collection order. A
# stale order costs only balance between the workers, never a test.
_LONGEST_FIRST = (
    "test_qp.py",
    "test_eval_regression.py",
    "test_tasks.py",
    "test_devices.py",
    "test_sac.py",
    "test_adapter.py",
    "test_sweep.py",
    "test_mjx.py",
    "test_task_episodes.py",
    "test_deploy.py",
    "test_objects.py",
    "test_io.py",
    "test_own_arm.py",
    "test_balance.py",
    "test_controller.py",
    "test_bases.py",
    "test_observer.py",
    "test_object_bases.py",
    "test_envs.py",
    "test_physics.py",
)


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(_LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: file order kept
