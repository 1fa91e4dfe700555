"""DPC on the observer (`EnvConfig.u_base='observer'`): the controller adds the policy's u to the
observer's estimate of each tick, and the policy is fitted to the residual u_oracle - u_obs (with
'gravity', to u_oracle - u_gravity; with 'model', to what the arms' model cannot know)."""

import dataclasses

import jax
import jax.numpy as jp
import numpy as np
import pytest
from helpers import ENGINE, FAST_COMPILE

import dpc_mjx
from dpc_mjx import DpcError
from dpc_mjx.adapter.data import Dataset, felt_u, payload_u, unmodelled_u
from dpc_mjx.envs import DEFAULT_TASK
from dpc_mjx.policy.regression import U_CLIP, regression_target
from dpc_mjx.rotations import wrench_to_world, wrench_to_yaw_frame

_BATCH = 2
_STEPS = 3
_U_TOL = 1e-5  # action units: float32 rounding of (u_oracle - u_obs) / u_scale
# qpos gap to the observer's episode, as a fraction of MBC's (measured 0.013-0.055 over 3 steps)
_OF_MBC_GAP = 0.2


def _states(env, action):
    """jax.device_get of `_STEPS` env steps from seed 0 under `action` (6,)."""
    reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)
    step = jax.jit(jax.vmap(env.step), compiler_options=FAST_COMPILE)
    state = reset(jax.random.split(jax.random.PRNGKey(0), _BATCH))
    actions = jp.tile(jp.asarray(action, jp.float32), (_BATCH, 1))
    out = []
    for _ in range(_STEPS):
        state = step(state, actions)
        out.append(jax.device_get(state))
    return out


def test_dpc_on_the_observer_with_a_zero_action_is_the_observer():
    """u = the observer's estimate + 0 at every tick: the 'observer' controller's episode, not
    MBC's. Compiled as the other tests' short programs (`FAST_COMPILE`, LLVM -O0) the two
    programs' balance QPs end at other iterates within their tolerance, so the states agree to
    a fraction of MBC's departure, not bit for bit (compiled at the library's level they were
    equal bit for bit over these steps, sensors on)."""
    kw = dict(arm="regular", engine=ENGINE, push_force=(0.0, 0.0))
    observer = _states(dpc_mjx.make(DEFAULT_TASK, controller="observer", **kw), np.ones(6))
    mbc = _states(dpc_mjx.make(DEFAULT_TASK, controller="mbc", **kw), np.zeros(6))
    on_observer = dpc_mjx.make(DEFAULT_TASK, controller="dpc", u_base="observer", **kw)
    assert on_observer.config.adds_observer_estimate
    residual = _states(on_observer, np.zeros(6))
    for a, b, c in zip(observer, residual, mbc, strict=True):
        gap = np.abs(a.pipeline_state.qpos - b.pipeline_state.qpos).max()
        mbc_gap = np.abs(a.pipeline_state.qpos - c.pipeline_state.qpos).max()
        assert gap < _OF_MBC_GAP * mbc_gap, (gap, mbc_gap)


def test_only_dpc_adds_the_estimate_and_bad_bases_are_refused():
    make = dpc_mjx.envs.get_config
    assert not make(DEFAULT_TASK, controller="dpc").adds_observer_estimate  # the paper's
    assert not make(DEFAULT_TASK, controller="mbc", u_base="observer").adds_observer_estimate
    with pytest.raises(DpcError, match="u_base.*'zero'.*'observer'"):
        make(DEFAULT_TASK, u_base="obs")
    with pytest.raises(DpcError, match="u_base='observer'.*u_frame='yaw'"):
        make(DEFAULT_TASK, u_base="observer", u_frame="world")


def _random_wrenches(n: int = 32) -> Dataset:
    """n rows of random u_oracle, u_gravity, u_unmodelled, u_payload and u_felt (world frame),
    u_obs (yaw frame) and headings."""
    rng = np.random.default_rng(0)
    yaw = rng.uniform(-np.pi, np.pi, n).astype(np.float32)
    wrench = lambda: rng.normal(0.0, 5.0, (n, 6)).astype(np.float32)  # noqa: E731 (N, N·m)
    return Dataset(
        s_body=np.zeros((n, 11), np.float32),
        s_arm=np.zeros((n, 0), np.float32),
        p_arm=np.zeros((n, 0), np.float32),
        s_drp_next=np.zeros((n, 2), np.float32),
        u_oracle=wrench(),
        u_obs=wrench(),
        yaw=yaw,
        u_gravity=wrench(),
        u_unmodelled=wrench(),
        u_payload=wrench(),
        u_felt=wrench(),
    )


