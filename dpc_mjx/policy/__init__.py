"""The deployable high-level estimator, apart from how it is trained (`dpc_mjx.sac` is SAC only):

    policy.py      `PolicyState`, `POLICY_INPUTS`, `act`, `dpc_policy`: a trained policy as data,
                   what it observes and how it acts (io, deploy and eval use it)
    regression.py  beyond the paper: the actor regressed on the oracle's u (`regress_actor`), the
                   default recipe's policy and SAC's warm start

policy = dpc_policy(adapter.config, adapter.encoder, state)   # raw obs -> action
"""

from dpc_mjx.policy.policy import (
    PAPER_INPUTS,
    POLICY_INPUTS,
    PolicyState,
    act,
    dpc_policy,
    inputs_named,
    observation_size,
    policy_observation,
    policy_template,
)
from dpc_mjx.policy.regression import U_CLIP, regress_actor

__all__ = [
    "PAPER_INPUTS",
    "POLICY_INPUTS",
    "U_CLIP",
    "PolicyState",
    "act",
    "dpc_policy",
    "inputs_named",
    "observation_size",
    "policy_observation",
    "policy_template",
    "regress_actor",
]
