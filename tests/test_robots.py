"""Robot assembly: masses, statics, specs and the committed MJCF (MuJoCo C, fast)."""

import math
import pathlib
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from dpc_mjx import DpcError, assets
from dpc_mjx.robots import VARIANTS, ArmSpec, Mount, RobotSpec, UrdfArm, build, resolve
from dpc_mjx.robots.arms import WIDOWX_RANGES
from dpc_mjx.robots.layout import layout, mount_wrench
from dpc_mjx.robots.mjcf import robot_filename, robot_xml, scene_filename, scene_xml
from dpc_mjx.robots.standing import home_ctrl, with_leg_servos

_MASS_TOL = 1e-6  # kg
_STATIC_FORCE_RTOL = 0.01  # mount force vs arm weight
_XML_ROUNDTRIP_TOL = 1e-5  # MJCF prints 6 significant digits
_MJCF_DIR = pathlib.Path(__file__).resolve().parents[1] / "mjcf"
_G = 9.81


@pytest.fixture(scope="module", params=sorted(VARIANTS))
def variant(request):
    name = request.param
    return name, build(name)


def test_every_variant_compiles_with_named_parts(variant):
    name, model = variant
    lay = layout(model)
    assert model.nu == 12 + lay.arm_act.size
    assert len(lay.arms) == len(VARIANTS[name].arms)
    assert lay.foot_sites.shape == (4,)
    assert model.key(0).name == "home"


def test_only_feet_touch_the_floor(variant):
    _, model = variant
    floor = model.geom("floor").id
    colliding = []
    for g in range(model.ngeom):
        if g == floor:
            continue
        a = model.geom_contype[g] & model.geom_conaffinity[floor]
        b = model.geom_contype[floor] & model.geom_conaffinity[g]
        if a or b:
            colliding.append(model.geom(g).name)
    assert sorted(colliding) == ["FL_foot", "FR_foot", "RL_foot", "RR_foot"]


def test_bare_a1_mass_matches_urdf():
    urdf = ET.parse(assets.urdf_path("a1")).getroot()
    urdf_mass = sum(float(m.get("value")) for m in urdf.iter("mass"))
    assert build("none").body_mass.sum() == pytest.approx(urdf_mass, abs=_MASS_TOL)


@pytest.mark.parametrize("name", ["regular", "longer", "heavier", "double"])
def test_arm_and_gripper_masses_match_spec(name):
    model = build(name)
    for arm_spec, arm in zip(VARIANTS[name].arms, layout(model).arms, strict=True):
        base = model.site_bodyid[arm.mount_site]
        gripper = model.body(arm.prefix + "gripper").id
        assert model.body_subtreemass[base] == pytest.approx(arm_spec.mass, abs=_MASS_TOL)
        assert model.body_subtreemass[gripper] == pytest.approx(
            arm_spec.gripper_mass, abs=_MASS_TOL
        )


@pytest.mark.parametrize("name", ["regular", "longer", "heavier", "double", "pusher"])
def test_widowx_joint_ranges_are_radians(name):
    """The arm's ranges are given in rad; MjSpec's default compiler unit is degrees."""
    model = build(name)
    for arm in layout(model).arms:
        for adr in arm.qpos:
            j = int(np.flatnonzero(model.jnt_qposadr == adr)[0])
            short = model.joint(j).name.removeprefix(arm.prefix)
            np.testing.assert_allclose(model.jnt_range[j], WIDOWX_RANGES[short], err_msg=short)


@pytest.mark.parametrize("name", [n for n in sorted(VARIANTS) if n != "none"])
def test_mount_sensor_reads_arm_weight_when_standing(name):
    """Standing on leg servos, arms at home: the arm pushes down on the trunk by its weight."""
    model = with_leg_servos(build(name))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    data.ctrl[:] = home_ctrl(model)
    lay = layout(model)
    n = int(1.5 / model.opt.timestep)
    fz = []
    for k in range(n):
        mujoco.mj_step(model, data)
        if k >= n - 50:
            fz.append(sum(mount_wrench(arm, data)[0][2] for arm in lay.arms))
    weight = _G * sum(model.body_subtreemass[model.site_bodyid[a.mount_site]] for a in lay.arms)
    assert -np.mean(fz) == pytest.approx(weight, rel=_STATIC_FORCE_RTOL)


