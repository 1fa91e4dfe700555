"""The command line's persistent compilation cache (`dpc_mjx/compile_cache.py`): on by default in
a folder of the user's cache named after this machine's backend and CPU, the environment's choice
first (a folder, or empty: off), a folder set before in the process kept; a second process reads
the entries back without the messages every read writes, and a process on another CPU reads none.
"""

import os
import pathlib
import re
import subprocess
import sys

import jax
import pytest
from jax._src import compilation_cache as jax_cache

from dpc_mjx import compile_cache

HITS = "/jax/compilation_cache/cache_hits"
REQUESTS = "/jax/compilation_cache/compile_requests_use_cache"
MESSAGES = ("cpu_aot_loader", "Assume version compatibility")  # what a plain read prints

# A fresh process: `enable()` (after `{patch}`), then one tiny jitted program written to the cache
# whatever its compile time; prints the folder, the cache hits and the compiles that asked it.
_PROGRAM = """
import jax, jax.numpy as jp
from dpc_mjx import compile_cache
events = []
jax.monitoring.register_event_listener(lambda event, **kw: events.append(event))
{patch}
folder = compile_cache.enable()
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
jax.jit(lambda x: jp.sin(x) @ x.T + 1)(jp.ones((4, 4))).block_until_ready()
print(folder, events.count({hits!r}), events.count({requests!r}))
"""


def _env(cache_home: pathlib.Path, **extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != compile_cache.VARIABLE}
    return {**env, "XDG_CACHE_HOME": str(cache_home), **extra}


def _run(env: dict, patch: str = "") -> tuple[str, int, int, str]:
    """(folder, hits, cache requests, stderr) of `_PROGRAM` in a fresh process."""
    code = _PROGRAM.format(patch=patch, hits=HITS, requests=REQUESTS)
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    folder, hits, requests = out.stdout.split()[-3:]
    return folder, int(hits), int(requests), out.stderr


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> tuple[dict, str]:
    """A cache home whose folder for this machine holds the program's entries: (env, folder)."""
    env = _env(tmp_path_factory.mktemp("cache_home"))
    folder, hits, requests, _ = _run(env)
    assert hits == 0 and requests > 0 and any(pathlib.Path(folder).iterdir())
    return env, folder


def _enable_in_a_fresh_process(env: dict) -> str:
    code = "from dpc_mjx import compile_cache; print(compile_cache.enable())"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.strip().splitlines()[-1]


def test_on_by_default_in_the_users_cache_folder_of_this_machine(tmp_path):
    folder = _enable_in_a_fresh_process(_env(tmp_path))
    assert folder == str(tmp_path / "dpc_mjx" / "jax" / compile_cache.machine_key())
    backend, cpu_and_hash = compile_cache.machine_key().split("-", 1)
    assert backend == compile_cache.backend_name()  # 'cpu' here: no accelerator plugin
    assert re.fullmatch(r"[a-z0-9.-]+-[0-9a-f]{10}", cpu_and_hash)


def test_the_environment_decides_a_folder_or_off(tmp_path):
    env = dict(os.environ)
    env[compile_cache.VARIABLE] = str(tmp_path / "mine")
    assert _enable_in_a_fresh_process(env) == str(tmp_path / "mine")  # as it is: no CPU folder
    env[compile_cache.VARIABLE] = ""
    assert _enable_in_a_fresh_process(env) == "None"


def test_a_folder_set_before_in_the_process_is_kept():
    before = jax.config.jax_compilation_cache_dir  # the test suite's (tests/conftest.py)
    assert before and compile_cache.enable() == before
    assert jax.config.jax_compilation_cache_dir == before
    assert compile_cache.default_folder().parts[-3:-1] == ("dpc_mjx", "jax")


_X86 = """processor\t: 0
vendor_id\t: GenuineIntel
cpu family\t: 6
model\t\t: 207
model name\t: Intel(R) Xeon(R) Gold 6338 CPU @ 2.00GHz
flags\t\t: fpu sse2 avx2 avx512f
bugs\t\t: spectre_v1

processor\t: 1
vendor_id\t: GenuineIntel
"""


