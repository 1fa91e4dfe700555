"""Fixed links whose inertia MuJoCo refuses, fused into the link they hang from
(`dpc_mjx.robots.bases.fuse`): the sum checked against MuJoCo C's own fusion of static bodies, a
base whose only fault is such a link reads and builds (with a warning naming it), and a link a
joint moves with an impossible inertia is refused by name. MuJoCo C and numpy only."""

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from dpc_mjx import DpcError, assets
from dpc_mjx.robots import build
from dpc_mjx.robots.bases.describe import describe
from dpc_mjx.robots.bases.file import base_file_path, read_base
from dpc_mjx.robots.bases.fuse import combine, read_inertial, refused, rpy_matrix
from dpc_mjx.run import cli

_MASS_TOL = 1e-9  # kg: sums of a few masses in float64
_INERTIA_TOL = 1e-9  # kg·m², m: our sum vs MuJoCo C's fusion (float64 eigen decompositions)
# A cover plate's inertia as ANYmal C's `hatch` has it: rank one, so MuJoCo refuses it.
_HATCH = {"ixx": "0.0", "iyy": "0.0", "izz": "0.003", "ixy": "0.0", "ixz": "0.0", "iyz": "0.0"}
_HATCH_MASS = 0.142  # kg


def _link(name: str, mass: float, inertia: dict, xyz="0 0 0", rpy="0 0 0") -> ET.Element:
    link = ET.Element("link", name=name)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", xyz=xyz, rpy=rpy)
    ET.SubElement(inertial, "mass", value=str(mass))
    ET.SubElement(inertial, "inertia", inertia)
    return link


def _fixed(name: str, parent: str, child: str, xyz: str, rpy: str) -> ET.Element:
    joint = ET.Element("joint", name=name, type="fixed")
    ET.SubElement(joint, "origin", xyz=xyz, rpy=rpy)
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    return joint


def _a1_with(tmp_path, change) -> str:
    root = ET.parse(base_file_path("a1")).getroot()
    change(root)
    path = tmp_path / "a1_changed.urdf"
    path.write_text(ET.tostring(root, encoding="unicode"))
    return str(path)


def _add_hatch(root: ET.Element) -> None:
    """A cover on the A1's trunk, fixed, turned, with a rank-one inertia."""
    root.append(_link("hatch", _HATCH_MASS, _HATCH, xyz="0.01 0.0 0.02", rpy="0.1 0 0"))
    root.append(_fixed("trunk_hatch", "trunk", "hatch", "0.116 0.0 0.0758", "0 0.2 0.3"))


def _bad_calf(root: ET.Element) -> None:
    """The FR calf (a knee moves it; its foot is welded to it) given a rank-one inertia."""
    link = next(link for link in root.findall("link") if link.get("name") == "FR_calf")
    link.find("inertial/inertia").attrib.update(_HATCH)


def _bad_thigh(root: ET.Element) -> None:
    """The FR thigh (a joint moves it, no link is welded to it) given a rank-one inertia."""
    link = next(link for link in root.findall("link") if link.get("name") == "FR_thigh")
    link.find("inertial/inertia").attrib.update(_HATCH)


def test_the_sum_is_mujocos_own_fusion_of_a_static_body():
    """Parent and child with possible, full inertias at turned frames: our sum vs MuJoCo C's
    `fusestatic` (which fuses the static child into the parent)."""
    parent_inertia = {"ixx": "0.3", "iyy": "0.4", "izz": "0.5", "ixy": "0.01", "ixz": "0.02",
                      "iyz": "-0.03"}  # fmt: skip
    child_inertia = {"ixx": "0.02", "iyy": "0.03", "izz": "0.04", "ixy": "-0.004", "ixz": "0.001",
                     "iyz": "0.002"}  # fmt: skip
    parent = _link("parent", 2.0, parent_inertia, xyz="0.1 -0.05 0.02", rpy="0.3 -0.2 0.1")
    child = _link("child", 0.7, child_inertia, xyz="0.03 0.02 -0.01", rpy="-0.4 0.5 0.2")
    joint = _fixed("weld", "parent", "child", "0.2 0.1 -0.3", "0.6 0.1 -0.7")
    robot = ET.Element("robot", name="r")
    robot.extend([ET.Element("link", name="world"), parent, child, joint])
    slide = ET.SubElement(robot, "joint", name="slide", type="prismatic")
    ET.SubElement(slide, "parent", link="world")
    ET.SubElement(slide, "child", link="parent")
    ET.SubElement(slide, "axis", xyz="1 0 0")
    ET.SubElement(slide, "limit", effort="1", lower="-1", upper="1", velocity="1")
    ext = ET.SubElement(robot, "mujoco")
    ET.SubElement(ext, "compiler", fusestatic="true", inertiafromgeom="false")
    model = mujoco.MjModel.from_xml_string(ET.tostring(robot, encoding="unicode"))
    b = model.body("parent").id
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.body_iquat[b])
    rot = rot.reshape(3, 3)
    want = rot @ np.diag(model.body_inertia[b]) @ rot.T  # kg·m², parent's axes

    got = combine(
        read_inertial(parent), read_inertial(child), rpy_matrix([0.6, 0.1, -0.7]),
        np.array([0.2, 0.1, -0.3]),
    )  # fmt: skip
    assert [model.body(i).name for i in range(model.nbody)] == ["world", "parent"]  # fused
    assert got.mass == pytest.approx(model.body_mass[b], abs=_MASS_TOL)
    np.testing.assert_allclose(got.com, model.body_ipos[b], atol=_INERTIA_TOL)
    np.testing.assert_allclose(got.inertia, want, atol=_INERTIA_TOL)