def test_mount_sensor_sign_under_known_wrench():
    """A known upward force at the gripper is transmitted to the trunk (arm lifts the trunk)."""
    model = with_leg_servos(build("regular"))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    data.ctrl[:] = home_ctrl(model)
    arm = layout(model).arms[0]
    for _ in range(200):
        mujoco.mj_step(model, data)
    before = mount_wrench(arm, data)[0][2]
    gripper = model.body(arm.prefix + "gripper").id
    data.xfrc_applied[gripper, 2] = 5.0  # N, upward at the palm COM
    for _ in range(200):
        mujoco.mj_step(model, data)
    after = mount_wrench(arm, data)[0][2]
    assert after - before == pytest.approx(5.0, rel=0.05)


# --- invalid input fails early with the library's error -------------------------------------


@pytest.mark.parametrize(
    "arm, match",
    [
        (ArmSpec(upper_arm_length=0.0), "upper_arm_length"),
        (ArmSpec(upper_arm_length=-0.1), "upper_arm_length"),
        (ArmSpec(gripper_mass=float("nan")), "gripper_mass"),
        (ArmSpec(forearm_mass=float("inf")), "forearm_mass"),
        (ArmSpec(shoulder_height=0.01), "shoulder_height"),
        (ArmSpec(mount=Mount((0.5, 0.0, 0.057))), "outside the reference trunk box"),
        (ArmSpec(mount=Mount((0.0, 0.0, 0.2))), "outside the reference trunk box"),
        (ArmSpec(mount=Mount((0.0, 0.0, float("nan")))), "finite"),
        (UrdfArm("ur5"), "unknown URDF arm"),
    ],
)
def test_invalid_arm_specs_raise(arm, match):
    with pytest.raises(DpcError, match=match):
        build(arm)


def test_unknown_variant_lists_known_ones():
    with pytest.raises(DpcError, match="known variants: .*regular"):
        build("regularr")


def test_too_many_and_overlapping_arms_raise():
    with pytest.raises(DpcError, match="at most 2"):
        resolve(RobotSpec("triple", (ArmSpec(),) * 3))
    with pytest.raises(DpcError, match="apart"):
        resolve(RobotSpec("stacked", (ArmSpec(), ArmSpec())))
    with pytest.raises(DpcError, match="tuple"):
        resolve(RobotSpec("listed", [ArmSpec()]))
    with pytest.raises(DpcError, match="Expected a variant name"):
        build(3)


# --- the committed MJCF never drifts from the code ------------------------------------------


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_committed_mjcf_is_what_the_code_generates(name):
    robot, scene = _MJCF_DIR / robot_filename(name), _MJCF_DIR / scene_filename(name)
    hint = "run `make mjcf` and commit the result"
    assert robot.read_text() == robot_xml(name), hint
    assert scene.read_text() == scene_xml(name), hint


@pytest.mark.parametrize("name", ["regular", "so100"])
def test_mjcf_scene_loads_to_the_built_model(name):
    from_file = mujoco.MjModel.from_xml_path(str(_MJCF_DIR / scene_filename(name)))
    built = build(name)
    for field in (
        "body_mass",
        "body_pos",
        "body_inertia",
        "geom_size",
        "jnt_range",
        "actuator_gainprm",
        "actuator_biasprm",
        "key_qpos",
        "geom_contype",
    ):
        np.testing.assert_allclose(
            getattr(from_file, field), getattr(built, field), atol=_XML_ROUNDTRIP_TOL, err_msg=field
        )
    assert from_file.opt.timestep == built.opt.timestep
    assert math.isclose(from_file.body_mass.sum(), built.body_mass.sum(), abs_tol=1e-5)
    # the headlight on in both, not MuJoCo 4's "auto" (2), which lets a renderer turn it off
    assert from_file.vis.headlight.active == built.vis.headlight.active == 1
