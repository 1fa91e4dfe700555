"""Bases read from their files (`dpc_mjx.robots.bases.file`), checked against the files themselves:
the URDF's XML read here, and a MuJoCo C model compiled here from the file as it is (root link and
all). MuJoCo C and numpy only: nothing here compiles a JAX program."""

import importlib.metadata
import json
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from dpc_mjx import DpcError, assets
from dpc_mjx.robots import build
from dpc_mjx.robots.arms import REFERENCE_TRUNK_HALF_EXTENTS
from dpc_mjx.robots.arms import file as arm_file
from dpc_mjx.robots.bases import a1
from dpc_mjx.robots.bases import file as base_file
from dpc_mjx.robots.bases.file import (
    LEGS,
    MESHES,
    NAMED_BASES,
    arm_urdf,
    base_file_path,
    read_base,
)
from dpc_mjx.robots.urdf import strip_meshes

_MASS_TOL = 1e-5  # kg: the file's masses summed vs the spec's (Go1's, B1's 1e-6 kg roots dropped)
_FOOT_TOL = 1e-5  # m: a home foot's centre vs its target (the solver stops within 1e-6 m)
_EXACT = 1e-9  # m, rad: values copied from the file or from robots.bases.a1
_ABDUCTION_TOL = 1e-6  # rad: a home hip ab/adduction left at 0 (the solver stops within 1e-6 m)
_A1_HOME_ANGLE_TOL = 0.01  # rad: the solved A1 home vs bases.a1.HOME_LEG (0.9, -1.8 at 0.27 m)
_UNITREE_PARTS = ("hip", "thigh", "calf")  # Unitree's names: {place}_{part}_joint, hip to knee
_BASES = ("a1", "b1", "go1", "go2")  # the named bases alone (b1-z1: the B1 with its Z1, below)

_installed = assets.wheel_installed() and importlib.metadata.version(assets.WHEEL)
needs_copied_wheel = pytest.mark.skipif(
    _installed != assets.WHEEL_VERSION,
    reason=f"the shipped URDFs are copies of example-robot-data {assets.WHEEL_VERSION}",
)


def _xml(name: str) -> ET.Element:
    return ET.parse(base_file_path(name)).getroot()


def _file_model(root: ET.Element) -> mujoco.MjModel:
    """The URDF as it is (meshes dropped), static links kept apart, inertias from the file but
    the root link's: Go1's and B1's 1e-6 kg `base` has a singular inertia MuJoCo refuses."""
    root = ET.fromstring(ET.tostring(root))
    children = {j.find("child").get("link") for j in root.findall("joint")}
    for link in root.findall("link"):
        strip_meshes(link)
        if link.get("name") not in children and link.find("inertial") is not None:
            link.remove(link.find("inertial"))
    ext = ET.SubElement(root, "mujoco")
    ET.SubElement(ext, "compiler", fusestatic="false", inertiafromgeom="false")
    return mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))


def _masses(root: ET.Element) -> dict[str, float]:
    return {
        link.get("name"): float(m.get("value")) if (m := link.find("inertial/mass")) is not None
        else 0.0
        for link in root.findall("link")
    }  # fmt: skip


def _welded(root: ET.Element, link: str) -> set[str]:
    found = {link}
    for j in root.findall("joint"):
        if j.get("type") == "fixed" and j.find("parent").get("link") == link:
            found |= _welded(root, j.find("child").get("link"))
    return found


def _in_trunk_frame(model, data, trunk: str, point: np.ndarray) -> np.ndarray:
    b = model.body(trunk).id
    return data.xmat[b].reshape(3, 3).T @ (point - data.xpos[b])


@pytest.mark.parametrize("name", _BASES)
def test_legs_are_placed_by_geometry_as_unitree_names_them(name):
    spec = read_base(name)
    assert [leg.place for leg in spec.legs] == list(LEGS)
    for leg in spec.legs:
        assert leg.joints == tuple(f"{leg.place}_{part}_joint" for part in _UNITREE_PARTS)
        assert leg.foot == f"{leg.place}_foot"
        assert leg.foot_radius > 0.0
    assert len(spec.leg_joints) == 12 and spec.others == ()


