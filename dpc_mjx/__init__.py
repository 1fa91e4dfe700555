"""dpc_mjx: Disturbance Predictive Control for legged mobile manipulation in MuJoCo MJX."""

import contextlib as _contextlib
import io as _io

from dpc_mjx import xla_flags  # noqa: F401  (first: sets XLA_FLAGS before jax starts a backend)
from dpc_mjx._version import __version__

# mujoco.mjx prints "Failed to import warp" when the optional GPU backend is absent; we use the
# JAX backend, so import it once here with that message silenced.
with _contextlib.redirect_stdout(_io.StringIO()):
    from mujoco import mjx  # noqa: F401

from dpc_mjx import adapter, control, deploy, envs, io, physics, robots, sac  # noqa: E402
from dpc_mjx.envs import make  # noqa: E402
from dpc_mjx.errors import DpcError  # noqa: E402
from dpc_mjx.run.sweep import sweep  # noqa: E402

__all__ = [
    "DpcError",
    "__version__",
    "adapter",
    "control",
    "deploy",
    "envs",
    "io",
    "make",
    "physics",
    "robots",
    "sac",
    "sweep",
]
