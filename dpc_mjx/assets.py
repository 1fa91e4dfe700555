"""Robot description files shipped by the `example-robot-data` wheel.

The wheel installs its URDFs under `cmeel.prefix/share/example-robot-data/robots/`; we find them
through the installed distribution's file list, so no path on this machine is hard-coded and nothing
is downloaded.
"""

from __future__ import annotations

import functools
import importlib.metadata
import pathlib

from dpc_mjx.errors import DpcError

_DIST = "example-robot-data"

# Short name -> URDF path inside the robots/ folder of the wheel.
URDFS = {
    "a1": "a1_description/urdf/a1.urdf",
    "so100": "so_arm_description/urdf/so100.urdf",
    "z1": "z1_description/urdf/z1.urdf",
}


@functools.cache
def _robots_dir() -> pathlib.Path:
    try:
        dist = importlib.metadata.distribution(_DIST)
    except importlib.metadata.PackageNotFoundError as e:
        raise DpcError(
            f"The '{_DIST}' package is not installed; it ships the A1 and arm URDFs. "
            "Install the project with `make install` (or `pip install -e .`)."
        ) from e
    for f in dist.files or ():
        parts = pathlib.PurePosixPath(str(f)).parts
        if "robots" in parts and parts[-1] == "a1.urdf":
            path = pathlib.Path(dist.locate_file(f))
            return path.parents[2]  # .../robots/a1_description/urdf/a1.urdf -> .../robots
    raise DpcError(
        f"The installed '{_DIST}' wheel has no robots/a1_description/urdf/a1.urdf; "
        "reinstall the pinned version from pyproject.toml."
    )


def urdf_path(name: str) -> pathlib.Path:
    """Path of the URDF named `name` (one of `URDFS`) inside the installed wheel."""
    if name not in URDFS:
        raise DpcError(f"No URDF named {name!r}; known: {sorted(URDFS)}.")
    path = _robots_dir() / URDFS[name]
    if not path.is_file():
        raise DpcError(f"{path} is missing from the '{_DIST}' wheel; reinstall it.")
    return path
