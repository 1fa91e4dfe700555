"""dpc_mjx.xla_flags: which XLA flags are added to XLA_FLAGS, and that jax starts with them."""

import os
import subprocess
import sys

from dpc_mjx import xla_flags

SCHEDULER = "xla_cpu_enable_concurrency_optimized_scheduler"


def knows(name: str) -> bool:
    return True  # stands in for a jaxlib that knows every flag


def test_a_flag_is_appended_once_and_a_users_setting_is_kept():
    assert xla_flags.with_flags("", knows=knows) == f"--{SCHEDULER}=false"
    assert xla_flags.with_flags(" --xla_foo=1 ", knows=knows) == f"--xla_foo=1 --{SCHEDULER}=false"
    mine = f"--{SCHEDULER}=true --xla_foo=1"
    assert xla_flags.with_flags(mine, knows=knows) == mine
    assert xla_flags.with_flags(f"--{SCHEDULER}", knows=knows) == f"--{SCHEDULER}"
    added_once = xla_flags.with_flags("", knows=knows)
    assert xla_flags.with_flags(added_once, knows=knows) == added_once


def test_a_flag_the_installed_jaxlib_does_not_know_is_never_added():
    assert xla_flags.with_flags("--xla_foo=1", knows=lambda name: False) == "--xla_foo=1"
    assert not xla_flags.jaxlib_knows("xla_cpu_no_such_flag_dpc_mjx")
    # The jaxlibs of constraints.txt and of `make test-latest` know it; a jaxlib that dropped
    # the flag makes this fail, and the docs' reason for the flag must then be checked again.
    assert xla_flags.jaxlib_knows(SCHEDULER)


def _import_in_a_fresh_python(xla_flags_env: str | None) -> str:
    """XLA_FLAGS after `import dpc_mjx` in a new process that then runs a jax computation."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if xla_flags_env is not None:
        env["XLA_FLAGS"] = xla_flags_env
    code = (
        "import os, dpc_mjx, jax.numpy as jp; assert float(jp.ones(3).sum()) == 3.0; "
        "print(os.environ['XLA_FLAGS'])"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert out.returncode == 0, out.stderr[-2000:]  # an unknown XLA flag aborts the process
    return out.stdout.strip().splitlines()[-1]


def test_importing_dpc_mjx_sets_the_flag_before_jax_starts():
    assert _import_in_a_fresh_python(None) == f"--{SCHEDULER}=false"
    assert _import_in_a_fresh_python(f"--{SCHEDULER}=true") == f"--{SCHEDULER}=true"
