"""dpc_mjx: Disturbance Predictive Control for legged mobile manipulation in MuJoCo MJX."""

import contextlib as _contextlib
import io as _io

# mujoco.mjx prints "Failed to import warp" when the optional GPU backend is absent; we use the
# JAX backend, so import it once here with that message silenced.
with _contextlib.redirect_stdout(_io.StringIO()):
    from mujoco import mjx  # noqa: F401

__version__ = "0.1.0"

from dpc_mjx import adapter, envs, io, robots, sac  # noqa: E402
from dpc_mjx.envs import make  # noqa: E402
from dpc_mjx.errors import DpcError  # noqa: E402

__all__ = ["DpcError", "__version__", "adapter", "envs", "io", "make", "robots", "sac"]
