"""What `dpc_mjx.robots.bases.file.read_base` inferred of a quadruped base, for the user to check
and correct (issue 27; `dpc-mjx base FILE [--out my_dog.json]`).

`describe(spec)`: the `BaseSpec` as readable text: the trunk, the masses, each leg (place, joints,
torque limits, foot and its radius, length, home angles), the trunk's box, the home height and
any other actuated subtree (an arm the file carries), each with where it came from; a warning
for each set of fixed links fused because MuJoCo refuses an inertia among them (`bases.fuse`).

`description(spec, json_path)`: the base's JSON file (`bases.file`'s module doc) that, written at
`json_path`, makes `read_base(json_path)` give the same legs, home height and foot radius; edit
its "legs", "home_height" or "foot_radius" to correct what inference got wrong.
"""

from __future__ import annotations

import os
import pathlib

from dpc_mjx.robots.bases.file import LEGS, BaseSpec
from dpc_mjx.robots.bases.fuse import describe_fused

_DIGITS = 4  # decimals printed: 0.1 mm, 0.1 g, 1e-4 rad
_SAME_RADIUS = 1e-12  # m: feet whose radii differ by less are given one radius in the JSON


def _num(x: float) -> str:
    """`x` with _DIGITS decimals, no "-0.0000" (a hip angle of -1e-12 rad reads 0.0000)."""
    return f"{round(float(x), _DIGITS) + 0.0:.{_DIGITS}f}"


def _vec(xs) -> str:
    return "(" + ", ".join(_num(x) for x in xs) + ")"


def describe(spec: BaseSpec) -> str:
    """`spec` as text, one fact a line, each with its unit and, where inferred, how."""
    skipped = ", ".join(spec.skipped_roots) or "none"
    lines = [
        f"base {spec.name}: {spec.path}",
        f"trunk: {spec.trunk} (gets the free joint; massless roots skipped above it: {skipped})",
        f"mass: {_num(spec.mass)} kg in all, {_num(spec.base_mass)} kg without other subtrees",
        f"rigid trunk: {_num(spec.trunk_mass)} kg, centre of mass {_vec(spec.trunk_com)} m",
        "  (positions in the trunk frame: x forward, y left, z up)",
        f"legs, in the order {' '.join(LEGS)} (feet: {spec.foot_from}):",
    ]
    for leg in spec.legs:
        lines += [
            f"  {leg.place}: joints {', '.join(leg.joints)} (hip, thigh, knee)",
            f"      torque limits {', '.join(_num(t) for t in leg.torque_limits)} N·m",
            f"      foot {leg.foot}: radius {_num(leg.foot_radius)} m, centre "
            f"{_vec(leg.foot_center)} m in its link's frame",
            f"      length {_num(leg.length)} m (thigh joint, knee, foot centre); thigh joint at "
            f"{_vec(leg.hip)} m",
            f"      home angles {', '.join(_num(q) for q in leg.home)} rad",
        ]
    lines += [
        f"trunk box: centre {_vec(spec.trunk_box_center)} m, half extents "
        f"{_vec(spec.trunk_half_extents)} m, around its {spec.trunk_box_from}",
        f"home height: {_num(spec.home_height)} m, trunk origin above floor ({spec.home_from})",
    ]
    if not spec.others:
        lines.append("other actuated subtrees: none")
    for limb in spec.others:
        lines += [
            f"other actuated subtree at {limb.root}: joints {', '.join(limb.joints)}",
            f"    mass {_num(limb.mass)} kg, mounted at {_vec(limb.mount_pos)} m, turned by "
            f"{_vec(limb.mount_quat)} (w, x, y, z); split it off with "
            "dpc_mjx.robots.bases.file.arm_urdf",
        ]
    if _one_radius(spec) is None:
        lines.append("note: the feet's radii differ, so the JSON leaves foot_radius out")
    if spec.fused:
        lines += [f"warning: {line}" for line in describe_fused(spec.fused).splitlines()]
        lines.append("  (check the file's inertias there; the fused links keep their frames)")
    return "\n".join(lines)


def description(spec: BaseSpec, json_path: str | os.PathLike) -> dict:
    """The JSON object of the base's file to write at `json_path` (`read_base(json_path)` then
    gives `spec`'s legs, home pose and feet): "file" the URDF, relative to the JSON's folder
    where it lies in that folder or below it, else absolute; "legs" each place's first joint;
    "home_height" (m); "foot_radius" (m), left out where the four feet's radii differ."""
    folder = pathlib.Path(json_path).expanduser().resolve().parent
    urdf = spec.path.resolve()
    file = urdf.relative_to(folder) if urdf.is_relative_to(folder) else urdf
    out = {
        "file": file.as_posix(),
        "legs": {leg.place: leg.joints[0] for leg in spec.legs},
        "home_height": spec.home_height,
    }
    radius = _one_radius(spec)
    if radius is not None:
        out["foot_radius"] = radius
    return out


def _one_radius(spec: BaseSpec) -> float | None:
    """m: the feet's one radius, None where they differ (one radius cannot reproduce them)."""
    radii = [leg.foot_radius for leg in spec.legs]
    return spec.foot_radius if max(radii) - min(radii) < _SAME_RADIUS else None


__all__ = ["describe", "description"]
