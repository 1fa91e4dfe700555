"""The run configuration, the command line's argument handling and its errors (no compiling)."""

import dataclasses
import json

import pytest

from dpc_mjx import DpcError, io
from dpc_mjx.envs import DEFAULT_TASK
from dpc_mjx.envs.registry import get_config, task_name
from dpc_mjx.io.serialization import jsonable
from dpc_mjx.run import cli, pipeline
from dpc_mjx.run import eval as run_eval
from dpc_mjx.run.config import RunConfig, read_run_config, recipe, start_run, tuples
from dpc_mjx.run.pipeline import SHIPPED, SHIPPED_PAPER
from dpc_mjx.sac import SacConfig

TRANSFERRED = ("longer", "heavier", "double", "so100", "z1", "pusher")  # docs/results-transfer.md


def test_run_config_takes_dotted_overrides_and_round_trips_through_json(tmp_path):
    config = RunConfig().replace(
        **{"arm": "longer", "sac.num_envs": 32, "adapter.epochs": 5, "env.push_force": (0, 40)}
    )
    assert config.arm == "longer" and config.sac.num_envs == 32 and config.adapter.epochs == 5
    assert config.env_overrides == {"push_force": (0, 40)}
    start_run(config, tmp_path, resume=False)
    assert read_run_config(tmp_path) == config
    with pytest.raises(DpcError, match="already holds a run"):
        start_run(config, tmp_path, resume=False)
    with pytest.raises(DpcError, match="another configuration"):
        start_run(config.replace(samples=10), tmp_path, resume=True)


def test_run_config_rejects_unknown_or_invalid_options():
    with pytest.raises(DpcError, match="Unknown run option 'sacc.num_envs'"):
        RunConfig().replace(**{"sacc.num_envs": 3})
    with pytest.raises(DpcError, match="Unknown option"):
        RunConfig().replace(**{"sac.num_env": 3})
    with pytest.raises(DpcError, match="known options"):
        RunConfig().replace(**{"env.push_forces": (0, 1)})
    with pytest.raises(DpcError, match="actor_init"):
        RunConfig().replace(actor_init="pretrained")
    with pytest.raises(DpcError, match="samples"):
        RunConfig().replace(samples=0)
    with pytest.raises(DpcError, match="policy_input='latent' is not one of"):
        RunConfig().replace(policy_input="latent")
    with pytest.raises(DpcError, match="trains nothing: set sac.num_timesteps"):
        RunConfig().replace(actor_init="random")  # the default has no SAC stage
    assert RunConfig().replace(actor_init="random", **{"sac.num_timesteps": 100_000})
    with pytest.raises(DpcError, match="critic_privileged .* needs actor_init='random'"):
        RunConfig().replace(**{"sac.critic_privileged": True, "sac.num_timesteps": 100_000})
    with pytest.raises(DpcError, match="must be true or false"):
        RunConfig().replace(**{"sac.critic_privileged": "yes"})
    with pytest.raises(DpcError, match="Unknown recipe 'papers'"):
        recipe("papers")


def test_the_paper_recipe_is_sac_from_a_random_actor_with_an_asymmetric_critic(tmp_path):
    paper = recipe("paper")
    assert paper.actor_init == "random" and paper.sac.critic_privileged
    assert paper.sac.num_timesteps == 1_000_000 and paper.dagger_rounds == 0
    assert recipe("default") == RunConfig().replace(**{"env.u_base": "model"})  # the shipped form
    args = cli._parser().parse_args(
        ["train", "--run", str(tmp_path), "--recipe", "paper", "--set", "sac.num_envs=32"]
    )
    assert cli._run_config(args) == paper.replace(**{"sac.num_envs": 32})
    twice = ["train", "--run", str(tmp_path), "--set", "env.engine=native", "--set", "seed=3"]
    config = cli._run_config(cli._parser().parse_args(twice))  # each --set adds, none replaces
    assert config.env_overrides["engine"] == "native" and config.seed == 3
    twice = ["eval", "--env", "engine=native", "--env", "observer_gain=20"]
    assert cli._parser().parse_args(twice).env == ["engine=native", "observer_gain=20"]


