"""A quadruped base's MJCF file (.xml), read by `robots.bases.file.read_base` as it reads a URDF
and built by `robots.bases.model.base_mjspec` as it builds one.

`MjcfTree.parse(path)`: the file's bodies as a `bases.urdf_tree.LinkTree`: a body is a link, its one
hinge or slide joint the joint from its parent body, a body without a joint welded to its parent;
the one top-level body is the root (a free joint on it, if any, is dropped: the library gives the
trunk its own); every body and joint is named (the library finds them by name). What a URDF's
tags give, the MJCF gives as MuJoCo compiles it (<include>s, defaults and units resolved):

- masses and inertias: the compiled bodies' (their <inertial>, else their geoms');
- torque limits (N·m; N on a slide): the tightest of the joint's `actuatorfrcrange` and, for each
  actuator on the joint, its `forcerange` and, for a motor, its `ctrlrange` (x gain); x the gear;
- collision shapes: the geoms that collide (contype or conaffinity not 0), primitives, and the
  trunk's meshes where it has no primitive.

`MjcfTree.compile`: the model `read_base` measures (the trunk welded at the origin). `load_mjcf`:
the spec `base_mjspec` adds its free joint, motors, feet and sensors to. Both hold the file's
bodies with their compiled inertias made explicit, the colliding geoms (visuals in the spec), no
meshes (but the trunk's when measuring), and none of what the library gives every base itself:
the file's actuators, sensors, sites, keyframes, contact pairs and excludes, tendons and equality
constraints (a leg is a serial chain), options, and the world's own geoms, lights and cameras.
"""

from __future__ import annotations

import math
import pathlib
import xml.etree.ElementTree as ET

import mujoco

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.bases.urdf_tree import LinkTree, UrdfTree
from dpc_mjx.robots.urdf import make_visual

MJCF_SUFFIX = ".xml"
_MOVABLE = {mujoco.mjtJoint.mjJNT_HINGE: "hinge", mujoco.mjtJoint.mjJNT_SLIDE: "slide"}
_PRIMITIVES = (
    mujoco.mjtGeom.mjGEOM_SPHERE,
    mujoco.mjtGeom.mjGEOM_CAPSULE,
    mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    mujoco.mjtGeom.mjGEOM_CYLINDER,
    mujoco.mjtGeom.mjGEOM_BOX,
)
_QUAT = mujoco.mjtOrientation.mjORIENTATION_QUAT
_FIX_LIMIT = (
    "give it a <motor> with forcerange (or ctrlrange) in N·m, or actuatorfrcrange on the joint "
    "(> 0 both ways), in the MJCF"
)


def is_mjcf(path: str | pathlib.Path) -> bool:
    """Whether a base file is an MJCF (by its suffix; else a URDF)."""
    return pathlib.Path(path).suffix.lower() == MJCF_SUFFIX


def read_tree(p: pathlib.Path) -> LinkTree:
    """The base file's tree of links: an MJCF's bodies or a URDF's links."""
    return MjcfTree.parse(p) if is_mjcf(p) else UrdfTree.parse(p)


