"""Bases read from MJCF files (`dpc_mjx.robots.bases.mjcf_tree`): the shipped A1's URDF as MuJoCo
converts it to MJCF (`mj_saveLastXML`, no internet needed), and the same A1 rewritten as a
Menagerie-style file (free joint, degrees, motors, visual meshes, sites, sensors, keyframe, floor,
options), each read and built as the URDF is. MuJoCo C and numpy, but one env stepped twice."""

import json
import math
import pathlib
import struct
import xml.etree.ElementTree as ET

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import FAST_COMPILE

import dpc_mjx
from dpc_mjx import DpcError, assets
from dpc_mjx.robots.bases.describe import description
from dpc_mjx.robots.bases.file import LEGS, arm_urdf, base_file_path, read_base
from dpc_mjx.robots.bases.model import base_mjspec
from dpc_mjx.robots.urdf import strip_meshes

_EXACT = 1e-9  # kg, N·m, m: values the MJCF carries as the URDF has them
_SAVED = 1e-5  # m, rad, kg·m²: values mj_saveLastXML rounds to 6 significant digits
_HOME_TOL = 1e-4  # rad: home angles solved on the rounded file vs on the URDF
_GEAR = 2.0  # the Menagerie-style file's motors: ctrlrange 16.75 x gear 2 = the A1's 33.5 N·m
_A1_EFFORT = 33.5  # N·m, the A1 URDF's <limit effort>


def _convert(urdf: pathlib.Path, out: pathlib.Path) -> pathlib.Path:
    """The URDF, meshes stripped, as MuJoCo converts it (static bodies kept), saved as MJCF."""
    root = ET.parse(urdf).getroot()
    for link in root.findall("link"):
        strip_meshes(link)
    ext = ET.SubElement(root, "mujoco")
    ET.SubElement(ext, "compiler", fusestatic="false", discardvisual="false")
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    mujoco.mj_saveLastXML(str(out), model)
    return out


