"""The high-level estimator's networks: brax SAC actor and twin critics, 2 x 128 ReLU (paper §IV).

The actor maps the standardised observation `[s_body, z]` to the mean and (pre-softplus) scale of
a tanh-squashed Gaussian over the action a in [-1, 1]^6 (brax's `NormalTanhDistribution`); the
env scales a to u = [f_a, tau_a]. A deployed policy acts with the mode, tanh(mean).

Asymmetric actor-critic (`critic_extra` > 0): the observation the trainer stores is
`[policy obs (observation_size), privileged (critic_extra)]`; the critics read all of it, the
actor only its first `observation_size` entries (the slice is taken after the standardisation,
which is elementwise, so the actor's part of the statistics is its own).
"""

from __future__ import annotations

from collections.abc import Sequence

from brax.training import distribution
from brax.training import networks as brax_networks
from brax.training.acme import running_statistics
from brax.training.agents.sac import networks as sac_networks
from brax.training.types import identity_observation_preprocessor
from flax import linen

HIDDEN = (128, 128)  # the paper's actor and critic sizes


def make_networks(
    observation_size: int,
    action_size: int,
    hidden: Sequence[int] = HIDDEN,
    normalize_observations: bool = True,
    critic_extra: int = 0,
) -> sac_networks.SACNetworks:
    """brax `SACNetworks` with ReLU MLPs of `hidden` units; observations standardised with brax's
    running statistics when `normalize_observations` (their mean and std are then part of the
    policy's parameters). With `critic_extra`, the critics also see that many privileged values
    appended to the actor's `observation_size` (see the module docstring)."""
    preprocess = (
        running_statistics.normalize
        if normalize_observations
        else identity_observation_preprocessor
    )

    def actor_view(obs, stats):  # (..., observation_size + critic_extra) -> the actor's part
        return preprocess(obs, stats)[..., :observation_size]

    action_distribution = distribution.NormalTanhDistribution(event_size=action_size)
    return sac_networks.SACNetworks(
        policy_network=brax_networks.make_policy_network(
            action_distribution.param_size,
            observation_size,
            preprocess_observations_fn=actor_view if critic_extra else preprocess,
            hidden_layer_sizes=tuple(hidden),
            activation=linen.relu,
        ),
        q_network=brax_networks.make_q_network(
            observation_size + critic_extra,
            action_size,
            preprocess_observations_fn=preprocess,
            hidden_layer_sizes=tuple(hidden),
            activation=linen.relu,
        ),
        parametric_action_distribution=action_distribution,
    )