class MjcfTree(LinkTree):
    """An MJCF's bodies and joints, checked (module doc). `joints[name]` holds its type ("hinge",
    "slide"; "fixed" for a body welded to its parent, keyed ("welded", body): never a name),
    parent and child body; `spec` is the file as parsed, `model` as compiled (no body fused)."""

    def __init__(self, path: pathlib.Path, spec: mujoco.MjSpec, model: mujoco.MjModel):
        self.path, self.spec, self.model = path, spec, model
        tops = [body.name for body in spec.worldbody.bodies]
        if len(tops) != 1:
            raise DpcError(
                f"Base {path}: <worldbody> holds {len(tops)} top-level bodies {tops}; a base file "
                "holds one, the trunk (or a massless body above it), with the legs inside it. "
                "Remove the others (a scene's objects) or give the robot's own file."
            )
        self.root_name = tops[0]
        self.joints = {}
        for body in spec.bodies[1:]:
            self._add(body)

    def _add(self, body: mujoco.MjsBody) -> None:
        joints = list(body.joints)
        if not body.name or any(not j.name for j in joints if j.type in _MOVABLE):
            raise DpcError(
                f"Base {self.path}: a body or joint inside {body.parent.name!r} has no name; "
                "name every body and joint of the base (the library finds them by name)."
            )
        if body.name == self.root_name:
            if joints and (len(joints) > 1 or joints[0].type != mujoco.mjtJoint.mjJNT_FREE):
                raise DpcError(
                    f"Base {self.path}: the root body {body.name!r} has joints other than a free "
                    "joint; the trunk moves freely. Give it a <freejoint/> or no joint."
                )
            return
        if len(joints) > 1 or any(j.type not in _MOVABLE for j in joints):
            raise DpcError(
                f"Base {self.path}: body {body.name!r} has {len(joints)} joints "
                f"({', '.join(f'{j.name} ({j.type.name[6:].lower()})' for j in joints)}); a base's "
                "bodies have one hinge or slide joint each, or none (welded). Nest one body per "
                "joint."
            )
        key = joints[0].name if joints else ("welded", body.name)
        kind = _MOVABLE[joints[0].type] if joints else "fixed"
        self.joints[key] = {"type": kind, "parent": body.parent.name, "child": body.name}

    @classmethod
    def parse(cls, p: pathlib.Path) -> MjcfTree:
        try:
            tag = ET.parse(p).getroot().tag
        except ET.ParseError as e:
            raise DpcError(f"Base file {p} is not well-formed XML ({e}); fix the file.") from e
        if tag != "mujoco":
            raise DpcError(
                f"Base file {p}: an MJCF's top element is <mujoco>, not <{tag}>; give a URDF "
                "the suffix .urdf."
            )
        try:
            spec = mujoco.MjSpec.from_file(str(p))
            spec.compiler.fusestatic = False  # every body kept, by its name
            model = spec.compile()
        except ValueError as e:
            raise DpcError(f"MuJoCo cannot read the base file {p}: {e}. Fix the file.") from e
        return cls(p, spec, model)

    def mass(self, link: str) -> float:
        return float(self.model.body(link).mass[0])

    def effort(self, joint: str, place: str) -> float:
        """N·m (N on a slide): the tightest torque limit the file sets on `joint` (module doc);
        `DpcError` where it sets none."""
        m, j = self.model, self.model.joint(joint).id
        limits = []  # N·m, each limit's smaller side
        if m.jnt_actfrclimited[j]:
            limits.append(min(-m.jnt_actfrcrange[j, 0], m.jnt_actfrcrange[j, 1]))
        for a in range(m.nu):
            if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or m.actuator_trnid[a, 0] != j:
                continue
            gear = abs(m.actuator_gear[a, 0])
            if m.actuator_forcelimited[a]:
                limits.append(gear * min(-m.actuator_forcerange[a, 0], m.actuator_forcerange[a, 1]))
            motor = m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
            motor &= m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE
            if motor and m.actuator_ctrllimited[a]:
                low, high = m.actuator_ctrlrange[a] * abs(m.actuator_gainprm[a, 0])
                limits.append(gear * min(-low, high))
        effort = float(min(limits, default=0.0))
        if not effort > 0.0:
            raise DpcError(
                f"Base {self.path}: leg {place}'s joint {joint!r} has no torque limit; "
                f"{_FIX_LIMIT}."
            )
        return effort

    def compile(self, trunk: str, skipped: tuple[str, ...], mesh_dir=None) -> mujoco.MjModel:
        """The base alone, its trunk welded at the origin (module doc); `mesh_dir` unused (an
        MJCF names its meshes itself)."""
        spec = self.base_spec(trunk, skipped)
        _keep_colliding(spec, trunk, trunk_meshes=True)
        try:
            return spec.compile()
        except ValueError as e:
            raise DpcError(f"MuJoCo cannot read the base file {self.path}: {e}. Fix it.") from e

    def base_spec(self, trunk: str, skipped: tuple[str, ...], drop=()) -> mujoco.MjSpec:
        """The file's bodies, inertias explicit, the trunk top-level at the origin without a
        joint, `skipped` (massless roots) made frames, the bodies `drop` names removed; none of
        what the library adds itself (module doc)."""
        spec = self.spec.copy()
        for element in [
            *spec.actuators, *spec.sensors, *spec.sites, *spec.keys, *spec.pairs,
            *spec.excludes, *spec.tendons, *spec.equalities, *spec.worldbody.geoms,
            *spec.worldbody.lights, *spec.worldbody.cameras,
        ]:  # fmt: skip
            spec.delete(element)
        spec.option = mujoco.MjSpec().option  # the library sets its own
        for body in spec.bodies[1:]:
            _explicit_inertia(body, self.model.body(body.name))
        compiler = spec.compiler  # the inertias above are final
        compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
        compiler.settotalmass, compiler.boundmass, compiler.boundinertia = -1.0, 0.0, 0.0
        for name in drop:
            spec.delete(spec.body(name))
        for name in skipped:
            for geom in spec.body(name).geoms:
                spec.delete(geom)
            spec.body(name).to_frame()
        body = spec.body(trunk)
        for joint in body.joints:
            spec.delete(joint)  # the file's free joint: the library adds its own
        frame = body
        while frame is not None:  # the trunk and the frames above it at the origin
            frame.pos, frame.quat, frame.alt.type = [0, 0, 0], [1, 0, 0, 0], _QUAT
            frame = frame.frame
        return spec


