"""The low-level controller, judged by what it achieves in simulation (small batches; MuJoCo C
through the native engine, `tests/helpers.ENGINE`: the controller in MJX is in every MJX env of
test_eval_regression, test_sweep and test_objects)."""

import jax
import jax.numpy as jp
import numpy as np
import pytest

from dpc_mjx import DpcError, sim
from dpc_mjx.control import gait
from dpc_mjx.control.closed_loop import init_loop, make_chunk, summarize
from dpc_mjx.control.controller import make_controller
from dpc_mjx.physics import NativePhysics
from dpc_mjx.robots import build
from dpc_mjx.robots.standing import perturbed_home
from dpc_mjx.rotations import roll_pitch_yaw

_G = 9.81
_BATCH = 4
_TICKS = 125  # 0.5 s per compiled chunk
_VERTICAL_BALANCE_RTOL = 0.02  # sum f_z vs m (g + qdd_des_z)
_HEIGHT_TOL = 0.02  # m, standing COM height vs desired
_LEVEL_TOL = 0.02  # rad, oracle pitch under a known wrench
_MAX_SPEED_RMSE = 0.1  # m/s
_MAX_YAW_RATE_RMSE = 0.2  # rad/s
_MAX_TILT_RMS = 0.1  # rad


def _start(model, controller, seed=0):
    mx = sim.put_model(model)
    data = sim.batched_data(
        mx, perturbed_home(model, _BATCH, seed=seed), np.tile(model.key_ctrl[0], (_BATCH, 1))
    )
    return mx, init_loop(controller, data)


@pytest.fixture(scope="module")
def standing():
    """Bare A1 on the stand gait; u is given from outside (one compile serves MBC and oracle)."""
    model = build("none")
    controller = make_controller(model, gait_=gait.stand())
    mx, ls = _start(model, controller)
    chunk = make_chunk(mx, controller, _TICKS, kind="given", physics=NativePhysics(model))
    return model, controller, ls, chunk


def _run(chunk, ls, seconds, command=(0, 0, 0), wrench=np.zeros(6), u=np.zeros(6)):
    cmd = jp.tile(jp.asarray(command, jp.float32), (_BATCH, 1))
    w = jp.tile(jp.asarray(wrench, jp.float32), (_BATCH, 1))
    uu = jp.tile(jp.asarray(u, jp.float32), (_BATCH, 1))
    for _ in range(round(seconds / (_TICKS * 0.004))):
        ls = chunk(ls, cmd, w, uu)
    return jax.device_get(ls)


def test_standing_qp_forces_carry_the_weight(standing):
    model, controller, ls, chunk = standing
    ls = _run(chunk, ls, 1.5)
    cfg = controller.config
    mass = float(cfg.balance.mass)
    fz = ls.ctrl.forces[..., 2].sum(-1)  # (B,) N asked of the stance feet
    com_z = ls.data.qpos[:, 2] + controller.idx.com_offset[2]
    kp_z = float(cfg.balance.kp[2])
    qdd_z = kp_z * (cfg.body_height - com_z)  # eq. 9 at rest
    np.testing.assert_allclose(fz, mass * (_G + qdd_z), rtol=_VERTICAL_BALANCE_RTOL)
    np.testing.assert_allclose(com_z, cfg.body_height, atol=_HEIGHT_TOL)
    assert mass == pytest.approx(model.body_mass.sum())  # bare A1: the model is the robot


def test_oracle_holds_level_under_a_known_wrench_while_mbc_tilts(standing):
    _, _, ls, chunk = standing
    wrench = np.array([0.0, 0.0, -30.0, 0.0, 8.0, 0.0])  # N, N·m at the trunk COM (world)
    mbc = _run(chunk, ls, 2.0, wrench=wrench)
    oracle = _run(chunk, ls, 2.0, wrench=wrench, u=wrench)
    pitch_mbc = np.asarray(roll_pitch_yaw(mbc.data.qpos[:, 3:7]))[:, 1]
    pitch_oracle = np.asarray(roll_pitch_yaw(oracle.data.qpos[:, 3:7]))[:, 1]
    assert np.all(np.abs(pitch_oracle) < _LEVEL_TOL), pitch_oracle
    assert np.all(np.abs(pitch_mbc) > 2 * np.abs(pitch_oracle).max() + 0.02), pitch_mbc


@pytest.mark.parametrize(
    "variant",
    [pytest.param("none", marks=pytest.mark.slow), "regular"],  # breadth: test-all
)
def test_trot_tracks_forward_speed_and_yaw_rate(variant):
    model = build(variant)
    controller = make_controller(model, gait_=gait.trot())
    mx, ls0 = _start(model, controller, seed=3)
    chunk = make_chunk(mx, controller, _TICKS, kind="mbc", physics=NativePhysics(model))
    for command in ((0.3, 0.0, 0.0), (0.0, 0.0, 0.5)):
        ls = _run(chunk, ls0, 4.0, command=command)
        r = summarize(ls.metrics)
        assert r["fall_rate"] == 0.0, (variant, command, r)
        assert r["speed_rmse"] < _MAX_SPEED_RMSE, (variant, command, r)
        assert r["yaw_rate_rmse"] < _MAX_YAW_RATE_RMSE, (variant, command, r)
        assert max(r["roll_rms"], r["pitch_rms"]) < _MAX_TILT_RMS, (variant, command, r)
        dist = np.linalg.norm(ls.data.qpos[:, :2] - ls0.data.qpos[:, :2], axis=1)
        if command[0] > 0:  # it really walked: ~0.3 m/s for the 3 s after the first
            assert np.all(dist > 0.8), dist


def test_unknown_controller_and_gait_fail_clearly():
    model = build("none")
    controller = make_controller(model)
    with pytest.raises(DpcError, match="Unknown controller"):
        make_chunk(sim.put_model(model), controller, 10, kind="dpc?")
    with pytest.raises(DpcError, match="duty"):
        gait.make_gait(0.3, 1.5, (0, 0.5, 0.5, 0))
