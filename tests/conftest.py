"""Shared test set-up: the library's XLA flags, a persistent JAX compilation cache, and
the test files ordered longest first so that `make test`'s two workers (`-n 2 --dist loadfile`: a
file at a time) finish together instead of one waiting on the other's last long file."""

import os
import pathlib

import jax

# `import dpc_mjx` before jax's first array (importing jax starts no backend): it sets XLA_FLAGS,
# where unset, to the pinned jaxlib's flags (`dpc_mjx.xla_flags`: XLA:CPU's older fusion
# emitters and LLVM -O1, about half the compile), and the tests' subprocesses inherit them.
import dpc_mjx  # noqa: F401

_CACHE = pathlib.Path(__file__).resolve().parents[1] / ".cache" / "jax"
jax.config.update("jax_compilation_cache_dir", os.environ.get("DPC_JAX_CACHE", str(_CACHE)))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

# The files that compile most, longest first, from `pytest --durations` of a cold `make test`
# (docs/commands.md, "make test"; 2026-12-03); every other file runs after them in collection order.
# A stale order costs only balance between the workers, never a test.
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