def load_mjcf(path: pathlib.Path, trunk: str, skipped: tuple[str, ...], others) -> mujoco.MjSpec:
    """The base's MJCF as a spec for `base_model.base_mjspec` (module doc): the colliding
    primitives as massless visuals (`robots.urdf.make_visual`), no meshes, the `others` (the
    `bases.file.Limb`s: an arm the file carries) left out, static bodies fused on compile."""
    tree = MjcfTree.parse(path)
    drop = []
    for limb in others:  # the limb's root, or where that is the trunk its first moving body
        first = tree.joints[limb.joints[0]]["child"]
        drop.append(first if limb.root == trunk else limb.root)
    spec = tree.base_spec(trunk, skipped, tuple(drop))
    _keep_colliding(spec, trunk, trunk_meshes=False)
    for geom in spec.geoms:
        make_visual(geom)
    spec.compiler.fusestatic, spec.compiler.discardvisual = True, False
    return spec


def _explicit_inertia(body: mujoco.MjsBody, compiled) -> None:
    """The body's compiled mass (kg), COM (m, body frame) and principal inertia (kg·m²) written
    into the spec, so that dropping or emptying geoms leaves the dynamics as the file's."""
    body.explicitinertial = True
    body.mass = float(compiled.mass[0])
    body.ipos, body.iquat = list(compiled.ipos), list(compiled.iquat)
    body.ialt.type = _QUAT
    body.inertia = list(compiled.inertia)
    body.fullinertia = [math.nan] * 6  # the principal inertia above replaces it


def _keep_colliding(spec: mujoco.MjSpec, trunk: str, trunk_meshes: bool) -> None:
    """Remove the geoms that do not collide (contype and conaffinity 0) and every non-primitive
    one, but, with `trunk_meshes`, the trunk's collision meshes where it has no primitive; then
    the mesh assets no geom uses."""

    def colliding(geom: mujoco.MjsGeom) -> bool:
        return bool(geom.contype or geom.conaffinity)

    trunk_geoms = [g for g in spec.body(trunk).geoms if colliding(g)]
    mesh_trunk = trunk_meshes and not any(g.type in _PRIMITIVES for g in trunk_geoms)
    for geom in list(spec.geoms):
        trunk_mesh = mesh_trunk and geom.parent.name == trunk
        if not (colliding(geom) and (geom.type in _PRIMITIVES or trunk_mesh)):
            spec.delete(geom)
    used = {g.meshname for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH}
    for mesh in list(spec.meshes):
        if (mesh.name or pathlib.Path(mesh.file).stem) not in used:
            spec.delete(mesh)


__all__ = ["MJCF_SUFFIX", "MjcfTree", "is_mjcf", "load_mjcf", "read_tree"]
