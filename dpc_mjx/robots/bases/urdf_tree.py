"""A base's URDF (`dpc_mjx.robots.bases.file` reads it): its tree of links and joints, checked
(`LinkTree`: the walks, shared with an MJCF's bodies, `robots.bases.mjcf_tree`); the XML MuJoCo
compiles of it (the base alone, the trunk welded at the world origin, so that world coordinates
are trunk-frame coordinates); a subtree of it (an arm it carries) as a URDF of its own; the
base's JSON file.
"""

from __future__ import annotations

import copy
import pathlib
import xml.etree.ElementTree as ET

import mujoco

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.bases.fuse import Fused, apply_to_urdf, fuse_plan
from dpc_mjx.robots.urdf import MESH_FORMATS, URDF_MOVABLE, read_description, strip_meshes

MASSLESS = 1e-4  # kg: a root link lighter than this is a placeholder (Go1's base: 1e-6 kg)


class LinkTree:
    """Links joined into one tree by joints, walked as `bases.file` walks a base: `joints[name]`
    holds its type ("fixed" or movable), parent and child link; `root_name` is the root link.
    A URDF's (`UrdfTree`) or an MJCF's bodies (`bases.mjcf_tree.MjcfTree`)."""

    path: pathlib.Path
    joints: dict[str, dict]
    root_name: str

    def mass(self, link: str) -> float:
        """kg, the link's own."""
        raise NotImplementedError

    def effort(self, joint: str, place: str) -> float:
        """N·m, the torque limit of `joint` (of the leg at `place`); `DpcError` where none."""
        raise NotImplementedError

    def compile(self, trunk: str, skipped: tuple[str, ...], mesh_dir) -> mujoco.MjModel:
        """The base alone, `trunk` welded at the origin, `skipped` dropped (world coordinates
        are trunk-frame coordinates); `mesh_dir`: the folder of a named base's meshes, or None."""
        raise NotImplementedError

    def fused(self, trunk: str, skipped: tuple[str, ...]) -> tuple[Fused, ...]:
        """The links `compile` fuses into the link they hang from (`robots.bases.fuse`)."""
        return ()

    def out(self, link: str) -> list[str]:
        return [n for n, j in self.joints.items() if j["parent"] == link]

    def welded(self, link: str) -> list[str]:
        """`link` and the links fixed joints weld below it, parents first."""
        found = [link]
        for name in self.out(link):
            if self.joints[name]["type"] == "fixed":
                found += self.welded(self.joints[name]["child"])
        return found

    def movable_out(self, link: str) -> list[str]:
        """The movable joints out of `link` and the links welded to it."""
        return [
            n for w in self.welded(link) for n in self.out(w) if self.joints[n]["type"] != "fixed"
        ]

    def chain(self, first: str) -> tuple[str, ...]:
        """The movable joints from `first` outwards while there is exactly one next."""
        if first not in self.joints or self.joints[first]["type"] == "fixed":
            raise DpcError(f"Base {self.path}: {first!r} is not a movable joint of the file.")
        chain = [first]
        while len(nxt := self.movable_out(self.joints[chain[-1]]["child"])) == 1:
            chain += nxt
        return tuple(chain)

    def branches(self, chain: tuple[str, ...]) -> bool:
        return bool(self.movable_out(self.joints[chain[-1]]["child"]))

    def end_links(self, chain: tuple[str, ...]) -> list[str]:
        return self.welded(self.joints[chain[-1]]["child"])

    def subtree_links(self, root: str) -> list[str]:
        """`root` and every link below it, breadth first."""
        links, todo = [], [root]
        while todo:
            link = todo.pop(0)
            links.append(link)
            todo += [self.joints[j]["child"] for j in self.out(link)]
        return links

    def subtree_joints(self, first: str) -> tuple[str, ...]:
        found, todo = [], [first]
        while todo:
            name = todo.pop(0)
            found.append(name)
            todo += self.movable_out(self.joints[name]["child"])
        return tuple(found)

    def trunk(self) -> tuple[str, tuple[str, ...]]:
        """The trunk link and the massless links above it (dropped): a massless root welded to
        one link below it is skipped (Go1's `base`); one carrying links welded on (ANYmal's
        `base`) is the trunk, whose mass is theirs."""
        name, skipped = self.root_name, []
        while self.mass(name) < MASSLESS:
            out = self.out(name)
            if len(out) == 1 and self.joints[out[0]]["type"] == "fixed":
                skipped.append(name)
                name = self.joints[out[0]]["child"]
                continue
            if sum(self.mass(w) for w in self.welded(name)) < MASSLESS:
                raise DpcError(
                    f"Base {self.path}: the root link {name!r} and the links welded to it have "
                    "no mass; the trunk is the root link (it gets the free joint). Give it an "
                    "<inertial> (mass > 0) or remove it."
                )
            break
        return name, tuple(skipped)


