"""A user's own arm from a URDF or MJCF file: checked before anything is compiled, read as a spec.

What the library needs of the file: one tree of links (bodies) whose root we weld to the base's
trunk, at least one movable joint (URDF revolute, continuous or prismatic; MJCF hinge or slide), a
mass and an inertia on every link that moves, and the mesh files its geometry names. What it
infers (the end effector and home pose only when not told: `UrdfArm.ee_body`, `.home`):

- the root: the URDF's root link, skipping massless links welded on by a fixed joint (a `world`
  or `base_footprint` link); the MJCF's one top-level body;
- the end effector: the last link of the longest chain of movable joints (the first such chain);
- the home pose: every joint at 0 rad (m), kept HOME_MARGIN inside its range.

Meshes: paths relative to the file, `package://NAME/...` (NAME found as a folder above the file or
on ROS_PACKAGE_PATH), `file://` and absolute paths all resolve. Formats MuJoCo reads (STL, OBJ,
MSH) are kept; others (COLLADA .dae, ...) are dropped with a warning naming them. A URDF link's
<collision> shapes are kept only where it has no <visual>. Every geom becomes visual only (no mass,
no contacts): like the library's other arms, the arm never collides, and its inertia comes from the
file (MJCF bodies without an <inertial> get the inertia MuJoCo computes from their geoms).
The file's XML is prepared for MuJoCo by `dpc_mjx.robots.arms.prepare`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import pathlib
import warnings
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms.prepare import prepare_mjcf, prepare_urdf
from dpc_mjx.robots.urdf import MESH_FORMATS, inside

SUFFIXES = {".urdf": "urdf", ".xml": "mjcf"}


@dataclasses.dataclass(frozen=True)
class ArmFile:
    """An arm file read and checked (no physics compiled): the spec and what was inferred.

    `spec` is the arm alone: its root body at the origin, every other body below it, explicit
    inertias, no actuators, sensors or keyframes of its own; `joints` maps each movable joint to
    its range (rad or m; None where unlimited), in tree order.
    """

    path: pathlib.Path
    kind: str  # "urdf" or "mjcf"
    spec: mujoco.MjSpec
    root: str
    ee_body: str
    joints: dict[str, tuple[float, float] | None]
    dropped_meshes: tuple[str, ...]
    has_geometry: bool


def check_path(path: str | os.PathLike) -> tuple[pathlib.Path, str]:
    """The file as an absolute path and its kind ("urdf" or "mjcf"), or a `DpcError`."""
    p = pathlib.Path(path).expanduser()
    if not p.is_file():
        raise DpcError(
            f"Arm file {str(path)!r} does not exist; give the path of the arm's .urdf or MJCF "
            f".xml file (relative paths are taken from the current directory, {os.getcwd()})."
        )
    kind = SUFFIXES.get(p.suffix.lower())
    if kind is None:
        raise DpcError(
            f"Arm file {p} is not a URDF (.urdf) or MJCF (.xml) file; convert the arm's "
            "description to one of them (xacro files: run `xacro` first)."
        )
    return p.resolve(), kind


def read(
    path: str | os.PathLike,
    *,
    ee_body: str | None = None,
    keep_meshes: bool = True,
) -> ArmFile:
    """Read and check an arm file (see the module doc); `DpcError` naming the problem and the fix.

    `keep_meshes=False` drops every mesh (the named arms, whose meshes are COLLADA or unused).
    """
    p, kind = check_path(path)
    cached = _read_cached(p, p.stat().st_mtime_ns, kind, ee_body, keep_meshes)
    return dataclasses.replace(cached, spec=cached.spec.copy())  # the caller may edit its spec


@functools.lru_cache(maxsize=32)
def _read_cached(p, _mtime, kind, ee_body, keep_meshes) -> ArmFile:
    try:
        tree = ET.parse(p).getroot()
    except ET.ParseError as e:
        raise DpcError(f"Arm file {p} is not well-formed XML ({e}); fix the file.") from e
    expected = {"urdf": "robot", "mjcf": "mujoco"}[kind]
    if tree.tag != expected:
        raise DpcError(
            f"Arm file {p}: a {kind.upper()} file's top element is <{expected}>, this one's is "
            f"<{tree.tag}>; give a URDF (.urdf, <robot>) or an MJCF (.xml, <mujoco>) file."
        )
    if kind == "urdf":
        xml, root, dropped, has_geometry = prepare_urdf(p, tree, keep_meshes)
    else:
        xml, root, dropped, has_geometry = prepare_mjcf(p, tree, keep_meshes)
    for name in dropped:
        warnings.warn(
            f"{p}: mesh {name} is in a format MuJoCo cannot read (it reads {MESH_FORMATS}); "
            "dropped from the arm's visuals (its inertia is unaffected).",
            stacklevel=4,
        )
    try:
        spec = mujoco.MjSpec.from_string(xml)
        model = spec.compile()
    except ValueError as e:
        raise DpcError(f"MuJoCo cannot read the arm file {p}: {e}. Fix the file.") from e
    joints = _movable_joints(model, p)
    _check_inertia(model, p)
    ee_body = ee_body or _chain_end(model, root)
    _body_or_error(model, ee_body, "ee_body", p)
    _make_inertia_explicit(spec, model)
    for kind_list in (spec.actuators, spec.sensors, spec.keys):
        for element in list(kind_list):
            spec.delete(element)
    spec.compiler.fusestatic = True  # static links fuse into their parents once attached
    return ArmFile(p, kind, spec, root, ee_body, joints, tuple(dropped), has_geometry)


def check_home(arm_file: ArmFile, home: dict[str, float], what: str = "arm") -> None:
    """`DpcError` unless every joint named in `home` is a movable joint of the arm and its angle
    (rad, m for a slide) lies inside the joint's range."""
    for name, q in home.items():
        if name not in arm_file.joints:
            raise DpcError(
                f"{what}: home names joint {name!r}, which {arm_file.path.name} has no movable "
                f"joint of; its movable joints: {list(arm_file.joints)}."
            )
        rng = arm_file.joints[name]
        if not math.isfinite(q) or (rng is not None and not rng[0] <= q <= rng[1]):
            raise DpcError(
                f"{what}: home {name}={q} is outside the joint's range [{rng[0]:.3f}, "
                f"{rng[1]:.3f}] (rad, m for a slide); give an angle inside it."
            )


