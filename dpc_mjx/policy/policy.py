"""A trained high-level estimator as data (`PolicyState`), what it observes (`POLICY_INPUTS`,
`policy_observation`) and how it acts (`act`, `dpc_policy`).

The actor is brax's SAC policy MLP; deployed, it acts with the mode of its tanh-Gaussian:

    a = tanh(loc),  [loc, scale] = MLP((obs - mean) / std)

on one of two observations (`PolicyState.inputs`), both built from a raw env observation
`[s_body, s_arm, p_arm, u_obs]` and the arm's frozen encoder E:

    'paper'     [s_body, z],         z = E(s_body, s_arm, p_arm)   (paper §III-C)
    'observer'  [s_body, z, u_obs]   plus the disturbance observer's estimate (yaw frame): the
                                     policy learns a correction of the classical estimate

Everything arm-specific reaches the policy only through z, so a new arm needs only a new encoder
either way (u_obs is arm-agnostic). `dpc_policy` chains the encoder and the actor into the policy
of a raw env, the form `envs.rollout.run_episodes` takes.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from brax.training import networks as brax_networks
from flax import struct

from dpc_mjx.adapter.networks import AdapterConfig, EncoderState, Normalizer, encode
from dpc_mjx.envs.observations import S_BODY_SIZE, U_OBS_SIZE
from dpc_mjx.errors import DpcError

# The policy's observation blocks, in order, per named option (see the module docstring).
POLICY_INPUTS = {"paper": ("s_body", "z"), "observer": ("s_body", "z", "u_obs")}
PAPER_INPUTS = POLICY_INPUTS["paper"]


@struct.dataclass
class PolicyState:
    """The actor's parameters and its observation standardisation."""

    params: dict  # flax params of brax's policy MLP (hidden_0 .. hidden_k)
    obs_norm: Normalizer  # over its observation (`inputs`: 11 + latent [+ 6],)
    hidden: tuple[int, ...] = struct.field(pytree_node=False, default=(128, 128))
    action_size: int = struct.field(pytree_node=False, default=6)
    inputs: tuple[str, ...] = struct.field(pytree_node=False, default=PAPER_INPUTS)


def inputs_named(name: str) -> tuple[str, ...]:
    """The observation blocks of the named option (`POLICY_INPUTS`); `DpcError` if unknown."""
    if name not in POLICY_INPUTS:
        raise DpcError(f"policy_input={name!r} is not one of {sorted(POLICY_INPUTS)}.")
    return POLICY_INPUTS[name]


def observation_size(inputs: tuple[str, ...], latent_size: int) -> int:
    """Entries of the policy's observation made of `inputs`."""
    sizes = {"s_body": S_BODY_SIZE, "z": latent_size, "u_obs": U_OBS_SIZE}
    return sum(sizes[k] for k in inputs)


def policy_observation(
    adapter_config: AdapterConfig, encoder: EncoderState, obs: jax.Array, inputs: tuple[str, ...]
) -> jax.Array:
    """(..., observation_size) the blocks `inputs` from a raw env observation (..., n_in + 6)
    `[s_body, s_arm, p_arm, u_obs]`, n_in the encoder's input size."""
    n_in = int(encoder.input_norm.mean.shape[-1])
    blocks = {
        "s_body": obs[..., :S_BODY_SIZE],
        "z": encode(adapter_config, encoder, obs[..., :n_in]),
        "u_obs": obs[..., n_in : n_in + U_OBS_SIZE],
    }
    return jp.concatenate([blocks[k] for k in inputs], axis=-1)


def actor_module(policy: PolicyState) -> brax_networks.MLP:
    return brax_networks.MLP(layer_sizes=[*policy.hidden, 2 * policy.action_size])


def policy_template(
    observation_size: int,
    hidden: tuple[int, ...],
    action_size: int,
    inputs: tuple[str, ...] = PAPER_INPUTS,
) -> PolicyState:
    """Shapes of a `PolicyState` (to restore a saved one against)."""
    shell = PolicyState(
        params={}, obs_norm=None, hidden=hidden, action_size=action_size, inputs=inputs
    )
    obs = jax.ShapeDtypeStruct((observation_size,), jp.float32)
    params = jax.eval_shape(actor_module(shell).init, jax.random.PRNGKey(0), obs)
    return shell.replace(params=params, obs_norm=Normalizer.template(observation_size))


def act(policy: PolicyState, obs: jax.Array) -> jax.Array:
    """Deterministic action (..., action_size) in [-1, 1] from its observation (`inputs`)."""
    logits = actor_module(policy).apply(policy.params, policy.obs_norm(obs))
    return jp.tanh(logits[..., : policy.action_size])


@struct.dataclass
class DpcPolicy:
    """The DPC policy of one arm as data, called as `(obs (B, n_in + 6) of a raw env, key) ->
    action (B, 6)`: the arm's encoder, then the actor's mode. Its weights are leaves, so a
    compiled rollout takes them as arguments (`rollout.make_chunk`): one program serves every
    export of the same shapes."""

    adapter_config: AdapterConfig = struct.field(pytree_node=False)
    encoder: EncoderState
    policy: PolicyState

    def __call__(self, obs: jax.Array, key: jax.Array) -> jax.Array:
        del key
        latent_obs = policy_observation(self.adapter_config, self.encoder, obs, self.policy.inputs)
        return act(self.policy, latent_obs)

    def __hash__(self) -> int:
        # by identity, as a function is: `jax.jit(policy)` compiles it with its weights as
        # constants (the frozen dataclass's own hash would hash the weights' dicts and fail)
        return id(self)


def dpc_policy(
    adapter_config: AdapterConfig, encoder: EncoderState, policy: PolicyState
) -> DpcPolicy:
    """(obs (B, n_in + 6) of a raw env, key) -> action (B, 6): encoder, then the actor's mode."""
    return DpcPolicy(adapter_config, encoder, policy)
