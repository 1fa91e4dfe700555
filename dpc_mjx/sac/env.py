"""The high-level estimator's view of a DPC env (paper §III-C): the policy's observation.

`LatentObsWrapper` wraps one unbatched `DpcEnv` (batch it afterwards with `wrap_for_training`):
it replaces the env's observation `[s_body, s_arm, p_arm, u_obs]` by the policy's (`inputs`, see
`sac.policy`): `[s_body (11), z (latent_size)]` (the paper's) or `[s_body, z, u_obs (6)]`, z
computed inside `reset`/`step` by a frozen encoder (`adapter.encode`), so the policy never sees
the arm's joints: the same policy serves any arm that has an encoder.
"""

from __future__ import annotations

import jax
from brax.envs.base import State, Wrapper

from dpc_mjx.adapter.networks import AdapterConfig, EncoderState
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.errors import DpcError
from dpc_mjx.sac.policy import PAPER_INPUTS, observation_size, policy_observation


class LatentObsWrapper(Wrapper):
    """obs `[s_body, s_arm, p_arm, u_obs]` -> the blocks `inputs`; everything else unchanged."""

    def __init__(
        self,
        env: DpcEnv,
        adapter_config: AdapterConfig,
        encoder: EncoderState,
        inputs: tuple[str, ...] = PAPER_INPUTS,
    ):
        super().__init__(env)
        if not isinstance(env.unwrapped, DpcEnv) or env is not env.unwrapped:
            raise DpcError("LatentObsWrapper wraps an unbatched DpcEnv (from dpc_mjx.make).")
        n_in = int(encoder.input_norm.mean.shape[-1])
        if n_in != env.obs_layout.encoder_size:
            raise DpcError(
                f"The encoder takes {n_in} inputs but this env's arm observation has "
                f"{env.obs_layout.encoder_size} ([s_body, s_arm, p_arm] of its arm): use the "
                "encoder trained (or transferred) for this arm."
            )
        self.adapter_config = adapter_config
        self.encoder = encoder
        self.policy_inputs = tuple(inputs)

    @property
    def observation_size(self) -> int:
        return observation_size(self.policy_inputs, self.adapter_config.latent_size)

    def latent_obs(self, obs: jax.Array) -> jax.Array:
        """(..., observation_size) the policy's observation from a raw one (..., n_in + 6)."""
        return policy_observation(self.adapter_config, self.encoder, obs, self.policy_inputs)

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        return state.replace(obs=self.latent_obs(state.obs))

    def step(self, state: State, action: jax.Array) -> State:
        # The inner env reads only pipeline_state and info, never the observation it returned.
        state = self.env.step(state, action)
        return state.replace(obs=self.latent_obs(state.obs))
