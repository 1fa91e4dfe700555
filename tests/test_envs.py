"""The DPC environments: brax API, observation layout, reward, NaN isolation, errors (batch 2)."""

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import ENGINE, FAST_COMPILE, CountTraces, recorded_compiles

import dpc_mjx
from dpc_mjx import DpcError
from dpc_mjx.envs import DEFAULT_TASK, base, observations, registry, wrap_for_training
from dpc_mjx.envs import config as env_config
from dpc_mjx.envs.disturbances import DisturbanceSampler, make_sampler
from dpc_mjx.robots.layout import layout
from dpc_mjx.rotations import roll_pitch_yaw, wrench_to_world, wrench_to_yaw_frame

_BATCH = 2
_TASK = DEFAULT_TASK
_REWARD_TOL = 1e-5
_U_OBS_ATOL = 1e-4  # N, N·m: u_obs against the observer's estimate turned here (float32)
_OBS_SIZES = {  # arm -> (s_arm, p_arm) sizes: 5 joints (4 hinges + finger) per WidowX-like arm
    "none": (0, 0),
    "regular": (10, 5),
    "double": (20, 10),
}


def _keys(seed=0, n=_BATCH):
    return jax.random.split(jax.random.PRNGKey(seed), n)


def _finite(tree) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(x)))) for x in jax.tree.leaves(tree))


def _row(tree, i):
    return jax.tree.map(lambda x: np.asarray(x)[i], tree)


@pytest.fixture(scope="module")
def regular():
    """The regular arm behind the training wrappers, jitted once; three steps taken."""
    env = dpc_mjx.make(_TASK, arm="regular", engine=ENGINE)
    counted = CountTraces(env)
    wrapped = wrap_for_training(counted, episode_length=100)
    reset = jax.jit(wrapped.reset, compiler_options=FAST_COMPILE)
    step = jax.jit(wrapped.step, compiler_options=FAST_COMPILE)
    action = jp.zeros((_BATCH, env.action_size))
    states = [reset(_keys())]
    for _ in range(3):
        states.append(step(states[-1], action))
    return env, counted, step, action, states  # on the device, as a training loop has them


@pytest.fixture(
    scope="module",
    # test-all: an env compile each (~35 s); every task x arm also steps in tests/test_matrix.py
    params=[pytest.param(arm, marks=pytest.mark.slow) for arm in ("none", "double")],
)
def plain(request):
    """Other variants, unwrapped: jit(vmap(reset)) and jit(vmap(step)), two steps."""
    env = dpc_mjx.make(_TASK, arm=request.param, engine=ENGINE)
    reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)
    step = jax.jit(jax.vmap(env.step), compiler_options=FAST_COMPILE)
    s = reset(_keys(1))
    states = [s]
    for _ in range(2):
        states.append(step(states[-1], jp.zeros((_BATCH, env.action_size))))
    return request.param, env, jax.device_get(states)


def _check_layout(arm, env, states):
    s_arm, p_arm = _OBS_SIZES[arm]
    lay = env.obs_layout
    assert env.observation_size == 11 + s_arm + p_arm + 6 == lay.size
    assert lay.encoder_size == 11 + s_arm + p_arm
    assert env.action_size == 6
    for s in states:
        assert s.obs.shape == (_BATCH, env.observation_size)
        parts = lay.split(s.obs)
        sizes = [parts[k].shape[-1] for k in ("s_body", "s_arm", "p_arm", "u_obs")]
        assert sizes == [11, s_arm, p_arm, 6]
        # u_obs: the controller's disturbance-observer estimate (world) in the yaw frame
        yaw = np.asarray(roll_pitch_yaw(s.pipeline_state.qpos[:, 3:7]))[:, 2]
        estimate = s.info["ctrl"].observer.estimate
        expected = np.asarray(wrench_to_yaw_frame(estimate, yaw))
        np.testing.assert_allclose(parts["u_obs"], expected, atol=_U_OBS_ATOL, rtol=0)
        assert s.info["privileged"].shape == (_BATCH, dpc_mjx.envs.PRIVILEGED_SIZE)
        assert _finite((s.obs, s.reward, s.done, s.metrics, s.info["privileged"]))
        assert _finite(s.pipeline_state.qpos) and _finite(s.pipeline_state.qvel)
    assert np.any(np.abs(states[-1].info["ctrl"].observer.estimate) > 1.0)  # N or N·m: not 0
    last = states[-1]
    assert np.all(last.done == 0), "a standing start should not fall or blow up in 60 ms"
    np.testing.assert_allclose(last.pipeline_state.time, 0.02 * (len(states) - 1), atol=1e-4)


