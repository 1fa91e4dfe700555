"""The variants in MJX: finite stepping, standing, agreement with MuJoCo C, batched params.

The batched-params test compiles with XLA's backend optimisation off (`helpers.fast_jit`): 300
steps at batch 2, compile-bound (92 -> 72 s in a cold suite run). The standing runs and the
comparison with MuJoCo C compile as users' programs do (FAST_COMPILE saved them 7 s of 99)."""

import functools

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import fast_jit
from mujoco import mjx

from dpc_mjx import sim
from dpc_mjx.robots import VARIANTS, build
from dpc_mjx.robots.arms.params import batch_arm_params
from dpc_mjx.robots.layout import layout, mount_wrench
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.rotations import roll_pitch_yaw

_BATCH = 4
_CHUNK = 50  # steps per compiled call
_STAND_SECONDS = 2.0
_MIN_HEIGHT = 0.18  # m; the home trunk height is 0.27
_MAX_TILT = 0.3  # rad of roll or pitch
_MJX_C_HEIGHT_TOL = 2e-3  # m, after 100 steps (MJX float32 vs C float64)
_MJX_C_QUAT_TOL = 2e-3
# Mount force vs arm weight once the drop from the keyframe has settled: the arm swings for about
# 0.8 s (the longer, heavier arm's force is 8% off at 0.4 s), then agrees to ~0.2%.
_BATCHED_FORCE_RTOL = 0.01
_BATCHED_CALLS = 6  # x 50 steps = 1.2 s
_G = 9.81


# test-all only: regular's structure (longer, heavier, pusher: one plate instead of the gripper;
# double: two of regular's arms), no arm (none), or URDF arms whose models
# tests/test_assets_offline.py builds and steps in MuJoCo C (so100, z1). The default run stands
# `regular` in MJX.
_BREADTH = ("double", "none", "longer", "heavier", "pusher", "so100", "z1")


@functools.cache
def _on_servos(variant: str):
    """(model with leg servos, its MJX model, jit(vmap) of _CHUNK MJX steps): one compile per
    variant, shared by the standing run and the comparison with MuJoCo C."""
    model = with_leg_servos(build(variant))
    mx = sim.put_model(model)
    return model, mx, sim.make_rollout(mx, _CHUNK)


@pytest.fixture(
    scope="module",
    params=[
        pytest.param(v, marks=pytest.mark.slow) if v in _BREADTH else v for v in sorted(VARIANTS)
    ],
)
def standing_run(request):
    """Per variant: batched MJX states after one chunk and after 2 s of standing on servos."""
    model, mx, rollout = _on_servos(request.param)
    data = sim.batched_data(
        mx, perturbed_home(model, _BATCH, seed=0), np.tile(home_ctrl(model), (_BATCH, 1))
    )
    first = rollout(data)
    last = first
    for _ in range(round(_STAND_SECONDS / model.opt.timestep / _CHUNK) - 1):
        last = rollout(last)
    return request.param, jax.device_get(first), jax.device_get(last)


def test_variant_steps_finitely_in_mjx(standing_run):
    name, first, _ = standing_run
    for field in ("qpos", "qvel", "qacc", "sensordata"):
        assert np.isfinite(getattr(first, field)).all(), f"{name}: non-finite {field}"


def test_standing_robot_does_not_fall_in_mjx(standing_run):
    name, _, last = standing_run
    assert np.isfinite(last.qpos).all()
    assert (last.qpos[:, 2] > _MIN_HEIGHT).all(), f"{name}: trunk heights {last.qpos[:, 2]}"
    roll, pitch, _ = np.asarray(roll_pitch_yaw(last.qpos[:, 3:7])).T
    assert (np.abs(roll) < _MAX_TILT).all() and (np.abs(pitch) < _MAX_TILT).all(), name


def test_mjx_agrees_with_mujoco_c():
    """100 steps from a perturbed home pose (the standing run's compiled chunk, row 0)."""
    model, mx, rollout = _on_servos("regular")
    qpos = perturbed_home(model, _BATCH, seed=1)
    ctrl = home_ctrl(model)
    data = mujoco.MjData(model)
    data.qpos[:], data.ctrl[:] = qpos[0], ctrl
    for _ in range(2 * _CHUNK):
        mujoco.mj_step(model, data)
    dx = rollout(rollout(sim.batched_data(mx, qpos, np.tile(ctrl, (_BATCH, 1)))))
    assert float(dx.qpos[0, 2]) == pytest.approx(data.qpos[2], abs=_MJX_C_HEIGHT_TOL)
    np.testing.assert_allclose(np.asarray(dx.qpos[0, 3:7]), data.qpos[3:7], atol=_MJX_C_QUAT_TOL)


def test_one_compile_serves_a_batch_of_arm_parameters():
    model = with_leg_servos(build("regular"))
    lengths, masses = [0.14, 0.28], [0.1, 0.5]
    mx, in_axes = batch_arm_params(
        sim.put_model(model), model, upper_arm_length=lengths, gripper_mass=masses
    )
    traces = []

    def step(m, d):
        traces.append(1)  # runs only while tracing
        return jax.lax.scan(lambda d, _: (mjx.step(m, d), None), d, None, length=50)[0]

    run = fast_jit(jax.vmap(step, in_axes=(in_axes, 0)))  # compile-bound
    data = sim.batched_data(
        mx, np.tile(model.key_qpos[0], (2, 1)), np.tile(home_ctrl(model), (2, 1))
    )
    for _ in range(_BATCHED_CALLS):
        data = run(mx, data)
    assert len(traces) == 1
    arm = layout(model).arms[0]
    fz = -np.asarray(jax.vmap(lambda d: mount_wrench(arm, d)[0][2])(data))
    base = model.site_bodyid[arm.mount_site]
    weights = _G * np.asarray(mx.body_subtreemass[:, base])
    np.testing.assert_allclose(
        weights, _G * (model.body_subtreemass[base] + np.array([0, 0.4])), rtol=1e-5
    )
    np.testing.assert_allclose(fz, weights, rtol=_BATCHED_FORCE_RTOL)
    assert fz[1] - fz[0] > 0.3 * _G  # the heavier gripper pushes harder on the trunk
    assert np.asarray(mx.body_pos[:, model.body("arm0/forearm").id, 2]) == pytest.approx(lengths)
    assert jp.all(jp.isfinite(data.qpos))
