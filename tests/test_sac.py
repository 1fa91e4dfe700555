"""The high-level estimator: the latent-observation env, a few hundred SAC steps on the regular
arm (one compile, the env traced once), resume after a kill continues the counters."""

import dataclasses

import jax
import jax.numpy as jp
import numpy as np
import pytest
from brax.training.acme import running_statistics
from brax.training.agents.sac import networks as sac_networks
from flax import linen
from helpers import ENGINE, CountTraces, fast_jit

import dpc_mjx
from dpc_mjx import DpcError
from dpc_mjx.adapter import AdapterConfig, Dataset, EncoderState, Normalizer, encode
from dpc_mjx.adapter.networks import encoder_module
from dpc_mjx.envs import DEFAULT_TASK
from dpc_mjx.envs.observations import PRIVILEGED, PRIVILEGED_SIZE
from dpc_mjx.rotations import roll_pitch_yaw, wrench_to_world, wrench_to_yaw_frame
from dpc_mjx.sac import (
    HIDDEN,
    POLICY_INPUTS,
    LatentObsWrapper,
    PrivilegedCriticWrapper,
    SacConfig,
    act,
    make_networks,
    make_trainer,
    policy_state,
    train,
)
from dpc_mjx.sac.warm_start import regress_actor

_CONFIG = SacConfig(
    num_timesteps=768,  # 3 epochs of 32 actor steps x 8 envs
    num_envs=8,
    batch_size=32,
    grad_updates_per_step=2,
    min_replay_size=128,
    max_replay_size=2048,
    epoch_steps=256,
    eval_every=1,  # after every epoch (an epoch also runs after an evaluation)
    eval_envs=2,
)


_WARM_START_R2 = 0.9  # held-out R^2 of every u component after the warm start
_WARM_START_ATOL = 0.15  # action units (u / u_scale), a few held-out samples


class _Killed(Exception):
    pass


def reaching_latent_env(engine: str = ENGINE):
    """The reaching env (regular arm, 100-step episodes: short evaluations) and the same env seen
    through an untrained encoder, `[s_body, z]` (tests/test_devices.py runs it sharded, on MJX)."""
    env = dpc_mjx.make(DEFAULT_TASK, arm="regular", episode_length=100, engine=engine)
    config = AdapterConfig()
    n_in = env.obs_layout.encoder_size  # [s_body, s_arm, p_arm]
    params = encoder_module(config).init(jax.random.PRNGKey(0), jp.zeros((1, n_in)))
    encoder = EncoderState(params=params, input_norm=Normalizer(jp.zeros(n_in), jp.ones(n_in)))
    return env, LatentObsWrapper(env, config, encoder)


@pytest.fixture(scope="module")
def latent_env():
    return reaching_latent_env()


def test_latent_env_shows_the_policy_body_state_and_z(latent_env):
    env, wrapped = latent_env
    assert wrapped.observation_size == 11 + 2
    assert wrapped.action_size == 6
    obs = jp.linspace(-1.0, 1.0, env.observation_size)  # [s_body, s_arm, p_arm, u_obs]
    out = wrapped.latent_obs(obs)
    np.testing.assert_array_equal(out[:11], obs[:11])
    assert np.all(np.abs(np.asarray(out[11:])) < 1.0)
    # the 'observer' option appends u_obs, the raw observation's last 6 entries, after z
    with_observer = LatentObsWrapper(
        env, wrapped.adapter_config, wrapped.encoder, POLICY_INPUTS["observer"]
    )
    assert with_observer.observation_size == 11 + 2 + 6
    out_obs = with_observer.latent_obs(obs)
    np.testing.assert_array_equal(out_obs[:13], out)
    np.testing.assert_array_equal(out_obs[13:], obs[env.obs_layout.u_obs])
    np.testing.assert_array_equal(obs[env.obs_layout.u_obs], obs[-6:])
    wrong = EncoderState(params={}, input_norm=Normalizer(jp.zeros(3), jp.ones(3)))
    with pytest.raises(DpcError, match="encoder takes 3 inputs"):
        LatentObsWrapper(env, AdapterConfig(), wrong)


