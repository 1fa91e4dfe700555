"""Bring your own arm: a URDF or MJCF file the library has never seen, checked before any compile,
built on the A1, stepped in MJX, transferred to and evaluated (docs/own-arm.md)."""

import json
import shutil
import struct
import warnings

import jax
import mujoco
import numpy as np
import pytest
from helpers import ENGINE, fast_jit

from dpc_mjx import DpcError, io
from dpc_mjx.control.static_balance import static_balance
from dpc_mjx.envs.registry import make, resolve_arm
from dpc_mjx.io.shipped import export_cells
from dpc_mjx.robots import (
    Mount,
    UrdfArm,
    arm_argument,
    arm_name,
    build,
    layout,
    resolve,
)
from dpc_mjx.robots.arms.file import read
from dpc_mjx.run import cli
from dpc_mjx.run.eval import evaluate
from dpc_mjx.run.pipeline import SHIPPED, evaluate_export, transfer_arm

_MASS_TOL = 1e-9  # kg: masses are copied, not recomputed


def _stl(path, size=0.03):
    """A binary STL tetrahedron (m)."""
    corners = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)], float) * size
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(faces)))
        for face in faces:
            f.write(struct.pack("<3f", 0, 0, 0))
            for v in face:
                f.write(struct.pack("<3f", *corners[v]))
            f.write(b"\0\0")


def _link(name, mass, visual="", inertial=True):
    inertia = (
        f'<inertial><origin xyz="0 0 0.03"/><mass value="{mass}"/>'
        '<inertia ixx="2e-4" iyy="2e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>'
        if inertial
        else ""
    )
    return f'<link name="{name}">{inertia}{visual}</link>'


def _joint(name, kind, parent, child, z, axis="0 1 0", limits=True):
    limit = '<limit lower="-1.5" upper="1.5" effort="10" velocity="3"/>' if limits else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="0 0 {z}"/><axis xyz="{axis}"/>{limit}</joint>'
    )


def _mesh(filename):
    return f'<visual><geometry><mesh filename="{filename}"/></geometry></visual>'


def write_urdf(root, *, links=None, joints=None, top="robot"):
    """A 3-joint arm of 0.6 kg in root/my_arm_pkg/urdf/my_arm.urdf: a massless `world` link welded
    on top, meshes by relative path, by package:// and in COLLADA (dropped), primitives."""
    pkg = root / "my_arm_pkg"
    _stl(pkg / "meshes" / "link2.stl")
    _stl(pkg / "meshes" / "link3.stl")
    (pkg / "meshes" / "base.dae").write_text("<COLLADA/>")
    cylinder = '<visual><geometry><cylinder radius="0.02" length="0.05"/></geometry></visual>'
    default_links = {
        "world": '<link name="world"/>',
        "base_link": _link("base_link", 0.2, _mesh("package://my_arm_pkg/meshes/base.dae")),
        "link1": _link("link1", 0.15, cylinder),
        "link2": _link("link2", 0.15, _mesh("../meshes/link2.stl")),
        "link3": _link("link3", 0.1, _mesh("package://my_arm_pkg/meshes/link3.stl")),
        "tool": '<link name="tool"/>',
    }
    default_joints = {
        "fix": _joint("fix", "fixed", "world", "base_link", 0, limits=False),
        "j1": _joint("j1", "revolute", "base_link", "link1", 0.03, axis="0 0 1"),
        "j2": _joint("j2", "revolute", "link1", "link2", 0.05),
        "j3": _joint("j3", "revolute", "link2", "link3", 0.12),
        "tool": _joint("tool_fix", "fixed", "link3", "tool", 0.1, limits=False),
    }
    body = {**default_links, **(links or {})}
    body_joints = {**default_joints, **(joints or {})}
    text = "".join(v for v in body.values() if v) + "".join(v for v in body_joints.values() if v)
    path = pkg / "urdf" / "my_arm.urdf"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f'<{top} name="my_arm">{text}</{top}>')
    return path


_MJCF = """<mujoco model="mjcf_arm">
  <compiler angle="degree" meshdir="assets"/>
  <asset><mesh name="tet" file="tet.stl"/></asset>
  <worldbody>
    <light pos="0 0 1"/>
    <body name="base">
      <geom type="cylinder" size="0.03 0.01" mass="0.2"/>
      <body name="upper" pos="0 0 0.03">
        <joint name="shoulder" axis="0 1 0" range="-90 90"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.12" size="0.015" mass="0.2"/>
        <body name="lower" pos="0 0 0.12">
          <joint name="elbow" axis="0 1 0" range="-120 120"/>
          <geom type="mesh" mesh="tet" mass="0.1"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator><motor joint="shoulder"/></actuator>
</mujoco>"""


def write_mjcf(root, text=_MJCF):
    _stl(root / "mjcf_arm" / "assets" / "tet.stl")
    path = root / "mjcf_arm" / "arm.xml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def urdf(tmp_path_factory):
    return write_urdf(tmp_path_factory.mktemp("arm"))


