"""A quadruped base read from its URDF or MJCF file as a `BaseSpec` (`robots.bases.model` builds
it).

`read_base(base)`: `base` is a named base (`NAMED_BASES`: a1, go1, go2, b1, and b1-z1, the B1
carrying a Z1 whose arm `arm_urdf` splits off; their URDFs ship in `dpc_mjx/descriptions/`), the
path of a .urdf or an MJCF .xml file, or of a .json file naming that file and what inference
cannot decide (`{"file": "my_dog.urdf", "legs": {"FR": "<hip joint>", ...}, "home_height": 0.3,
"foot_radius": 0.02}`, paths relative to the JSON). An MJCF is read as a URDF is, its bodies the
links (`robots.bases.mjcf_tree` says how: its free joint's body or its one top-level body is the
root, its torque limits are its motors' or joints' force ranges). What is inferred:

- the trunk: the URDF's root link, skipping massless links (< MASSLESS kg) welded on top by a
  fixed joint (Go1's and B1's `base`); it gets the free joint;
- the legs: the chains of movable joints (revolute, continuous, prismatic) out of the trunk whose
  end lies below the trunk's origin at the zero pose (joints at 0, clipped into their ranges),
  exactly four, of three joints each, hip to knee; each leg's place (FR, FL, RR, RL: front/rear,
  right/left) from the signs of its foot's x (forward) and y (left) in the trunk frame at the zero
  pose, never from the names; other chains (an arm) are kept as `others` with their mount;
- the feet: the sphere collision shape of the chain's end links (the farthest from the knee), else
  a sphere of FOOT_FRACTION x the leg's length at the end link's origin (Go2: no sphere);
- torque limits: each leg joint's URDF <limit effort> (N·m), required;
- masses and the trunk's inertia: the URDF's <inertial>s as MuJoCo reads them (an inertia that
  breaks the triangle inequality, as ANYmal's camera links do, balanced by MuJoCo; a fixed link's
  that MuJoCo refuses, ANYmal C's `hatch`, fused into the link it hangs from with a warning,
  `robots.bases.fuse`); the trunk's are the rigid trunk's: its link and the links welded to it,
  an arm's base not counted;
- the trunk's box: around its collision primitives, or, where it has only collision meshes (Go2),
  around their vertices (STL, OBJ or MSH files; the named bases' in `descriptions/meshes/<name>/`);
- the home pose: each foot under its hip (`robots.bases.measure.solve_home`; sideways where it
  hangs at the zero pose: under the thigh joint on Unitree's legs, outboard of it by the shank's
  offset on ANYmal C's and Solo 12's) with the trunk's origin `home_height` above the floor, by
  default HOME_FRACTION of the leg's length plus the feet's radius (the A1: 0.625 x 0.4 m +
  0.02 m = 0.27 m, `robots.bases.a1.HOME_HEIGHT`).
"""

from __future__ import annotations

import dataclasses
import functools
import os
import pathlib
import warnings

import mujoco
import numpy as np

from dpc_mjx import assets
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.bases import geometry
from dpc_mjx.robots.bases.fuse import Fused, describe_fused
from dpc_mjx.robots.bases.measure import check_efforts, solve_home, trunk_numbers
from dpc_mjx.robots.bases.mjcf_tree import is_mjcf, read_tree
from dpc_mjx.robots.bases.urdf_tree import MASSLESS, UrdfTree, read_json, subtree_urdf
from dpc_mjx.robots.urdf import inside

# Name -> (file in dpc_mjx/descriptions/, the path it was copied from under the wheel's robots/):
# `assets.URDFS`' quadrupeds (b1-z1: the B1 carrying a Z1, its `others`).
NAMED_BASES = {name: assets.URDFS[name] for name in ("a1", "go1", "go2", "b1", "b1-z1")}
MESHES = assets.DESCRIPTIONS / "meshes"  # meshes/<name>/: the collision meshes a named base reads