def test_regular_resets_and_steps_finitely(regular):
    env, _, _, _, states = regular
    states = jax.device_get(states)
    _check_layout("regular", env, states)
    assert set(base.METRICS) <= set(states[-1].metrics)
    assert "episode_metrics" in states[-1].info  # brax's EpisodeWrapper ran


def test_other_variants_reset_and_step_finitely(plain):
    arm, env, states = plain
    _check_layout(arm, env, states)
    if arm == "none":  # no arm, no end-effector force
        assert np.all(states[-1].info["privileged"][:, 6:] == 0)


def test_step_is_traced_once(regular):
    _, counted, step, action, states = regular
    assert counted.traces == 1  # reset, then 3 steps of the jitted wrapped env


def test_reward_is_the_papers_formula(regular):
    """Eqs. 2-4 on the true state (the observation is as measured: sensor errors)."""
    env, _, _, _, states = regular
    s = jax.device_get(states[-1])
    d = s.pipeline_state
    sb = np.asarray(jax.vmap(observations.s_body)(d, s.info["dist"].command))  # (B, 11), true
    for i in range(_BATCH):
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, np.asarray(d.qpos[i, 3:7], float))
        yaw_rate = (rot.reshape(3, 3) @ np.asarray(d.qvel[i, 3:6], float))[2]  # world z, rad/s
        roll, pitch = sb[i, 0], sb[i, 1]
        command = sb[i, 8:11]
        np.testing.assert_allclose(command, s.info["dist"].command[i], atol=1e-6)
        err = np.array([sb[i, 5], sb[i, 6], yaw_rate]) - command  # yaw-frame v_x, v_y; yaw rate
        r_vel = np.exp(-8 * err**2).sum()  # eq. 2
        r_orn = np.exp(-8 * roll**2) + np.exp(-8 * pitch**2)  # eq. 3, desired roll = pitch = 0
        expected = 0.08 * r_vel + 0.05 * r_orn  # eq. 4
        assert float(s.reward[i]) == pytest.approx(expected, abs=_REWARD_TOL)
        assert float(s.metrics["r_total"][i]) == pytest.approx(expected, abs=_REWARD_TOL)


def test_nan_in_one_env_resets_only_that_env(regular):
    env, counted, step, action, states = regular
    s = states[-1]
    qvel = s.pipeline_state.qvel.at[0].set(jp.nan)
    bad = s.replace(pipeline_state=s.pipeline_state.replace(qvel=qvel))
    out, ref = jax.device_get(step(bad, action)), jax.device_get(step(s, action))
    assert counted.traces == 1  # same compiled step
    assert _finite(out)  # nothing non-finite survives, in any env
    assert out.done[0] == 1 and out.metrics["nan_resets"][0] == 1 and out.reward[0] == 0
    assert out.pipeline_state.time[0] == 0.0  # env 0 restarted (fresh reset)
    assert float(out.info["ctrl"].t[0]) == 0.0  # ... with a fresh controller state
    assert out.metrics["nan_resets"][1] == 0
    for a, b in zip(jax.tree.leaves(_row(out, 1)), jax.tree.leaves(_row(ref, 1)), strict=True):
        np.testing.assert_array_equal(a, b)  # env 1 exactly as without the NaN next to it


def test_fall_ends_the_episode_with_the_penalty(regular):
    env, counted, step, action, states = regular
    s = states[-1]
    base_pose = jp.array([0.0, 0.0, 0.6, np.cos(0.6), np.sin(0.6), 0.0, 0.0])
    qpos = s.pipeline_state.qpos.at[1, :7].set(base_pose)  # in the air, rolled 1.2 rad
    tilted = s.replace(pipeline_state=s.pipeline_state.replace(qpos=qpos))
    out = jax.device_get(step(tilted, action))
    assert counted.traces == 1
    assert out.done.tolist() == [0, 1]
    assert out.metrics["fall"].tolist() == [0, 1] and out.metrics["nan_resets"][1] == 0
    penalty = env.config.fall_penalty
    assert float(out.reward[1]) == pytest.approx(float(out.metrics["r_total"][1]) + penalty)
    assert out.info["episode_metrics"]["fall"][1] == 1


