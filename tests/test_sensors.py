"""The sensor model (`control/sensors.py`): its errors have the documented sizes, reach the
controller's state as documented, leave an exact-sensor env untouched, and the env's
observation carries them."""

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import ENGINE, FAST_COMPILE

import dpc_mjx
from dpc_mjx.control import sensors
from dpc_mjx.control.state import BodyState
from dpc_mjx.envs import DEFAULT_TASK, observations
from dpc_mjx.rotations import roll_pitch_yaw

_TICKS = 20_000  # draws for the noise statistics
_STD_RTOL = 0.05  # relative error of a sample std over _TICKS draws (~1% expected)
# rad: roll/pitch of R R_x(a) R_y(b) against (roll + a, pitch + b) for a, b ~ 0.01 at an attitude
# of ~0.1 rad: second order, ~1e-3
_SMALL_ANGLE_TOL = 1e-3
_MEAN_SIGMAS = 6  # the sample mean of _TICKS draws is within this many of its std errors


def test_noise_has_the_documented_std_and_a_bounded_constant_bias():
    bias = sensors.draw_bias(jax.random.PRNGKey(0), 5, 2.0)  # scale 2: twice the robot values
    for name, (_, bound) in sensors._SPECS.items():
        assert np.all(np.abs(np.asarray(getattr(bias, name))) <= 2.0 * bound + 1e-9), name
    assert np.any(np.asarray(bias.gyro) != 0.0)
    keys = jax.random.split(jax.random.PRNGKey(1), _TICKS)
    draws = jax.vmap(lambda k: sensors.draw(k, bias, 2.0))(keys)
    for name, (std, _) in sensors._SPECS.items():
        x = np.asarray(getattr(draws, name))
        if x.size == 0:
            continue
        sem = 2.0 * std / np.sqrt(_TICKS)
        np.testing.assert_allclose(x.mean(0), getattr(bias, name), atol=_MEAN_SIGMAS * sem)
        np.testing.assert_allclose(x.std(0), 2.0 * std, rtol=_STD_RTOL, err_msg=name)
    zero = sensors.draw(keys[0], sensors.zeros(5), 0.0)
    assert all(np.all(np.asarray(v) == 0.0) for v in jax.tree.leaves(zero))


def _state(seed: int) -> BodyState:
    rng = np.random.default_rng(seed)
    yaw, roll, pitch = 0.7, 0.05, -0.08
    cz, sz, cx, sx, cy, sy = (f(a) for a in (yaw, roll, pitch) for f in (np.cos, np.sin))
    rot = (
        np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    )
    f = lambda *shape: jp.asarray(rng.normal(size=shape), jp.float32)  # noqa: E731
    return BodyState(
        com_pos=f(3),
        com_vel=f(3),
        rot=jp.asarray(rot, jp.float32),
        ang_vel=f(3),
        foot_pos=f(4, 3),
        foot_vel=f(4, 3),
        hip_pos=f(4, 3),
        foot_jac=f(4, 3, 3),
    )