LEGS = ("FR", "FL", "RR", "RL")  # front-right, front-left, rear-right, rear-left (the A1's)
LEG_DOF = 3  # joints per leg: hip (ab/adduction), thigh, knee
PLACE_MARGIN = 0.01  # m: a foot's x and y at the zero pose lie at least this far off the midplanes
HOME_FRACTION = 0.625  # home: the hip this fraction of the leg's length above the foot's centre
FOOT_FRACTION = 0.05  # a foot without a sphere in its file: radius = this x the leg's length
_JSON_KEYS = ("file", "legs", "home_height", "foot_radius")  # "file" required
_FIX_LEGS = (
    'name the legs in a JSON file, {"file": "<the base file>", "legs": {"FR": "<its first joint>", '
    '"FL": ..., "RR": ..., "RL": ...}}, and read that (or pass legs={...} to read_base)'
)


@dataclasses.dataclass(frozen=True)
class Leg:
    """One leg: frames are the trunk's (x forward, y left, z up), angles rad, lengths m."""

    place: str  # one of LEGS
    joints: tuple[str, ...]  # LEG_DOF joint names, hip (ab/adduction), thigh, knee
    torque_limits: tuple[float, ...]  # N·m per joint, the file's (URDF: <limit effort>)
    foot: str  # the link holding the foot
    foot_center: tuple[float, float, float]  # m, in the foot link's frame
    foot_radius: float  # m
    hip: tuple[float, float, float]  # m, trunk frame: the thigh joint at the zero pose
    length: float  # m, thigh joint -> knee -> foot centre
    home: tuple[float, ...]  # rad per joint: the foot under `hip`, on the floor at home


@dataclasses.dataclass(frozen=True)
class Limb:
    """An actuated subtree that is not a leg (an arm), welded to the trunk at `root`."""

    root: str  # the link its first joint moves from (Z1 on B1: link00)
    joints: tuple[str, ...]  # its movable joints, from the trunk outwards
    mount_pos: tuple[float, float, float]  # m, `root`'s origin in the trunk frame
    mount_quat: tuple[float, float, float, float]  # (w, x, y, z), `root`'s axes in the trunk's
    mass: float  # kg, `root` and everything below it


@dataclasses.dataclass(frozen=True)
class BaseSpec:
    """A quadruped base read from its file (module doc): what the library needs of it."""

    name: str
    path: pathlib.Path
    trunk: str  # the link that gets the free joint
    skipped_roots: tuple[str, ...]  # massless links above the trunk, dropped
    legs: tuple[Leg, ...]  # in LEGS order
    foot_from: str  # where the feet's radius comes from
    mass: float  # kg: the trunk and every link below it (legs, attachments, `others`)
    trunk_mass: float  # kg: the rigid trunk's, its link and the links welded to it (no arm)
    trunk_com: tuple[float, float, float]  # m, trunk frame
    trunk_inertia: tuple[tuple[float, ...], ...]  # kg·m², (3, 3) about trunk_com, trunk axes
    trunk_box_center: tuple[float, float, float]  # m, trunk frame
    trunk_half_extents: tuple[float, float, float]  # m, along the trunk's axes
    trunk_box_from: str  # "collision primitives" or "collision meshes"
    home_height: float  # m: the trunk's origin above the floor at home
    home_from: str  # how home_height was chosen
    others: tuple[Limb, ...] = ()  # actuated subtrees that are not legs
    fused: tuple[Fused, ...] = ()  # fixed links whose inertia MuJoCo refuses, fused (bases.fuse)

    @property
    def leg_joints(self) -> tuple[str, ...]:
        """(12,) joint names, legs in LEGS order, each hip to knee."""
        return tuple(name for leg in self.legs for name in leg.joints)

    @property
    def torque_limits(self) -> np.ndarray:
        """(12,) N·m, in `leg_joints` order."""
        return np.array([t for leg in self.legs for t in leg.torque_limits])

    @property
    def home_qpos(self) -> np.ndarray:
        """(12,) rad, in `leg_joints` order."""
        return np.array([q for leg in self.legs for q in leg.home])

    @property
    def base_mass(self) -> float:
        """kg: `mass` less the `others` (the base without the arm its file carries)."""
        return self.mass - sum(limb.mass for limb in self.others)

    @property
    def foot_radius(self) -> float:
        """m, the largest of the four feet's (the named bases' are equal)."""
        return max(leg.foot_radius for leg in self.legs)


