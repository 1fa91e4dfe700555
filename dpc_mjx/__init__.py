"""dpc_mjx: Disturbance Predictive Control for legged mobile manipulation in MuJoCo MJX."""

import contextlib
import io

# mujoco.mjx prints "Failed to import warp" when the optional GPU backend is absent; we use the
# JAX backend, so import it once here with that message silenced.
with contextlib.redirect_stdout(io.StringIO()):
    from mujoco import mjx  # noqa: F401

from dpc_mjx import envs, robots
from dpc_mjx.envs import make
from dpc_mjx.errors import DpcError

__version__ = "0.1.0"

__all__ = ["DpcError", "envs", "make", "robots", "__version__"]
