"""The classical controllers on the arms' own model (`feedforward`, `feedforward_observer`) and
DPC on it (`EnvConfig.u_base='model'`): what the low-level controller adds, what they achieve on
the heavy Z1, and the legs' weight the feedforward observer counts as known (the regression's
target: tests/test_u_base.py; the numpy runner's u: tests/test_io.py)."""

import jax
import jax.numpy as jp
import numpy as np
from helpers import ENGINE, FAST_COMPILE, STANDING_STILL

import dpc_mjx
from dpc_mjx.control.state import legs_weight_wrench, read_state
from dpc_mjx.envs import DEFAULT_TASK
from dpc_mjx.envs.controller_batch import ControllerBatch
from dpc_mjx.run.eval import evaluate

_EPISODES = 16  # per controller
_EPISODE_STEPS = 250  # 5 s
_SETTLE_STEPS = 100  # env steps (2 s) standing still, the observer settled (5 / K = 0.25 s)
# the observer's estimate on the bare base against the legs' weight term (measured on the A1:
# 0.04 N and 0.17 N·m apart; the rest is the legs' small motion and the estimate's noise)
_BIAS_F_TOL = 0.3  # N
_BIAS_TAU_TOL = 0.3  # N·m


def _one_step(env, action):
    """One env step from seed 0's reset, run op by op (no compiled program, so two envs that do
    the same arithmetic give the same bits)."""
    state = env.reset(jax.random.PRNGKey(0))
    return env.step(state, jp.asarray(action, jp.float32))


def test_dpc_on_the_model_with_a_zero_action_is_the_feedforward_controller():
    """u = the arms' model wrench + 0 at every tick: the `feedforward` controller's step to the
    bit, and not MBC's."""
    kw = dict(arm="z1", engine=ENGINE, push_force=(0.0, 0.0))
    feedforward = _one_step(dpc_mjx.make(DEFAULT_TASK, controller="feedforward", **kw), np.ones(6))
    on_model = _one_step(
        dpc_mjx.make(DEFAULT_TASK, controller="dpc", u_base="model", **kw), np.zeros(6)
    )
    mbc = _one_step(dpc_mjx.make(DEFAULT_TASK, controller="mbc", **kw), np.zeros(6))
    np.testing.assert_array_equal(feedforward.pipeline_state.qpos, on_model.pipeline_state.qpos)
    assert np.abs(feedforward.pipeline_state.qpos - mbc.pipeline_state.qpos).max() > 1e-4
    wrench = on_model.info["ctrl"].arm.wrench  # (6,) N, N·m: z1's 5.5 kg on the base
    assert np.all(np.isfinite(wrench)) and wrench[2] < -10.0, wrench


def test_on_the_heavy_z1_the_model_wrench_keeps_the_body_level_and_up():
    """16 episodes x 5 s of reaching with pushes, paired: the feedforward controllers tilt the
    trunk less than MBC (RMS roll and pitch under half of MBC's: 0.03 against 0.15 rad at
    64 x 20 s) and fall no more often."""
    names = ("mbc", "feedforward", "feedforward_observer")
    results = evaluate(
        ["z1"],
        list(names),
        episodes=_EPISODES,
        steps=_EPISODE_STEPS,
        seed=83000,
        overrides={"engine": ENGINE},
        progress=False,
    )
    cells = {c.controller: c for c in results}
    tilt = {n: np.hypot(cells[n].roll_rms, cells[n].pitch_rms) for n in names}
    falls = {n: cells[n].fall_rate for n in names}
    for name in names[1:]:
        assert tilt[name] < 0.5 * tilt["mbc"], tilt
        assert falls[name] <= falls["mbc"], falls
    assert np.all(np.isfinite(list(tilt.values())))


def test_the_legs_weight_is_the_observers_bias_on_a_bare_base():
    """The bare A1 standing still (no arm: nothing acts on it but gravity and the ground): the
    momentum observer's estimate is not 0 but the legs' weight at the feet that tau = J^T f does
    not carry (`state.legs_weight_wrench`), which `feedforward_observer` counts as known."""
    env = dpc_mjx.make(DEFAULT_TASK, arm="none", controller="mbc", engine=ENGINE, **STANDING_STILL)
    reset = jax.jit(env.reset, compiler_options=FAST_COMPILE)
    step = jax.jit(env.step, compiler_options=FAST_COMPILE)
    state = reset(jax.random.PRNGKey(0))
    for _ in range(_SETTLE_STEPS):
        state = step(state, jp.zeros(6))
    d = state.pipeline_state
    legs = legs_weight_wrench(
        env.controller.idx,
        d,
        read_state(env.controller.idx, d),
        jp.ones(4, bool),
        env.lay.foot_radius,  # the contact points, as the observer's known wrench has them
    )
    estimate = state.info["ctrl"].observer.estimate
    assert legs[2] > 5.0  # N: the feet push harder than asked
    np.testing.assert_allclose(estimate[:3], legs[:3], atol=_BIAS_F_TOL)
    np.testing.assert_allclose(estimate[3:], legs[3:], atol=_BIAS_TAU_TOL)


def test_only_the_envs_that_read_the_model_wrench_compute_it():
    """The arms' model wrench costs a fifth of an env step: computed where a controller adds it,
    under u_base 'model' (the data record it), and in a batch with such a controller."""
    kw = dict(arm="regular", engine=ENGINE)
    assert dpc_mjx.make(DEFAULT_TASK, controller="mbc", **kw).controller.arm is None
    assert dpc_mjx.make(DEFAULT_TASK, controller="dpc", **kw).controller.arm is None
    for on in (
        dpc_mjx.make(DEFAULT_TASK, controller="feedforward", **kw),
        dpc_mjx.make(DEFAULT_TASK, controller="mbc", u_base="model", **kw),
    ):
        assert on.controller.arm is not None
    env = dpc_mjx.make(DEFAULT_TASK, controller="dpc", **kw)
    ControllerBatch(env, ["mbc", "observer"])
    assert env.controller.arm is None
    ControllerBatch(env, ["mbc", "feedforward_observer"])
    assert env.controller.arm is not None