def read_base(
    base: str | os.PathLike,
    *,
    home_height: float | None = None,
    legs: dict[str, str] | None = None,
    foot_radius: float | None = None,
) -> BaseSpec:
    """The base `base` (a name of NAMED_BASES, a .urdf, .xml or .json path; module doc), read and
    checked: `DpcError` naming the problem and the fix. `legs` maps each place of LEGS to the
    first joint of its leg; `home_height` (m) and `foot_radius` (m) replace the inferred ones."""
    name, path, mesh_dir, options = _locate(base)
    given = {"home_height": home_height, "legs": legs, "foot_radius": foot_radius}
    options.update({k: v for k, v in given.items() if v is not None})
    leg_names = options.get("legs")
    if leg_names is not None:
        if not isinstance(leg_names, dict) or sorted(leg_names) != sorted(LEGS):
            raise DpcError(
                f"Base {path}: legs must map each of {LEGS} to a joint, got {leg_names}."
            )
        leg_names = tuple((place, leg_names[place]) for place in LEGS)
    height, radius = options.get("home_height"), options.get("foot_radius")
    for what, value in (("home_height", height), ("foot_radius", radius)):
        if value is not None and not (isinstance(value, (int, float)) and 0 < value < 10):
            raise DpcError(f"Base {path}: {what} must be a length in m (> 0), got {value!r}.")
    return _read_cached(path, path.stat().st_mtime_ns, name, mesh_dir, height, leg_names, radius)


def arm_urdf(spec: BaseSpec, limb: Limb | None = None) -> str:
    """The URDF text of an arm carried in the base's file (`limb`, default the one of
    `spec.others`): its links and joints, meshes dropped. Write it to a .urdf file and mount it as
    `UrdfArm(path)` at `limb.mount_pos` (m, trunk frame) turned by `limb.mount_quat`."""
    if is_mjcf(spec.path):
        raise DpcError(
            f"Base {spec.path} is an MJCF, not a URDF to split; copy its arm's bodies into an "
            "MJCF file of their own and mount that as UrdfArm(path)."
        )
    if limb is None:
        if len(spec.others) != 1:
            raise DpcError(
                f"Base {spec.path} carries {len(spec.others)} actuated subtrees besides its legs "
                f"({[o.root for o in spec.others]}); name the one to split off (limb=...)."
            )
        limb = spec.others[0]
    return subtree_urdf(UrdfTree.parse(spec.path), limb.root, f"{spec.name}_{limb.root}")


def base_file_path(name: str) -> pathlib.Path:
    """The shipped URDF of the named base `name` (one of NAMED_BASES)."""
    if name not in NAMED_BASES:
        raise DpcError(f"No base named {name!r}; known: {sorted(NAMED_BASES)}.")
    return assets.urdf_path(name)  # the one registry of shipped files


def _locate(base) -> tuple[str, pathlib.Path, pathlib.Path | None, dict]:
    """(name, URDF or MJCF path, folder of a named base's meshes or None, a JSON's options)."""
    if isinstance(base, str) and base in NAMED_BASES:
        return base, base_file_path(base), MESHES / base, {}
    p = pathlib.Path(base).expanduser()
    if not p.is_file():
        raise DpcError(
            f"Base file {str(base)!r} does not exist; give a named base ({sorted(NAMED_BASES)}), "
            "the path of the quadruped's .urdf or MJCF .xml file or of a .json naming it (paths "
            f"relative to the current directory, {os.getcwd()})."
        )
    if p.suffix.lower() == ".json":
        options = read_json(p, _JSON_KEYS)
        name, path, mesh_dir, _ = _locate(p.parent / str(options.pop("file")))
        return name, path, mesh_dir, options
    if p.suffix.lower() != ".urdf" and not is_mjcf(p):
        raise DpcError(
            f"Base file {p} is not a URDF (.urdf), an MJCF (.xml) or a JSON (.json) naming one; "
            "convert the robot's description to URDF or MJCF (xacro files: run `xacro` first)."
        )
    named = [n for n in NAMED_BASES if base_file_path(n) == p.resolve()]  # a shipped file
    mesh_dir = MESHES / named[0] if named else None
    return (named[0] if named else p.stem), p.resolve(), mesh_dir, {}