def test_the_residual_target_is_the_oracles_u_minus_the_estimate_in_either_frame():
    data = _random_wrenches()
    u_oracle, u_obs, yaw = data.u_oracle, data.u_obs, data.yaw
    scale = np.full(6, 40.0, np.float32)
    world = regression_target(data, scale, "world", "observer")
    expected = (u_oracle - np.asarray(wrench_to_world(u_obs, yaw))) / scale
    np.testing.assert_allclose(world, np.clip(expected, -U_CLIP, U_CLIP), atol=_U_TOL)
    yaw_frame = regression_target(data, scale, "yaw", "observer")
    expected = (data.u_oracle_in("yaw") - u_obs) / scale
    np.testing.assert_allclose(yaw_frame, np.clip(expected, -U_CLIP, U_CLIP), atol=_U_TOL)
    paper = regression_target(data, scale, "yaw", "zero")
    expected = np.clip(data.u_oracle_in("yaw") / scale, -U_CLIP, U_CLIP)
    np.testing.assert_allclose(paper, expected, atol=0)
    assert np.any(np.abs(world - paper) > 0.01)  # the estimate made a difference


def test_the_target_on_the_arms_gravity_is_the_oracles_u_minus_it():
    """u_base 'gravity' (the arms' weight): the actor is fitted to what that wrench leaves of the
    oracle's u, in either frame; without its column, refused."""
    data = _random_wrenches()
    scale = np.full(6, 40.0, np.float32)
    world = regression_target(data, scale, "world", "gravity")
    expected = np.clip((data.u_oracle - data.u_gravity) / scale, -U_CLIP, U_CLIP)
    np.testing.assert_allclose(world, expected, atol=_U_TOL)
    yaw_frame = regression_target(data, scale, "yaw", "gravity")
    expected = (data.u_oracle_in("yaw") - data.u_gravity_in("yaw")) / scale
    np.testing.assert_allclose(yaw_frame, np.clip(expected, -U_CLIP, U_CLIP), atol=_U_TOL)
    without = dataclasses.replace(data, u_gravity=None)
    with pytest.raises(DpcError, match="no u_gravity"):
        regression_target(without, scale, "world", "gravity")


def test_the_target_on_the_arms_model_is_what_the_model_cannot_know():
    """u_base 'model': the actor is fitted to u_unmodelled alone (the oracle's u minus the model
    wrench on the exact state), with `model_target` 'payload' to u_payload alone (the payloads'
    weight wrench), with 'felt' to u_felt alone, in either frame; without its column, refused."""
    data = _random_wrenches()
    scale = np.full(6, 40.0, np.float32)
    targets = (("unmodelled", "u_unmodelled"), ("payload", "u_payload"), ("felt", "u_felt"))
    for target, column in targets:
        wrench = getattr(data, column)
        world = regression_target(data, scale, "world", "model", model_target=target)
        np.testing.assert_allclose(world, np.clip(wrench / scale, -U_CLIP, U_CLIP), atol=_U_TOL)
        yaw_frame = regression_target(data, scale, "yaw", "model", model_target=target)
        expected = np.asarray(wrench_to_yaw_frame(wrench, data.yaw)) / scale
        np.testing.assert_allclose(yaw_frame, np.clip(expected, -U_CLIP, U_CLIP), atol=_U_TOL)
        without = dataclasses.replace(data, **{column: None})
        with pytest.raises(DpcError, match=f"no {column}"):
            regression_target(without, scale, "world", "model", model_target=target)
    assert not np.allclose(data.u_unmodelled, data.u_payload)  # the targets differ here
    assert not np.allclose(data.u_unmodelled, data.u_felt)


def test_the_model_target_is_checked():
    """`RunConfig.model_target`: one of `MODEL_TARGETS`, and only with u_base 'model'."""
    from dpc_mjx.run.config import RunConfig  # noqa: PLC0415

    model = {"env.u_base": "model"}
    assert RunConfig().replace(model_target="payload", **model).model_target == "payload"
    with pytest.raises(DpcError, match="model_target='slow' is not one of"):
        RunConfig().replace(model_target="slow", **model)
    with pytest.raises(DpcError, match="needs env.u_base=model"):
        RunConfig().replace(model_target="payload", **{"env.u_base": "zero"})