def test_sac_trains_resumes_after_a_kill_and_traces_the_env_once(latent_env, tmp_path, monkeypatch):
    """With the asymmetric critic (the paper recipe's; `critic_privileged`)."""
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: 3 epochs of 256 env steps
    _, wrapped = latent_env
    counted = CountTraces(wrapped)
    config = dataclasses.replace(_CONFIG, critic_privileged=True)
    trainer = make_trainer(counted, config)  # reused after the "kill": no second compile

    def kill_after_two(row):
        if row["epoch"] == 2:
            raise _Killed

    with pytest.raises(_Killed):
        train(trainer, run_dir=tmp_path, progress=False, on_epoch=kill_after_two)
    result = train(trainer, run_dir=tmp_path, resume=True, progress=False)
    # one compile of the epoch served every epoch, before and after the kill; one of the
    # deterministic evaluation
    assert counted.traces == 2
    rows = result.history
    assert [r["epoch"] for r in rows] == [0, 1, 2, 3]  # 0: the starting policy, evaluated
    assert [r["env_steps"] for r in rows] == [0, 256, 512, 768]
    rows = rows[1:]
    assert rows[0]["grad_steps"] > 0 and rows[2]["grad_steps"] > rows[1]["grad_steps"]
    assert all(np.isfinite(r["critic_loss"]) for r in rows)
    assert all(r["env_steps_per_s"] > 0 and r["grad_steps_per_s"] > 0 for r in rows)
    for r in rows:
        assert np.isfinite(r["eval_return"]) and 0.0 <= r["eval_fall_rate"] <= 1.0
        assert np.isfinite(r["eval_mbc_return"])  # the same episodes with u = 0
    log = (tmp_path / "sac_log.csv").read_text().splitlines()
    assert len(log) == 1 + 4  # header + epoch 0 + one row per epoch, across the kill
    obs = jp.zeros((4, wrapped.observation_size))  # the policy's: no privileged values
    assert result.policy.obs_norm.mean.shape == (wrapped.observation_size,)
    action = act(result.policy, obs)
    assert action.shape == (4, 6) and np.all(np.abs(np.asarray(action)) <= 1.0)


def test_the_asymmetric_critic_sees_privileged_values_and_the_actor_never_does(latent_env):
    env, wrapped = latent_env
    trainer = make_trainer(wrapped, dataclasses.replace(_CONFIG, critic_privileged=True))
    n_policy = wrapped.observation_size  # [s_body, z]
    assert trainer.observation_size == n_policy
    assert trainer.critic_observation_size == n_policy + PRIVILEGED_SIZE
    # the critics' view: the policy's observation, then u_oracle and the push in the yaw frame
    critic_env = PrivilegedCriticWrapper(wrapped)
    key = jax.random.PRNGKey(3)
    state, policy_view = jax.jit(lambda k: (critic_env.reset(k), wrapped.reset(k)))(key)
    np.testing.assert_array_equal(state.obs[:n_policy], policy_view.obs)
    yaw = roll_pitch_yaw(state.pipeline_state.qpos[3:7])[2]
    u_world = state.info["privileged"][PRIVILEGED["u_oracle"]]
    np.testing.assert_allclose(
        state.obs[n_policy : n_policy + 6], wrench_to_yaw_frame(u_world, yaw), rtol=1e-6
    )
    np.testing.assert_array_equal(state.obs[n_policy + 6], state.info["privileged"][6])
    # the actor reads the policy's part only; the critics read all of it
    carry = trainer.init(jax.random.PRNGKey(0))
    ts, nets = carry.training, trainer.networks
    stats = ts.normalizer.replace(
        mean=jp.linspace(-1.0, 1.0, trainer.critic_observation_size),
        std=jp.linspace(0.5, 2.0, trainer.critic_observation_size),
    )
    full = jax.random.normal(key, (5, trainer.critic_observation_size))
    other = full.at[:, n_policy:].add(3.0)  # other privileged values
    pi = nets.policy_network.apply
    np.testing.assert_array_equal(
        pi(stats, ts.policy_params, full), pi(stats, ts.policy_params, other)
    )
    q, a = nets.q_network.apply, jp.zeros((5, 6))
    assert not np.allclose(q(stats, ts.q_params, full, a), q(stats, ts.q_params, other, a))
    # the exported actor: the policy's observation and its part of the statistics, same actions
    policy = policy_state(trainer, ts.policy_params, stats)
    assert policy.obs_norm.mean.shape == (n_policy,) and policy.inputs == POLICY_INPUTS["paper"]
    loc = pi(stats, ts.policy_params, full)[:, :6]
    np.testing.assert_allclose(act(policy, full[:, :n_policy]), jp.tanh(loc), atol=1e-6)
    with pytest.raises(DpcError, match="asymmetric critic"):
        regress_actor(trainer, carry, wrapped.adapter_config, wrapped.encoder, None, None)


