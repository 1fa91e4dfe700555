"""An arm file's XML made ready for MuJoCo, before anything is compiled (`arm_file.read` calls
these): for a URDF, its one tree of links, massless roots welded on top dropped, joint kinds and
inertias checked (`prepare_urdf`); for an MJCF, its one top-level body without a joint
(`prepare_mjcf`); for both, mesh paths resolved (relative, `package://`, `file://`, absolute) and
meshes MuJoCo cannot read dropped (returned, for a warning).
"""

from __future__ import annotations

import os
import pathlib
import xml.etree.ElementTree as ET

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.urdf import MESH_FORMATS, URDF_MOVABLE, strip_meshes

_FIX_MESH = "put the file there, correct the path, or remove the element that names it"


# ---------------------------------------------------------------------------------------------
# URDF


def prepare_urdf(p, tree, keep_meshes) -> tuple[str, str, list[str], bool]:
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


def prepare_mjcf(p, tree, keep_meshes) -> tuple[str, str, list[str], bool]:
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
# Both formats: mesh files


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


__all__ = ["prepare_mjcf", "prepare_urdf"]
