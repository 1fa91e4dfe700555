"""Any quadruped: the named bases, and a file the library does not name, build, stand and trot.

The check (issue 27): the reaching task with pushes off and the command fixed at 0.3 m/s forward,
the arm's reaching motion as the task draws it, under MBC: no falls, and the forward speed's RMS
error to the command within SPEED_TOL. The default suite runs it for each named base on a few
envs for 2 s (native engine, the CPU path); `make test-all` runs the whole matrix (every named
base, no arm and `regular`, MJX and native, 64 envs for 10 s; `experiments/base_trot.py` prints
the same cells as a table). The A1's own numbers are checked exactly: its model and results must
not move (tests/test_eval_regression.py and the recorded tests guard them too).
"""

import dataclasses

import jax
import numpy as np
import pytest
from helpers import fast_jit, model_bytes

from dpc_mjx import DpcError, assets, make
from dpc_mjx.control.base_scaling import model_scale
from dpc_mjx.control.controller import make_controller
from dpc_mjx.envs.registry import RESIDUAL_BOUNDS, WEIGHT_SCALED, get_config
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.io.inference import NumpyPolicy
from dpc_mjx.io.shipped import SHIPPED, export_cells, shipped_for
from dpc_mjx.robots import VARIANTS, arm_name, build, layout
from dpc_mjx.robots.assemble import mount_on
from dpc_mjx.robots.bases.file import LEGS, base_file_path, read_base
from dpc_mjx.run import cli

CHECK = {
    "controller": "mbc",
    "push_force": (0.0, 0.0),
    "command_vx": (0.3, 0.3),
    "command_vy": (0.0, 0.0),
    "command_yaw": (0.0, 0.0),
}
SPEED_TOL = 0.1  # m/s: RMS of the forward speed's error to the 0.3 m/s command
SEED = 7  # chose nothing
_EXACT = 1e-12


def _trot(base, arm: str, engine: str, envs: int, seconds: float) -> dict:
    env = make("reaching", arm=arm, base=base, engine=engine, **CHECK)
    steps = round(seconds / env.config.policy_dt)
    return run_episodes(env, envs, steps, seed=SEED)


def _assert_trots(ep: dict, what: str) -> None:
    assert np.sum(ep["fell"]) == 0, f"{what}: {int(np.sum(ep['fell']))} falls"
    rms = np.sqrt(np.sum(ep["vx_sq_err"]) / np.sum(ep["measured"]))
    assert rms < SPEED_TOL, f"{what}: forward speed RMS error {rms:.3f} m/s"


@pytest.mark.parametrize("base", ["go1", "go2", "b1"])
def test_named_base_trots_under_mbc(base, monkeypatch):
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: 4 envs, 100 steps
    _assert_trots(_trot(base, "none", "native", envs=4, seconds=2.0), base)


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["native", "mjx"])
@pytest.mark.parametrize("arm", ["none", "regular"])
@pytest.mark.parametrize("base", ["a1", "go1", "go2", "b1"])
def test_base_matrix_trots_64_envs_for_10_s(base, arm, engine):
    _assert_trots(_trot(base, arm, engine, envs=64, seconds=10.0), f"{base}/{arm}/{engine}")


@pytest.mark.slow
@pytest.mark.skipif(not assets.wheel_installed(), reason="needs the example-robot-data wheel")
def test_a_quadruped_file_the_library_does_not_name_trots():
    path = assets.wheel_urdf("laikago_description/urdf/laikago.urdf")  # by path, no JSON
    _assert_trots(_trot(str(path), "regular", "native", envs=16, seconds=10.0), "laikago")