class UrdfTree(LinkTree):
    """A URDF's links and joints, checked: one tree of revolute, continuous, prismatic and fixed
    joints. `joints[name]` holds its type, parent and child link and XML element."""

    def __init__(self, path: pathlib.Path, root: ET.Element):
        self.path, self.root = path, root
        self.links = {link.get("name"): link for link in root.findall("link")}
        self.joints = {}
        for j in root.findall("joint"):
            kind = j.get("type")
            if kind not in (*URDF_MOVABLE, "fixed"):
                raise DpcError(
                    f"Base {path}: joint {j.get('name')!r} is {kind!r}; a base's joints are "
                    "revolute, continuous, prismatic or fixed (the trunk's free joint is added). "
                    "Replace it."
                )
            parent, child = j.find("parent").get("link"), j.find("child").get("link")
            self.joints[j.get("name")] = {"type": kind, "parent": parent, "child": child, "xml": j}
        children = {j["child"] for j in self.joints.values()}
        roots = [name for name in self.links if name not in children]
        if len(roots) != 1:
            raise DpcError(
                f"Base {path}: its links form {len(roots)} trees (roots {roots}); a base is one "
                "tree of links joined by <joint>s. Join or remove the loose links."
            )
        self.root_name = roots[0]

    @classmethod
    def parse(cls, p: pathlib.Path) -> UrdfTree:
        try:
            root = ET.parse(p).getroot()
        except ET.ParseError as e:
            raise DpcError(f"Base file {p} is not well-formed XML ({e}); fix the file.") from e
        if root.tag != "robot":
            raise DpcError(f"Base file {p}: a URDF's top element is <robot>, not <{root.tag}>.")
        return cls(p, root)

    def mass(self, link: str) -> float:
        return _mass(self.links[link])

    def effort(self, joint: str, place: str) -> float:
        """N·m, the joint's <limit effort>; `DpcError` where it has none."""
        limit = self.joints[joint]["xml"].find("limit")
        effort = float(limit.get("effort", 0.0)) if limit is not None else 0.0
        if not effort > 0.0:
            raise DpcError(
                f"Base {self.path}: leg {place}'s joint {joint!r} has no torque limit; give it "
                "<limit effort=...> (N·m, > 0) in the URDF."
            )
        return effort

    def compile(self, trunk: str, skipped: tuple[str, ...], mesh_dir) -> mujoco.MjModel:
        """`compile_base` of this tree."""
        return compile_base(self, trunk, skipped, mesh_dir)

    def fused(self, trunk: str, skipped: tuple[str, ...]) -> tuple[Fused, ...]:
        """Its fixed links whose inertia MuJoCo refuses, fused (`bases.fuse.fuse_plan`)."""
        return fuse_plan(self, trunk, skipped)


def _mass(link: ET.Element) -> float:
    mass = link.find("inertial/mass")
    return 0.0 if mass is None else float(mass.get("value", 0.0))


