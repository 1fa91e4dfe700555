"""What `import dpc_mjx` does: XLA_FLAGS only where `xla_flags` says, nothing else loaded, no
private jax module, no "Failed to import warp" on stdout."""

import os
import pathlib
import re
import subprocess
import sys

import dpc_mjx
from dpc_mjx import xla_flags

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "dpc_mjx"
SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
EMITTERS = "--xla_cpu_use_fusion_emitters=false"
LLVM_O1 = "--xla_backend_optimization_level=1"
ON_0_9_2 = f"{EMITTERS} {LLVM_O1}"  # a third faster compile, then ~40 % faster again


def test_the_flags_are_set_only_where_xla_flags_is_unset_on_a_jaxlib_measured_with_them():
    named = (xla_flags.SCHEDULER, xla_flags.OLDER_EMITTERS, xla_flags.LLVM_O1)
    assert named == (SCHEDULER, EMITTERS, LLVM_O1)
    assert xla_flags.flags_for({}, "0.10.2") == SCHEDULER  # hung without it
    assert xla_flags.flags_for({}, "0.9.2") == ON_0_9_2
    assert xla_flags.flags_for({"JAX_PLATFORMS": "cpu"}, "0.9.2") == ON_0_9_2
    assert xla_flags.flags_for({"JAX_PLATFORMS": "cuda, cpu"}, "0.10.2") == SCHEDULER
    assert xla_flags.flags_for({"JAX_PLATFORMS": "cuda"}, "0.9.2") is None  # no CPU backend
    for users in ("", " ", "--xla_cpu_max_isa=AVX2", SCHEDULER.replace("false", "true")):
        assert xla_flags.flags_for({"XLA_FLAGS": users}, "0.9.2") is None
        assert xla_flags.flags_for({"XLA_FLAGS": users}, "0.10.2") is None
    assert xla_flags.flags_for({}, "0.11.2") is None  # not measured: XLA may not know them
    assert xla_flags.flags_for({}, None) is None  # no jaxlib installed


def _fresh_python(code: str, xla_flags_env: str | None) -> str:
    """stdout of `code` in a new process whose XLA_FLAGS is `xla_flags_env` (None: unset)."""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_PLATFORMS")}
    if xla_flags_env is not None:
        env["XLA_FLAGS"] = xla_flags_env
    args = [sys.executable, "-c", code]
    out = subprocess.run(args, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert out.returncode == 0, out.stderr[-2000:]  # an unknown XLA flag aborts the process
    return out.stdout


def test_import_leaves_a_users_xla_flags_byte_identical_and_loads_no_subpackage():
    code = (
        "import os, sys, dpc_mjx; print(repr(os.environ['XLA_FLAGS'])); print(sorted(m for m in "
        "sys.modules if m.split('.')[0] in ('dpc_mjx', 'jax', 'jaxlib', 'mujoco', 'brax')))"
    )
    eager = "['dpc_mjx', 'dpc_mjx._version', 'dpc_mjx.errors', 'dpc_mjx.xla_flags']"
    for users in ("", "  --xla_cpu_enable_fast_math=false  ", EMITTERS.replace("false", "true")):
        assert _fresh_python(code, users).splitlines() == [repr(users), eager]


def test_import_sets_the_jaxlibs_flags_and_jax_starts_with_them():
    code = (
        "import os, dpc_mjx, jax.numpy as jp; assert float(jp.ones(3).sum()) == 3.0; "
        "print(repr(os.environ.get('XLA_FLAGS')))"
    )
    flags = xla_flags.FLAGS_BY_JAXLIB.get(xla_flags.jaxlib_version())
    expected = " ".join(flags) if flags else None
    assert _fresh_python(code, None).strip() == repr(expected)


def test_the_lazy_names_load_and_unknown_names_raise():
    assert set(dpc_mjx.__all__) <= set(dir(dpc_mjx))
    assert dpc_mjx.sac is sys.modules["dpc_mjx.sac"]
    assert dpc_mjx.make is dpc_mjx.envs.make
    assert dpc_mjx.sweep is sys.modules["dpc_mjx.run.sweep"].sweep
    try:
        dpc_mjx.no_such_name  # noqa: B018
    except AttributeError as e:
        assert "no_such_name" in str(e)
    else:
        raise AssertionError("dpc_mjx.no_such_name did not raise AttributeError")


def test_mjx_imported_after_dpc_mjx_prints_nothing():
    # mujoco.mjx prints "Failed to import warp: ..." when warp is absent (brax imports mjx too,
    # so dpc_mjx cannot import it first through a helper of its own).
    code = "import dpc_mjx; from mujoco import mjx; print(mjx.__name__)"
    assert _fresh_python(code, "") == "mujoco.mjx\n"


# The one exception, and why: jax has no public hook around its reads of the persistent cache,
# where jaxlib logs its false "SIGILL" lines; `compile_cache.quiet_reads` wraps that reader when
# the CLI turns the cache on, and changes nothing where a jax has none (docs/decisions-engines.md,
# "The compilation cache's reads").
_PRIVATE_READERS = {"compile_cache.py"}


def test_no_module_reads_a_private_jax_module_or_jaxlibs_files():
    private = re.compile(r"jax\._src|from jax import _src|find_spec\(\"jaxlib\"\)|\bmmap\b")
    readers = {
        p.relative_to(PACKAGE).as_posix()
        for p in PACKAGE.rglob("*.py")
        if private.search(p.read_text())
    }
    offenders = sorted(readers - _PRIVATE_READERS)
    assert not offenders, f"modules that read jax's private modules or jaxlib's files: {offenders}"
    assert readers == _PRIVATE_READERS, f"the exception is stale: {sorted(readers)}"