def test_disturbance_schedule_follows_its_config():
    """Sampling alone (no physics): targets within bounds, pushes piecewise constant."""
    model = dpc_mjx.robots.build("regular")
    cfg = registry.get_config(_TASK, push_force=(10.0, 10.0), payload_mass=(0.2, 0.2))
    sampler: DisturbanceSampler = make_sampler(cfg, model, layout(model))
    d = sampler.init(jax.random.PRNGKey(3))
    forces, targets = [], []
    for k, t in enumerate(np.arange(0.0, 6.0, 0.02)):
        d = sampler.advance(d, jp.float32(t), jax.random.PRNGKey(k))
        forces.append(np.asarray(sampler.pushes(d, jp.float32(t), jp.float32(0.7))[0]))
        targets.append(np.asarray(sampler.arm_targets(d, jp.float32(t))))
        assert np.all(sampler.reach_low - 1e-6 <= d.ref_goal)
        assert np.all(d.ref_goal <= sampler.reach_high + 1e-6)
    norms = np.linalg.norm(forces, axis=1)
    assert np.all((np.abs(norms - 10.0) < 1e-4) | (norms == 0))  # |F| = 10 N or off
    assert 0 < np.mean(norms > 0) < 1  # some pushes, some pauses in 6 s
    assert np.max(np.abs(np.diff(targets, axis=0))) < 0.2  # smooth: no jumps of the servo targets
    np.testing.assert_allclose(
        sampler.ee_forces(d, 0.0, 0.0)[0, 2] - sampler.pushes(d, 0.0, 0.0)[0, 2],
        -9.81 * 0.2,
        rtol=1e-5,
    )


def test_sagittal_pushes_turn_with_the_heading():
    """push_axis_weights (1, 0, 1): no lateral push in the yaw frame, whatever the heading."""
    model = dpc_mjx.robots.build("regular")
    cfg = registry.get_config(_TASK, push_force=(10.0, 10.0), push_axis_weights=(1.0, 0.0, 1.0))
    sampler = make_sampler(cfg, model, layout(model))
    d = sampler.init(jax.random.PRNGKey(5))
    t = (d.push_on[0] + d.push_off[0]) / 2  # inside the first push
    ahead = np.asarray(sampler.pushes(d, t, jp.float32(0.0))[0])  # heading +x
    left = np.asarray(sampler.pushes(d, t, jp.float32(np.pi / 2))[0])  # heading +y
    assert np.linalg.norm(ahead) == pytest.approx(10.0, rel=1e-5)
    assert abs(ahead[1]) < 1e-5 and abs(left[0]) < 1e-5  # nothing across the heading
    np.testing.assert_allclose(left, [0.0, ahead[0], ahead[2]], atol=1e-5)


def test_action_scale_per_axis():
    config = registry.get_config(_TASK, max_force=(10.0, 20.0, 30.0), max_torque=5.0)
    assert config.u_scale == (10.0, 20.0, 30.0, 5.0, 5.0, 5.0)


def test_config_parts_read_and_replace_by_the_same_flat_names():
    """`EnvConfig`'s parts (sensors, disturbances, motion) hold its fields under their flat
    names, which stay what `make`, `--env` and the export sidecar use."""
    config = registry.get_config(_TASK)
    parts = [f.name for part in env_config.PARTS.values() for f in dataclasses.fields(part)]
    flat = [f.name for f in dataclasses.fields(config)]
    assert len(parts) == len(set(parts)) and set(parts) <= set(flat)  # each field in one part
    assert config.sensors == env_config.SensorConfig(sensor_noise=1.0, sensor_delay=1)
    assert config.disturbances.push_force == config.push_force == (0.0, 60.0)  # reaching's
    assert config.motion.command_vx == config.command_vx
    exact = env_config.SensorConfig(0.0, 0)
    assert config.replace(sensors=exact) == config.replace(sensor_noise=0.0, sensor_delay=0)
    assert registry.get_config(_TASK, sensors={"sensor_delay": 2}).sensor_delay == 2
    assert list(dataclasses.asdict(config)) == flat  # the sidecar's env_config: flat, as before
    with pytest.raises(DpcError, match=r"\['sensor_delay'\] given both alone and in sensors"):
        config.replace(sensors={"sensor_delay": 2}, sensor_delay=3)
    with pytest.raises(DpcError, match="sensors takes a SensorConfig or a dict of some of"):
        config.replace(sensors={"push_force": (0.0, 1.0)})
    with pytest.raises(DpcError, match="sensor_noise must be a finite number"):
        config.replace(sensors={"sensor_noise": -1.0})  # validated as the flat field is