@functools.lru_cache(maxsize=16)
def _read_cached(p, _mtime, name, mesh_dir, height, leg_names, radius) -> BaseSpec:
    tree = read_tree(p)  # a UrdfTree or an MjcfTree
    trunk, skipped = tree.trunk()
    fused = tree.fused(trunk, skipped)
    if fused:
        warnings.warn(f"Base {p}: {describe_fused(fused)}.", stacklevel=3)
    model = tree.compile(trunk, skipped, mesh_dir)
    data = mujoco.MjData(model)
    for j in range(model.njnt):  # the zero pose, clipped into the joints' ranges
        lo, hi = inside(model.jnt_range[j]) if model.jnt_limited[j] else (0.0, 0.0)
        data.qpos[model.jnt_qposadr[j]] = np.clip(0.0, lo, hi)
    mujoco.mj_kinematics(model, data)
    chains = [tree.chain(j) for j in tree.movable_out(trunk)]
    if leg_names is None:
        placed, others = _place_legs(tree, trunk, model, data, chains)
    else:
        placed = {place: tree.chain(first) for place, first in leg_names}
        for first, chain in zip(dict(leg_names).values(), placed.values(), strict=True):
            if first not in tree.movable_out(trunk):
                raise DpcError(
                    f"Base {p}: legs names {first!r}, which does not move a link of the trunk "
                    f"{trunk!r}; name each leg's first joint, one of {tree.movable_out(trunk)}."
                )
            _check_leg(tree, chain)
        others = [c for c in chains if c not in placed.values()]
    feet = {place: _foot(tree, model, data, chain, radius) for place, chain in placed.items()}
    anchors = {place: geometry.joint_anchors(model, data, c) for place, c in placed.items()}
    lengths = {place: geometry.leg_length(anchors[place], feet[place][3]) for place in LEGS}
    if height is None:
        height = HOME_FRACTION * float(np.mean(list(lengths.values())))
        height += max(foot[2] for foot in feet.values())
        home_from = f"{HOME_FRACTION} x the legs' mean length + the feet's radius"
    else:
        home_from = "given"
    legs = []
    for place in LEGS:
        chain, (foot, center, r, zero, _) = placed[place], feet[place]
        hip = anchors[place][1]
        target = np.array([hip[0], zero[1], r - height])  # m: under the hip (module doc)
        home, error = solve_home(model, data, chain, (model.body(foot).id, center), target)
        if error > geometry.HOME_TOL:
            raise DpcError(
                f"Base {p}: leg {place} cannot put its foot on the floor under its hip with the "
                f"trunk {height:.3f} m high (it stays {error:.3f} m off; the leg is "
                f"{lengths[place]:.3f} m long); give a lower home_height."
            )
        efforts = tuple(tree.effort(j, place) for j in chain)
        legs.append(
            Leg(place, chain, efforts, foot, _t(center), r, _t(hip), lengths[place], _t(home))
        )
    check_efforts(p, legs, float(model.body_subtreemass[model.body(trunk).id]))
    limbs = tuple(_limb(tree, model, data, chain) for chain in others)
    foot_from = {f[4] for f in feet.values()}
    return BaseSpec(
        name, p, trunk, skipped, tuple(legs), " / ".join(sorted(foot_from)),
        *trunk_numbers(tree, model, data, trunk, limbs), float(height), home_from, limbs, fused,
    )  # fmt: skip


def _t(x) -> tuple[float, ...]:
    return tuple(float(v) for v in x)


