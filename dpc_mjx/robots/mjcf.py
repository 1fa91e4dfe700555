"""Write every variant as MJCF, Menagerie style: a robot file and a scene file that includes it.

`mjcf/a1_<variant>.xml` holds the robot (A1, arms, actuators, sensors, options, home keyframe);
`mjcf/scene_<variant>.xml` includes it and adds the floor, light and sky. No file outside the
folder is referenced, so the folder can be copied anywhere and opened with `python -m
mujoco.viewer --mjcf mjcf/scene_regular.xml`.
"""

from __future__ import annotations

import pathlib
import xml.etree.ElementTree as ET

import mujoco

from dpc_mjx.robots.assemble import add_scene, robot_spec
from dpc_mjx.robots.variants import VARIANTS

_SCENE_PARTS = ("visual", "asset", "worldbody")  # what add_scene contributes


def robot_filename(name: str) -> str:
    return f"a1_{name}.xml"


def scene_filename(name: str) -> str:
    return f"scene_{name}.xml"


def robot_xml(name: str) -> str:
    """MJCF text of the robot file of variant `name`."""
    return robot_spec(name).to_xml()


def scene_xml(name: str) -> str:
    """MJCF text of the scene file of variant `name` (includes the robot file)."""
    parts = ET.fromstring(add_scene(mujoco.MjSpec()).to_xml())
    root = ET.Element("mujoco", model=f"a1_{name} scene")
    ET.SubElement(root, "include", file=robot_filename(name))
    for child in parts:
        if child.tag in _SCENE_PARTS:
            root.append(child)
    # The headlight on (add_scene), as MuJoCo 3 and 4 both read it: MuJoCo 3.17 writes nothing (on
    # is its default) and reads only integers, MuJoCo 4 writes "true" (its default is "auto").
    root.find("visual/headlight").set("active", "1")
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def write_mjcf(out_dir: str | pathlib.Path, names=tuple(VARIANTS)) -> list[pathlib.Path]:
    """Write robot and scene files of each variant into `out_dir`; return the paths written."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name in names:
        for filename, text in (
            (robot_filename(name), robot_xml(name)),
            (scene_filename(name), scene_xml(name)),
        ):
            path = out / filename
            path.write_text(text)
            written.append(path)
    return written
