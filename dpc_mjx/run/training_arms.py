"""The arms a run's adapter and oracle regression learn from: the run's arm and, with
`RunConfig.arm_family`, the family of arms drawn around it (`robots.arms.family`).

With a family of K - 1 arms, `collect_training_data` collects `samples / K` MBC samples on each
of the K arms from `ceil(data_envs / K)` envs, so that the data budget and each env's trajectory
length are the single-arm run's, and interleaves them (`Dataset.interleave`: the adapter's held-out
rows are the latest of every arm). Every arm shares the run's arm's structure, so one encoder
reads them all; the decoder and the policy see the whole family. Arm k collects from seed
`config.seed + FAMILY_SEED_STRIDE * k` (k = 0, the run's arm: the run's seed, the data of a run
without a family).
"""

from __future__ import annotations

import math

from dpc_mjx import adapter as adapter_lib
from dpc_mjx.controllers import Controller
from dpc_mjx.envs.registry import make
from dpc_mjx.robots.arms.family import describe
from dpc_mjx.robots.variants import Arm, resolve
from dpc_mjx.run.config import RunConfig

FAMILY_SEED_STRIDE = 10_000  # apart from DAgger's seed + k and the evaluation's seed + 1000


def training_arms(config: RunConfig) -> list[tuple[str, str | Arm]]:
    """(label, arm): the run's arm first (its name), then the family's members ('family-1:
    upper arm ... kg', `family.describe`)."""
    arms: list[tuple[str, str | Arm]] = [(config.arm, config.arm)]
    if config.arm_family.count:
        (base,) = resolve(config.arm).arms  # one parametric arm (`RunConfig.validate`)
        members = config.arm_family.members(base, config.seed)
        arms += [(f"family-{k}: {describe(arm)}", arm) for k, arm in enumerate(members, 1)]
    return arms


def collect_training_data(config: RunConfig, progress: bool = True) -> adapter_lib.Dataset:
    """The adapter's random-motion samples under MBC on every training arm (module docstring)."""
    arms = training_arms(config)
    n_envs = math.ceil(config.data_envs / len(arms))
    shares = [config.samples // len(arms)] * len(arms)
    shares[0] += config.samples - sum(shares)
    # every env built first: an arm the base cannot hold up is refused before any collection
    envs = [
        make(config.task, arm=a, controller=Controller.MBC, **config.env_overrides) for _, a in arms
    ]
    parts = []
    for k, ((label, _), env, samples) in enumerate(zip(arms, envs, shares, strict=True)):
        print(f"adapter: collecting {samples:,} samples ({label}, MBC)", flush=True)
        seed = config.seed + FAMILY_SEED_STRIDE * k
        burn_in = config.data_burn_in  # staggered starts (`adapter.collect`)
        kw = {"n_envs": n_envs, "seed": seed, "progress": progress, "burn_in": burn_in}
        parts.append(adapter_lib.collect(env, samples, **kw))
    return parts[0] if len(parts) == 1 else adapter_lib.Dataset.interleave(parts)