def test_a_urdf_arm_is_read_with_what_can_be_inferred(urdf):
    with pytest.warns(UserWarning, match=r"base\.dae is in a format MuJoCo cannot read"):
        arm_file = read(urdf)
    assert arm_file.root == "base_link"  # the massless `world` link welded on top is skipped
    assert arm_file.ee_body == "link3"  # the end of the longest chain of movable joints
    assert list(arm_file.joints) == ["j1", "j2", "j3"]
    assert arm_file.joints["j2"] == pytest.approx((-1.5, 1.5))
    arm = UrdfArm(str(urdf))
    assert arm.is_file and arm_name(arm) == "my_arm"
    assert arm.home_pose() == {"j1": 0.0, "j2": 0.0, "j3": 0.0}


def test_a_urdf_arm_builds_on_the_a1_with_its_meshes_mass_and_servos(urdf):
    arm = UrdfArm(str(urdf), home=(("j2", 0.4),))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = build(arm)
    lay = layout(model)
    assert len(lay.arms) == 1 and len(lay.arms[0].qpos) == 3 == len(lay.arms[0].act)
    arm_mass = model.body_subtreemass[model.body("arm0/base_link").id]
    assert arm_mass == pytest.approx(0.6, abs=_MASS_TOL)  # the file's masses, meshes massless
    assert model.nmesh == 2  # link2's (relative path) and link3's (package://); the .dae dropped
    assert np.all(model.geom_contype[model.geom_bodyid >= model.body("arm0/base_link").id] == 0)
    assert model.key_qpos[0][model.joint("arm0/j2").qposadr[0]] == pytest.approx(0.4)
    assert model.actuator("arm0/j2").forcerange[1] == pytest.approx(10.0)  # the URDF's effort
    assert static_balance(resolve(arm)).feasible


def test_an_mjcf_arm_gets_the_inertia_mujoco_computes_from_its_geoms(tmp_path):
    path = write_mjcf(tmp_path)
    arm_file = read(path)
    assert (arm_file.root, arm_file.ee_body) == ("base", "lower")
    assert arm_file.joints["elbow"] == pytest.approx((-2.0944, 2.0944), abs=1e-4)  # from degrees
    model = build(UrdfArm(str(path)))
    assert model.body_subtreemass[model.body("arm0/base").id] == pytest.approx(0.5, abs=_MASS_TOL)
    assert model.actuator("arm0/shoulder").biastype == mujoco.mjtBias.mjBIAS_AFFINE  # our servo
    assert model.nu == 12 + 2  # the file's own motor was replaced


def test_z1_passes_the_static_balance_check_and_a_heavy_arm_does_not(tmp_path):
    z1 = static_balance(resolve("z1"))
    assert z1.feasible and 0 < z1.torque_share < 1 and z1.mass > 17
    heavy = _link("link3", 25.0)  # 25 kg 0.6 m out from the shoulder
    path = write_urdf(
        tmp_path,
        links={"link3": heavy},
        joints={"j3": _joint("j3", "revolute", "link2", "link3", 0.6)},
    )
    heavy_arm = UrdfArm(str(path))
    assert resolve(heavy_arm).arms == (heavy_arm,)  # a pure lookup: no compile, no balance check
    with pytest.raises(DpcError, match="cannot hold this arm up .* lighter or shorter arm"):
        resolve_arm(heavy_arm)
    # and where an arm comes in, before any compile: make (transfer's first step), eval, sweep's
    # and eval's export cells
    with pytest.raises(DpcError, match="cannot hold this arm up"):
        make("a1_arm/reaching", arm=heavy_arm)
    with pytest.raises(DpcError, match="cannot hold this arm up"):
        evaluate(["regular", heavy_arm], ["mbc"])
    with pytest.raises(DpcError, match="cannot hold this arm up"):
        export_cells(SHIPPED, [str(path)], ["mbc"], "a1_arm/reaching")


_BAD_URDFS = {  # what is changed -> the error's words
    "no movable joint": (
        {
            "joints": {
                j: _joint(j, "fixed", p, c, 0.05, limits=False)
                for j, p, c in (
                    ("j1", "base_link", "link1"),
                    ("j2", "link1", "link2"),
                    ("j3", "link2", "link3"),
                )
            }
        },
        "has no movable joint",
    ),
    "link without inertia": (
        {"links": {"link2": _link("link2", 0.15, inertial=False)}},
        "link 'link2' moves .* no mass or inertia; give it an <inertial>",
    ),
    "missing mesh": (
        {"links": {"link2": _link("link2", 0.15, _mesh("meshes/nothere.stl"))}},
        "names mesh 'meshes/nothere.stl', not found at .*nothere.stl; put the file there",
    ),
    "unknown package": (
        {"links": {"link2": _link("link2", 0.15, _mesh("package://nopkg/a.stl"))}},
        "package 'nopkg', .* ROS_PACKAGE_PATH",
    ),
    "floating joint": (
        {"joints": {"j2": _joint("j2", "floating", "link1", "link2", 0.05)}},
        "joint 'j2' is 'floating'",
    ),
    "two trees": (
        {"links": {"loose": _link("loose", 0.1)}},
        r"form 2 trees \(roots \['world', 'loose'\]\)",
    ),
    "not a URDF": ({"top": "sdf"}, "top element is <robot>, this one's is <sdf>"),
}


