"""The latent dynamic adapter: random-motion data, training (eq. 1), transfer to a new encoder
against a frozen decoder, and clear errors (regular arm, reaching task, MBC; small budgets)."""

import dataclasses

import jax
import numpy as np
import pytest
from helpers import ENGINE

import dpc_mjx
from dpc_mjx import DpcError, adapter
from dpc_mjx.adapter import AdapterConfig, Dataset
from dpc_mjx.envs import DEFAULT_TASK

_SAMPLES = 4096
_ENVS = 16
_CHUNK = 32  # env steps per compiled call
_EPOCHS = 25
_MIN_GAIN = 0.2  # nats per sample the adapter must beat the constant predictor by (held out)


@pytest.fixture(scope="module")
def env():
    return dpc_mjx.make(DEFAULT_TASK, arm="regular", controller="mbc", engine=ENGINE)


@pytest.fixture(scope="module")
def data(env):
    return adapter.collect(env, _SAMPLES, n_envs=_ENVS, chunk=_CHUNK, progress=False)


@pytest.fixture(scope="module")
def trained(data):
    config = AdapterConfig(epochs=_EPOCHS, patience=_EPOCHS, batch_size=128)
    return adapter.train(data, config, progress=False)


def test_collect_returns_exactly_the_samples_asked(env, data):
    lay = env.obs_layout
    assert len(data) == _SAMPLES
    assert data.env_steps >= _SAMPLES
    assert data.s_body.shape == (_SAMPLES, 11)
    assert data.s_arm.shape == (_SAMPLES, lay.s_arm.stop - lay.s_arm.start)
    assert data.p_arm.shape == (_SAMPLES, lay.p_arm.stop - lay.p_arm.start)
    assert data.s_drp_next.shape == (_SAMPLES, 2)
    assert data.u_oracle.shape == (_SAMPLES, 6) and data.env_id.shape == (_SAMPLES,)
    # the arm's weight (~9 N for regular) and the payload always push the trunk down
    assert np.median(data.u_oracle[:, 2]) < -5.0
    for field in ("s_body", "s_arm", "p_arm", "s_drp_next", "u_oracle"):
        assert np.isfinite(getattr(data, field)).all(), field
    # Rows are (time, env) in order; no episode ends in the first 0.6 s, so in the first chunk
    # the target of row i is the roll and pitch rate of the same env one step later.
    first = _ENVS * (_CHUNK - 1)
    np.testing.assert_array_equal(
        data.s_drp_next[:first], data.s_body[_ENVS : first + _ENVS, adapter.DRP]
    )


def test_staggered_starts_cut_each_first_episode_at_its_own_step_and_drop_the_burn_in(env):
    batched = dpc_mjx.envs.wrap_for_training(env)
    state = batched.reset(jax.random.split(jax.random.PRNGKey(0), 256))
    length, burn_in = env.config.episode_length, 300
    steps = np.asarray(adapter.data._staggered(state, length, burn_in, seed=0).info["steps"])
    left = length - steps  # steps until each env's first episode is cut (k_i ~ U{1 .. burn_in})
    assert left.min() >= 1 and left.max() <= burn_in
    assert len(np.unique(left)) > 100  # spread, not one phase for all envs
    # with burn_in steps in 2 chunks the first 2 chunks' rows are dropped
    got = adapter.collect(env, 64, n_envs=_ENVS, chunk=_CHUNK, progress=False, burn_in=40)
    assert len(got) == 64 and got.env_steps == 3 * _CHUNK * _ENVS


def test_adapter_loss_decreases_and_beats_a_constant_predictor(data, trained):
    h = trained.history
    assert h["train_nll"][-1] < h["train_nll"][0]
    assert min(h["val_nll"]) < h["constant_val_nll"] - _MIN_GAIN
    _, held_out = data.split(trained.config.val_fraction)
    model, constant = adapter.nll(trained.config, trained.encoder, trained.decoder, held_out)
    assert model == pytest.approx(min(h["val_nll"]), abs=1e-4)  # the best epoch was kept
    assert model < constant - _MIN_GAIN
    z = adapter.encode(trained.config, trained.encoder, held_out.encoder_input)
    assert z.shape == (len(held_out), 2) and np.all(np.abs(np.asarray(z)) <= 1.0)
    mean, std = adapter.decode(trained.config, trained.decoder, z, held_out.s_body)
    assert mean.shape == std.shape == (len(held_out), 2) and np.all(np.asarray(std) > 0)


