"""The high-level estimator's networks: brax SAC actor and twin critics, 2 x 128 ReLU (paper §IV).

The actor maps the standardised observation `[s_body, z]` to the mean and (pre-softplus) scale of
a tanh-squashed Gaussian over the action a in [-1, 1]^6 (brax's `NormalTanhDistribution`); the
env scales a to u = [f_a, tau_a]. A deployed policy acts with the mode, tanh(mean).
"""

from __future__ import annotations

from collections.abc import Sequence

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
) -> sac_networks.SACNetworks:
    """brax `SACNetworks` with ReLU MLPs of `hidden` units; observations standardised with brax's
    running statistics when `normalize_observations` (their mean and std are then part of the
    policy's parameters)."""
    preprocess = (
        running_statistics.normalize
        if normalize_observations
        else identity_observation_preprocessor
    )
    return sac_networks.make_sac_networks(
        observation_size=observation_size,
        action_size=action_size,
        preprocess_observations_fn=preprocess,
        hidden_layer_sizes=tuple(hidden),
        activation=linen.relu,
    )
