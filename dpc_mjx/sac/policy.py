"""A trained high-level estimator as data (`PolicyState`) and how it acts (`act`, `dpc_policy`).

The actor is brax's SAC policy MLP; deployed, it acts with the mode of its tanh-Gaussian:

    a = tanh(loc),  [loc, scale] = MLP((obs - mean) / std),  obs = [s_body, z]

`dpc_policy` chains the frozen encoder and the actor into the policy of a raw DPC env (whose
observation is `[s_body, s_arm, p_arm]`), the form `envs.rollout.run_episodes` takes.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from brax.training import networks as brax_networks
from flax import struct

from dpc_mjx.adapter.networks import AdapterConfig, EncoderState, Normalizer, encode
from dpc_mjx.envs.observations import S_BODY_SIZE


@struct.dataclass
class PolicyState:
    """The actor's parameters and its observation standardisation."""

    params: dict  # flax params of brax's policy MLP (hidden_0 .. hidden_k)
    obs_norm: Normalizer  # over [s_body, z] (11 + latent,)
    hidden: tuple[int, ...] = struct.field(pytree_node=False, default=(128, 128))
    action_size: int = struct.field(pytree_node=False, default=6)


def actor_module(policy: PolicyState) -> brax_networks.MLP:
    return brax_networks.MLP(layer_sizes=[*policy.hidden, 2 * policy.action_size])


def policy_template(
    observation_size: int, hidden: tuple[int, ...], action_size: int
) -> PolicyState:
    """Shapes of a `PolicyState` (to restore a saved one against)."""
    shell = PolicyState(params={}, obs_norm=None, hidden=hidden, action_size=action_size)
    obs = jax.ShapeDtypeStruct((observation_size,), jp.float32)
    params = jax.eval_shape(actor_module(shell).init, jax.random.PRNGKey(0), obs)
    return shell.replace(params=params, obs_norm=Normalizer.template(observation_size))


def act(policy: PolicyState, obs: jax.Array) -> jax.Array:
    """Deterministic action (..., action_size) in [-1, 1] from `[s_body, z]` (..., 11 + latent)."""
    logits = actor_module(policy).apply(policy.params, policy.obs_norm(obs))
    return jp.tanh(logits[..., : policy.action_size])


def dpc_policy(adapter_config: AdapterConfig, encoder: EncoderState, policy: PolicyState):
    """(obs (B, n_in) of a raw env, key) -> action (B, 6): encoder, then the actor's mode."""

    def fn(obs: jax.Array, key: jax.Array) -> jax.Array:
        del key
        z = encode(adapter_config, encoder, obs)
        return act(policy, jp.concatenate([obs[..., :S_BODY_SIZE], z], axis=-1))

    return fn