def test_mujoco_refuses_what_refused_says_it_does():
    def inertial(values):
        return read_inertial(_link("x", 1.0, dict(zip(_HATCH, values, strict=True))))

    assert refused(inertial(["0", "0", "0.003", "0", "0", "0"]))  # rank one
    assert refused(inertial(["0.001", "0.001", "0.001", "0.001", "0", "0"]))  # not positive
    assert not refused(inertial(["0", "0", "0", "0", "0", "0"]))  # a frame's: MuJoCo reads it
    assert not refused(inertial(["0.001", "0.002", "0.0025", "0", "0", "0"]))


def test_a_fixed_link_with_a_bad_inertia_is_fused_and_the_base_builds(tmp_path):
    path = _a1_with(tmp_path, _add_hatch)
    with pytest.warns(UserWarning, match=r"fused 1 link\(s\).*'trunk'.*hatch.*refuses"):
        spec = read_base(path)
    a1 = read_base("a1")
    (fused,) = spec.fused
    assert (fused.into, fused.links, fused.refused) == ("trunk", ("hatch",), ("hatch",))
    assert spec.mass == pytest.approx(a1.mass + _HATCH_MASS, abs=_MASS_TOL)
    assert spec.trunk_mass == pytest.approx(a1.trunk_mass + _HATCH_MASS, abs=_MASS_TOL)
    assert spec.leg_joints == a1.leg_joints
    assert "warning: fused 1 link(s) no joint moves into 'trunk'" in describe(spec)
    model = build("none", base=spec)  # the env's model: the same masses
    trunk = model.body("trunk").id
    assert model.body_subtreemass[trunk] == pytest.approx(spec.mass, abs=1e-6)
    assert not read_base("a1").fused  # a file MuJoCo reads as it is: nothing fused


def test_dpc_mjx_base_reports_the_fused_links_with_a_warning(tmp_path, capsys):
    assert cli.main(["base", _a1_with(tmp_path, _add_hatch)]) == 0
    printed = capsys.readouterr().out
    assert "warning: fused 1 link(s) no joint moves into 'trunk'" in printed
    assert "hatch; because MuJoCo refuses the inertia of hatch" in printed


def test_a_moving_link_with_a_bad_inertia_is_refused_by_name(tmp_path):
    with pytest.raises(DpcError, match=r"link 'FR_thigh' \(moved by joint 'FR_thigh_joint'\).*"
                       r"Give 'FR_thigh' an <inertial>"):  # fmt: skip
        read_base(_a1_with(tmp_path, _bad_thigh))


def test_a_moving_link_made_whole_by_the_links_welded_to_it_is_fused(tmp_path):
    """The FR calf's own inertia refused, its foot (welded to it) makes the rigid body whole:
    what moves is possible, so the foot is fused into it (as ANYmal B's placeholder `base`)."""
    with pytest.warns(UserWarning, match="into 'FR_calf'"):
        spec = read_base(_a1_with(tmp_path, _bad_calf))
    assert [(f.into, f.links, f.refused) for f in spec.fused] == [
        ("FR_calf", ("FR_foot",), ("FR_calf",))
    ]


@pytest.mark.skipif(not assets.wheel_installed(), reason="needs the example-robot-data wheel")
def test_anymal_c_reads_with_its_hatch_fused():
    with pytest.warns(UserWarning, match="hatch"):
        spec = read_base(assets.wheel_urdf("anymal_c_simple_description/urdf/anymal.urdf"))
    (fused,) = spec.fused
    assert fused.into == "base" and "hatch" in fused.refused
    assert {leg.joints[0] for leg in spec.legs} == {"LF_HAA", "RF_HAA", "LH_HAA", "RH_HAA"}
