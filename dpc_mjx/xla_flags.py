"""The XLA flags this library sets for the CPU, each only on the jaxlib versions it was measured on.

`--xla_cpu_enable_concurrency_optimized_scheduler=false` (`SCHEDULER`, jaxlib 0.10.2): with XLA's
default (the concurrency-optimised scheduler for CPU programs), a batched MJX env step,
`jax.jit(jax.vmap(env.step))` at batch 1024, stopped for good (every thread asleep, no CPU used)
in 4 of 7 processes on jaxlib 0.10.2 on a 2-core CPU, and in 0 of 7 with the flag. jaxlib 0.9.2
ran the same step with and without it. It only changes how the CPU compiler orders
instructions, not its arithmetic.

`--xla_cpu_use_fusion_emitters=false` (`OLDER_EMITTERS`, jaxlib 0.9.2, the pinned version):
XLA:CPU's older loop emitters instead of its MLIR fusion emitters. The env step, many small
fusions (the balance QP, the random draws), compiles about a third faster with the same steps/s
(docs/benchmarks-cpu.md, "Compile time with the older fusion emitters"). The same HLO, so the same
arithmetic up to rounding (how a loop is vectorised, where FMA contracts): the spread between two
CPUs, which the recorded evaluations allow. Programs compiled before it (the shipped export's
training, the published tables until 2026-12-03) ran without it; `XLA_FLAGS=` reproduces them.
`--xla_backend_optimization_level=1` (`LLVM_O1`, jaxlib 0.9.2): LLVM's -O1 instead of its -O3
for the CPU kernels XLA emits. The env step compiles about 40 % faster and the reset about 3x
(native, batch 64, one core: 32 -> 18.5 s and 17 -> 5.4 s of XLA compile) at the same env
steps/s at batch 64 and 256 (docs/benchmarks-cpu.md, "LLVM's optimisation level"); level 0 compiles
faster still but runs the env 2.5x slower. Dense products and other library calls are not
emitted by LLVM and do not change; the arithmetic is the same IEEE operations, vectorised and
scheduled differently (rounding-level differences, like the emitters').
The flags concern XLA's CPU backend only; GPU programs are compiled as without them.

Rules (`dpc_mjx/__init__.py` calls `apply()` once, first thing; it imports no jax and opens no
file):
- XLA_FLAGS set in the environment, to anything (an empty string too), is left byte-identical:
  the user decides (`XLA_FLAGS=` runs XLA's defaults);
- otherwise XLA_FLAGS is set to the installed jaxlib's flags (`importlib.metadata`;
  `FLAGS_BY_JAXLIB`, the versions they were measured on and known to: XLA aborts the whole
  process on a flag it does not know, and flags come and go between releases), only where the
  CPU backend can start (JAX_PLATFORMS unset or naming `cpu`);
- XLA reads XLA_FLAGS once, when jax starts its first backend (the first array or
  `jax.devices()`), not at `import jax`. `import dpc_mjx` imports no jax, so importing it first
  is enough; a process that computed with jax before importing dpc_mjx runs without the flags
  (jax has no public call that says whether its backends started, so this is not detected).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from importlib import metadata

SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
OLDER_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
LLVM_O1 = "--xla_backend_optimization_level=1"

# jaxlib version -> the flags measured on it (docs/decisions.md, "Packaging and versions"): 0.10.2
# hung without SCHEDULER (OLDER_EMITTERS and LLVM_O1 not measured there); 0.9.2 compiles a third
# faster with OLDER_EMITTERS, faster again with LLVM_O1, and ran without SCHEDULER. Not measured:
# every other version.
FLAGS_BY_JAXLIB: dict[str, tuple[str, ...]] = {
    "0.9.2": (OLDER_EMITTERS, LLVM_O1),
    "0.10.2": (SCHEDULER,),
}


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
    if "XLA_FLAGS" in environ or jaxlib not in FLAGS_BY_JAXLIB:
        return None
    if not cpu_backend_allowed(environ.get("JAX_PLATFORMS")):
        return None
    return " ".join(FLAGS_BY_JAXLIB[jaxlib])


def apply() -> None:
    """Set XLA_FLAGS to the jaxlib's flags where the rules of the module docstring say so."""
    flags = flags_for(os.environ, jaxlib_version())
    if flags is not None:
        os.environ["XLA_FLAGS"] = flags