def _place_legs(tree, trunk, model, data, chains) -> tuple[dict, list]:
    """Legs (chains ending below the trunk's origin at the zero pose) by place, and the others."""
    legs, others, places = [], [], {}
    for chain in chains:
        end = data.xpos[_tip(tree, model, data, chain)]  # m, trunk frame
        (legs if end[2] < 0.0 else others).append((chain, end))
    if len(legs) != len(LEGS):
        raise DpcError(
            f"Base {tree.path}: found {len(legs)} legs (chains of movable joints from the trunk "
            f"{trunk!r} ending below it, first joints "
            f"{[c[0] for c, _ in legs]}); a quadruped has four. If this is a quadruped, "
            f"{_FIX_LEGS}."
        )
    for chain, end in legs:
        _check_leg(tree, chain)
        if min(abs(end[0]), abs(end[1])) < PLACE_MARGIN:
            raise DpcError(
                f"Base {tree.path}: the leg of {chain[0]!r} ends at x={end[0]:.3f}, y={end[1]:.3f}"
                f" m (trunk frame, zero pose), too near a midplane to tell front from rear and "
                f"left from right; {_FIX_LEGS}."
            )
        place = ("F" if end[0] > 0 else "R") + ("L" if end[1] > 0 else "R")
        if place in places:
            raise DpcError(
                f"Base {tree.path}: the legs of {places[place][0]!r} and {chain[0]!r} both end "
                f"{place} of the trunk at the zero pose; {_FIX_LEGS}."
            )
        places[place] = chain
    return places, [chain for chain, _ in others]


def _check_leg(tree, chain) -> None:
    if len(chain) != LEG_DOF or tree.branches(chain):
        raise DpcError(
            f"Base {tree.path}: the leg {list(chain)} has {len(chain)} joints"
            f"{' and branches' if tree.branches(chain) else ''}; a leg here is one chain of "
            f"{LEG_DOF} (hip, thigh, knee). Give each leg {LEG_DOF} movable joints."
        )


def _tip(tree, model, data, chain) -> int:
    """Body id of the chain's end link farthest from its last joint."""
    knee = data.xanchor[model.joint(chain[-1]).id]
    bodies = [model.body(link).id for link in tree.end_links(chain)]
    return max(bodies, key=lambda b: np.linalg.norm(data.xpos[b] - knee))


def _foot(tree, model, data, chain, radius) -> tuple:
    """(link, centre (3,) m in its frame, radius m, centre (3,) m in the trunk frame, source) of
    the leg's foot: the sphere farthest from the knee among the chain's end links, else the end
    link's origin with FOOT_FRACTION x the leg's length (or the `radius` given)."""
    knee = data.xanchor[model.joint(chain[-1]).id]
    spheres = [
        (np.linalg.norm(data.geom_xpos[g] - knee), g)
        for link in tree.end_links(chain)
        for g in range(model.ngeom)
        if model.geom_bodyid[g] == model.body(link).id
        and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE
    ]
    if spheres:
        g = max(spheres)[1]
        body = model.geom_bodyid[g]
        center, r, source = model.geom_pos[g], float(model.geom_size[g, 0]), "a sphere in the file"
    else:
        body = _tip(tree, model, data, chain)
        center, r, source = np.zeros(3), None, f"{FOOT_FRACTION} x the leg's length (no sphere)"
    world = data.xpos[body] + data.xmat[body].reshape(3, 3) @ center
    if r is None:
        anchors = geometry.joint_anchors(model, data, chain)
        r = FOOT_FRACTION * geometry.leg_length(anchors, world)
    if radius is not None:
        r, source = float(radius), "given"
    return model.body(body).name, center.copy(), r, world, source


def _limb(tree, model, data, chain) -> Limb:
    root = tree.joints[chain[0]]["parent"]
    b = model.body(root).id
    return Limb(
        root, tree.subtree_joints(chain[0]), _t(data.xpos[b]), _t(data.xquat[b]),
        float(model.body_subtreemass[b]),
    )  # fmt: skip


__all__ = [
    "FOOT_FRACTION",
    "HOME_FRACTION",
    "LEGS",
    "LEG_DOF",
    "MASSLESS",
    "NAMED_BASES",
    "BaseSpec",
    "Leg",
    "Limb",
    "arm_urdf",
    "base_file_path",
    "read_base",
]
