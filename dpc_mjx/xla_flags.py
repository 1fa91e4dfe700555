"""The one XLA flag this library sets, only on the jaxlib versions measured to need it.

`--xla_cpu_enable_concurrency_optimized_scheduler=false`: with XLA's default (the
concurrency-optimised scheduler for CPU programs), a batched MJX env step,
`jax.jit(jax.vmap(env.step))` at batch 1024, stopped for good (every thread asleep, no CPU used)
in 4 of 7 processes on jaxlib 0.10.2 on a 2-core CPU, and in 0 of 7 with the flag. jaxlib 0.9.2
(the pinned version) ran the same step with and without it, so it gets nothing
(docs/decisions.md, "Packaging and versions"). The flag only changes how the CPU compiler orders
instructions, not its arithmetic, and GPU programs not at all.

Rules (`dpc_mjx/__init__.py` calls `apply()` once, first thing; it imports no jax and opens no
file):
- XLA_FLAGS set in the environment, to anything (an empty string too), is left byte-identical:
  the user decides (`XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=true` runs XLA's
  default);
- otherwise XLA_FLAGS is set to the flag only if the installed jaxlib's version
  (`importlib.metadata`) is in `NEEDS_FLAG`, the versions measured to hang without it and to
  know it (XLA aborts the whole process on a flag it does not know, and flags come and go
  between releases), and the CPU backend can start (JAX_PLATFORMS unset or naming `cpu`);
- XLA reads XLA_FLAGS once, when jax starts its first backend (the first array or
  `jax.devices()`), not at `import jax`. `import dpc_mjx` imports no jax, so importing it first
  is enough; a process that computed with jax before importing dpc_mjx runs without the flag
  (jax has no public call that says whether its backends started, so this is not detected).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from importlib import metadata

FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler=false"

# jaxlib versions measured to hang without FLAG and to start with it (docs/decisions.md).
# Measured without a hang, so not here: 0.9.2. Not measured: every other version.
NEEDS_FLAG: frozenset[str] = frozenset({"0.10.2"})


def jaxlib_version() -> str | None:
    """The installed jaxlib's version, None if jaxlib is not installed."""
    try:
        return metadata.version("jaxlib")
    except metadata.PackageNotFoundError:
        return None


def cpu_backend_allowed(jax_platforms: str | None) -> bool:
    """Whether JAX_PLATFORMS (`jax_platforms`, None when unset) lets jax start its CPU backend."""
    if not jax_platforms:
        return True
    return "cpu" in (p.strip() for p in jax_platforms.split(","))


def flags_for(environ: Mapping[str, str], jaxlib: str | None) -> str | None:
    """The XLA_FLAGS to set for this environment and jaxlib version, None to set nothing."""
    if "XLA_FLAGS" in environ or jaxlib not in NEEDS_FLAG:
        return None
    if not cpu_backend_allowed(environ.get("JAX_PLATFORMS")):
        return None
    return FLAG


def apply() -> None:
    """Set XLA_FLAGS to `FLAG` where the rules of the module docstring say it is needed."""
    flags = flags_for(os.environ, jaxlib_version())
    if flags is not None:
        os.environ["XLA_FLAGS"] = flags