def _trajectories() -> Dataset:
    """Two envs stepped together for 6 steps (rows: time, then env); env 1's episode ends after
    its 3rd row (its 4th transition was dropped: its next state was a reset), so its last two
    rows start a new episode. Roll and pitch rates follow each env's own sequence."""
    drp = {0: [0.1 * k for k in range(7)], 1: [1.0, 1.1, 1.2, 1.3, 5.0, 5.1, 5.2]}
    rows = [(k, env) for k in range(6) for env in (0, 1) if (k, env) != (3, 1)]
    s_body = np.zeros((len(rows), 11), np.float32)
    s_body[:, 2] = [drp[env][k] for k, env in rows]
    s_drp_next = np.zeros((len(rows), 2), np.float32)
    s_drp_next[:, 0] = [drp[env][k + 1] for k, env in rows]
    s_body[:, 3] = s_drp_next[:, 1] = 0.5  # the pitch rate, equal everywhere
    u = np.zeros((len(rows), 6), np.float32)
    u[:, 0] = [float(k >= 1) for k, _ in rows]  # N: a step in the oracle's f_x at k = 1
    return Dataset(
        s_body=s_body,
        s_arm=np.zeros((len(rows), 0), np.float32),
        p_arm=np.zeros((len(rows), 0), np.float32),
        s_drp_next=s_drp_next,
        env_id=np.array([env for _, env in rows], np.int32),
        u_oracle=u,
        u_obs=np.zeros_like(u),
        yaw=np.zeros(len(rows), np.float32),
    )


def test_previous_rows_follow_each_env_within_an_episode():
    data = _trajectories()
    # rows: (0,0) (0,1) (1,0) (1,1) (2,0) (2,1) (3,0) (4,0) (4,1) (5,0) (5,1)
    expected = [-1, -1, 0, 1, 2, 3, 4, 6, -1, 7, 8]
    np.testing.assert_array_equal(data.previous_rows(), expected)
    with pytest.raises(DpcError, match="env_id"):
        Dataset(data.s_body, data.s_arm, data.p_arm, data.s_drp_next).previous_rows()


def test_the_fast_residual_leaves_out_its_exponential_average_along_each_episode():
    data, scale, alpha = _trajectories(), np.full(6, 10.0, np.float32), 0.02 / (0.08 + 0.02)
    # tau 0.08 s, rows 0.02 s apart: alpha 0.2
    fast = regression_target(data, scale, "yaw", "observer", slow_s=0.08, step_s=0.02)
    whole = regression_target(data, scale, "yaw", "observer")
    # env 0: f_x steps 0 -> 1 N at k = 1; the average a_k = 1 - (1 - alpha)^k, the target 1 - a_k
    env0 = data.env_id == 0
    k = np.arange(6)
    expected = np.where(k >= 1, (1 - alpha) ** k, 0.0) / 10.0
    np.testing.assert_allclose(fast[env0, 0], expected, atol=1e-7)
    # env 1's second episode starts afresh (its average is its first row's f_x, 1 N, so its
    # target is 0; carried over from the first episode's 0.36 it would be 0.064 and 0.051)
    np.testing.assert_allclose(fast[data.env_id == 1, 0], [0, 0.08, 0.064, 0, 0], atol=1e-7)
    np.testing.assert_array_equal(fast[:, 1:], 0.0)
    np.testing.assert_array_equal(whole[:, 0], data.u_oracle[:, 0] / 10.0)  # slow part kept
    # (force, torque): 0 keeps that part whole
    torque_only = regression_target(data, scale, "yaw", "observer", slow_s=(0.0, 0.08))
    np.testing.assert_array_equal(torque_only, whole)  # the step is in f_x
    force_only = regression_target(data, scale, "yaw", "observer", slow_s=(0.08, 0.0))
    np.testing.assert_array_equal(force_only, fast)
    with pytest.raises(DpcError, match="u_base='observer'"):
        regression_target(data, scale, "yaw", "zero", slow_s=0.5)


