"""What `bases.file.read_base` measures on a base compiled alone with its trunk welded at the origin
(`LinkTree.compile`; world coordinates are trunk-frame ones): the rigid trunk's numbers and a leg's
home pose; and the check that its leg joints' efforts are motors' limits, not placeholders."""

from __future__ import annotations

import mujoco
import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.bases import geometry
from dpc_mjx.robots.urdf import inside

KNEE_START = 0.5  # rad: a straight leg's home is solved again from its knee bent this much


def _t(x) -> tuple[float, ...]:
    return tuple(float(v) for v in x)


def trunk_numbers(tree, model, data, trunk, limbs) -> tuple:
    """mass, trunk mass, COM, inertia, box centre, half extents, box source (BaseSpec's order).
    The trunk's mass, COM and inertia are the rigid trunk's: its link and the links welded to
    it, less the roots of `limbs` (an arm's base) and what is welded to them."""
    b = model.body(trunk).id
    limb_links = {w for limb in limbs if limb.root != trunk for w in tree.welded(limb.root)}
    rigid = [model.body(w).id for w in tree.welded(trunk) if w not in limb_links]
    mass, com, inertia = geometry.rigid_inertia(model, data, rigid)
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == b]
    primitives = [g for g in geoms if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH]
    if not geoms:
        raise DpcError(
            f"Base {tree.path}: the trunk link {trunk!r} has no collision shape, so its box (where "
            "arms are mounted) is unknown; give it a <collision> <box> or a mesh (MJCF: <geom>)."
        )
    box = geometry.geom_box(model, data, primitives or geoms)
    return (
        float(model.body_subtreemass[b]), mass, _t(com), tuple(_t(row) for row in inertia),
        _t(box.mean(axis=0)), _t((box[1] - box[0]) / 2),
        "collision primitives" if primitives else "collision meshes",
    )  # fmt: skip


def solve_home(model, data, chain, foot, target) -> tuple[np.ndarray, float]:
    """`geometry.solve_leg` from the zero pose, and where that leaves the foot off (a leg
    straight at the zero pose, Solo 12's: no joint moves its foot along the leg), from the knee
    bent KNEE_START rad one way, then the other (clipped into its range)."""
    qadr = [model.jnt_qposadr[model.joint(name).id] for name in chain]
    start = data.qpos[qadr].copy()
    home, error = geometry.solve_leg(model, data, chain, foot, target)
    for bend in (-KNEE_START, KNEE_START):
        if error <= geometry.HOME_TOL:
            break
        knee = model.joint(chain[-1]).id
        lo, hi = inside(model.jnt_range[knee]) if model.jnt_limited[knee] else (-np.inf, np.inf)
        data.qpos[qadr] = [*start[:-1], np.clip(start[-1] + bend, lo, hi)]
        home, error = geometry.solve_leg(model, data, chain, foot, target)
    return home, error


__all__ = ["KNEE_START", "solve_home", "trunk_numbers"]


EFFORT_PLACEHOLDER = 50.0  # a leg joint's effort this many times its standing torque: no motor


def check_efforts(path, legs, mass: float) -> None:
    """`DpcError` for a leg joint whose effort (N·m) is `EFFORT_PLACEHOLDER` times or more the
    torque that holding the base up takes, m g L / 4 (each leg a quarter of the weight at its
    length's lever): a file's placeholder (Solo 12's 1000 N·m), which the controller would
    scale its joints' damping and armature by."""
    for leg in legs:
        standing = mass * 9.81 * leg.length / 4.0  # N·m
        if max(leg.torque_limits) >= EFFORT_PLACEHOLDER * standing:
            raise DpcError(
                f"Base {path}: leg {leg.place}'s joints declare efforts {leg.torque_limits} N·m, "
                f"{max(leg.torque_limits) / standing:.0f}x the {standing:.1f} N·m that holding "
                f"its {mass:.2f} kg up takes: a placeholder, not a motor's limit. Give each leg "
                "joint its motor's <limit effort> (N·m) in the URDF, or correct torque_limits in "
                "the JSON of `dpc-mjx base FILE --out my_dog.json`."
            )