@pytest.mark.parametrize("name", _BASES)
def test_torque_limits_and_masses_are_the_files(name):
    spec, root = read_base(name), _xml(name)
    efforts = {j.get("name"): j.find("limit") for j in root.findall("joint")}
    expected = [float(efforts[joint].get("effort")) for joint in spec.leg_joints]
    np.testing.assert_allclose(spec.torque_limits, expected, atol=_EXACT)
    masses = _masses(root)
    assert spec.mass == pytest.approx(sum(masses.values()), abs=_MASS_TOL)
    trunk = sum(masses[link] for link in _welded(root, spec.trunk))
    assert spec.trunk_mass == pytest.approx(trunk, abs=_MASS_TOL)
    inertia = np.array(spec.trunk_inertia)
    np.testing.assert_allclose(inertia, inertia.T, atol=_EXACT)
    assert np.all(np.linalg.eigvalsh(inertia) > 0.0)
    assert all(h > 0.0 for h in spec.trunk_half_extents)


@pytest.mark.parametrize("name", _BASES)
def test_home_pose_stands_on_the_feet_under_the_hips(name):
    spec = read_base(name)
    model = _file_model(_xml(name))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)  # every joint at 0: where the thigh joints sit
    thighs = {leg.place: model.body(leg.joints[1].replace("_joint", "")).id for leg in spec.legs}
    hips = {p: _in_trunk_frame(model, data, spec.trunk, data.xpos[b]) for p, b in thighs.items()}
    for joint, q in zip(spec.leg_joints, spec.home_qpos, strict=True):
        data.qpos[model.jnt_qposadr[model.joint(joint).id]] = q
    mujoco.mj_kinematics(model, data)
    for leg in spec.legs:
        foot = model.body(leg.foot).id
        center = data.xpos[foot] + data.xmat[foot].reshape(3, 3) @ np.array(leg.foot_center)
        center = _in_trunk_frame(model, data, spec.trunk, center)  # m, trunk at the origin
        sole = spec.home_height + center[2] - leg.foot_radius  # m above the floor
        assert abs(sole) < _FOOT_TOL, (leg.place, sole)
        np.testing.assert_allclose(center[:2], hips[leg.place][:2], atol=_FOOT_TOL)


def test_the_a1_read_from_its_file_is_robots_a1():
    spec = read_base("a1")
    assert spec.leg_joints == a1.LEG_JOINTS
    assert spec.trunk == a1.TRUNK
    assert spec.home_height == pytest.approx(a1.HOME_HEIGHT, abs=_EXACT)
    assert spec.foot_radius == pytest.approx(a1.FOOT_RADIUS, abs=_EXACT)
    np.testing.assert_allclose(spec.trunk_half_extents, a1.TRUNK_HALF_EXTENTS, atol=_EXACT)
    assert REFERENCE_TRUNK_HALF_EXTENTS == a1.TRUNK_HALF_EXTENTS  # the mounts' box is the A1's
    np.testing.assert_allclose(spec.trunk_box_center, 0.0, atol=_EXACT)
    np.testing.assert_allclose(spec.home_qpos, a1.home_leg_qpos(), atol=_A1_HOME_ANGLE_TOL)


def test_go2_has_a_mesh_trunk_and_no_foot_spheres():
    spec = read_base("go2")
    assert spec.trunk_box_from == "collision meshes"
    assert spec.skipped_roots == () and spec.trunk == "base"
    assert "no sphere" in spec.foot_from
    assert 0.015 < spec.foot_radius < 0.03  # m: 5 % of the 0.426 m leg; Go2's feet are ~0.022 m


def test_placement_follows_geometry_not_names(tmp_path):
    text = base_file_path("a1").read_text()
    swapped = text.replace("FR_", "XX_").replace("RL_", "FR_").replace("XX_", "RL_")
    (tmp_path / "swapped.urdf").write_text(swapped)
    spec = read_base(tmp_path / "swapped.urdf")
    assert [leg.joints[0] for leg in spec.legs] == [
        "RL_hip_joint",  # front right: the leg the file now calls RL
        "FL_hip_joint",
        "RR_hip_joint",
        "FR_hip_joint",
    ]