def compile_base(tree: UrdfTree, trunk: str, skipped: tuple[str, ...], mesh_dir) -> mujoco.MjModel:
    """The base alone, its trunk welded at the origin: no visuals, no collision meshes but the
    trunk's where it has no primitives, the file's inertias (none computed from shapes; fixed
    links whose inertia MuJoCo refuses fused, `tree.fused`)."""
    root = ET.fromstring(ET.tostring(tree.root))
    apply_to_urdf(root, tree.fused(trunk, skipped))
    for link in root.findall("link"):
        name = link.get("name")
        if name in skipped:
            root.remove(link)
            continue
        for visual in link.findall("visual"):
            link.remove(visual)
        shapes = link.findall("collision")
        meshes = [c for c in shapes if c.find("geometry/mesh") is not None]
        for collision in meshes:
            if name == trunk and len(meshes) == len(shapes):
                mesh = collision.find("geometry/mesh")
                mesh.set("filename", str(_mesh_file(tree.path, mesh.get("filename"), mesh_dir)))
            else:
                link.remove(collision)
    for j in root.findall("joint"):
        if j.find("parent").get("link") in skipped:
            root.remove(j)
    ext = ET.SubElement(root, "mujoco")
    ET.SubElement(
        ext, "compiler", fusestatic="false", discardvisual="false", strippath="false",
        inertiafromgeom="false", balanceinertia="true",
    )  # fmt: skip
    try:
        return mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    except ValueError as e:
        raise DpcError(
            f"MuJoCo cannot read the base file {tree.path}: {e}. Fix the file (every link a "
            "joint moves needs an <inertial> with mass > 0 and inertia > 0)."
        ) from e


def read_json(p: pathlib.Path, keys: tuple[str, ...]) -> dict:
    """A base's JSON file (`bases.file.read_base`): an object of `keys`, "file" a .urdf or an
    MJCF .xml."""
    first = "the .urdf or .xml, relative to the JSON"
    options = read_description(p, "Base JSON", keys, first)
    if pathlib.Path(str(options["file"])).suffix.lower() not in (".urdf", ".xml"):
        raise DpcError(
            f"Base JSON {p}: 'file' must name a .urdf or an MJCF .xml file, got "
            f"{options['file']!r}."
        )
    return options


def _mesh_file(p: pathlib.Path, file: str, mesh_dir) -> pathlib.Path:
    """A trunk collision mesh's file: a named base's in `mesh_dir`; else absolute, `file://`,
    `package://NAME/...` (NAME a folder above the URDF) or relative to the URDF."""
    if mesh_dir is not None:
        path = mesh_dir / pathlib.PurePosixPath(file).name
    elif file.startswith("package://"):
        package, _, rest = file.removeprefix("package://").partition("/")
        above = [f for f in p.parents if f.name == package or (f / package).is_dir()]
        base = above[0] if above else p.parent
        path = (base if base.name == package else base / package) / rest
    else:
        path = p.parent / file.removeprefix("file://")
    if path.suffix.lower() not in MESH_FORMATS or not path.is_file():
        raise DpcError(
            f"Base {p}: the trunk's only collision shapes are meshes, and {file!r} cannot be read "
            f"(looked for {path}; MuJoCo reads {MESH_FORMATS}): its box is their bounding box. "
            "Put the mesh file there (STL or OBJ), or give the trunk a <collision> <box>."
        )
    return path


def subtree_urdf(tree: UrdfTree, root: str, name: str) -> str:
    """A URDF of `root` and every link below it with the joints between them (an arm carried in
    a base's file, B1's Z1), meshes dropped and primitive collision shapes kept, as for the named
    arms (`robots.urdf.strip_meshes`); `root` is its root link."""
    out = ET.Element("robot", name=name)
    links = tree.subtree_links(root)
    for link in links:
        element = copy.deepcopy(tree.links[link])
        strip_meshes(element)
        out.append(element)
    for joint in tree.joints.values():
        if joint["parent"] in links:
            out.append(copy.deepcopy(joint["xml"]))
    ET.indent(out)
    return ET.tostring(out, encoding="unicode")


__all__ = ["MASSLESS", "LinkTree", "UrdfTree", "compile_base", "read_json", "subtree_urdf"]