def test_measured_state_carries_each_error_as_documented():
    s = _state(0)
    same = sensors.measured(s, sensors.zeros(5))
    for a, b in zip(jax.tree.leaves(same), jax.tree.leaves(s), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    noise = sensors.zeros(5).replace(
        tilt=jp.array([0.01, -0.01]),
        gyro=jp.array([0.1, 0.2, -0.3]),
        velocity=jp.array([0.05, -0.02, 0.01]),
        leg_q=jp.linspace(-0.01, 0.01, 12),
        leg_qd=jp.linspace(-0.1, 0.1, 12),
    )
    m = sensors.measured(s, noise)
    quat = lambda r: jp.asarray(_quat(np.asarray(r, float)))  # noqa: E731
    rpy, rpy_m = roll_pitch_yaw(quat(s.rot)), roll_pitch_yaw(quat(m.rot))
    np.testing.assert_allclose(rpy_m[:2] - rpy[:2], noise.tilt, atol=_SMALL_ANGLE_TOL)
    np.testing.assert_allclose(rpy_m[2], rpy[2], atol=_SMALL_ANGLE_TOL)
    np.testing.assert_allclose(m.rot.T @ m.ang_vel, s.rot.T @ s.ang_vel + noise.gyro, atol=1e-5)
    c, sn = np.cos(0.7), np.sin(0.7)
    dv = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]]) @ np.asarray(noise.velocity)
    np.testing.assert_allclose(m.com_vel - s.com_vel, dv, atol=1e-3)  # the yaw of a tilted R
    dq = np.asarray(noise.leg_q).reshape(4, 3)
    expected = np.einsum("fcj,fj->fc", np.asarray(s.foot_jac), dq)
    np.testing.assert_allclose(m.foot_pos - s.foot_pos, expected, atol=1e-6)
    np.testing.assert_allclose(m.com_pos, s.com_pos)  # positions are not corrupted


def _quat(rot: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, rot.reshape(-1))
    return q


@pytest.fixture(scope="module")
def resets():
    """A batch reset with the robot's sensors and one with exact sensors (same episodes)."""
    out = {}
    for noise in (1.0, 0.0):
        env = dpc_mjx.make(DEFAULT_TASK, arm="regular", sensor_noise=noise, engine=ENGINE)
        reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)  # called once
        out[noise] = env, reset(jax.random.split(jax.random.PRNGKey(3), 16))
    return out


def test_observation_is_measured_and_exact_sensors_observe_the_truth(resets):
    for noise, (env, state) in resets.items():
        lay = env.obs_layout
        true = jax.vmap(
            lambda d, c, e: observations.observation(env.lay, d, c, e)  # noqa: B023
        )(state.pipeline_state, state.info["dist"].command, state.info["ctrl"].observer.estimate)
        err = np.asarray(state.obs - true)
        if noise == 0.0:
            assert np.all(err == 0.0)
            continue
        bias = state.info["sensor_bias"]  # at reset, the observation has the episode's bias
        np.testing.assert_allclose(err[:, 0:2], bias.tilt, atol=1e-6)
        np.testing.assert_allclose(err[:, 2:5], bias.gyro, atol=1e-6)
        np.testing.assert_allclose(err[:, 5:8], bias.velocity, atol=1e-6)
        assert np.all(err[:, 8:11] == 0.0) and np.all(err[:, lay.p_arm] == 0.0)  # exact
        assert np.all(np.abs(err[:, 2:5]) <= sensors.GYRO[1] + 1e-7)
        assert len(set(np.round(err[:, 2], 6))) == len(err)  # a bias per episode


def test_sensor_options_are_checked():
    with pytest.raises(dpc_mjx.DpcError, match=r"sensor_delay must be an int in \[0, 10\]"):
        dpc_mjx.make(DEFAULT_TASK, arm="regular", sensor_delay=-1)
    with pytest.raises(dpc_mjx.DpcError, match="sensor_noise must be a finite number"):
        dpc_mjx.make(DEFAULT_TASK, arm="regular", sensor_noise=float("nan"))


@pytest.mark.slow  # an env step's compile (~1 min on 2 cores); `make test-all`
def test_torques_act_one_tick_after_their_measurement():
    """sensor_delay=1: after a step, the ctrl computed at the last tick is still queued, and the
    physics ran on the one computed a tick before (they differ while the robot trots)."""
    env = dpc_mjx.make(DEFAULT_TASK, arm="regular", sensor_noise=0.0, controller="mbc")
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    assert state.info["ctrl_queue"].shape == (1, env.model.nu)
    state = jax.jit(env.step)(state, jp.zeros(6))
    queued, applied = state.info["ctrl_queue"][0], state.pipeline_state.ctrl
    assert not np.allclose(queued, applied)
