"""The command line's persistent compilation cache (`dpc_mjx/compile_cache.py`): on by default in
the user's cache folder, the environment's choice first (a folder, or empty: off), a folder set
before in the process kept."""

import os
import pathlib
import subprocess
import sys

import jax

from dpc_mjx import compile_cache


def _enable_in_a_fresh_process(env: dict) -> str:
    code = "from dpc_mjx import compile_cache; print(compile_cache.enable())"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.strip().splitlines()[-1]


def test_on_by_default_in_the_users_cache_folder(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != compile_cache.VARIABLE}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    assert _enable_in_a_fresh_process(env) == str(tmp_path / "dpc_mjx" / "jax")


def test_the_environment_decides_a_folder_or_off(tmp_path):
    env = dict(os.environ)
    env[compile_cache.VARIABLE] = str(tmp_path / "mine")
    assert _enable_in_a_fresh_process(env) == str(tmp_path / "mine")
    env[compile_cache.VARIABLE] = ""
    assert _enable_in_a_fresh_process(env) == "None"


def test_a_folder_set_before_in_the_process_is_kept():
    before = jax.config.jax_compilation_cache_dir  # the test suite's (tests/conftest.py)
    assert before and compile_cache.enable() == before
    assert jax.config.jax_compilation_cache_dir == before
    assert pathlib.Path(compile_cache.default_folder()).parts[-2:] == ("dpc_mjx", "jax")
