"""What base files and arm files share (`robots.bases` and `robots.arms` both read through here):
one of the URDFs shipped with dpc_mjx (`dpc_mjx.assets`, copies of the example-robot-data wheel's)
loaded into an `mujoco.MjSpec` without its meshes, the geom and site groups of what is only drawn,
the mesh formats and URDF joint kinds MuJoCo reads, a joint's range narrowed for a home pose, and
the JSON file that names a robot file and what to read of it (`read_description`).

The visual meshes are COLLADA (.dae), which MuJoCo cannot read, and mesh collision shapes are
costly in MJX (and not shipped). We therefore drop every <visual> element and every mesh collision
shape, and keep the URDF's primitive collision shapes (boxes, cylinders, spheres) as *visual-only*
geoms, so the model still renders as a recognisable robot. The inertial properties come from the
URDF unchanged.
"""

from __future__ import annotations

import json
import pathlib
import xml.etree.ElementTree as ET

import mujoco

from dpc_mjx import assets
from dpc_mjx.errors import DpcError

VISUAL_GROUP = 1  # geom group of the visual-only primitives
VISUAL_GROUP_SITES = 4  # sites are hidden by default in the viewer
MESH_FORMATS = (".stl", ".obj", ".msh")  # the mesh files MuJoCo reads
URDF_MOVABLE = ("revolute", "continuous", "prismatic")
HOME_MARGIN = 0.05  # rad (m): an inferred home pose stays this far inside the joint range


def load_urdf(name: str | pathlib.Path, *, drop_links: tuple[str, ...] = ()) -> mujoco.MjSpec:
    """The URDF `name` (see `assets.URDFS`, or a path) as a spec, meshes removed, static bodies not
    yet fused.

    `drop_links` removes links (and the joints into or out of them) before loading; used to drop
    the URDF's dummy `base`/`world` link so the real root link can be given a free joint or be
    attached to another robot.
    """
    path = name if isinstance(name, pathlib.Path) else assets.urdf_path(name)
    root = ET.parse(path).getroot()
    for link in root.findall("link"):
        strip_meshes(link)
        if link.get("name") in drop_links:
            root.remove(link)
    for joint in root.findall("joint"):
        ends = {joint.find("parent").get("link"), joint.find("child").get("link")}
        if ends & set(drop_links):
            root.remove(joint)
    # MuJoCo's URDF extension: keep static bodies apart until we have added our sites.
    ext = ET.SubElement(root, "mujoco")
    ET.SubElement(ext, "compiler", fusestatic="false", discardvisual="false")
    spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    spec.compiler.fusestatic = True
    for geom in spec.geoms:
        make_visual(geom)
    return spec


def strip_meshes(link: ET.Element) -> None:
    """Remove a URDF link's <visual>s (the wheel's are COLLADA) and its mesh <collision>s, keeping
    its primitive collision shapes (made visual-only once loaded)."""
    for visual in link.findall("visual"):
        link.remove(visual)
    for collision in link.findall("collision"):
        if collision.find("geometry/mesh") is not None:
            link.remove(collision)


def make_visual(geom: mujoco.MjsGeom) -> None:
    """Turn a geom into a massless, non-colliding visual."""
    geom.contype = 0
    geom.conaffinity = 0
    geom.group = VISUAL_GROUP
    geom.density = 0.0
    geom.mass = 0.0


def inside(rng: tuple[float, float]) -> tuple[float, float]:
    """The joint range `rng` narrowed by `HOME_MARGIN` at each end (to half its width at most)."""
    lo, hi = rng
    margin = min(HOME_MARGIN, (hi - lo) / 2)
    return lo + margin, hi - margin


def read_description(p: pathlib.Path, what: str, keys: tuple[str, ...], first: str) -> dict:
    """A JSON file describing a robot file (a base's, an arm's): an object with the key `keys[0]`
    (its file) and any of the others; `DpcError` naming `what` and `first` (what the first key
    holds) otherwise."""
    try:
        d = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DpcError(f"{what} {p} is not valid JSON ({e}); fix the file.") from e
    if not isinstance(d, dict) or keys[0] not in d or set(d) - set(keys):
        got = f"keys {sorted(d)}" if isinstance(d, dict) else repr(d)
        raise DpcError(
            f'{what} {p}: expected a JSON object with "{keys[0]}" ({first}) and any of '
            f"{list(keys[1:])}; got {got}."
        )
    return d
