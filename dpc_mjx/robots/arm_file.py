"""A user's own arm from a URDF or MJCF file: checked before anything is compiled, read as a spec.

What the library needs of the file: one tree of links (bodies) whose root we weld to the A1's
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
from dpc_mjx.robots.urdf import strip_meshes

SUFFIXES = {".urdf": "urdf", ".xml": "mjcf"}
MESH_FORMATS = (".stl", ".obj", ".msh")  # the mesh files MuJoCo reads
URDF_MOVABLE = ("revolute", "continuous", "prismatic")
HOME_MARGIN = 0.05  # rad (m): an inferred home pose stays this far inside the joint range
_FIX_MESH = "put the file there, correct the path, or remove the element that names it"


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
        xml, root, dropped, has_geometry = _prepare_urdf(p, tree, keep_meshes)
    else:
        xml, root, dropped, has_geometry = _prepare_mjcf(p, tree, keep_meshes)
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


def inside(rng: tuple[float, float]) -> tuple[float, float]:
    """The joint range `rng` narrowed by `HOME_MARGIN` at each end (to half its width at most)."""
    lo, hi = rng
    margin = min(HOME_MARGIN, (hi - lo) / 2)
    return lo + margin, hi - margin


# ---------------------------------------------------------------------------------------------
# URDF


def _prepare_urdf(p, tree, keep_meshes) -> tuple[str, str, list[str], bool]:
    """The URDF as MuJoCo should read it (meshes resolved, dummy roots dropped, our compiler
    options), its root link, the meshes dropped for their format, whether any geometry is left."""
    links = {link.get("name"): link for link in tree.findall("link")}
    joints = tree.findall("joint")
    children = {j.find("child").get("link") for j in joints}
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise DpcError(
            f"Arm file {p}: its links form {len(roots)} trees (roots {roots}); an arm is one tree "
            "of links joined by <joint>s. Join or remove the loose links."
        )
    root = roots[0]
    while _mass(links[root]) == 0.0:  # a massless link welded on top, e.g. `world`
        out = [j for j in joints if j.find("parent").get("link") == root]
        if len(out) != 1 or out[0].get("type") != "fixed":
            break
        tree.remove(links.pop(root))
        tree.remove(out[0])
        joints.remove(out[0])
        root = out[0].find("child").get("link")
    for j in joints:
        kind = j.get("type")
        if kind not in (*URDF_MOVABLE, "fixed"):
            raise DpcError(
                f"Arm file {p}: joint {j.get('name')!r} is {kind!r}; an arm's joints are revolute, "
                "continuous, prismatic or fixed. Replace it (its base is welded to the trunk)."
            )
    for name in _links_without_inertia(links, joints):
        raise DpcError(
            f"Arm file {p}: link {name!r} moves (a joint drives it) but has no mass or inertia; "
            "give it an <inertial> with <mass value> > 0 and <inertia ixx iyy izz> > 0."
        )
    dropped = _urdf_geometry(p, links, keep_meshes)
    has_geometry = any(
        link.find("visual") is not None or link.find("collision") is not None
        for link in links.values()
    )
    ext = ET.SubElement(tree, "mujoco")
    ET.SubElement(ext, "compiler", fusestatic="false", discardvisual="false", strippath="false")
    return ET.tostring(tree, encoding="unicode"), root, dropped, has_geometry


def _urdf_geometry(p: pathlib.Path, links: dict, keep_meshes: bool) -> list[str]:
    """Resolve the links' mesh paths and drop what is not drawn: meshes MuJoCo cannot read
    (returned), a link's <collision>s where it has <visual>s; with `keep_meshes=False` (the named
    arms) every <visual> and mesh, keeping the primitive collision shapes."""
    dropped = []
    for link in links.values():
        if not keep_meshes:
            strip_meshes(link)
            continue
        has_visual = link.find("visual") is not None
        for element in [*link.findall("visual"), *link.findall("collision")]:
            mesh = element.find("geometry/mesh")
            file = "" if mesh is None else mesh.get("filename", "")
            unreadable = mesh is not None and pathlib.Path(file).suffix.lower() not in MESH_FORMATS
            hidden = element.tag == "collision" and has_visual
            if unreadable and not hidden:
                dropped.append(file)
            if hidden or unreadable:
                link.remove(element)
            elif mesh is not None:
                mesh.set("filename", str(_mesh_path(p, file, f"link {link.get('name')!r}")))
    return dropped


def _mass(link: ET.Element) -> float:
    mass = link.find("inertial/mass")
    return 0.0 if mass is None else float(mass.get("value", 0.0))


def _has_inertia(inertial: ET.Element | None) -> bool:
    inertia = None if inertial is None else inertial.find("inertia")
    if inertia is None:
        return False
    return sum(float(inertia.get(k, 0.0)) for k in ("ixx", "iyy", "izz")) > 0.0


def _links_without_inertia(links: dict, joints: list) -> list[str]:
    """Links a movable joint drives that lack a mass or an inertia: no mass of their own or
    welded on by fixed joints, or a mass of their own without an inertia."""
    fixed_children: dict[str, list[str]] = {}
    for j in joints:
        if j.get("type") == "fixed":
            parent, child = j.find("parent").get("link"), j.find("child").get("link")
            fixed_children.setdefault(parent, []).append(child)

    def welded_mass(name: str) -> float:
        return _mass(links[name]) + sum(welded_mass(c) for c in fixed_children.get(name, []))

    bad = []
    for j in joints:
        name = j.find("child").get("link")
        if j.get("type") not in URDF_MOVABLE:
            continue
        own = _mass(links[name])
        if welded_mass(name) <= 0.0 or (
            own > 0.0 and not _has_inertia(links[name].find("inertial"))
        ):
            bad.append(name)
    return bad


# ---------------------------------------------------------------------------------------------
# MJCF


def _prepare_mjcf(p, tree, keep_meshes) -> tuple[str, str, list[str], bool]:
    """The MJCF with mesh paths absolute and unreadable meshes dropped, its one top-level body,
    the meshes dropped, whether any geometry is left."""
    if tree.find(".//include") is not None:
        raise DpcError(
            f"Arm file {p} uses <include>; merge the included files into one MJCF file "
            "(e.g. `python -c \"import mujoco; m = mujoco.MjSpec.from_file('arm.xml'); "
            "open('merged.xml','w').write(m.to_xml())\"`)."
        )
    world = tree.find("worldbody")
    bodies = [] if world is None else world.findall("body")
    if len(bodies) != 1:
        raise DpcError(
            f"Arm file {p}: <worldbody> holds {len(bodies)} top-level bodies; an arm file holds "
            "one, the arm's base (welded to the trunk), with the rest of the arm inside it."
        )
    base = bodies[0]
    if base.find("joint") is not None or base.find("freejoint") is not None:
        raise DpcError(
            f"Arm file {p}: the base body {base.get('name')!r} has a joint; the arm's base is "
            "welded to the trunk, so remove its <joint>/<freejoint>."
        )
    for element in list(world):
        if element.tag != "body":
            world.remove(element)  # floors, lights, cameras of the arm's own scene
    dropped = _mjcf_meshes(p, tree, keep_meshes)
    has_geometry = next(base.iter("geom"), None) is not None
    if not base.get("name"):
        raise DpcError(f"Arm file {p}: name the base body (<body name=...>) to weld it on.")
    return ET.tostring(tree, encoding="unicode"), base.get("name"), dropped, has_geometry


def _mjcf_meshes(p: pathlib.Path, tree: ET.Element, keep_meshes: bool) -> list[str]:
    """The compiler's asset folders and the mesh assets' paths made absolute; meshes MuJoCo cannot
    read removed with the geoms using them (returned)."""
    compiler = tree.find("compiler")
    if compiler is None:
        compiler = ET.Element("compiler")
        tree.insert(0, compiler)
    compiler.set("assetdir", str(p.parent / compiler.get("assetdir", "")))
    for key in ("meshdir", "texturedir"):  # absolute, as the XML is read from a string
        if compiler.get(key):
            compiler.set(key, str(p.parent / compiler.get(key)))
    mesh_dir = pathlib.Path(compiler.get("meshdir") or compiler.get("assetdir"))
    dropped, removed = [], set()
    for asset in tree.findall("asset"):
        for mesh in asset.findall("mesh"):
            file = mesh.get("file")
            if file is None:
                continue  # a mesh given by its vertices
            name = mesh.get("name") or pathlib.Path(file).stem
            if not keep_meshes or pathlib.Path(file).suffix.lower() not in MESH_FORMATS:
                asset.remove(mesh)
                removed.add(name)
                if keep_meshes:
                    dropped.append(file)
            else:
                path = _mesh_path(p, file, f"mesh {name!r}", base=mesh_dir)
                mesh.set("file", str(path))
    for parent in tree.iter():
        for geom in list(parent.findall("geom")):
            if geom.get("mesh") in removed:
                parent.remove(geom)
    return dropped


# ---------------------------------------------------------------------------------------------
# Both formats, on the compiled arm alone


def _mesh_path(p: pathlib.Path, file: str, owner: str, base: pathlib.Path | None = None):
    """A mesh's file: absolute, `file://`, `package://NAME/...` or relative to `base` (default the
    arm file's folder); `DpcError` if it is not there."""
    if file.startswith("file://"):
        path = pathlib.Path(file.removeprefix("file://"))
    elif file.startswith("package://"):
        package, _, rest = file.removeprefix("package://").partition("/")
        path = _find_package(p, package) / rest
    else:
        path = (base or p.parent) / file
    if not path.is_file():
        raise DpcError(
            f"Arm file {p}: {owner} names mesh {file!r}, not found at {path}; {_FIX_MESH}."
        )
    return path.resolve()


def _find_package(p: pathlib.Path, package: str) -> pathlib.Path:
    """A ROS package's folder: a folder of that name above the file or beside one above it, or on
    ROS_PACKAGE_PATH."""
    for folder in p.parents:
        if folder.name == package:
            return folder
        if (folder / package).is_dir():
            return folder / package
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if entry and (pathlib.Path(entry) / package).is_dir():
            return pathlib.Path(entry) / package
    raise DpcError(
        f"Arm file {p} names meshes in package {package!r}, which is neither a folder above the "
        f"file nor on ROS_PACKAGE_PATH; add the folder holding {package}/ to ROS_PACKAGE_PATH."
    )


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
