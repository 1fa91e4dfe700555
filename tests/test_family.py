"""A family of arms for training (issue 28, item 3): the arms drawn, the run's options, the data
of several arms as one dataset. No compile: the collection's wiring is checked with a stand-in
for `adapter.collect` (the collection itself is tests/test_adapter.py's)."""

import numpy as np
import pytest

from dpc_mjx import DpcError
from dpc_mjx.adapter import Dataset
from dpc_mjx.robots.arms import ArmSpec, UrdfArm
from dpc_mjx.robots.arms.family import LINK_MASSES, ArmFamily
from dpc_mjx.robots.variants import VARIANTS
from dpc_mjx.run import training_arms
from dpc_mjx.run.config import RunConfig


def test_members_are_the_arm_with_lengths_and_masses_drawn_inside_the_ranges():
    family = ArmFamily(count=40)
    pusher = VARIANTS["pusher"].arms[0]
    members = family.members(pusher, seed=3)
    assert members == family.members(pusher, seed=3)  # the seed fixes them
    assert members != family.members(pusher, seed=4)
    assert len(members) == 40 and ArmFamily().members(pusher, seed=3) == ()
    for arm in members:
        assert (arm.ee_shape, arm.mount, arm.link_radius) == ("plate", pusher.mount, 0.018)
        assert 0.10 <= arm.upper_arm_length <= 0.30 and 0.10 <= arm.forearm_length <= 0.22
        assert 0.1 <= arm.gripper_mass <= 1.0
        scales = np.array([getattr(arm, m) / getattr(pusher, m) for m in LINK_MASSES])
        # one factor for every link (each mass rounded to 0.1 g)
        np.testing.assert_allclose(scales, scales[0], rtol=2e-3)
        assert 0.69 <= scales[0] <= 5.01
    masses = [arm.mass for arm in members]
    assert min(masses) < 1.5 and max(masses) > 3.5  # the draws spread over the range


def test_bad_family_options_are_refused_with_the_option_to_fix():
    with pytest.raises(DpcError, match="arm_family.gripper_mass"):
        ArmFamily(count=2, gripper_mass=(1.0, 0.1)).validate()
    with pytest.raises(DpcError, match="arm_family.count"):
        ArmFamily(count=-1).validate()
    with pytest.raises(DpcError, match="parametric ArmSpec"):
        ArmFamily(count=2).members(UrdfArm("z1"), seed=0)


def test_the_run_config_takes_a_family_and_refuses_what_it_cannot_train():
    config = RunConfig().replace(
        **{"arm_family.count": 3, "arm_family.upper_arm_length": [0.12, 0.2]}
    )
    assert config.arm_family == ArmFamily(count=3, upper_arm_length=(0.12, 0.2))
    assert RunConfig.from_json(config.to_json()) == config
    old = RunConfig().to_json()
    del old["arm_family"]  # a config.json written before families
    assert RunConfig.from_json(old) == RunConfig()
    with pytest.raises(DpcError, match="carries 2"):
        RunConfig().replace(arm="double", **{"arm_family.count": 2})
    with pytest.raises(DpcError, match="not a UrdfArm"):
        RunConfig().replace(arm="z1", **{"arm_family.count": 2})
    with pytest.raises(DpcError, match="sac.num_timesteps=0"):
        RunConfig().replace(**{"arm_family.count": 2, "sac.num_timesteps": 100_000})


def _part(n: int, n_envs: int, tag: float) -> Dataset:
    rows = np.arange(n, dtype=np.float32)[:, None]
    return Dataset(
        s_body=np.repeat(rows, 11, 1),
        s_arm=np.full((n, 10), tag, np.float32),
        p_arm=np.zeros((n, 5), np.float32),
        s_drp_next=np.zeros((n, 2), np.float32),
        env_id=np.arange(n, dtype=np.int32) % n_envs,
        env_steps=n,
    )


def test_interleaved_arms_keep_their_order_and_each_gives_its_latest_rows_to_validation():
    parts = [_part(60, 4, 0.0), _part(30, 2, 1.0), _part(30, 3, 2.0)]
    data = Dataset.interleave(parts)
    assert len(data) == 120 and data.env_steps == 120
    for tag, part in enumerate(parts):
        mine = data.s_arm[:, 0] == tag
        np.testing.assert_array_equal(data.s_body[mine], part.s_body)  # in order, all there
    np.testing.assert_array_equal(np.unique(data.env_id), np.arange(9))  # envs 0-3, 4-5, 6-8
    train, held_out = data.split(0.1)
    for tag, part in enumerate(parts):
        rows = held_out.s_body[held_out.s_arm[:, 0] == tag, 0]
        np.testing.assert_array_equal(rows, np.arange(len(part) - len(rows), len(part)))
        assert len(rows) == len(part) // 10


def test_the_collection_splits_the_budget_and_the_envs_over_the_family(monkeypatch):
    config = RunConfig().replace(**{"arm_family.count": 2, "samples": 1001, "data_envs": 64})
    calls = []  # ("make", arm) and ("collect", env, samples, n_envs, seed), in call order

    def make(task, arm, controller, **overrides):
        calls.append(("make", arm))
        return arm  # the env stands for its arm

    def collect(env, samples, n_envs, seed, progress, burn_in):
        assert burn_in == config.data_burn_in
        calls.append(("collect", env, samples, n_envs, seed))
        return _part(samples, n_envs, float(len(calls)))

    monkeypatch.setattr(training_arms, "make", make)
    monkeypatch.setattr(training_arms.adapter_lib, "collect", collect)
    data = training_arms.collect_training_data(config, progress=False)
    arms = ["regular", *config.arm_family.members(ArmSpec(), config.seed)]
    assert calls[:3] == [("make", arm) for arm in arms]  # every env built before collecting
    assert calls[3:] == [
        ("collect", arms[0], 335, 22, 0),
        ("collect", arms[1], 333, 22, 10_000),
        ("collect", arms[2], 333, 22, 20_000),
    ]
    counts = [int((data.s_arm[:, 0] == tag).sum()) for tag in (4.0, 5.0, 6.0)]
    assert counts == [335, 333, 333] and data.env_id.max() == 3 * 22 - 1