def _another_arm(data: Dataset) -> Dataset:
    """The same motions seen through a structurally different arm: more joints (the s_arm and
    p_arm columns repeated with other signs), so the encoder's input size changes."""
    return dataclasses.replace(
        data,
        s_arm=np.concatenate([data.s_arm, -data.s_arm[:, :4]], axis=1),
        p_arm=np.concatenate([data.p_arm, -data.p_arm[:, :2]], axis=1),
    )


def test_transfer_trains_only_a_new_encoder(data, trained):
    before = jax.tree.map(np.array, trained.decoder)
    new = _another_arm(data)
    config = dataclasses.replace(trained.config, epochs=8, patience=8)
    encoder, history = adapter.transfer(new, trained.decoder, config, progress=False)
    after = jax.tree.map(np.array, trained.decoder)
    for a, b in zip(jax.tree.leaves(before), jax.tree.leaves(after), strict=True):
        assert a.tobytes() == b.tobytes()  # the decoder is bit-for-bit unchanged
    assert encoder.input_norm.mean.shape == (new.encoder_input.shape[1],)
    assert history["train_nll"][-1] < history["train_nll"][0]
    assert min(history["val_nll"]) < history["constant_val_nll"] - _MIN_GAIN


def test_adapter_errors_are_clear(data, trained):
    with pytest.raises(DpcError, match="latent_size"):
        adapter.transfer(data, trained.decoder, AdapterConfig(latent_size=3), progress=False)
    with pytest.raises(DpcError, match="val_fraction"):
        AdapterConfig(val_fraction=1.5).validate()
    with pytest.raises(DpcError, match="samples"):
        adapter.collect(object(), 0)
    with pytest.raises(DpcError, match="Dataset or a DPC env"):
        adapter.train("data.npz")
    with pytest.raises(DpcError, match="rows"):
        Dataset(data.s_body, data.s_arm[:10], data.p_arm, data.s_drp_next)


@pytest.mark.slow  # a 'policy' env's compile (~1 min on 2 cores); `make test-all`
def test_dagger_data_are_the_students_states_labelled_by_the_oracle(data):
    """`collect` with a policy on a 'policy' env (DAgger): the episodes start as MBC's, then the
    student's u (here a constant 30 N down) moves the robot to other states, and each row keeps
    the oracle's u measured in the state the student visited."""
    env = dpc_mjx.make(DEFAULT_TASK, arm="regular", controller="dpc", engine=ENGINE)
    n = _ENVS * 8

    def student(obs, key):
        del key
        return jax.numpy.zeros(obs.shape[:-1] + (6,)).at[..., 2].set(-0.5)  # f_z = -30 N

    own = adapter.collect(env, n, n_envs=_ENVS, chunk=8, progress=False, policy=student)
    np.testing.assert_array_equal(own.s_body[:_ENVS], data.s_body[:_ENVS])  # same starts
    assert not np.allclose(own.s_body[-_ENVS:], data.s_body[n - _ENVS : n])  # other states
    assert own.u_oracle.shape == (n, 6) and np.isfinite(own.u_oracle).all()
    assert own.u_obs.shape == (n, 6) and own.yaw.shape == (n,)
    np.testing.assert_array_equal(own.u_oracle[:_ENVS], data.u_oracle[:_ENVS])
    both = Dataset.concatenate([data, own])
    assert len(both) == len(data) + n and both.env_steps == data.env_steps + own.env_steps
    np.testing.assert_array_equal(both.u_oracle[len(data) :], own.u_oracle)
