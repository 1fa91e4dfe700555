"""The arms' wrench over the MPC's horizon (`EnvConfig.u_ahead`): the arms' model wrench's change
along their servo targets ahead (`arm_estimate.planned_change`), added to the present u of the
controllers that add the model wrench.

The change is referenced against MuJoCo C: along a slow move (velocities and accelerations near
zero) it is the change of the arms' weight and its moment about the base's COM at the targets'
poses (`mj_kinematics`, `state.gravity_u`). In an env, the plan's wrench sequence
(`MPCPlan.wrench`) varies along the horizon for the feedforward while the arm reaches, and is
held for MBC, in one batch.
"""

from __future__ import annotations

import types

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import fast_jit

from dpc_mjx import DpcError, make
from dpc_mjx.control.arm_estimate import planned_change
from dpc_mjx.control.arm_model import arm_model
from dpc_mjx.control.state import gravity_u, state_index
from dpc_mjx.envs import ahead
from dpc_mjx.envs.controller_batch import ControllerBatch
from dpc_mjx.envs.rollout import run_recorded
from dpc_mjx.robots import build
from dpc_mjx.robots.layout import layout

N = 10  # the MPC's steps
_SLOW_DT = 10.0  # s between the targets' steps: velocities ~1e-3 rad/s, accelerations ~1e-5
_SLOW_TOL = 2e-3  # N and N·m: float32 sums over the arm's bodies, and the slow move's dynamics
SEED = 11  # chose nothing


def _still(model, lay):
    """(the home key's kinematics, the base as `planned_change` reads it, its COM lever)."""
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    mujoco.mj_kinematics(model, d)
    rot = jp.asarray(d.xmat[lay.trunk].reshape(3, 3), jp.float32)
    lever = rot @ jp.asarray(state_index(model, lay).com_offset, jp.float32)
    return d, types.SimpleNamespace(rot=rot, ang_vel=jp.zeros(3)), lever


@pytest.mark.parametrize("name", ["regular", "z1"])
def test_along_a_slow_move_the_change_is_the_weights_moment(name):
    model = build(name)
    lay = layout(model)
    d, s, lever = _still(model, lay)
    q0 = d.qpos[lay.arm_qpos].copy()
    move = np.zeros_like(q0)
    move[:2] = (0.6, -0.5)  # rad: the first two joints (a waist and a shoulder)
    # (N + 2, n): the targets at k = -1 .. N, a straight line from q0
    targets = q0 + np.linspace(-1.0, N, N + 2)[:, None] / N * move
    change = np.asarray(planned_change(arm_model(model, lay), s, lever, targets, _SLOW_DT))
    masses = jp.asarray(model.body_mass[lay.arm_bodies], jp.float32)
    gravity = jp.asarray(model.opt.gravity, jp.float32)
    com = jp.asarray(d.xpos[lay.trunk]) + lever
    weights = []
    for q in targets[1:-1]:
        d.qpos[lay.arm_qpos] = q
        mujoco.mj_kinematics(model, d)
        weights.append(gravity_u(masses, gravity, jp.asarray(d.xipos[lay.arm_bodies]), com))
    want = np.asarray(weights) - np.asarray(weights[0])
    assert np.abs(want[:, 3:]).max() > 0.1  # N·m: the move does shift the arm's weight
    np.testing.assert_allclose(change, want, atol=_SLOW_TOL)


def test_held_targets_change_nothing():
    model = build("regular")
    lay = layout(model)
    d, s, lever = _still(model, lay)
    targets = np.tile(d.qpos[lay.arm_qpos], (N + 2, 1))
    change = planned_change(arm_model(model, lay), s, lever, targets, 0.03)
    np.testing.assert_allclose(change, 0.0, atol=1e-6)


def test_u_ahead_is_an_env_option_with_a_clear_error():
    with pytest.raises(DpcError, match="needs low_level='mpc'"):
        make("reaching", arm="regular", u_ahead="model")
    with pytest.raises(DpcError, match="u_ahead"):
        make("reaching", arm="regular", low_level="mpc", u_ahead="ahead")


