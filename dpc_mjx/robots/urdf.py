"""Load one of the URDFs shipped with dpc_mjx (`dpc_mjx.assets`, copies of the example-robot-data
wheel's) into an `mujoco.MjSpec`, without its meshes.

The visual meshes are COLLADA (.dae), which MuJoCo cannot read, and mesh collision shapes are
costly in MJX (and not shipped). We therefore drop every <visual> element and every mesh collision
shape, and keep the URDF's primitive collision shapes (boxes, cylinders, spheres) as *visual-only*
geoms, so the model still renders as a recognisable robot. The inertial properties come from the
URDF unchanged.
"""

from __future__ import annotations

import pathlib
import xml.etree.ElementTree as ET

import mujoco

from dpc_mjx import assets

VISUAL_GROUP = 1  # geom group of the visual-only primitives


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