def test_the_a1_keeps_its_names_and_numbers():
    model = build("regular")
    lay = layout(model)
    names = [model.joint(j).name for j in lay.leg_joints]
    assert names == [f"{leg}_{part}_joint" for leg in LEGS for part in ("hip", "thigh", "calf")]
    assert model.body(lay.trunk).name == "trunk"
    assert lay.foot_radius == 0.02
    np.testing.assert_array_equal(lay.torque_limits, np.full(12, 33.5))
    ctl = make_controller(model)
    assert model_scale(model) == model_scale(build("none"))  # the arm is not the base's
    assert (model_scale(model).mass, model_scale(model).length) == (1.0, 1.0)
    assert (ctl.fall_height, ctl.config.body_height, ctl.config.swing_height) == (0.15, 0.26, 0.08)
    assert (ctl.config.raibert_k, ctl.config.max_pos_error) == (0.03, 0.05)
    np.testing.assert_array_equal(np.asarray(ctl.config.swing_kp), [500.0] * 3)
    np.testing.assert_array_equal(np.asarray(ctl.config.balance.f_max), 180.0)


def test_another_base_is_scaled_by_the_stated_rules():
    model = build(dataclasses.replace(VARIANTS["none"], base="b1"))
    scale, ctl = model_scale(model), make_controller(model)
    assert scale.mass == pytest.approx(55.689 / 13.741, rel=1e-4)  # the files' trunk + legs
    assert scale.length == pytest.approx(0.7 / 0.4, rel=1e-3)
    assert ctl.fall_height == pytest.approx(0.15 * scale.height, abs=_EXACT)
    kp = 500.0 * scale.mass / scale.length
    np.testing.assert_allclose(np.asarray(ctl.config.swing_kp), [kp] * 3, rtol=1e-6)
    np.testing.assert_allclose(
        np.asarray(ctl.config.torque_limit), read_base("b1").torque_limits, rtol=1e-6
    )
    assert float(ctl.config.balance.mass) == pytest.approx(55.689, abs=1e-3)


def test_the_tasks_pushes_payloads_and_u_bounds_follow_the_bases_weight():
    a1, b1 = get_config("reaching"), get_config("reaching", base="b1")
    m = 55.689 / 13.741  # the files' trunk + legs, B1 over A1
    for name in WEIGHT_SCALED:
        got, want = np.asarray(getattr(b1, name)), np.asarray(getattr(a1, name)) * m
        np.testing.assert_allclose(got, want, atol=0.01, err_msg=name)  # rounded to 0.01
    assert get_config("reaching", base="a1") == a1  # the A1's exactly as drawn
    given = get_config("reaching", base="b1", push_force=(0.0, 60.0))  # given: used as given
    assert given.push_force == (0.0, 60.0) and given.max_force == b1.max_force
    assert make("reaching", base="b1").config.u_scale == b1.u_scale  # make uses the same rule


def test_a_residual_of_the_arms_model_is_bounded_to_small_loads_scaled_by_the_bases_weight():
    """u_base='model': u's bounds are `RESIDUAL_BOUNDS` (the A1's), scaled like the rest on
    another base; bounds given are used as given, each on its own."""
    m = 55.689 / 13.741  # the files' trunk + legs, B1 over A1
    want = RESIDUAL_BOUNDS["model"]
    for base, scale in (("a1", 1.0), ("b1", m)):
        got = get_config("reaching", base=base, u_base="model")
        for name, a1_value in want.items():
            np.testing.assert_allclose(getattr(got, name), np.asarray(a1_value) * scale, atol=0.01)
    paper = get_config("reaching")  # the paper's form: u is the whole wrench
    assert paper.max_force == (15.0, 15.0, 60.0) and paper.max_torque == (12.0, 12.0, 3.0)
    given = get_config("reaching", u_base="model", max_force=(15.0, 15.0, 60.0))
    assert given.max_force == (15.0, 15.0, 60.0) and given.max_torque == want["max_torque"]