def default_home(arm_file: ArmFile) -> dict[str, float]:
    """Every movable joint at 0, moved `HOME_MARGIN` inside its range where 0 is outside it."""
    home = {}
    for name, rng in arm_file.joints.items():
        home[name] = 0.0 if rng is None else float(np.clip(0.0, *inside(rng)))
    return home


# ---------------------------------------------------------------------------------------------
# Both formats, on the compiled arm alone


def _body_or_error(model: mujoco.MjModel, name: str, what: str, p: pathlib.Path) -> None:
    names = [model.body(b).name for b in range(1, model.nbody)]
    if name not in names:
        raise DpcError(f"{what}={name!r} is not a body of {p.name}; its bodies: {names}.")


def _movable_joints(model: mujoco.MjModel, p: pathlib.Path) -> dict:
    joints = {}
    for j in range(model.njnt):
        kind = model.jnt_type[j]
        if kind not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            raise DpcError(
                f"Arm file {p}: joint {model.joint(j).name!r} is a ball or free joint; an arm's "
                "joints are hinges (revolute) or slides (prismatic). Replace it."
            )
        rng = tuple(float(x) for x in model.jnt_range[j]) if model.jnt_limited[j] else None
        joints[model.joint(j).name] = rng
    if not joints:
        raise DpcError(
            f"Arm file {p} has no movable joint (every joint is fixed); an arm needs at least one "
            "revolute, continuous or prismatic joint (MJCF: hinge or slide)."
        )
    return joints


def _check_inertia(model: mujoco.MjModel, p: pathlib.Path) -> None:
    for b in range(1, model.nbody):
        if model.body_jntnum[b] and (
            model.body_mass[b] <= mujoco.mjMINVAL or model.body_inertia[b].sum() <= mujoco.mjMINVAL
        ):
            raise DpcError(
                f"Arm file {p}: body {model.body(b).name!r} moves but has no mass or inertia; give "
                "it an <inertial> (mass > 0, inertia > 0) or geoms with mass."
            )


def _chain_end(model: mujoco.MjModel, root: str) -> str:
    """The body at the end of the longest chain of movable joints below `root` (the first)."""
    root_id = model.body(root).id
    depth = np.full(model.nbody, -1)
    depth[root_id] = 0
    for b in range(root_id + 1, model.nbody):  # parents come before children
        if depth[model.body_parentid[b]] >= 0:
            depth[b] = depth[model.body_parentid[b]] + model.body_jntnum[b]
    return model.body(int(np.argmax(depth))).name


def _make_inertia_explicit(spec: mujoco.MjSpec, model: mujoco.MjModel) -> None:
    """Every body's compiled mass, COM and principal inertia written into the spec, so the geoms
    can become massless visuals without changing the dynamics."""
    for body in spec.bodies:
        if body.name == "world" or not body.name:
            continue
        b = model.body(body.name).id
        body.explicitinertial = True
        body.mass = float(model.body_mass[b])
        body.ipos = list(model.body_ipos[b])
        body.iquat = list(model.body_iquat[b])
        body.inertia = list(model.body_inertia[b])
        body.fullinertia = [math.nan] * 6  # the principal inertia above replaces it


__all__ = ["SUFFIXES", "ArmFile", "check_home", "check_path", "default_home", "read"]
