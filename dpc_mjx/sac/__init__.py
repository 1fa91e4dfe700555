"""The high-level estimator (paper §III-C): SAC on `[s_body, z]` (or `[s_body, z, u_obs]`),
acting through u = [f_a, tau_a].

    env.py         `LatentObsWrapper`: a DPC env as the policy sees it (`POLICY_INPUTS`);
                   `PrivilegedCriticWrapper`: plus what the asymmetric critic sees
    networks.py    brax's SAC actor and twin critics at the paper's sizes
    config.py      `SacConfig`: the hyperparameters (brax's SAC's, and those of our loop)
    trainer.py     `make_trainer`: the jitted pieces, brax's SAC in our epoch, the evaluation
    state.py       `Carry`: what an epoch hands to the next (learning state, buffer, best policy)
    replay.py      `RingSamplingQueue`: brax's uniform replay queue, written in place as a ring
    train.py       `train`, `restore_policy`: our host loop (log, checkpoint, resume, best policy)
    log.py         the CSV log, one row per epoch
    checkpoint.py  the full training state on disk, for resuming

The trained policy as data (`PolicyState`, `dpc_policy`) and the oracle regression that starts it
are `dpc_mjx.policy` (`sac.policy` and `sac.warm_start` re-export them).

env = LatentObsWrapper(make("reaching", arm="regular"), adapter.config, adapter.encoder)
result = train(env, SacConfig(num_timesteps=500_000), run_dir="runs/dpc")
policy = dpc_policy(adapter.config, adapter.encoder, result.policy)   # raw obs -> action
"""

from dpc_mjx.policy.policy import POLICY_INPUTS, PolicyState, act, dpc_policy, inputs_named
from dpc_mjx.sac.config import SacConfig
from dpc_mjx.sac.env import LatentObsWrapper, PrivilegedCriticWrapper
from dpc_mjx.sac.networks import HIDDEN, make_networks
from dpc_mjx.sac.train import TrainResult, policy_state, restore_policy, train
from dpc_mjx.sac.trainer import make_trainer

__all__ = [
    "HIDDEN",
    "LatentObsWrapper",
    "PrivilegedCriticWrapper",
    "POLICY_INPUTS",
    "PolicyState",
    "SacConfig",
    "TrainResult",
    "act",
    "dpc_policy",
    "inputs_named",
    "make_networks",
    "make_trainer",
    "policy_state",
    "restore_policy",
    "train",
]