def test_the_feedforward_plans_along_the_arms_targets(monkeypatch):
    """One batch, MBC and the feedforward on the MPC with u_ahead 'model', 25 env steps of the
    reaching task: the feedforward's planned wrench varies along the horizon while the arm moves
    (MBC's is held, its u 0), every output is finite, and nobody falls."""
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: 4 envs, 25 steps
    env = make(
        "reaching", arm="regular", engine="native", low_level="mpc", u_ahead="model",
        controller="dpc", push_force=(0.0, 0.0),
    )  # fmt: skip
    batch = ControllerBatch(env, ["mbc", "feedforward"])
    keys = jax.random.split(jax.random.PRNGKey(SEED), 4)
    state = jax.jit(batch.reset)(keys)  # the whole batch (`ControllerBatch.batched`)
    step = jax.jit(batch.step)
    spread = np.zeros(4)  # N and N·m: the largest change of a plan's wrench along its horizon
    for _ in range(25):
        state = step(state, jp.zeros((4, 6)))
        wrench = np.asarray(state.info["ctrl"].mpc.wrench)  # (4, N, 6)
        assert np.isfinite(wrench).all() and np.isfinite(np.asarray(state.obs)).all()
        spread = np.maximum(spread, np.abs(wrench - wrench[:, :1]).max(axis=(1, 2)))
        assert not np.asarray(state.done).any()
    mbc = np.asarray(state.info["controller"]) == 0
    assert mbc.any() and (~mbc).any()
    np.testing.assert_allclose(spread[mbc], 0.0, atol=1e-6)  # held
    assert (spread[~mbc] > 0.05).all(), spread  # N, N·m: the arm's planned motion


# The privileged replay ('replay', `envs/ahead.py`) -------------------------------------------

_TICK_DT = 0.004  # s, the control tick
_REPLAY_TOL = 1e-4  # N and N·m: float32 sums of the same wrenches in two compiled programs


def test_the_replayed_change_interpolates_the_recording():
    mpc = types.SimpleNamespace(dt=0.03, steps=N)  # 7.5 ticks a step: between two ticks
    slope = jp.arange(1.0, 7.0)  # (6,) N and N·m per tick
    recording = jp.arange(200.0)[:, None] * slope  # (T, 6): r_i = i * slope
    change = np.asarray(ahead.replay_change(recording, jp.asarray(0.2), _TICK_DT, mpc))
    want = (np.arange(N) * 0.03 / _TICK_DT)[:, None] * np.asarray(slope)
    np.testing.assert_allclose(change, want, rtol=1e-5)
    # past the recording's end it is held: from the last tick on the change stops growing
    late = np.asarray(ahead.replay_change(recording, jp.asarray(199 * _TICK_DT), _TICK_DT, mpc))
    np.testing.assert_allclose(late, 0.0, atol=1e-3)


def test_a_replay_needs_a_replay_env_and_a_recording_that_fits():
    held = make("reaching", arm="regular", engine="native", low_level="mpc", controller="oracle")
    state = jax.vmap(held.reset)(jax.random.split(jax.random.PRNGKey(SEED), 2))
    with pytest.raises(DpcError, match="u_ahead='replay'"):
        ahead.attach(state, np.zeros((2, 10, 6)))
    replay = make(
        "reaching", arm="regular", engine="native", low_level="mpc", controller="oracle",
        u_ahead="replay",
    )  # fmt: skip
    state = jax.vmap(replay.reset)(jax.random.split(jax.random.PRNGKey(SEED), 2))
    with pytest.raises(DpcError, match="does not fit"):
        ahead.attach(state, np.zeros((2, 10, 6)))