def test_the_key_names_the_cpu_and_changes_with_its_instruction_sets(tmp_path, monkeypatch):
    cpuinfo = tmp_path / "cpuinfo"
    monkeypatch.setattr(compile_cache, "CPUINFO", cpuinfo)
    monkeypatch.setattr(compile_cache, "backend_name", lambda: "cpu")
    cpuinfo.write_text(_X86)
    key = compile_cache.machine_key()
    assert key.startswith("cpu-intel-xeon-gold-6338-")
    cpuinfo.write_text(_X86.replace(" avx512f", ""))  # the same model name, no AVX-512
    assert compile_cache.machine_key() not in (key, "")
    arm = "processor\t: 0\nFeatures\t: fp asimd sve\nCPU implementer\t: 0x41\nCPU part\t: 0xd40\n"
    cpuinfo.write_text(arm)
    assert compile_cache.machine_key().startswith("cpu-arm-0x41-0xd40-")
    monkeypatch.setattr(compile_cache, "CPUINFO", tmp_path / "none")  # not Linux
    assert compile_cache.cpu_description()[1] == []


_LOG = b"E1205 19:59:49.268940    2704 cpu_aot_loader.cc:220] "
_AOT = (
    b"Loading XLA:CPU AOT result. Target machine feature +%s is not  supported on the host "
    b"machine. Machine type used for XLA:CPU compilation doesn't match the machine type for "
    b"execution. Compile machine features: [+avx2,+prefer-no-gather] vs host machine features: "
    b"[avx2]. This could lead to execution errors such as SIGILL.\n"
)


def test_only_the_spurious_lines_are_dropped():
    pjrt = b"W1205 19:59:49.267686    2693 pjrt_executable.cc:642] Assume version compatibility. "
    assert compile_cache.is_spurious(pjrt + b"PjRt-IFRT does not track XLA executable versions.\n")
    assert compile_cache.is_spurious(_LOG + _AOT % b"prefer-no-gather")
    assert compile_cache.is_spurious(_LOG + _AOT % b"prefer-no-scatter")
    assert not compile_cache.is_spurious(_LOG + _AOT % b"avx512f")  # a real mismatch: printed
    assert not compile_cache.is_spurious(_LOG + b"prefer-no-gather: some other message\n")


def test_a_second_process_reads_back_without_the_messages(written):
    env, folder = written
    again, hits, requests, stderr = _run(env)
    assert again == folder and hits == requests > 0  # every program read back
    assert not [m for m in MESSAGES if m in stderr], stderr
    # The same read without `quiet_reads` prints them (jaxlib 0.9.2: PjRt's on every read).
    *_, plain = _run(env, "compile_cache.quiet_reads = lambda: False")
    assert MESSAGES[1] in plain


def test_a_process_on_another_cpu_reads_none_of_this_ones(written):
    env, folder = written
    other = "compile_cache.machine_key = lambda: 'cpu-another-cpu-0123456789'"
    elsewhere, hits, requests, _ = _run(env, other)
    assert pathlib.Path(elsewhere).name == "cpu-another-cpu-0123456789" != pathlib.Path(folder).name
    assert hits == 0 and requests > 0  # compiled again, into its own folder


def _claim_a_feature(entry: pathlib.Path) -> bytes | None:
    """Rewrite a cache entry as if compiled on a CPU with one more feature than this one (the
    first `-feature` of its recorded target made `+feature`); that feature, None if none."""
    raw = jax_cache.decompress_executable(entry.read_bytes())
    found = re.search(rb",-([a-z0-9][a-z0-9._-]*),", raw)
    if found is None:
        return None
    raw = raw.replace(b",-%s," % found[1], b",+%s," % found[1])
    entry.write_bytes(jax_cache.compress_executable(raw))
    return found[1]


def test_a_real_mismatch_is_still_printed(tmp_path):
    env = {**_env(tmp_path), compile_cache.VARIABLE: str(tmp_path / "mine")}  # read as it is
    _run(env)  # its own entries: jax's keys depend on the folder's path (a copy is never read)
    entries = (tmp_path / "mine").glob("jit_*-cache")
    claimed = [f for e in entries if (f := _claim_a_feature(e))]
    if not claimed:
        pytest.skip("no entry records a feature this CPU lacks")
    _, hits, _, stderr = _run(env)
    assert hits > 0 and "feature +prefer-no-" not in stderr and MESSAGES[1] not in stderr
    for feature in claimed:
        assert f"Target machine feature +{feature.decode()} is not" in stderr