def test_json_names_the_legs_and_the_height(tmp_path):
    legs = {place: f"{place}_hip_joint" for place in LEGS}
    path = tmp_path / "a1.json"
    path.write_text(
        json.dumps({"file": str(base_file_path("a1")), "legs": legs, "home_height": 0.25})
    )
    spec = read_base(path)
    assert spec.home_height == 0.25 and spec.home_from == "given"
    assert spec.leg_joints == a1.LEG_JOINTS


def _a1_without(tmp_path, change) -> str:
    root = _xml("a1")
    change(root)
    path = tmp_path / "bad.urdf"
    path.write_text(ET.tostring(root, encoding="unicode"))
    return str(path)


def _drop_leg(root: ET.Element, leg: str = "RL") -> None:
    for element in [*root.findall("link"), *root.findall("joint")]:
        if element.get("name").startswith(f"{leg}_"):
            root.remove(element)


def _fix_knee(root: ET.Element) -> None:
    next(j for j in root.findall("joint") if j.get("name") == "FR_calf_joint").set("type", "fixed")


def _no_effort(root: ET.Element) -> None:
    joint = next(j for j in root.findall("joint") if j.get("name") == "FL_thigh_joint")
    del joint.find("limit").attrib["effort"]


def _two_right_rear(root: ET.Element) -> None:
    """The RL leg moved to the right: two legs end rear right."""
    for j in root.findall("joint"):
        if j.get("name") in ("RL_hip_joint", "RL_thigh_joint"):
            x, y, z = (float(v) for v in j.find("origin").get("xyz").split())
            j.find("origin").set("xyz", f"{x} {-y} {z}")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (_drop_leg, r"found 3 legs.*JSON file.*\"legs\""),
        (_fix_knee, r"leg \['FR_hip_joint', 'FR_thigh_joint'\] has 2 joints.*Give each leg 3"),
        (_no_effort, r"'FL_thigh_joint' has no torque limit; give it <limit effort"),
        (_two_right_rear, r"'RR_hip_joint' and 'RL_hip_joint' both end RR.*\"legs\""),
    ],
    ids=["three_legs", "two_joint_leg", "no_effort", "two_rear_right"],
)
def test_bad_files_say_what_to_fix(tmp_path, change, message):
    with pytest.raises(DpcError, match=message):
        read_base(_a1_without(tmp_path, change))


def test_missing_file_and_unreachable_height_say_what_to_fix(tmp_path):
    with pytest.raises(DpcError, match="does not exist; give a named base"):
        read_base(tmp_path / "nope.urdf")
    with pytest.raises(DpcError, match="give a lower home_height"):
        read_base("a1", home_height=1.0)


def test_a_mesh_trunk_without_its_mesh_says_what_to_fix(tmp_path):
    (tmp_path / "go2.urdf").write_bytes(base_file_path("go2").read_bytes())
    with pytest.raises(DpcError, match="base_convex.stl.*cannot be read.*Put the mesh file"):
        read_base(tmp_path / "go2.urdf")


@needs_copied_wheel
@pytest.mark.parametrize("name", sorted(NAMED_BASES))
def test_shipped_base_files_are_the_wheels(name):
    assert base_file_path(name).read_bytes() == assets.wheel_urdf(NAMED_BASES[name][1]).read_bytes()


@needs_copied_wheel
def test_shipped_go2_trunk_mesh_is_the_wheels():
    wheel = assets.wheel_urdf("go2_description/collisions/base_convex.stl")
    assert (MESHES / "go2" / "base_convex.stl").read_bytes() == wheel.read_bytes()