def test_the_pushes_change_is_their_schedule_as_a_wrench_about_the_com():
    env = make("reaching", arm="regular", engine="native", low_level="mpc", u_ahead="pushes")
    state = jax.jit(env.reset)(jax.random.PRNGKey(SEED))
    d = state.pipeline_state
    t = float(d.time)
    dist = state.info["dist"].replace(  # one push of 50 N down, 0.1 s to 0.2 s from now
        push=jp.array([[0.0, 0.0, -50.0]]),
        push_on=jp.array([t + 0.1]),
        push_off=jp.array([t + 0.2]),
    )
    change = np.asarray(ahead.push_change(env, dist, d))  # (N, 6) at t + k 0.03 s
    force = np.array([0.0, 0.0, -50.0])
    lever = np.asarray(d.site_xpos[env.ee_sites[0]] - env.com_pos(d))
    on = (np.arange(N) * 0.03 >= 0.1 - 1e-6) & (np.arange(N) * 0.03 < 0.2 - 1e-6)  # k = 4, 5, 6
    want = np.where(on[:, None], np.concatenate([force, np.cross(lever, force)]), 0.0)
    np.testing.assert_allclose(change, want, atol=1e-4)
    # of the pushes under way only: this one has not begun, its change is not known
    np.testing.assert_allclose(ahead.push_change(env, dist, d, begun_only=True), 0.0, atol=1e-6)
    begun = dist.replace(push_on=jp.array([t - 0.1]))  # under way, ends at t + 0.2
    ends = np.asarray(ahead.push_change(env, begun, d, begun_only=True))
    off = np.arange(N) * 0.03 >= 0.2 - 1e-6  # k >= 7: it has ended
    np.testing.assert_allclose(ends, np.where(off[:, None], -want[4], 0.0), atol=1e-4)


def _recorded(before, after):
    """A step's record: its ticks' mount wrenches (the recording), the one it ended with, and
    the wrench the MPC planned against."""
    del before
    return after.info["u_ticks"], after.info["privileged"][:, :6], after.info["ctrl"].mpc.wrench


def _plans(before, after):
    """A step's record: the MPC's plan after it."""
    del before
    return after.info["ctrl"].mpc


def test_a_replay_plans_against_the_recorded_change(monkeypatch):
    """Two passes of 12 env steps, the oracle on the MPC, 3 envs, pushes on: the first (a zero
    recording) plans against u held, and its recording is the measured mount wrench of each
    tick; the second plans against the recording's change along its horizon."""
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: 3 envs, 12 steps
    options = dict(engine="native", low_level="mpc", controller="oracle", push_force=(30.0, 60.0))
    replay = make("reaching", arm="regular", u_ahead="replay", **options)
    steps, episodes = 12, 3
    _, (ticks, measured, first) = run_recorded(replay, episodes, steps, _recorded, SEED)
    np.testing.assert_array_equal(first, np.broadcast_to(first[:, :, :1], first.shape))  # held
    # the first tick of step s + 1 reads the data that step s ended with
    np.testing.assert_allclose(ticks[1:, :, 0], measured[:-1], atol=_REPLAY_TOL)
    recordings = ahead.recording(ticks)  # (episodes, steps * 5, 6)
    assert np.abs(np.diff(recordings, axis=1)).max() > 1.0  # N: the wrench does change
    length = replay.config.episode_length * replay.n_substeps
    full = np.pad(recordings, ((0, 0), (0, length - recordings.shape[1]), (0, 0)))

    _, plan = run_recorded(replay, episodes, steps, _plans, SEED, lambda s: ahead.attach(s, full))
    mpc = replay.controller.config.mpc
    for s in (3, 8):  # steps whose plans reach into the recording
        for e in range(episodes):
            want = ahead.replay_change(jp.asarray(full[e]), plan.t0[s, e], _TICK_DT, mpc)
            got = plan.wrench[s, e] - plan.wrench[s, e, :1]
            np.testing.assert_allclose(got, want, atol=_REPLAY_TOL)
            assert np.abs(got).max() > 0.1  # N: the plan is not held
