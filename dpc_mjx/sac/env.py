"""The high-level estimator's view of a DPC env: observation `[s_body, z]` (paper §III-C).

`LatentObsWrapper` wraps one unbatched `DpcEnv` (batch it afterwards with `wrap_for_training`):
it replaces the env's observation `[s_body, s_arm, p_arm]` by `[s_body (11), z (latent_size)]`,
z computed inside `reset`/`step` by a frozen encoder (`adapter.encode`), so the policy never sees
the arm's joints: the same policy serves any arm that has an encoder.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from brax.envs.base import State, Wrapper

from dpc_mjx.adapter.networks import AdapterConfig, EncoderState, encode
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.observations import S_BODY_SIZE
from dpc_mjx.errors import DpcError


class LatentObsWrapper(Wrapper):
    """obs `[s_body, s_arm, p_arm]` -> `[s_body, z]`; everything else unchanged."""

    def __init__(self, env: DpcEnv, adapter_config: AdapterConfig, encoder: EncoderState):
        super().__init__(env)
        if not isinstance(env.unwrapped, DpcEnv) or env is not env.unwrapped:
            raise DpcError("LatentObsWrapper wraps an unbatched DpcEnv (from dpc_mjx.make).")
        n_in = int(encoder.input_norm.mean.shape[-1])
        if n_in != env.observation_size:
            raise DpcError(
                f"The encoder takes {n_in} inputs but this env's observation has "
                f"{env.observation_size} ([s_body, s_arm, p_arm] of its arm): use the encoder "
                "trained (or transferred) for this arm."
            )
        self.adapter_config = adapter_config
        self.encoder = encoder

    @property
    def observation_size(self) -> int:
        return S_BODY_SIZE + self.adapter_config.latent_size

    def latent_obs(self, obs: jax.Array) -> jax.Array:
        """(..., 11 + latent) `[s_body, z]` from a raw observation (..., n_in)."""
        z = encode(self.adapter_config, self.encoder, obs)
        return jp.concatenate([obs[..., :S_BODY_SIZE], z], axis=-1)

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        return state.replace(obs=self.latent_obs(state.obs))

    def step(self, state: State, action: jax.Array) -> State:
        # The inner env reads only pipeline_state and info, never the observation it returned.
        state = self.env.step(state, action)
        return state.replace(obs=self.latent_obs(state.obs))
