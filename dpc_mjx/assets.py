"""Robot description files: the URDFs shipped with dpc_mjx, and the optional wheel's others.

The named bases (A1, Go1, Go2, B1, and the B1 carrying a Z1) and arms (SO-100, Unitree Z1) are
built from verbatim copies of the `example-robot-data` 6.0.0 wheel's URDFs, committed as package
data in `dpc_mjx/descriptions/` (provenance and licences in its README.md; `URDFS` is the one
registry of them). Every named variant and base reads these copies, also where the wheel is
installed: one source, so every install builds the same model (tests/test_assets_offline.py checks
the copies against the wheel's files, and the models built from both). No named model reads a
mesh: the wheel's visual meshes are COLLADA, the bases collide through their feet only and the
arms never collide (`dpc_mjx.robots.urdf`), so renders draw primitives on every install (Go2's
trunk collision mesh, shipped in `descriptions/meshes/go2/`, only gives its box its size). The
repository's `mjcf/` folder (`dpc-mjx mjcf mjcf`) is an export of the variants built from these
files, not a source: an `ArmSpec` of your own or your own arm file needs the bare A1, and `mjcf/`
is not in the installed package.

The 440 MB wheel is optional (`pip install 'dpc_mjx[urdf]'`): `wheel_urdf` finds its other robots'
URDFs, through the installed distribution's file list (no path of this machine is hard-coded and
nothing is downloaded), e.g. to mount one as your own arm (`dpc_mjx.robots.arms.file`; its STL
meshes are drawn), `UrdfArm(str(wheel_urdf("so_arm_description/urdf/so101.urdf")))`.
"""

from __future__ import annotations

import functools
import importlib.metadata
import pathlib

from dpc_mjx.errors import DpcError

DESCRIPTIONS = pathlib.Path(__file__).parent / "descriptions"  # the committed URDFs

# Short name -> (file in DESCRIPTIONS, the path it was copied from under the wheel's robots/).
URDFS = {
    "a1": ("a1.urdf", "a1_description/urdf/a1.urdf"),
    "go1": ("go1.urdf", "go1_description/urdf/go1.urdf"),
    "go2": ("go2.urdf", "go2_description/urdf/go2.urdf"),
    "b1": ("b1.urdf", "b1_description/urdf/b1.urdf"),
    "b1-z1": ("b1-z1.urdf", "b1_description/urdf/b1-z1.urdf"),
    "so100": ("so100.urdf", "so_arm_description/urdf/so100.urdf"),
    "z1": ("z1.urdf", "z1_description/urdf/z1.urdf"),
}

WHEEL = "example-robot-data"
WHEEL_VERSION = "6.0.0"  # the version the committed copies come from
INSTALL_HINT = (
    f"`pip install 'dpc_mjx[urdf]'` (or `pip install {WHEEL}`), or give the "
    "path of the robot's own .urdf or MJCF .xml file"
)


def urdf_path(name: str) -> pathlib.Path:
    """Path of the committed URDF named `name` (one of `URDFS`); needs no wheel."""
    if name not in URDFS:
        raise DpcError(f"No URDF named {name!r}; known: {sorted(URDFS)}.")
    path = DESCRIPTIONS / URDFS[name][0]
    if not path.is_file():
        raise DpcError(
            f"{path} is missing from the installed dpc_mjx; reinstall it (`pip install .` ships "
            "dpc_mjx/descriptions/ as package data)."
        )
    return path


def wheel_urdf(path: str) -> pathlib.Path:
    """Path of the file `path` under the optional wheel's `robots/` folder (e.g.
    "so_arm_description/urdf/so101.urdf"); `DpcError` saying how to install the wheel if it is
    missing, or which robots it has if `path` is not among its files."""
    robots = _wheel_robots_dir()
    full = robots / path
    if not full.is_file():
        names = sorted(p.name for p in robots.iterdir() if p.is_dir())
        raise DpcError(
            f"The '{WHEEL}' wheel has no robots/{path}; its robots: {names} "
            "(their URDFs under <robot>/urdf/)."
        )
    return full


def wheel_installed() -> bool:
    """Whether the optional `example-robot-data` wheel is installed."""
    try:
        _wheel_robots_dir()
    except DpcError:
        return False
    return True


@functools.cache
def _wheel_robots_dir() -> pathlib.Path:
    """The wheel's `.../share/example-robot-data/robots` folder."""
    try:
        dist = importlib.metadata.distribution(WHEEL)
    except importlib.metadata.PackageNotFoundError as e:
        raise DpcError(
            f"This URDF comes from the optional '{WHEEL}' wheel (440 MB), which is not "
            f"installed; install it with {INSTALL_HINT}. The named variants need no wheel."
        ) from e
    for f in dist.files or ():
        parts = pathlib.PurePosixPath(str(f)).parts
        if parts[-2:] == ("urdf", "a1.urdf") and "robots" in parts:
            return pathlib.Path(dist.locate_file(f)).parents[2]  # robots/a1_description/urdf/
    raise DpcError(
        f"The installed '{WHEEL}' wheel has no robots/ folder of URDFs; reinstall it with "
        f"`pip install --force-reinstall {WHEEL}`."
    )