def test_the_gpu_preset_keeps_the_learning_rule_per_env_step(tmp_path):
    """More envs everywhere on a GPU: SAC's with the same update-to-data ratio and actor steps
    per epoch, the adapter's data with staggered starts, 1,024 evaluation episodes in whole-
    episode chunks; --device picks a preset (auto: the backend's), --set still wins over it."""
    cpu, gpu = recipe("paper", "cpu"), recipe("paper", "gpu")
    assert gpu.sac.num_envs == 16 * cpu.sac.num_envs
    ratio = lambda c: c.sac.grad_updates_per_step / c.sac.num_envs  # noqa: E731
    assert ratio(gpu) == ratio(cpu) == 1 / 4
    assert gpu.sac.actor_steps_per_epoch == cpu.sac.actor_steps_per_epoch
    assert (cpu.data_envs, cpu.data_burn_in, cpu.eval_episodes) == (64, 0, 64)
    assert gpu.data_envs == 2048 and gpu.data_burn_in == gpu.episode_steps
    assert gpu.eval_episodes >= 1024 and gpu.eval_chunk == gpu.episode_steps
    assert recipe("paper", "tpu") == gpu and recipe("paper") == cpu
    assert recipe("paper", "auto") == cpu  # the tests run on a CPU
    args = ["train", "--run", str(tmp_path), "--device", "gpu", "--set", "sac.num_envs=512"]
    config = cli._run_config(cli._parser().parse_args(args))
    assert config.sac.num_envs == 512 and config.sac.grad_updates_per_step == 256
    with pytest.raises(DpcError, match="Unknown device preset 'npu'"):
        recipe("default", "npu")


def test_cli_reports_bad_input_with_the_library_error(tmp_path, capsys):
    assert cli.main(["train", "--run", str(tmp_path / "r"), "--set", "sac.num_envs"]) == 2
    assert "Options take name=value" in capsys.readouterr().err
    assert cli.main(["eval", "--export", str(tmp_path / "missing")]) == 2
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "config.json").write_text(json.dumps({"arm": "regular"}))
    assert cli.main(["export", "--run", str(tmp_path / "x")]) == 2
    assert "Not a RunConfig" in capsys.readouterr().err
    assert cli.main(["transfer", "--export", str(tmp_path / "missing"), "--arm", "so100"]) == 2


def test_shipped_artefacts_load_and_are_the_default_recipe():
    """`dpc-mjx eval` works without training, and `dpc-mjx train` with no options reproduces the
    recipe the shipped policy was trained with."""
    art = io.load(SHIPPED)
    # its own arm first, then the encoders transferred to it (`dpc-mjx transfer --samples 10000`)
    assert list(art.meta["encoders"])[0] == "regular"
    assert sorted(list(art.meta["encoders"])[1:]) == sorted(TRANSFERRED)
    assert all(art.arm_spec(arm) == arm for arm in art.encoders)
    # its sidecar names the task ("reaching"; older ones "a1_arm/reaching": `LEGACY_PREFIX`)
    defaults = recipe("default")
    assert task_name(art.meta["extra"]["task"]) == DEFAULT_TASK == defaults.task
    # read with today's SacConfig (options added since default to what the export did)
    assert SacConfig(**tuples(art.meta["sac_config"])) == defaults.sac
    assert art.meta["adapter_config"] == jsonable(dataclasses.asdict(defaults.adapter))
    assert art.meta["extra"]["actor_init"] == defaults.actor_init
    assert art.meta["extra"]["policy_input"] == defaults.policy_input == "paper"
    assert art.policy.inputs == ("s_body", "z") and defaults.sac.num_timesteps == 0
    env = art.meta["env_config"]  # the default reaching task: yaw-frame u, the robot's sensors
    assert (env["u_frame"], env["sensor_noise"], env["sensor_delay"]) == ("yaw", 1.0, 1)
    assert env["u_base"] == defaults.env_overrides["u_base"] == "model"  # on the arms' model
    trained = get_config(DEFAULT_TASK, **defaults.env_overrides)  # its residual's bounds
    assert (tuple(env["max_force"]), tuple(env["max_torque"])) == (
        trained.max_force,
        trained.max_torque,
    )


