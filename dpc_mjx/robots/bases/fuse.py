"""A base URDF's fixed links whose inertia MuJoCo refuses, fused into the link they hang from
(`bases.file.read_base` reads a base through this; `BaseSpec.fused` records what was done).

MuJoCo reads a URDF <inertia> as a full matrix and refuses one whose smallest eigenvalue is below
`MJ_EPS` (zero excepted: an all-zero inertia is a frame's), also on a link no joint moves: a
vendor file's cover or sensor link (ANYmal C's `hatch`, a rank-one inertia) would stop the whole
robot. A link that no joint moves is rigid with the link it hangs from, so its mass, centre of mass
and inertia are added to that link's (`combine`: the parallel-axis theorem, the fixed joint's
rotation applied), as MuJoCo's own `fusestatic` does with static bodies; the fused link keeps its
frame and its collision shapes, massless. Only refused links are fused, so a file MuJoCo reads as
it is (every named base) is read exactly as before.

Where the sum is refused in turn, it is carried up the fixed joints to the next link a joint moves
(or the trunk), which then gathers the links welded to it that carry no joint (covers, shells,
sensors; never a leg's or an arm's first link): the rigid body that moves is what must have a
possible inertia. Where even that is refused, the link a joint moves has an impossible inertia of
its own, and the base is refused with a `DpcError` naming it and the fix.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from dpc_mjx.errors import DpcError

MJ_EPS = 1e-14  # kg·m²: MuJoCo's mjEPS, the least eigenvalue of a full inertia it reads


@dataclasses.dataclass(frozen=True)
class Inertial:
    """A link's mass properties in some frame: mass kg, com (3,) m, inertia (3, 3) kg·m² about
    the com along that frame's axes."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


@dataclasses.dataclass(frozen=True)
class Fused:
    """Links whose inertias were added to `into`'s (their frames and shapes stay, massless)."""

    into: str  # the link that holds the sum: the one they hang from, or the next a joint moves
    links: tuple[str, ...]  # the links fused into it, deepest first
    refused: tuple[str, ...]  # of `into` and `links`, those whose own inertia MuJoCo refuses
    mass: float  # kg, `into`'s now
    com: tuple[float, float, float]  # m, in `into`'s frame
    inertia: tuple[float, ...]  # kg·m² about `com`, `into`'s axes: ixx, iyy, izz, ixy, ixz, iyz


def rpy_matrix(rpy) -> np.ndarray:
    """(3, 3): a URDF origin's rpy (rad, fixed axes x, y, z) as a rotation, R = Rz Ry Rx."""
    (cr, cp, cy), (sr, sp, sy) = np.cos(rpy), np.sin(rpy)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])  # fmt: skip


def _origin(element: ET.Element | None) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (3, 3), translation (3,) m) of an element's <origin>."""
    origin = None if element is None else element.find("origin")
    if origin is None:
        return np.eye(3), np.zeros(3)
    xyz = np.array([float(v) for v in origin.get("xyz", "0 0 0").split()])
    return rpy_matrix([float(v) for v in origin.get("rpy", "0 0 0").split()]), xyz


