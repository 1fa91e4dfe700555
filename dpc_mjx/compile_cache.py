"""JAX's persistent compilation cache for the command line: a program compiled once is read back
from disk by the next process that builds the same one (same HLO, jax, XLA flags and device).

`dpc-mjx` turns it on (`enable`) in a folder of the user's cache, `default_folder()`:
`$XDG_CACHE_HOME/dpc_mjx/jax`, else `~/.cache/dpc_mjx/jax`. The environment decides first:

    JAX_COMPILATION_CACHE_DIR=/some/folder   that folder (jax's own variable)
    JAX_COMPILATION_CACHE_DIR=               off (set and empty)

and a cache folder set before in the same process (a test suite's, an application's) is kept.
Library calls (`import dpc_mjx`) never turn it on by themselves: `enable()` is the caller's choice.

What it cannot hold: programs with host callbacks, i.e. every env program of the native engine
(`dpc_mjx/physics.py` steps MuJoCo C through a callback; jax does not persist such executables),
so on a CPU, whose default engine is native, the cache serves the MJX programs, the adapter's and
the networks', not the native env's. Entries are written only for programs that took at least
`MIN_COMPILE_SECONDS` to compile; the folder is never pruned (delete it to reclaim the space).
"""

from __future__ import annotations

import os
import pathlib

VARIABLE = "JAX_COMPILATION_CACHE_DIR"
MIN_COMPILE_SECONDS = 1.0  # s: cheaper programs are compiled again rather than read from disk


def default_folder() -> pathlib.Path:
    """The user's cache folder for dpc_mjx's compiled programs."""
    root = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(root) / "dpc_mjx" / "jax"


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
    return folder
