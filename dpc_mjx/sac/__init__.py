"""The high-level estimator (paper §III-C): SAC on `[s_body, z]`, acting through u = [f_a, tau_a].

env = LatentObsWrapper(make("a1_arm/reaching", arm="regular"), adapter.config, adapter.encoder)
result = train(env, SacConfig(num_timesteps=500_000), run_dir="runs/dpc")
policy = dpc_policy(adapter.config, adapter.encoder, result.policy)   # raw obs -> action
"""

from dpc_mjx.sac.env import LatentObsWrapper
from dpc_mjx.sac.networks import HIDDEN, make_networks
from dpc_mjx.sac.policy import PolicyState, act, dpc_policy
from dpc_mjx.sac.train import (
    SacConfig,
    TrainResult,
    make_trainer,
    policy_state,
    restore_policy,
    train,
)

__all__ = [
    "HIDDEN",
    "LatentObsWrapper",
    "PolicyState",
    "SacConfig",
    "TrainResult",
    "act",
    "dpc_policy",
    "make_networks",
    "make_trainer",
    "policy_state",
    "restore_policy",
    "train",
]
