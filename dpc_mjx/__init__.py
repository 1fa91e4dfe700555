"""dpc_mjx: Disturbance Predictive Control for legged mobile manipulation in MuJoCo MJX.

`import dpc_mjx` loads this file, `errors`, `_version` and `xla_flags`, and no jax. It does two
things before any subpackage can start jax:
- `xla_flags.apply()`: sets XLA_FLAGS only where it is unset and the installed jaxlib is one
  measured to need the flag (docs/scaling.md, "XLA flags on a CPU"; `dpc_mjx/xla_flags.py`);
- keeps mujoco.mjx's two lines "Failed to import warp: ..." and "Failed to import mujoco_warp:
  ..." (printed when the optional GPU backend is absent; we use MJX's JAX backend) off stdout,
  wherever mjx is first imported (by dpc_mjx, by brax or by you): a finder that wraps the one
  module `mujoco.mjx.warp` and leaves `sys.meta_path` once that module has loaded.
The subpackages, `make`, `sweep` and `Controller` load on first use (PEP 562 `__getattr__`).
"""

from __future__ import annotations

import contextlib as _contextlib
import importlib as _importlib
import importlib.abc as _abc
import importlib.machinery as _machinery
import io as _io
import sys as _sys

from dpc_mjx import xla_flags
from dpc_mjx._version import __version__
from dpc_mjx.errors import DpcError

xla_flags.apply()

# Loaded on first use: subpackages (and the modules deploy, physics) by name, functions (and the
# `Controller` names) from their module.
_SUBMODULES = frozenset(
    ("adapter", "control", "deploy", "envs", "io", "physics", "policy", "robots", "run", "sac")
)
_FUNCTIONS = {
    "make": "dpc_mjx.envs",
    "sweep": "dpc_mjx.run.sweep",
    "Controller": "dpc_mjx.controllers",
}

__all__ = [
    "Controller",
    "DpcError",
    "__version__",
    "adapter",
    "control",
    "deploy",
    "envs",
    "io",
    "make",
    "physics",
    "policy",
    "robots",
    "run",
    "sac",
    "sweep",
]


def __getattr__(name: str):
    """`dpc_mjx.<name>` for the names loaded on first use (PEP 562)."""
    if name in _SUBMODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    if name in _FUNCTIONS:
        value = getattr(_importlib.import_module(_FUNCTIONS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


_WARP = "mujoco.mjx.warp"
_WARP_LINES = ("Failed to import warp:", "Failed to import mujoco_warp:")


class _QuietWarpLoader(_abc.Loader):
    """mujoco.mjx.warp's own loader, run with those two lines of its stdout dropped."""

    def __init__(self, loader: _abc.Loader):
        self.loader = loader

    def __getattr__(self, name: str):  # get_source, get_resource_reader ...: the real loader's
        if name == "loader":  # not set yet (a copy): no recursion
            raise AttributeError(name)
        return getattr(self.loader, name)

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module) -> None:
        out = _io.StringIO()
        try:
            with _contextlib.redirect_stdout(out):
                self.loader.exec_module(module)
        finally:
            lines = out.getvalue().splitlines(keepends=True)
            _sys.stdout.write("".join(s for s in lines if not s.startswith(_WARP_LINES)))


class _QuietWarpFinder(_abc.MetaPathFinder):
    """Finds `mujoco.mjx.warp` as Python would, with `_QuietWarpLoader`; then removes itself."""

    def find_spec(self, name: str, path=None, target=None):
        if name != _WARP:
            return None
        if self in _sys.meta_path:
            _sys.meta_path.remove(self)
        spec = _machinery.PathFinder.find_spec(name, path, target)
        if spec is not None and spec.loader is not None:
            spec.loader = _QuietWarpLoader(spec.loader)
        return spec


if _WARP not in _sys.modules:
    _sys.meta_path.insert(0, _QuietWarpFinder())
