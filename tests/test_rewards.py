"""The paper's reward (eqs. 2-4) on hand-made states."""

import math

import jax.numpy as jp
import mujoco
import numpy as np
import pytest

from dpc_mjx.envs import observations as obs
from dpc_mjx.envs import rewards
from dpc_mjx.robots import build
from dpc_mjx.robots.layout import layout

_TOL = 1e-6


def test_perfect_tracking_gets_the_maximum():
    out = rewards.total_reward(
        jp.array([0.3, 0.0, 0.5]), jp.array([0.3, 0.0, 0.5]), jp.zeros(2), jp.zeros(2)
    )
    assert float(out["r_vel"]) == pytest.approx(3.0, abs=_TOL)
    assert float(out["r_orn"]) == pytest.approx(2.0, abs=_TOL)
    assert float(out["r_total"]) == pytest.approx(0.34, abs=_TOL)
    assert rewards.MAX_REWARD == pytest.approx(0.34)


def test_terms_follow_the_formulas():
    vel, vel_des = jp.array([0.5, -0.1, 0.2]), jp.array([0.3, 0.0, 0.5])
    rp, rp_des = jp.array([0.1, -0.2]), jp.array([0.0, 0.05])
    out = rewards.total_reward(vel, vel_des, rp, rp_des)
    r_vel = math.exp(-8 * 0.2**2) + math.exp(-8 * 0.1**2) + math.exp(-8 * 0.3**2)
    r_orn = math.exp(-8 * 0.1**2) + math.exp(-8 * 0.25**2)
    assert float(out["r_vel"]) == pytest.approx(r_vel, abs=_TOL)
    assert float(out["r_orn"]) == pytest.approx(r_orn, abs=_TOL)
    assert float(out["r_total"]) == pytest.approx(0.08 * r_vel + 0.05 * r_orn, abs=_TOL)


def test_batched_input_reduces_the_last_axis():
    out = rewards.total_reward(
        jp.zeros((5, 3)), jp.ones((5, 3)), jp.zeros((5, 2)), jp.zeros((5, 2))
    )
    assert out["r_total"].shape == (5,)
    assert float(out["r_vel"][0]) == pytest.approx(3 * math.exp(-8), abs=_TOL)


def test_observation_blocks_on_a_hand_made_state():
    model = build("regular")
    lay = layout(model)
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    yaw = 0.5 * math.pi  # facing +y: world velocity +y is forward
    d.qpos[3:7] = [math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]
    d.qvel[0:3] = [0.0, 0.4, 0.1]
    d.qvel[3:6] = [0.1, -0.2, 0.3]
    body = np.asarray(obs.s_body(d, jp.array([0.4, 0.0, 0.3])))
    assert body.shape == (obs.S_BODY_SIZE,)
    np.testing.assert_allclose(body[:2], 0.0, atol=_TOL)  # level
    np.testing.assert_allclose(body[2:5], [0.1, -0.2, 0.3], atol=_TOL)
    np.testing.assert_allclose(body[5:8], [0.4, 0.0, 0.1], atol=1e-6)
    np.testing.assert_allclose(body[8:], [0.4, 0.0, 0.3], atol=_TOL)
    assert obs.s_arm(lay, d).shape == (10,)  # 5 joints: q then qdot
    np.testing.assert_allclose(obs.p_arm(lay, d), model.key_ctrl[0][lay.arm_act])
