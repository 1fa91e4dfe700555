"""XLA flags this library sets for the CPU backend, before jax starts its backends.

`--xla_cpu_enable_concurrency_optimized_scheduler=false`: with XLA's default (the
concurrency-optimised scheduler), a batched MJX env step, `jax.jit(jax.vmap(env.step))` at
batch 1024, never finished its first call on jax 0.10.2 on a 2-core CPU (every thread asleep, no
CPU used for 18 min); with the flag it compiles and runs in 57 s, then 0.57 s a step
(docs/decisions.md, "Packaging and versions"). The flag only changes how the CPU compiler orders
instructions, so GPU programs are unaffected.

Rules (`apply()` runs when this module is imported, first thing in `dpc_mjx/__init__.py`):
- a flag the user already set in XLA_FLAGS, with any value, is left as it is (so
  `XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=true` turns ours off);
- a flag is added only if the installed jaxlib knows it: XLA aborts the whole process on an
  unknown flag, and flags come and go between releases. "Knows" means its name is compiled into
  jaxlib's shared library (the flag table holds it; found in 20 ms on jaxlib 0.9.2 and 0.10.2);
- XLA reads XLA_FLAGS once, when the first backend starts (the first array or `jax.devices()`),
  not at `import jax`; if that already happened, we warn that the flag came too late.
"""

from __future__ import annotations

import importlib.util
import mmap
import os
import sys
import warnings
from pathlib import Path

# (name, value) of the flags we add; each entry's reason is in the module docstring.
FLAGS: tuple[tuple[str, str], ...] = (("xla_cpu_enable_concurrency_optimized_scheduler", "false"),)


def jaxlib_knows(name: str) -> bool:
    """Whether the installed jaxlib's XLA has the flag `name` (without the leading --)."""
    spec = importlib.util.find_spec("jaxlib")
    if spec is None or not spec.submodule_search_locations:
        return False
    libraries = [p for d in spec.submodule_search_locations for p in Path(d).glob("*.so")]
    needle = name.encode()
    for library in sorted(libraries, key=lambda p: -p.stat().st_size):  # XLA: the largest
        with open(library, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
            if m.find(needle) >= 0:
                return True
    return False


def is_set(xla_flags: str, name: str) -> bool:
    """Whether the XLA_FLAGS string `xla_flags` sets `name` (`--name`, `--name=value`)."""
    return any(f.split("=", 1)[0] == f"--{name}" for f in xla_flags.split())


def with_flags(xla_flags: str, flags=FLAGS, knows=jaxlib_knows) -> str:
    """`xla_flags` with every flag of `flags` appended that it does not set and jaxlib knows."""
    added = [f"--{n}={v}" for n, v in flags if not is_set(xla_flags, n) and knows(n)]
    return " ".join([xla_flags.strip(), *added]).strip()


def apply() -> None:
    """Add our flags to os.environ["XLA_FLAGS"] (the rules in the module docstring)."""
    current = os.environ.get("XLA_FLAGS", "")
    updated = with_flags(current)
    if updated == current:
        return
    os.environ["XLA_FLAGS"] = updated
    if "jax" in sys.modules and _backends_started():
        warnings.warn(
            f"dpc_mjx: jax started its backends before dpc_mjx was imported, so XLA ignores "
            f"XLA_FLAGS={updated!r}; batched MJX steps may hang on the CPU. Import dpc_mjx "
            f"first, or set XLA_FLAGS before starting Python.",
            stacklevel=2,
        )


def _backends_started() -> bool:
    try:
        from jax._src import xla_bridge  # private; present in jax 0.9 and 0.10

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):
        return False


apply()