def test_shipped_paper_export_is_the_paper_recipe_and_its_actor_sees_no_privileged_value():
    """`regular-paper`: SAC from a random actor with the asymmetric critic; the exported actor's
    observation is the paper's `[s_body, z]`, nothing privileged."""
    art = io.load(SHIPPED_PAPER)
    paper = recipe("paper")
    assert SacConfig(**tuples(art.meta["sac_config"])) == paper.sac
    assert (
        art.meta["extra"]["actor_init"] == "random" and art.meta["sac_config"]["critic_privileged"]
    )
    assert art.meta["extra"]["sac_env_steps"] >= paper.sac.num_timesteps
    assert art.policy.inputs == ("s_body", "z")
    layout = art.meta["policy"]["observation_layout"]
    assert len(layout) == art.policy.obs_norm.mean.shape[-1] == 11 + art.adapter_config.latent_size
    assert not any("oracle" in name or "push" in name or "payload" in name for name in layout)


def test_a_run_has_one_seed_that_the_adapter_and_sac_follow(tmp_path):
    """`seed` is the run's; `adapter.seed` and `sac.seed` always equal it (the default run's
    seeds are those of the shipped export, all 0) and are not options of their own."""
    assert (RunConfig().seed, RunConfig().adapter.seed, RunConfig().sac.seed) == (0, 0, 0)
    config = RunConfig().replace(seed=5)
    assert config.adapter.seed == config.sac.seed == 5
    assert dataclasses.replace(config, seed=7).sac.seed == 7
    for key in ("sac.seed", "adapter.seed"):
        with pytest.raises(DpcError, match=f"{key} is the run's seed.*set `seed`"):
            RunConfig().replace(**{key: 5})
    args = ["train", "--run", str(tmp_path / "r"), "--set", "sac.seed=5"]
    with pytest.raises(DpcError, match="--set seed=5"):
        cli._run_config(cli._parser().parse_args(args))
    # a config file of an earlier version, whose sub-seeds were overwritten by the run's: read
    # as the run it was, and resumable under the same options
    old = RunConfig().to_json() | {"seed": 3, "eval_steps": 1000}
    old["sac"] = old["sac"] | {"seed": 0}
    old["adapter"] = old["adapter"] | {"seed": 9}
    (tmp_path / "config.json").write_text(json.dumps(old))
    read = read_run_config(tmp_path)
    assert (read.seed, read.adapter.seed, read.sac.seed, read.eval_steps) == (3, 3, 3, 1000)
    start_run(RunConfig().replace(seed=3), tmp_path, resume=True)  # eval_steps 1000 = reaching's
    with pytest.raises(DpcError, match="another configuration"):
        start_run(RunConfig().replace(seed=4), tmp_path, resume=True)


def test_eval_steps_follow_the_task_unless_set(tmp_path, monkeypatch):
    """`train`'s evaluation runs episodes of the task's length, as `dpc-mjx eval` does."""
    assert RunConfig().eval_steps is None and RunConfig().episode_steps == 1000  # reaching
    pushing = RunConfig().replace(task="a1_arm/pushing", arm="pusher")
    assert pushing.episode_steps == 500
    assert pushing.replace(eval_steps=200).episode_steps == 200
    assert RunConfig().replace(**{"env.episode_length": 300}).episode_steps == 300
    with pytest.raises(DpcError, match="eval_steps must be an int >= 1"):
        RunConfig().replace(eval_steps=0)
    steps = []
    monkeypatch.setattr(run_eval, "evaluate", lambda *a, **kw: steps.append(kw["steps"]) or [])
    pipeline.evaluate_run(pushing, tmp_path, SHIPPED)
    pipeline.evaluate_export(SHIPPED, task=pushing.task, csv=tmp_path / "e.csv")
    assert steps == [None, None]  # both: `eval.evaluate`'s default, the task's episode length