def test_b1_z1_reads_as_the_b1_with_the_z1_as_another_limb():
    spec, b1 = read_base("b1-z1"), read_base("b1")
    assert spec.leg_joints == b1.leg_joints
    np.testing.assert_allclose(spec.home_qpos, b1.home_qpos, atol=_EXACT)
    (arm,) = spec.others
    assert arm.root == "link00" and len(arm.joints) == 7  # 6 joints and the gripper's
    np.testing.assert_allclose(arm.mount_pos, (0.35, 0.0, 0.09), atol=_EXACT)  # m, trunk frame
    np.testing.assert_allclose(arm.mount_quat, (1.0, 0.0, 0.0, 0.0), atol=_EXACT)
    assert spec.mass == pytest.approx(sum(_masses(_xml("b1-z1")).values()), abs=_MASS_TOL)
    assert spec.base_mass == pytest.approx(b1.mass, abs=_MASS_TOL)  # the legs make the base
    assert spec.trunk_mass == pytest.approx(b1.trunk_mass, abs=_MASS_TOL)  # the arm not counted


def test_the_z1_split_from_b1_z1_is_the_z1_arm(tmp_path):
    spec = read_base("b1-z1")
    path = tmp_path / "b1_z1_arm.urdf"
    path.write_text(arm_urdf(spec))
    split, z1 = arm_file.read(path), arm_file.read(assets.urdf_path("z1"), keep_meshes=False)
    assert split.root == "link00" and split.joints.keys() == z1.joints.keys()
    for name, rng in split.joints.items():
        np.testing.assert_allclose(rng, z1.joints[name], atol=_EXACT, err_msg=name)
    assert sum(_masses(ET.parse(path).getroot()).values()) == pytest.approx(
        spec.others[0].mass, abs=_MASS_TOL
    )
    ours, theirs = split.spec.compile(), z1.spec.compile()  # the same links, masses, inertias
    for field in ("body_mass", "body_inertia", "body_pos", "jnt_axis"):
        np.testing.assert_allclose(getattr(ours, field), getattr(theirs, field), atol=_EXACT)


@pytest.mark.skipif(not assets.wheel_installed(), reason="needs the example-robot-data wheel")
@pytest.mark.filterwarnings("ignore:.*fused 37 link")  # ANYmal C's (tests/test_urdf_fuse.py)
@pytest.mark.parametrize(
    "file",
    [
        "solo_description/robots/solo12.urdf",  # straight legs at the zero pose
        "anymal_c_simple_description/urdf/anymal.urdf",  # feet outboard of the thigh joints
    ],
)
def test_home_stands_where_the_legs_hang_sideways_and_from_a_bent_knee(file, monkeypatch):
    """Feet on the floor under the thigh joint fore-aft, sideways where they hang at the zero
    pose (ANYmal C's shank is offset outboard); a leg straight at the zero pose (Solo 12's) is
    solved again from a bent knee (`bases.measure.solve_home`). Solo 12's file declares
    placeholder efforts, refused below; the home pose does not depend on them."""
    monkeypatch.setattr(base_file, "check_efforts", lambda *args: None)
    spec = read_base(assets.wheel_urdf(file))
    base_file._read_cached.cache_clear()  # no spec read without the check outlives the test
    model = build("none", base=spec)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_kinematics(model, data)
    trunk = model.body(spec.trunk).id
    for leg in spec.legs:
        foot = _in_trunk_frame(
            model, data, spec.trunk, data.site_xpos[model.site(f"{leg.place}_foot").id]
        )
        assert data.xpos[trunk][2] + foot[2] - leg.foot_radius == pytest.approx(0.0, abs=_FOOT_TOL)
        assert foot[0] == pytest.approx(leg.hip[0], abs=_FOOT_TOL)
        assert leg.home[0] == pytest.approx(0.0, abs=_ABDUCTION_TOL)  # it hangs as at zero


@pytest.mark.skipif(not assets.wheel_installed(), reason="needs the example-robot-data wheel")
def test_a_placeholder_effort_is_refused_naming_the_leg_and_the_fix():
    """Solo 12's URDF gives every joint effort="1000" N·m, hundreds of times what holding its
    2.5 kg up takes; the controller would scale damping and armature by it (it fell in 16 of 16
    episodes with an arm), so the file is refused with what to correct."""
    base_file._read_cached.cache_clear()  # read anew, with the check
    with pytest.raises(DpcError, match=r"leg FR's joints declare efforts .*placeholder.*effort"):
        read_base(assets.wheel_urdf("solo_description/robots/solo12.urdf"))