@pytest.mark.parametrize("case", sorted(_BAD_URDFS))
def test_an_arm_file_the_library_cannot_use_is_refused_with_the_fix(case, tmp_path):
    changes, message = _BAD_URDFS[case]
    path = write_urdf(tmp_path, **changes)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(DpcError, match=message):
            resolve(UrdfArm(str(path)))


def test_bad_paths_homes_and_bodies_are_refused_before_building(urdf, tmp_path):
    with pytest.raises(DpcError, match="does not exist"):
        resolve(UrdfArm(str(tmp_path / "none.urdf")))
    (tmp_path / "arm.sdf").write_text("<sdf/>")
    with pytest.raises(DpcError, match=r"unknown URDF arm .*or give the path of a \.urdf"):
        resolve(UrdfArm(str(tmp_path / "arm.sdf")))
    (tmp_path / "broken.urdf").write_text("<robot><link></robot>")
    with pytest.raises(DpcError, match="not well-formed XML"):
        resolve(UrdfArm(str(tmp_path / "broken.urdf")))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(DpcError, match=r"home j2=3.0 is outside the joint's range \[-1.500"):
            resolve(UrdfArm(str(urdf), home=(("j2", 3.0),)))
        with pytest.raises(DpcError, match="home names joint 'j9'.*movable joints: \\['j1'"):
            resolve(UrdfArm(str(urdf), home=(("j9", 0.0),)))
        with pytest.raises(DpcError, match="ee_body='hand' is not a body of my_arm.urdf"):
            resolve(UrdfArm(str(urdf), ee_body="hand"))
        with pytest.raises(DpcError, match="outside the reference trunk box"):
            resolve(UrdfArm(str(urdf), mount=Mount((0.5, 0, 0.057))))
    two = _MJCF.replace('<light pos="0 0 1"/>', '<body name="b2"><geom size="0.01"/></body>')
    with pytest.raises(DpcError, match="holds 2 top-level bodies"):
        resolve(UrdfArm(str(write_mjcf(tmp_path, two))))
    free = _MJCF.replace('<body name="base">', '<body name="base"><freejoint/>')
    with pytest.raises(DpcError, match="base body 'base' has a joint"):
        resolve(UrdfArm(str(write_mjcf(tmp_path, free))))


def test_arm_arguments_take_variants_files_and_descriptions(urdf, tmp_path):
    assert arm_argument("z1") == "z1"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert arm_argument(str(urdf)) == UrdfArm(str(urdf.resolve()))
        description = tmp_path / "my_arm.json"
        description.write_text(json.dumps({
            "urdf": str(urdf), "ee_body": "link2", "ee_offset": [0, 0, 0.1],
            "mount": {"pos": [0.05, 0, 0.057], "yaw": 0.3}, "home": {"j2": 0.2},
        }))  # fmt: skip
        arm = arm_argument(str(description))
    assert arm == UrdfArm(
        str(urdf), Mount((0.05, 0, 0.057), 0.3), "link2", (0, 0, 0.1), (("j2", 0.2),)
    )
    with pytest.raises(DpcError, match="Unknown arm 'arm7': not a variant"):
        arm_argument("arm7")
    description.write_text(json.dumps({"file": str(urdf)}))
    with pytest.raises(DpcError, match='expected a JSON object with "urdf"'):
        arm_argument(str(description))
    description.write_text(json.dumps({"urdf": str(urdf), "mount": [0, 0, 0]}))
    with pytest.raises(DpcError, match=r'"mount" is \{"pos"'):
        arm_argument(str(description))


def test_a_new_urdf_arm_goes_through_transfer_and_evaluation(monkeypatch, urdf, tmp_path, capsys):
    """The whole path a user takes: `dpc-mjx transfer --arm my_arm.urdf` (data collection, here
    in MuJoCo C, `--env engine=native`; an encoder against the frozen decoder) then `dpc-mjx eval
    --arms my_arm.urdf`."""
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: a few steps of each program
    export = tmp_path / "export"
    shutil.copytree(SHIPPED, export)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        on = {"engine": ENGINE}
        history = transfer_arm(export, str(urdf), samples=128, n_envs=8, progress=False, env=on)
        assert np.isfinite(min(history["val_nll"]))
        art = io.load(export)
        assert set(art.encoders) - set(io.load(SHIPPED).encoders) == {"my_arm"}
        assert art.arm_spec("my_arm") == UrdfArm(str(urdf.resolve()))
        (cell,) = evaluate_export(
            export, arms=[str(urdf)], controllers=["dpc"], episodes=2, steps=10, env=on
        )
    assert (cell.arm, cell.controller) == ("my_arm", "dpc")
    assert np.all(np.isfinite(cell.per_episode["return"])) and cell.nan_resets == 0
    assert cell.falls == 0  # 0.2 s from a standing start
    assert "| my_arm | dpc |" in capsys.readouterr().out
    assert cli.main(["eval", "--export", str(export), "--arms", str(tmp_path / "x.urdf")]) == 2