def read_inertial(link: ET.Element) -> Inertial:
    """The link's <inertial> in the link's frame (none: zero mass and inertia)."""
    inertial = link.find("inertial")
    if inertial is None:
        return Inertial(0.0, np.zeros(3), np.zeros((3, 3)))
    mass = inertial.find("mass")
    i = inertial.find("inertia")
    v = {k: 0.0 if i is None else float(i.get(k, 0.0)) for k in _KEYS}
    full = np.array([
        [v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
        [v["ixz"], v["iyz"], v["izz"]],
    ])  # fmt: skip
    rot, pos = _origin(inertial)
    m = 0.0 if mass is None else float(mass.get("value", 0.0))
    return Inertial(m, pos, rot @ full @ rot.T)


_KEYS = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")


def refused(inertial: Inertial) -> bool:
    """Whether MuJoCo refuses this inertia in a URDF: not all zero and an eigenvalue < MJ_EPS."""
    i = inertial.inertia
    return bool(np.any(i != 0.0)) and float(np.linalg.eigvalsh(i)[0]) < MJ_EPS


def combine(parent: Inertial, child: Inertial, rot: np.ndarray, pos: np.ndarray) -> Inertial:
    """`parent` plus `child`, the child's frame at `pos` (m) turned by `rot` in the parent's:
    masses add, the com is the mass-weighted mean, each inertia is turned into the parent's axes
    and moved to the common com by the parallel-axis theorem, I + m (|d|² E - d dᵀ)."""
    c_child = rot @ child.com + pos
    mass = parent.mass + child.mass
    if mass <= 0.0:
        com = (parent.com + c_child) / 2
    else:
        com = (parent.mass * parent.com + child.mass * c_child) / mass
    total = np.zeros((3, 3))
    for m, c, inertia in ((parent.mass, parent.com, parent.inertia),
                          (child.mass, c_child, rot @ child.inertia @ rot.T)):  # fmt: skip
        d = c - com
        total += inertia + m * (d @ d * np.eye(3) - np.outer(d, d))
    return Inertial(mass, com, (total + total.T) / 2)


def fuse_plan(tree, trunk: str, skipped: tuple[str, ...]) -> tuple[Fused, ...]:
    """The fusions the base `tree` (a `bases.urdf_tree.UrdfTree`, trunk `trunk`, links `skipped`
    dropped) needs (module doc); () where MuJoCo reads every link's inertia as it is."""
    into_joint = {j["child"]: name for name, j in tree.joints.items()}
    order = [n for n in tree.subtree_links(trunk) if n not in skipped]  # parents first
    inertial = {n: read_inertial(tree.links[n]) for n in order}
    bad = {n for n in order if refused(inertial[n])}
    if not bad:
        return ()
    merged: dict[str, list[str]] = {}  # link -> the links fused into it
    done: set[str] = set()  # links fused

    def fuse(link: str, parent: str) -> None:
        rot, pos = _origin(tree.joints[into_joint[link]]["xml"])
        inertial[parent] = combine(inertial[parent], inertial[link], rot, pos)
        inertial[link] = Inertial(0.0, np.zeros(3), np.zeros((3, 3)))
        merged.setdefault(parent, []).extend([*merged.pop(link, []), link])
        done.add(link)

    for link in reversed(order):  # children before parents: a refused sum is carried up
        if link != trunk and _fixed(tree, into_joint, link) and refused(inertial[link]):
            fuse(link, tree.joints[into_joint[link]]["parent"])
    for head in [n for n in order if refused(inertial[n])]:  # moved by a joint, or the trunk
        for link in reversed([w for w in _attachments(tree, head) if w not in done]):
            fuse(link, tree.joints[into_joint[link]]["parent"])
        if refused(inertial[head]):
            raise DpcError(_impossible(tree, head, into_joint, inertial[head]))
    return tuple(_record(n, merged[n], bad, inertial[n]) for n in order if n in merged)


def _attachments(tree, link: str) -> list[str]:
    """The links welded to `link` through links no joint moves anything from (covers, shells,
    sensors; not a leg's or an arm's first link nor what is welded to it), parents first."""
    found = []
    for name in tree.out(link):
        child = tree.joints[name]["child"]
        if tree.joints[name]["type"] == "fixed" and not tree.movable_out(child):
            found += [child, *_attachments(tree, child)]
    return found


def _fixed(tree, into_joint: dict, link: str) -> bool:
    return tree.joints[into_joint[link]]["type"] == "fixed"


def _record(into: str, links: list[str], bad: set[str], inertial: Inertial) -> Fused:
    i = inertial.inertia
    return Fused(
        into, tuple(links), tuple(n for n in (into, *links) if n in bad), float(inertial.mass),
        tuple(float(c) for c in inertial.com),
        tuple(float(x) for x in (i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2])),
    )  # fmt: skip


def _impossible(tree, head: str, into_joint: dict, inertial: Inertial) -> str:
    moved = f"moved by joint {into_joint[head]!r}" if head in into_joint else "the trunk"
    eig = ", ".join(f"{e:.3g}" for e in np.linalg.eigvalsh(inertial.inertia))
    return (
        f"Base {tree.path}: link {head!r} ({moved}) has an impossible inertia: its principal "
        f"moments, with the links welded to it that no joint moves, are {eig} kg·m², and MuJoCo "
        f"needs each >= {MJ_EPS:g}. Give {head!r} an <inertial> with mass > 0 and a positive "
        "definite <inertia> (ixx, iyy, izz > 0, each at most the sum of the other two) in the URDF."
    )


def apply_to_urdf(root: ET.Element, fused: tuple[Fused, ...]) -> None:
    """Write `fused` into a URDF's XML (`root`, <robot>): each `into` link's <inertial> the sum,
    each fused link's removed."""
    links = {link.get("name"): link for link in root.findall("link")}
    for f in fused:
        for name in f.links:
            for inertial in links[name].findall("inertial"):
                links[name].remove(inertial)
        link = links[f.into]
        for inertial in link.findall("inertial"):
            link.remove(inertial)
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "origin", xyz=" ".join(repr(c) for c in f.com), rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=repr(f.mass))
        ET.SubElement(inertial, "inertia", {k: repr(v) for k, v in zip(_KEYS, f.inertia)})


def apply_to_spec(spec: mujoco.MjSpec, fused: tuple[Fused, ...]) -> None:
    """Write `fused` into a spec loaded from the URDF as it is (`robots.urdf.load_urdf`): the
    bodies of links it dropped are passed over."""
    names = {b.name for b in spec.bodies}
    for f in fused:
        for name in (n for n in f.links if n in names):
            body = spec.body(name)
            body.mass, body.ipos, body.iquat, body.inertia = 0.0, [0, 0, 0], [1, 0, 0, 0], [0, 0, 0]
            body.fullinertia = [np.nan, 0, 0, 0, 0, 0]
        if f.into in names:
            body = spec.body(f.into)
            body.mass, body.ipos, body.iquat = f.mass, list(f.com), [1, 0, 0, 0]
            body.fullinertia = list(f.inertia)


def describe_fused(fused: tuple[Fused, ...]) -> str:
    """One line per fusion: which links, into which, and which of them MuJoCo refused."""
    return "\n".join(
        f"fused {len(f.links)} link(s) no joint moves into {f.into!r} (their mass, centre of mass "
        f"and inertia added to its; now {f.mass:.4f} kg): {', '.join(f.links)}; because MuJoCo "
        f"refuses the inertia of {', '.join(f.refused)} (not positive definite)"
        for f in fused
    )


__all__ = [
    "MJ_EPS",
    "Fused",
    "Inertial",
    "apply_to_spec",
    "apply_to_urdf",
    "combine",
    "describe_fused",
    "fuse_plan",
    "read_inertial",
    "refused",
    "rpy_matrix",
]