def test_networks_are_braxs_sac_networks_without_the_privileged_values():
    """`make_networks` builds brax's `make_sac_networks` (same parameters from the same key)."""
    ours, brax_nets = (
        make_networks(13, 6),
        sac_networks.make_sac_networks(
            13,
            6,
            preprocess_observations_fn=running_statistics.normalize,
            hidden_layer_sizes=HIDDEN,
            activation=linen.relu,
        ),
    )
    key = jax.random.PRNGKey(1)
    for mine, theirs in (
        (ours.policy_network, brax_nets.policy_network),
        (ours.q_network, brax_nets.q_network),
    ):
        for x, y in zip(jax.tree.leaves(mine.init(key)), jax.tree.leaves(theirs.init(key))):
            np.testing.assert_array_equal(x, y)


def test_resume_without_a_checkpoint_or_with_another_config_fails_clearly(latent_env, tmp_path):
    _, wrapped = latent_env
    with pytest.raises(DpcError, match="checkpoint"):
        train(wrapped, _CONFIG, tmp_path / "empty", resume=True, progress=False)
    with pytest.raises(DpcError, match="min_replay_size"):
        SacConfig(num_timesteps=100, min_replay_size=200).validate()


def test_actor_warm_start_regresses_the_oracle_u(latent_env):
    """Synthetic samples whose u_oracle, in the yaw frame, is a function of s_body (and the world
    frame's turns with a random heading): the regressed actor's mean reproduces the yaw-frame u
    on held-out samples (its R^2 None on a component that is always 0), and its exploration
    scale is the one asked for."""
    env, wrapped = latent_env
    trainer = make_trainer(wrapped, _CONFIG)
    carry = trainer.init(jax.random.PRNGKey(0))
    rng = np.random.default_rng(0)
    n, lay = 4096, env.obs_layout
    obs = rng.normal(size=(n, lay.encoder_size)).astype(np.float32)  # [s_body, s_arm, p_arm]
    u_scale = np.asarray(env.config.u_scale, np.float32)
    u = 0.5 * u_scale * np.tanh(obs[:, :6] - 0.5 * obs[:, 5:11])  # (n, 6) from s_body alone
    u[:, 1] = 0.0  # no f_y in the yaw frame (as no push acts sideways): nothing to explain
    yaw = rng.uniform(-np.pi, np.pi, n).astype(np.float32)
    u_world = np.asarray(wrench_to_world(u, yaw))
    data = Dataset(
        *(obs[:, lay.s_body], obs[:, lay.s_arm], obs[:, lay.p_arm], obs[:, :2]),
        u_oracle=u_world,
        u_obs=rng.normal(size=(n, 6)).astype(np.float32),  # not a policy input here
        yaw=yaw,
    )
    carry, report = regress_actor(
        trainer, carry, wrapped.adapter_config, wrapped.encoder, data, u_scale, epochs=60
    )
    assert report["samples"] == n and report["r2"][1] is None, report  # "constant"
    assert min(r for i, r in enumerate(report["r2"]) if i != 1) > _WARM_START_R2, report
    policy = policy_state(trainer, carry.training.policy_params, carry.training.normalizer)
    held_out = obs[-8:]  # the last 10% are the regression's validation samples
    z = encode(
        wrapped.adapter_config,
        wrapped.encoder,
        jp.asarray(held_out),
    )
    action = np.asarray(act(policy, jp.concatenate([jp.asarray(held_out[:, :11]), z], -1)))
    np.testing.assert_allclose(action, u[-8:] / u_scale, atol=_WARM_START_ATOL)
    with pytest.raises(DpcError, match="u_oracle"):
        regress_actor(
            trainer,
            carry,
            wrapped.adapter_config,
            wrapped.encoder,
            dataclasses.replace(data, u_oracle=None),
            u_scale,
        )


def test_no_sac_stage_returns_the_starting_actor_without_compiling_an_epoch(latent_env):
    """sac.num_timesteps=0 (the default recipe): `train` applies actor_init and returns that
    actor; nothing is trained, evaluated or compiled beyond the initial state."""
    _, wrapped = latent_env
    trainer = make_trainer(wrapped, dataclasses.replace(_CONFIG, num_timesteps=0))
    marked = {}

    def actor_init(trainer_, carry):
        params = jax.tree.map(lambda x: x + 1.0, carry.training.policy_params)
        marked["params"] = params
        return carry.replace(training=carry.training.replace(policy_params=params))

    result = train(trainer, progress=False, actor_init=actor_init)
    assert result.history == [] and result.selected_epoch == 0
    assert "epoch" not in trainer.compile_seconds and "evaluate" not in trainer.compile_seconds
    for a, b in zip(jax.tree.leaves(result.policy.params), jax.tree.leaves(marked["params"])):
        np.testing.assert_array_equal(a, b)
    assert trainer.config.epochs == 0