def test_tasks_answer_to_their_old_names():
    """`make("a1_arm/reaching")` is `make("reaching")`: the old robot prefix is an alias."""
    assert "reaching" in registry.known_tasks()
    for task in registry.known_tasks():
        old = f"a1_arm/{task}"
        assert registry.get_config(old) == registry.get_config(task)
        assert registry.default_arm(old) == registry.default_arm(task)
        assert registry.task_name(old) == registry.task_name(task) == task
    with pytest.raises(DpcError, match=r"known tasks: \[.*'reaching'"):
        registry.get_config("juggling")


def test_invalid_task_arm_and_options_fail_before_compiling(monkeypatch):
    def no_build(*_):
        pytest.fail("the model was built before the arguments were checked")

    monkeypatch.setattr(base, "build", no_build)
    with recorded_compiles() as compiles:
        with pytest.raises(DpcError, match=f"known tasks.*{DEFAULT_TASK}"):
            dpc_mjx.make("a1_arm/juggling")
        with pytest.raises(DpcError, match="known variants"):
            dpc_mjx.make(_TASK, arm="regularr")
        with pytest.raises(DpcError, match="controller 'pid'.*'mbc'"):
            dpc_mjx.make(_TASK, controller="pid")
        with pytest.raises(DpcError, match="low <= high"):
            dpc_mjx.make(_TASK, push_force=(40.0, 0.0))
        with pytest.raises(DpcError, match="known options"):
            dpc_mjx.make(_TASK, push_forces=(0.0, 40.0))
        with pytest.raises(DpcError, match="episode_length"):
            dpc_mjx.make(_TASK, episode_length=0)
        with pytest.raises(DpcError, match=r"max_force must be a number or an \(x, y, z\)"):
            dpc_mjx.make(_TASK, max_force=(10.0, 10.0))
        with pytest.raises(DpcError, match="max_torque must be > 0"):
            dpc_mjx.make(_TASK, max_torque=(1.0, -1.0, 1.0))
        with pytest.raises(DpcError, match=r"observer_gain must be a finite number in \[1.0"):
            dpc_mjx.make(_TASK, observer_gain=0.0)
        with pytest.raises(DpcError, match=r"observer_gain must be a number or a \(force, torque"):
            dpc_mjx.make(_TASK, observer_gain=(10.0, 20.0, 30.0))
        with pytest.raises(DpcError, match="observer_aligned must be True or False"):
            dpc_mjx.make(_TASK, observer_aligned="yes")
    assert compiles == []
    monkeypatch.undo()
    with pytest.raises(DpcError, match="multiple of the physics step"):
        dpc_mjx.make(_TASK, arm="none", policy_dt=0.005)


def test_the_observer_options_reach_the_controller():
    """`observer_gain` and `observer_aligned` set the controller's observer: its gains and the
    delay it aligns to (the env's sensor_delay, or none)."""
    env = dpc_mjx.make(_TASK, arm="none", sensor_delay=2, observer_aligned=True, observer_gain=30)
    ob = env.controller.config.observer
    assert (ob.delay, ob.k_force, ob.k_torque) == (2, 30, 30)
    ob = dpc_mjx.make(_TASK, arm="none", observer_gain=(10, 40)).controller.config.observer
    assert (ob.k_force, ob.k_torque) == (10, 40)
    assert dpc_mjx.make(_TASK, arm="none", sensor_delay=2).controller.config.observer.delay == 0


def test_yaw_frame_wrench_turns_with_the_heading():
    """The policy's u in the yaw frame ('yaw', the default u_frame) reaches the controller turned
    by the heading: a forward force at heading pi/2 is a world +y force, and back."""
    u = np.array([[10.0, 0.0, -5.0, 1.0, 2.0, 0.5]])  # N, N·m in the yaw frame
    world = np.asarray(wrench_to_world(u, np.array([np.pi / 2])))
    np.testing.assert_allclose(world, [[0.0, 10.0, -5.0, -2.0, 1.0, 0.5]], atol=1e-5)
    yaw = np.linspace(-3.0, 3.0, 7)
    many = np.random.default_rng(0).normal(size=(7, 6))
    back = wrench_to_yaw_frame(wrench_to_world(many, yaw), yaw)
    np.testing.assert_allclose(back, many, atol=1e-5)
    assert registry.get_config(_TASK).u_frame == "yaw"
    with pytest.raises(DpcError, match=r"u_frame='body' is not valid; choose one of \['yaw'"):
        registry.get_config(_TASK, u_frame="body")