def test_a_fast_residual_run_needs_the_observer_base():
    from dpc_mjx.run.config import RunConfig  # noqa: PLC0415

    with pytest.raises(DpcError, match="env.u_base=observer"):
        RunConfig().replace(residual_slow_s=0.5)
    with pytest.raises(DpcError, match="residual_slow_s.*in \\[0.0, 60.0\\]"):
        RunConfig().replace(residual_slow_s=-1.0, **{"env.u_base": "observer"})
    with pytest.raises(DpcError, match="a number or a \\(force, torque\\) pair"):
        RunConfig().replace(residual_slow_s=[1.0, 2.0, 3.0], **{"env.u_base": "observer"})
    assert not RunConfig().replace(residual_slow_s=(0, 0)).splits_residual
    for slow in (0.5, [0.0, 1.0]):  # a list as `--set residual_slow_s=[0,1]` gives it
        config = RunConfig().replace(residual_slow_s=slow, **{"env.u_base": "observer"})
        assert config.splits_residual
        expected = tuple(slow) if isinstance(slow, list) else slow
        assert config.residual_slow_s == expected
        assert RunConfig.from_json(config.to_json()).residual_slow_s == expected


# What the arms' model cannot know, on the simulator's exact state: the model against the measured
# wrench of one forward pass agrees to float32 rounding (measured |u| <= 1e-3 N over free motion,
# docs/results-arm-model.md: R^2 1.000), so the residual is the external force on the gripper.
_UNMODELLED_TOL_F = 0.02  # N, per axis
_PAYLOAD_KG = 0.3


def _unpushed(payload: float):
    """The reaching env on `regular` under MBC with no push and a payload of `payload` kg."""
    return dpc_mjx.make(
        DEFAULT_TASK,
        arm="regular",
        engine=ENGINE,
        controller="mbc",
        push_force=(0.0, 0.0),
        payload_mass=(payload, payload),
    )


@pytest.mark.parametrize("payload", [0.0, _PAYLOAD_KG])
def test_the_unmodelled_wrench_is_the_force_on_the_gripper(payload):
    """`adapter.data.unmodelled_u` (`Dataset.u_unmodelled`): zero with no push and no payload,
    the payload's weight (a force m g at the gripper) with one, while the arm reaches and the
    robot trots; its torque that force's moment about the base's COM. With no push it is
    `payload_u` (`Dataset.u_payload`, the 'model' target)."""
    env = _unpushed(payload)
    states = _states(env, np.zeros(6))
    for state in states:
        d = state.pipeline_state
        u = np.asarray(jax.vmap(lambda x: unmodelled_u(env, x))(d))  # (B, 6) world
        weight = np.array([0.0, 0.0, -payload * 9.81])
        np.testing.assert_allclose(u[:, :3], np.tile(weight, (_BATCH, 1)), atol=_UNMODELLED_TOL_F)
        ee = np.asarray(d.site_xpos[:, env.lay.arms[0].ee_site])  # (B, 3) m, world
        com = np.asarray(jax.vmap(env.com_pos)(d))
        moment = np.cross(ee - com, weight)
        np.testing.assert_allclose(u[:, 3:], moment, atol=_UNMODELLED_TOL_F)
        carried = jp.full((_BATCH, 1), payload, jp.float32)  # kg, one arm
        u_payload = np.asarray(jax.vmap(lambda x, m: payload_u(env, x, m))(d, carried))
        np.testing.assert_allclose(u_payload, u, atol=_UNMODELLED_TOL_F)


def test_what_the_mount_feels_beyond_the_servos_motion_is_zero_on_a_free_arm():
    """`adapter.data.felt_u` (`Dataset.u_felt`, the 'felt' target): with no push and no payload,
    and no joint limit or friction acting on the arm, the servos' law and the arm's model give
    the arm's motion (tests/test_arm_model.py), so the mount feels nothing beyond it; with a
    payload it is not zero, and smaller than the payload's weight (the servos hold the load, and
    the model of their motion sees their effort)."""
    for payload in (0.0, _PAYLOAD_KG):
        env = _unpushed(payload)
        for state in _states(env, np.zeros(6)):
            d = state.pipeline_state
            assert not np.any(np.asarray(d.qfrc_constraint)[:, env.lay.arm_dof])  # a free arm
            felt = np.asarray(jax.vmap(lambda x: felt_u(env, x))(d))  # (B, 6) world
            if payload == 0.0:
                np.testing.assert_allclose(felt, 0.0, atol=_UNMODELLED_TOL_F)
            else:
                weight = payload * 9.81  # N
                assert np.all(np.linalg.norm(felt[:, :3], axis=1) > 10 * _UNMODELLED_TOL_F)
                assert np.all(np.linalg.norm(felt[:, :3], axis=1) < weight)
