"""The high-level estimator's view of a DPC env (paper §III-C): the policy's observation.

`LatentObsWrapper` wraps one unbatched `DpcEnv` (batch it afterwards with `wrap_for_training`):
it replaces the env's observation `[s_body, s_arm, p_arm, u_obs]` by the policy's (`inputs`, see
`dpc_mjx.policy`): `[s_body (11), z (latent_size)]` (the paper's) or `[s_body, z, u_obs (6)]`, z
computed inside `reset`/`step` by a frozen encoder (`adapter.encode`), so the policy never sees
the arm's joints: the same policy serves any arm that has an encoder.

`PrivilegedCriticWrapper` (around a `LatentObsWrapper` or a wrapper of one, for SAC's asymmetric
critic, `SacConfig.critic_privileged`) appends what only a simulator knows: `[policy obs,
u_oracle (6), payload (1), ee push force (3)]`, u_oracle and the push force in the yaw frame (the
policy's u frame; `observations.PRIVILEGED`). The trainer's critics read all of it, its actor
only the policy's part (`sac.networks`); an exported policy never sees it.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from brax.envs.base import State, Wrapper

from dpc_mjx.adapter.networks import AdapterConfig, EncoderState
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.observations import PRIVILEGED, PRIVILEGED_SIZE
from dpc_mjx.errors import DpcError
from dpc_mjx.policy.policy import PAPER_INPUTS, observation_size, policy_observation
from dpc_mjx.rotations import roll_pitch_yaw, rot_z, wrench_to_yaw_frame


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


class PrivilegedCriticWrapper(Wrapper):
    """obs `[policy obs]` -> `[policy obs, privileged (10,), yaw frame]` (module docstring)."""

    def __init__(self, env: Wrapper):
        super().__init__(env)
        if not isinstance(env.unwrapped, DpcEnv) or env is env.unwrapped:
            raise DpcError(
                "PrivilegedCriticWrapper wraps the policy's view of a DpcEnv (a LatentObsWrapper)."
            )
        self.policy_inputs = getattr(env, "policy_inputs", PAPER_INPUTS)
        self.policy_observation_size = env.observation_size

    @property
    def observation_size(self) -> int:
        return self.policy_observation_size + PRIVILEGED_SIZE

    def with_privileged(self, state: State) -> State:
        priv = state.info["privileged"]  # (10,) world frame
        yaw = roll_pitch_yaw(state.pipeline_state.qpos[3:7])[2]  # () rad, the trunk's heading
        u = wrench_to_yaw_frame(priv[PRIVILEGED["u_oracle"]], yaw)
        push = rot_z(yaw).T @ priv[PRIVILEGED["ee_force"]]  # (3,) N, world -> yaw frame
        extra = jp.concatenate([u, priv[PRIVILEGED["payload"]], push])
        return state.replace(obs=jp.concatenate([state.obs, extra]))

    def reset(self, rng: jax.Array) -> State:
        return self.with_privileged(self.env.reset(rng))

    def step(self, state: State, action: jax.Array) -> State:
        # The inner wrapper rebuilds its observation from pipeline_state, never reads state.obs.
        return self.with_privileged(self.env.step(state, action))