def test_an_arm_mount_moves_to_the_same_place_of_another_trunk():
    go2 = read_base("go2")  # its box comes from its collision mesh, off the trunk's origin
    mount = VARIANTS["regular"].arms[0].mount
    moved = mount_on(go2, mount)
    top = go2.trunk_box_center[2] + go2.trunk_half_extents[2]
    assert moved.pos[2] == pytest.approx(top, abs=_EXACT)  # on the top face, as on the A1
    assert mount_on(read_base("a1"), mount) is mount


def test_build_takes_the_base_by_name_path_or_spec():
    want = model_bytes(build(dataclasses.replace(VARIANTS["regular"], base="go2")))
    assert model_bytes(build("regular", base="go2")) == want
    assert model_bytes(build(arm="regular", base=read_base("go2"))) == want
    assert model_bytes(build("regular", base=base_file_path("go2"))) == want  # the shipped file
    assert model_bytes(build("none", base="a1")) == model_bytes(build("none"))


def test_a_base_the_library_cannot_find_is_refused_before_anything_compiles():
    with pytest.raises(DpcError, match="does not exist"):
        make("reaching", arm="none", base="no_such_dog.urdf")
    with pytest.raises(DpcError, match="base="):
        make("reaching", arm="none", base="")


def test_an_export_is_not_evaluated_on_another_base_than_its_own():
    with pytest.raises(DpcError, match="trained on the base 'a1'"):
        export_cells(SHIPPED, None, ["mbc", "dpc"], "reaching", {"base": "go2"})
    assert export_cells(SHIPPED, None, ["mbc"], "reaching", {"base": "go2"})[2]["base"] == "go2"


@pytest.mark.parametrize(("base", "arm"), [("go2", "regular"), ("b1", "z1")])
def test_the_shipped_export_of_a_base_is_its_own(base, arm):
    export = shipped_for(base)
    assert export != SHIPPED and shipped_for(None) == SHIPPED
    artefacts, arms, options = export_cells(export, None, ["dpc"], "reaching", {"base": base})
    assert options["base"] == base and [arm_name(a) for a in arms] == [arm]
    scaled = get_config("reaching", base=base, u_base="model")  # its residual bounds, scaled
    np.testing.assert_allclose(artefacts.meta["action_scaling"]["u_scale"], scaled.u_scale)
    runner = NumpyPolicy(export, arm)  # the numpy runner: a finite u within its bounds
    assert runner.base == "model"  # added to the arms' model wrench, from its arm-model file
    obs = np.zeros(runner.input_size, np.float32)
    residual = runner.residual(obs)
    assert np.all(np.isfinite(residual))
    assert np.all(np.abs(residual) <= np.asarray(scaled.u_scale) + 1e-6)
    n = runner.arm_model.n  # standing level and still: u_model is the arms' weight (fz < 0)
    still = {"targets": np.zeros(n), "rot": np.eye(3), "ang_vel": np.zeros(3)}
    u = runner.u(obs, 0.0, measured=still | {"desired": np.zeros(6), "com": np.zeros(3)})
    assert np.all(np.isfinite(u)) and u[2] < residual[2]


def test_the_commands_take_base(capsys):
    # go1 has no export of its own: the A1's is refused before anything compiles
    assert cli.main(["eval", "--base", "go1", "--controllers", "mbc", "dpc"]) != 0
    assert "trained on the base 'a1'" in capsys.readouterr().err
    args = cli._parser().parse_args(["train", "--run", "runs/x", "--base", "go2"])
    assert cli._run_config(args).env_overrides["base"] == "go2"


def test_a_file_that_is_not_a_quadruped_is_refused():
    with pytest.raises(DpcError, match="found 0 legs"):  # an arm
        make("reaching", arm="none", base=str(assets.urdf_path("z1")))
    if assets.wheel_installed():  # a humanoid
        g1 = assets.wheel_urdf("g1_description/urdf/g1_29dof_rev_1_0.urdf")
        with pytest.raises(DpcError, match="found 2 legs"):
            make("reaching", arm="none", base=str(g1))