def _tetrahedron_stl(path: pathlib.Path, size: float = 0.1) -> None:
    """A binary STL of one tetrahedron, `size` m along each axis."""
    vertices = [(0, 0, 0), (size, 0, 0), (0, size, 0), (0, 0, size)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    data = bytearray(80) + struct.pack("<I", len(faces))
    for face in faces:
        data += struct.pack("<3f", 0, 0, 0)
        for i in face:
            data += struct.pack("<3f", *vertices[i])
        data += b"\0\0"
    path.write_bytes(bytes(data))


def _sub(parent: ET.Element, tag: str, index: int | None = None, **attrib) -> ET.Element:
    element = ET.Element(tag, {k: str(v) for k, v in attrib.items()})
    parent.insert(len(parent) if index is None else index, element)
    return element


def _menagerie_style(converted: pathlib.Path) -> ET.Element:
    """The converted A1 as a hand-written MJCF: the trunk at the top with a free joint, angles in
    degrees, torque limits on motors (gear 2) and a position servo (forcerange), a visual mesh and
    a visual sphere (must not count), sites, a sensor, a keyframe, options, floor and light."""
    root = ET.parse(converted).getroot()
    root.find("compiler").attrib.update(angle="degree", meshdir="meshes")
    _sub(root, "option", 1, timestep="0.01", impratio="100")
    visual = _sub(_sub(root, "default", 2), "default", **{"class": "visual"})
    _sub(visual, "geom", type="mesh", contype=0, conaffinity=0, group=2)
    _sub(_sub(root, "asset", 3), "mesh", file="trunk.stl")
    world = root.find("worldbody")
    base = world.find("body")
    trunk = base.find("body")
    world.remove(base)
    world.append(trunk)
    trunk.set("pos", "0 0 0.4")
    _sub(trunk, "freejoint", 0, name="floating")
    _sub(trunk, "geom", **{"class": "visual", "mesh": "trunk"})
    _sub(trunk, "site", name="imu")
    _sub(world, "geom", 0, name="floor", type="plane", size="0 0 1")
    _sub(world, "light", 0, pos="0 0 2")
    actuators = _sub(root, "actuator")
    for joint in root.iter("joint"):
        del joint.attrib["actuatorfrcrange"]
        low, high = (float(x) for x in joint.get("range").split())
        joint.set("range", f"{math.degrees(low)!r} {math.degrees(high)!r}")
        name = joint.get("name")
        if "thigh" in name:
            _sub(actuators, "position", joint=name, kp=50, forcerange="-33.5 33.5")
        else:
            limit = _A1_EFFORT / _GEAR
            _sub(actuators, "motor", joint=name, gear=_GEAR, ctrlrange=f"{-limit} {limit}")
    for place in LEGS:
        foot = next(b for b in root.iter("body") if b.get("name") == f"{place}_foot")
        _sub(foot, "geom", size=0.05, contype=0, conaffinity=0)  # a visual ball, larger
        _sub(foot, "site", name=f"{place}_foot")
    _sub(_sub(root, "sensor"), "gyro", site="imu")
    qpos = " ".join(["0 0 0.4 1 0 0 0"] + ["0"] * 12)
    _sub(_sub(root, "keyframe"), "key", name="home", qpos=qpos)
    return root


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """(the converted A1, the Menagerie-style A1, its folder)."""
    folder = tmp_path_factory.mktemp("mjcf")
    converted = _convert(base_file_path("a1"), folder / "a1.xml")
    (folder / "meshes").mkdir()
    _tetrahedron_stl(folder / "meshes" / "trunk.stl")
    styled = folder / "a1_menagerie.xml"
    styled.write_text(ET.tostring(_menagerie_style(converted), encoding="unicode"))
    return converted, styled, folder


def _assert_reads_as_the_a1(spec, trunk: str) -> None:
    a1 = read_base("a1")
    assert spec.trunk == trunk and spec.leg_joints == a1.leg_joints
    assert [leg.place for leg in spec.legs] == list(LEGS)
    assert [leg.foot for leg in spec.legs] == [leg.foot for leg in a1.legs]
    np.testing.assert_allclose(spec.torque_limits, a1.torque_limits, atol=_EXACT)
    assert spec.mass == pytest.approx(a1.mass, abs=_EXACT)
    assert spec.trunk_mass == pytest.approx(a1.trunk_mass, abs=_EXACT)
    np.testing.assert_allclose(spec.trunk_inertia, a1.trunk_inertia, atol=_SAVED)
    np.testing.assert_allclose(spec.trunk_half_extents, a1.trunk_half_extents, atol=_EXACT)
    assert spec.foot_radius == pytest.approx(a1.foot_radius, abs=_EXACT)
    assert spec.home_height == pytest.approx(a1.home_height, abs=_SAVED)
    np.testing.assert_allclose(spec.home_qpos, a1.home_qpos, atol=_HOME_TOL)
    assert spec.others == () and spec.trunk_box_from == "collision primitives"


def test_the_converted_a1_reads_as_its_urdf(files):
    spec = read_base(files[0])
    _assert_reads_as_the_a1(spec, "trunk")
    assert spec.skipped_roots == ("base",)  # the URDF's massless root, a body here


def test_a_menagerie_style_a1_reads_as_its_urdf(files):
    _assert_reads_as_the_a1(read_base(files[1]), "trunk")


_COUNTS = {
    mujoco.mjtObj.mjOBJ_BODY: "nbody",
    mujoco.mjtObj.mjOBJ_JOINT: "njnt",
    mujoco.mjtObj.mjOBJ_GEOM: "ngeom",
    mujoco.mjtObj.mjOBJ_ACTUATOR: "nu",
    mujoco.mjtObj.mjOBJ_SENSOR: "nsensor",
    mujoco.mjtObj.mjOBJ_SITE: "nsite",
}


def _names(model: mujoco.MjModel, kind: mujoco.mjtObj) -> list[str | None]:
    return [mujoco.mj_id2name(model, kind, i) for i in range(getattr(model, _COUNTS[kind]))]


@pytest.mark.parametrize("which", [0, 1], ids=["converted", "menagerie_style"])
def test_an_mjcf_base_builds_the_urdfs_model(files, which):
    ours = base_mjspec(read_base(files[which])).compile()
    theirs = base_mjspec(read_base("a1")).compile()
    for kind in _COUNTS:
        assert _names(ours, kind) == _names(theirs, kind), kind
    for field in ("body_mass", "body_pos", "body_inertia", "geom_size", "geom_contype",
                  "geom_conaffinity", "actuator_ctrlrange", "dof_damping", "dof_armature",
                  "jnt_range"):  # fmt: skip
        np.testing.assert_allclose(
            getattr(ours, field), getattr(theirs, field), atol=_SAVED, err_msg=field
        )
    assert ours.opt.timestep == theirs.opt.timestep and ours.opt.impratio == theirs.opt.impratio
    assert (ours.nkey, ours.nmesh, ours.nlight) == (0, 0, theirs.nlight)


def test_a_json_names_an_mjcf_and_describe_reproduces_it(files, tmp_path):
    _, styled, folder = files
    legs = {place: f"{place}_hip_joint" for place in LEGS}
    path = folder / "a1.json"
    path.write_text(json.dumps({"file": styled.name, "legs": legs, "home_height": 0.25}))
    spec = read_base(path)
    assert spec.home_height == 0.25 and spec.home_from == "given"
    assert spec.leg_joints == read_base("a1").leg_joints
    again = tmp_path / "again.json"
    again.write_text(json.dumps(description(spec, again)))
    assert read_base(again).home_qpos.tolist() == spec.home_qpos.tolist()


def test_an_env_on_an_mjcf_base_builds_and_steps(files):
    env = dpc_mjx.make(
        "reaching", arm="none", base=str(files[1]), controller="mbc", engine="native",
        push_force=(0.0, 0.0),
    )  # fmt: skip
    reset = jax.jit(env.reset, compiler_options=FAST_COMPILE)
    step = jax.jit(env.step, compiler_options=FAST_COMPILE)
    state = reset(jax.random.PRNGKey(0))
    for _ in range(2):
        state = step(state, jp.zeros(env.action_size))
    assert float(state.done) == 0.0 and np.all(np.isfinite(np.asarray(state.obs)))


def _edited(files, tmp_path, change) -> pathlib.Path:
    root = ET.parse(files[1]).getroot()
    change(root)
    path = files[2] / f"{tmp_path.name}.xml"  # beside meshes/
    path.write_text(ET.tostring(root, encoding="unicode"))
    return path


def _element(root: ET.Element, tag: str, **attrib) -> ET.Element:
    return next(e for e in root.iter(tag) if all(e.get(k) == v for k, v in attrib.items()))


def _no_limit(root):  # a position servo's ctrlrange is an angle, not a torque
    del _element(root, "position", joint="FL_thigh_joint").attrib["forcerange"]


def _two_robots(root):
    box = _sub(root.find("worldbody"), "body", name="box")
    _sub(box, "freejoint")
    _sub(box, "geom", size=0.1)


def _unnamed(root):
    del _element(root, "body", name="RR_calf").attrib["name"]


def _two_joints(root):
    _sub(_element(root, "body", name="FR_hip"), "joint", name="FR_hip_yaw", axis="0 0 1")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (_no_limit, r"leg FL's joint 'FL_thigh_joint' has no torque limit; give it a <motor>"),
        (_two_robots, r"2 top-level bodies \['trunk', 'box'\].*Remove the others"),
        (_unnamed, r"inside 'RR_thigh' has no name; name every body and joint"),
        (_two_joints, r"body 'FR_hip' has 2 joints.*one hinge or slide joint each"),
    ],
    ids=["no_limit", "two_robots", "unnamed_body", "two_joints"],
)
def test_bad_mjcf_files_say_what_to_fix(files, tmp_path, change, message):
    with pytest.raises(DpcError, match=message):
        read_base(_edited(files, tmp_path, change))


def test_an_mjcf_arm_a_urdf_named_xml_and_other_files_are_refused(files, tmp_path):
    arm = _convert(assets.urdf_path("z1"), tmp_path / "z1.xml")
    with pytest.raises(DpcError, match="found 0 legs"):
        dpc_mjx.make("reaching", arm="none", base=str(arm))
    urdf = tmp_path / "a1_urdf.xml"
    urdf.write_bytes(base_file_path("a1").read_bytes())
    with pytest.raises(DpcError, match="top element is <mujoco>, not <robot>; give a URDF"):
        read_base(urdf)
    sdf = tmp_path / "a1.sdf"
    sdf.write_text("<sdf/>")
    with pytest.raises(DpcError, match=r"not a URDF \(.urdf\), an MJCF \(.xml\) or a JSON"):
        read_base(sdf)
    with pytest.raises(DpcError, match="is an MJCF, not a URDF to split"):
        arm_urdf(read_base(files[0]))
