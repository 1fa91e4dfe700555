"""What one SAC epoch hands to the next (`Carry`): the learning state, the replay buffer, the key,
the counters and the best policy seen so far.

Each is a `flax.struct.dataclass` pytree: it crosses `jax.jit` (`sac.trainer`'s epoch), and a
checkpoint (`sac.checkpoint`) holds all of it.
"""

from __future__ import annotations

import jax
import optax
from brax.training import replay_buffers
from brax.training.acme import running_statistics
from flax import struct


@struct.dataclass
class TrainingState:
    """Everything that learns, and the counters."""

    policy_params: dict
    policy_opt: optax.OptState
    q_params: dict
    q_opt: optax.OptState
    target_q_params: dict
    log_alpha: jax.Array  # () log of the entropy temperature
    alpha_opt: optax.OptState
    normalizer: running_statistics.RunningStatisticsState  # over the observation
    env_steps: jax.Array  # () env steps so far
    grad_steps: jax.Array  # () gradient steps so far


@struct.dataclass
class BestPolicy:
    """The best policy the periodic evaluations have seen."""

    policy_params: dict
    normalizer: running_statistics.RunningStatisticsState
    score: jax.Array  # () mean evaluation return (NO_SCORE before the first evaluation)
    epoch: jax.Array  # () epochs trained before it was evaluated (-1: none yet; 0: the start)


NO_SCORE = -1e9  # finite on purpose: every array of a checkpoint stays finite


@struct.dataclass
class Carry:
    """What one epoch hands to the next; a checkpoint holds all of it but `env_state`."""

    training: TrainingState
    buffer: replay_buffers.ReplayBufferState
    key: jax.Array
    epoch: jax.Array  # () epochs done
    best: BestPolicy


__all__ = ["NO_SCORE", "BestPolicy", "Carry", "TrainingState"]
