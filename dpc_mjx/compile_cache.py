"""JAX's persistent compilation cache for the command line: a program compiled once is read back
from disk by the next process that builds the same one (same HLO, jax, XLA flags and device).

`dpc-mjx` turns it on (`enable`) in a folder of the user's cache, `default_folder()`:
`$XDG_CACHE_HOME/dpc_mjx/jax/<machine>` (else `~/.cache/dpc_mjx/jax/<machine>`), where
`<machine>` (`machine_key()`) names what makes a compiled program valid here: the backend jax is
set to run on, then the CPU's model and a hash of its instruction-set features, e.g.
`cpu-intel-xeon-processor-3f9a2c41d0` (`/proc/cpuinfo` on Linux: vendor, family, model, model
name and flags; elsewhere `platform.machine()` and `platform.processor()`). Home folders shared
between nodes of different CPUs (a cluster's) thus hold one folder per CPU, and no node ever
reads programs compiled for another CPU's instruction set (which can die with SIGILL). The
environment decides first:

    JAX_COMPILATION_CACHE_DIR=/some/folder   that folder, as it is (jax's own variable)
    JAX_COMPILATION_CACHE_DIR=               off (set and empty)

and a cache folder set before in the same process (a test suite's, an application's) is kept.
Library calls (`import dpc_mjx`) never turn it on by themselves: `enable()` is the caller's choice.

Quiet reads (`quiet_reads`). Every read of an XLA:CPU entry on an AVX-512 CPU makes jaxlib 0.9.2
log `cpu_aot_loader.cc] ... Target machine feature +prefer-no-gather is not supported on the host
machine ... SIGILL` (and `+prefer-no-scatter`), and every read on any backend `pjrt_executable.cc]
Assume version compatibility ...`: the first two name LLVM tuning preferences that XLA adds to the
features of every AVX-512 target and that no CPU reports (jax-ml/jax#38445, openxla/xla#44565),
the last is PjRt-IFRT saying it keeps no executable versions; none is about the entry read. While
jax reads an entry (`jax._src.compilation_cache.get_executable_and_time`, milliseconds),
file descriptor 2 is held in a temporary file, then written back without exactly those lines
(`is_spurious`). Every other line comes back, a `cpu_aot_loader` line naming a real feature
(`+avx512f`, `+amx-tile`) included; what any thread writes to stderr during a read comes after
it, and is lost only if the process dies inside the read.

What it cannot hold: programs with host callbacks, i.e. every env program of the native engine
(`dpc_mjx/physics.py` steps MuJoCo C through a callback; jax does not persist such executables),
so on a CPU, whose default engine is native, the cache serves the MJX programs, the adapter's and
the networks', not the native env's. Entries are written only for programs that took at least
`MIN_COMPILE_SECONDS` to compile; the folder is never pruned (delete it to reclaim the space).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import pathlib
import pkgutil
import platform
import re
import sys
import tempfile
import threading
from importlib import metadata

VARIABLE = "JAX_COMPILATION_CACHE_DIR"
MIN_COMPILE_SECONDS = 1.0  # s: cheaper programs are compiled again rather than read from disk
CPUINFO = pathlib.Path("/proc/cpuinfo")

# /proc/cpuinfo keys: what names the CPU (x86: model name; Arm: implementer and part) and its
# instruction sets (x86: flags; Arm: Features; RISC-V: isa).
_IDENTITY_KEYS = (
    "vendor_id",
    "cpu family",
    "model",
    "model name",
    "CPU implementer",
    "CPU architecture",
    "CPU variant",
    "CPU part",
    "Hardware",
    "uarch",
)
_FEATURE_KEYS = ("flags", "Features", "isa")
_NAME_KEYS = ("model name", "Hardware", "uarch", "cpu model")

# The lines a read of an entry writes that say nothing about the entry (module docstring): absl's
# prefix `E1205 19:59:49.268940    2704 file.cc:220] `, then the message, to its first words.
_SPURIOUS = re.compile(
    rb"[EW]\d{4} \d\d:\d\d:\d\d\.\d+ +\d+ (?:"
    rb"cpu_aot_loader\.cc:\d+\] Loading XLA:CPU AOT result\. Target machine feature "
    rb"\+prefer-no-(?:gather|scatter) is not +supported on the host machine\. .*"
    rb"This could lead to execution errors such as SIGILL\.$"
    rb"|pjrt_executable\.cc:\d+\] Assume version compatibility\. PjRt-IFRT does not track XLA "
    rb"executable versions\.$)"
)
_STDERR = 2  # the file descriptor C++ logs to
_READ_LOCK = threading.Lock()  # one read holds fd 2 at a time


def default_folder() -> pathlib.Path:
    """The user's cache folder for dpc_mjx's compiled programs on this machine."""
    root = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(root) / "dpc_mjx" / "jax" / machine_key()


def machine_key() -> str:
    """`<backend>-<cpu model>-<hash>`: the folder name of this machine's programs (module
    docstring). The hash (10 hex digits) covers the architecture and every line of
    `cpu_description()`, so two CPUs that differ in any instruction set get two folders."""
    identity, features = cpu_description()
    text = "\n".join([platform.machine(), *identity, " ".join(features)])
    digest = hashlib.sha256(text.encode()).hexdigest()[:10]
    return f"{backend_name()}-{_slug(_cpu_name(identity))}-{digest}"


def cpu_description() -> tuple[list[str], list[str]]:
    """(identity, features) of this machine's CPU: from `CPUINFO` (Linux) its first processor's
    `key: value` lines of `_IDENTITY_KEYS` and the sorted words of `_FEATURE_KEYS`; where there
    is no such file, `platform.machine()`'s and `platform.processor()`'s names, no features."""
    try:
        text = CPUINFO.read_text(errors="replace")
    except OSError:
        return [f"machine: {platform.machine()}", f"processor: {platform.processor()}"], []
    fields: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip() not in fields:  # the first processor's (all cores show the same)
            fields[key.strip()] = value.strip()
    identity = [f"{k}: {fields[k]}" for k in _IDENTITY_KEYS if k in fields]
    features = sorted({w for k in _FEATURE_KEYS for w in fields.get(k, "").split()})
    return identity, features


def _cpu_name(identity: list[str]) -> str:
    fields = dict(line.split(": ", 1) for line in identity)
    for key in _NAME_KEYS:
        if fields.get(key):
            return fields[key]
    if "CPU part" in fields:  # Arm: implementer and part numbers
        return f"arm-{fields.get('CPU implementer', '')}-{fields['CPU part']}"
    return fields.get("processor") or platform.machine() or "unknown"


def _slug(name: str, most: int = 32) -> str:
    """`Intel(R) Xeon(R) Gold 6338 CPU @ 2.00GHz` -> `intel-xeon-gold-6338`."""
    name = re.sub(r"\((?:r|tm|c)\)|\bcpu\b|@.*$", " ", name.lower())
    return re.sub(r"[^a-z0-9.]+", "-", name).strip("-.")[:most].rstrip("-.") or "unknown"


def backend_name() -> str:
    """The backend jax is set to run on, told without starting it (`jax.distributed` must come
    before any backend): the first of JAX_PLATFORMS (`jax_platforms`); else 'gpu' or 'tpu' where
    such a plugin is installed (jax prefers it), else 'cpu'. Each entry's own key also names its
    platform and devices (jax's `cache_key`), so a guess that is off costs only a second folder."""
    import jax  # noqa: PLC0415 (only once a command runs: `import dpc_mjx` imports no jax)

    first = (jax.config.jax_platforms or "").split(",")[0].strip().lower()
    if first:
        return "gpu" if first in ("cuda", "rocm") else _slug(first)
    plugins = {ep.name for ep in metadata.entry_points(group="jax_plugins")}
    if importlib.util.find_spec("jax_plugins") is not None:
        import jax_plugins  # noqa: PLC0415 (the namespace of jax's plugins, where installed)

        plugins |= {name for _, name, _ in pkgutil.iter_modules(jax_plugins.__path__)}
    if importlib.util.find_spec("libtpu") is not None or any("tpu" in p for p in plugins):
        return "tpu"
    if any("cuda" in p or "rocm" in p for p in plugins):
        return "gpu"
    return "cpu"


def is_spurious(line: bytes) -> bool:
    """Whether a line of stderr is one of the messages every cache read writes (module
    docstring): a `cpu_aot_loader` line about `+prefer-no-gather`/`+prefer-no-scatter` only, or
    PjRt's `Assume version compatibility`."""
    return _SPURIOUS.match(line.rstrip(b"\r\n")) is not None


def _flush_stderr() -> None:
    if sys.stderr is not None:  # None without a console (pythonw)
        sys.stderr.flush()


def _held_stderr(read, *args, **kwargs):
    """`read(*args, **kwargs)` with fd 2 held in a temporary file, then written back without the
    spurious lines; a plain read where there is no stderr or no temporary file."""
    try:
        held = tempfile.TemporaryFile()
    except OSError:  # no temporary folder: read as jax does
        return read(*args, **kwargs)
    with _READ_LOCK, held:
        try:
            saved = os.dup(_STDERR)
        except OSError:  # no stderr (a daemon's): nothing to hold
            return read(*args, **kwargs)
        _flush_stderr()
        os.dup2(held.fileno(), _STDERR)
        try:
            return read(*args, **kwargs)
        finally:
            _flush_stderr()
            os.dup2(saved, _STDERR)
            os.close(saved)
            held.seek(0)
            kept = [x for x in held.read().splitlines(keepends=True) if not is_spurious(x)]
            rest = b"".join(kept)
            while rest:  # a pipe may take part of it at a time
                rest = rest[os.write(_STDERR, rest) :]


def quiet_reads() -> bool:
    """Hold fd 2 through every read of the persistent cache (module docstring), once per
    process. jax has no public hook there: this wraps `jax._src.compilation_cache
    .get_executable_and_time`, which `jax._src.compiler` looks up at each read; False where this
    jax has none (then nothing changes: the messages are printed)."""
    try:
        from jax._src import compilation_cache  # noqa: PLC0415 (jax's reader of entries)
    except ImportError:
        return False
    read = getattr(compilation_cache, "get_executable_and_time", None)
    if read is None:
        return False
    if not getattr(read, "_dpc_quiet", False):

        def quiet_read(*args, **kwargs):
            return _held_stderr(read, *args, **kwargs)

        quiet_read._dpc_quiet = True  # type: ignore[attr-defined]
        compilation_cache.get_executable_and_time = quiet_read
    return True


def enable() -> str | None:
    """Turn on the persistent compilation cache for this process (module docstring); returns its
    folder, or None when it is off (`JAX_COMPILATION_CACHE_DIR` set and empty)."""
    import jax  # noqa: PLC0415 (only once a command runs: `import dpc_mjx` imports no jax)

    if jax.config.jax_compilation_cache_dir:  # set before: by the environment or the process
        folder = jax.config.jax_compilation_cache_dir
    elif VARIABLE in os.environ:  # set and empty: off
        return None
    else:
        folder = str(default_folder())
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    quiet_reads()
    return folder
