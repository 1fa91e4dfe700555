"""DPC on the arms' gravity wrench (`EnvConfig.u_base='gravity'`): u = the arms' weight and its
torque about the base's COM at their pose (from the arm file's masses, `DpcEnv.arm_gravity`) plus
the policy's u (its regression target: tests/test_u_base.py)."""

import jax
import jax.numpy as jp
import numpy as np
from helpers import ENGINE, FAST_COMPILE, STANDING_STILL

import dpc_mjx
from dpc_mjx.control.state import gravity_u
from dpc_mjx.envs import DEFAULT_TASK
from dpc_mjx.rotations import roll_pitch_yaw, wrench_to_world

_BATCH = 2
_SETTLE_STEPS = 40  # env steps (0.8 s) standing still before the wrenches are compared
# The mount wrench of an arm held still, standing, exact sensors, against its gravity wrench:
# what is left is the arm servos' small motion and the trunk's sway (measured on z1, 0.8 s after
# reset: 0.11 N and 0.023 N·m at most)
_REST_F_TOL = 1.0  # N
_REST_TAU_TOL = 0.2  # N·m


def test_gravity_u_is_the_weight_and_its_moment_about_the_com():
    """Two point masses: the sum of m g and of (c_b - c) x m g (N, N·m), against hand sums."""
    masses = jp.array([1.0, 2.0])
    coms = jp.array([[0.3, 0.0, 0.1], [0.0, -0.2, 0.5]])
    u = np.asarray(gravity_u(masses, jp.array([0.0, 0.0, -9.81]), coms, jp.array([0.1, 0.0, 0.0])))
    np.testing.assert_allclose(u[:3], [0.0, 0.0, -3.0 * 9.81], rtol=1e-6)
    # (x, y, z) x (0, 0, -m g) = (-y m g, x m g, 0): x about the COM 0.2 and -0.1, y 0 and -0.2
    expected_tau = [-(0.0 * 1.0 + -0.2 * 2.0) * 9.81, (0.2 * 1.0 + -0.1 * 2.0) * 9.81, 0.0]
    np.testing.assert_allclose(u[3:], expected_tau, atol=1e-5)


def test_an_arm_held_still_loads_its_mount_with_its_gravity_wrench():
    """z1 (5.5 kg, far forward of the COM), standing, the arm at home, no pushes or payload,
    exact sensors: the measured mount wrench (the oracle's u) is the arm's gravity wrench."""
    env = dpc_mjx.make(
        DEFAULT_TASK,
        arm="z1",
        controller="mbc",
        engine=ENGINE,
        reach_fraction=0.0,
        payload_mass=(0.0, 0.0),
        **STANDING_STILL,
    )
    reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)
    step = jax.jit(jax.vmap(env.step), compiler_options=FAST_COMPILE)
    state = reset(jax.random.split(jax.random.PRNGKey(0), _BATCH))
    zeros = jp.zeros((_BATCH, env.action_size))
    for _ in range(_SETTLE_STEPS):
        state = step(state, zeros)
    gravity = np.asarray(jax.vmap(env.arm_gravity)(state.pipeline_state))
    oracle = np.asarray(state.info["privileged"][:, :6])
    assert not np.any(state.done)
    weight = env.model.body_mass[np.concatenate([a.bodies for a in env.lay.arms])].sum() * 9.81
    np.testing.assert_allclose(gravity[:, 2], -weight, rtol=1e-5)
    assert np.all(np.abs(gravity[:, 4]) > 1.0), gravity  # a real moment to match, N·m
    np.testing.assert_allclose(oracle[:, :3], gravity[:, :3], atol=_REST_F_TOL, rtol=0)
    np.testing.assert_allclose(oracle[:, 3:], gravity[:, 3:], atol=_REST_TAU_TOL, rtol=0)


def test_dpc_on_gravity_adds_the_arms_gravity_wrench_to_the_policys_u():
    """The 'dpc' controller's u of a tick (world frame) with u_base='gravity': the arms' gravity
    wrench plus the policy's yaw-frame u turned by the heading."""
    kw = dict(arm="regular", controller="dpc", engine=ENGINE)
    env = dpc_mjx.make(DEFAULT_TASK, u_base="gravity", **kw)
    d = jax.jit(env.reset)(jax.random.PRNGKey(0)).pipeline_state
    u_policy = jp.array([1.0, -2.0, 3.0, 0.5, -0.5, 0.1])  # yaw frame, N and N·m
    u, add_estimate, add_model = env.controller_u(d, u_policy)
    assert not add_estimate and not add_model  # nothing is added by the low-level controller
    yaw = roll_pitch_yaw(d.qpos[None, 3:7])[0, 2]
    expected = wrench_to_world(u_policy, yaw) + env.arm_gravity(d)
    np.testing.assert_allclose(u, expected, atol=1e-5)
    assert abs(float(env.arm_gravity(d)[2])) > 5.0  # the regular arm's weight, N
