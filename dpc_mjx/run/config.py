"""The configuration of a whole run (`RunConfig`) and the run folder's config file.

The defaults are the recipe of the shipped `regular` run (docs/results-estimator.md).
Hyperparameters are overridden by dotted name (`RunConfig().replace(**{"sac.num_envs": 32})`, or
`dpc-mjx train --set sac.num_envs=32`); the env's own options are the task config's fields
(`env.<field>`), SAC's are `SacConfig`'s and the adapter's `AdapterConfig`'s.

A run has one seed, `RunConfig.seed` (`--set seed=N`): the adapter's data and training and SAC
use it (`adapter.seed` and `sac.seed` always equal it; setting them is an error), the DAgger round
k collects from seed + k, and the evaluation runs the episodes of seed + 1000.
"""

from __future__ import annotations

import dataclasses
import pathlib
from typing import Any

from dpc_mjx import adapter as adapter_lib
from dpc_mjx import sac
from dpc_mjx.controllers import Controller
from dpc_mjx.envs.config import check_number_or_pair
from dpc_mjx.envs.registry import DEFAULT_TASK, get_config
from dpc_mjx.errors import DpcError
from dpc_mjx.policy.regression import MODEL_TARGETS
from dpc_mjx.robots.arms.family import ArmFamily
from dpc_mjx.robots.variants import resolve
from dpc_mjx.serialization import jsonable, read_json, tuples, write_json
from dpc_mjx.writer import barrier, is_writer

CONFIG_FILE = "config.json"
ACTOR_INITS = ("random", "oracle_regression")
_SUB_SEEDS = ("adapter.seed", "sac.seed")  # set from RunConfig.seed, never on their own


# The SAC settings of the shipped run (docs/history/sac-export-v5.md): a longer run
# than SacConfig's default, larger batches, a shorter horizon (a push acts within ~0.2-1 s), a
# low starting temperature and a slow actor, so that the oracle-regressed actor is refined rather
# than overwritten; the critics learn alone for the first 20,000 gradient steps.
TRAINED_SAC = sac.SacConfig(
    num_timesteps=1_000_000,
    batch_size=512,
    discounting=0.97,
    init_alpha=0.01,
    actor_warmup_steps=20_000,
    actor_learning_rate=3e-5,
)


# Named recipes: dotted overrides of `RunConfig()` (`dpc-mjx train --recipe NAME`, then `--set`).
RECIPES: dict[str, dict[str, Any]] = {
    # the shipped `regular` export: DPC on the arms' model wrench (u = the model wrench from the
    # measured states + the policy's u), the actor regressed on what the model cannot know, no
    # SAC stage (docs/results-arm-model.md)
    "default": {"env.u_base": "model"},
    # the paper's recipe, made to work (`regular-paper`): SAC from a random actor on the paper's
    # reward; the actor never sees an oracle label. Ours: an asymmetric critic (it sees u_oracle,
    # the payload and the push force: privileged, simulator-only), a low starting temperature,
    # a 10,000-step critic warm-up, TRAINED_SAC's discount and batch.
    "paper": {
        "actor_init": "random",
        "sac.num_timesteps": 1_000_000,
        "sac.critic_privileged": True,
        "sac.actor_warmup_steps": 10_000,
        "sac.actor_learning_rate": None,
    },
}


# Device presets: dotted overrides for the accelerator JAX runs on (`--device`, default auto:
# `jax.default_backend()`), applied after the recipe and before `--set`. The CPU preset is the
# shipped recipe. On a GPU a batch of envs costs about what one env does up to thousands (18-25 ms
# an env step on an H200 at any batch up to a few thousand: docs/benchmarks.md, "On a GPU"), so:
# - the adapter's data come from 2,048 envs, each env's first episode cut short after a random
#   number of steps and the first 1,000 steps' rows dropped (`data_burn_in`: staggered starts),
#   so that 100,000 samples spread over the episodes' whole length as 64 envs' 1,560 steps do,
#   not over 49 steps after each reset;
# - the evaluation runs 1,024 episodes per controller in chunks of a whole 20 s episode;
# - SAC steps 1,024 envs with the recipe's rule held: one gradient step per 4 env steps
#   (`sac.grad_updates_per_step` = `sac.num_envs` / 4, the update-to-data ratio of both recipes),
#   the same batch, and epochs of 256 actor steps; it evaluates on 128 episodes.
DEVICE_PRESETS: dict[str, dict[str, Any]] = {
    "cpu": {},
    "gpu": {
        "data_envs": 2048,
        "data_burn_in": 1000,
        "eval_episodes": 1024,
        "eval_chunk": 1000,
        "sac.num_envs": 1024,
        "sac.grad_updates_per_step": 256,
        "sac.epoch_steps": 262_144,
        "sac.eval_envs": 128,
    },
}


def preset_name(device: str) -> str:
    """The preset of a device name ('auto': the backend JAX runs on; 'tpu' takes the GPU's)."""
    if device == "auto":
        import jax  # noqa: PLC0415 (jax only for --device auto)

        device = jax.default_backend()
    preset = "gpu" if device in ("gpu", "tpu", "cuda", "rocm") else device
    if preset not in DEVICE_PRESETS:
        raise DpcError(f"Unknown device preset {device!r}; choose from {sorted(DEVICE_PRESETS)}.")
    return preset


def recipe(name: str, device: str = "cpu") -> RunConfig:
    """`RunConfig()` with the overrides of the named recipe (`RECIPES`), then those of the
    device preset of `device` ('auto', 'cpu' or 'gpu', `preset_name`, `DEVICE_PRESETS`)."""
    if name not in RECIPES:
        raise DpcError(f"Unknown recipe {name!r}; the recipes are {sorted(RECIPES)}.")
    return RunConfig().replace(**{**RECIPES[name], **DEVICE_PRESETS[preset_name(device)]})


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """Everything a run does (the env's own options are `env_overrides` of its task config).

    The defaults are the recipe of the shipped `regular` run; `recipe("paper")` (SAC from a
    random actor with an asymmetric critic) that of `regular-paper` (`RECIPES`).
    """

    task: str = DEFAULT_TASK
    arm: str = "regular"  # a variant name (`dpc_mjx.robots.VARIANTS`)
    # Arms drawn around `arm` whose data join the adapter's and the regression's
    # (`robots.arms.family`; count 0: the run's arm alone, the paper's protocol)
    arm_family: ArmFamily = ArmFamily()
    env_overrides: dict = dataclasses.field(default_factory=dict)  # EnvConfig fields
    samples: int = 100_000  # random-motion transitions for the adapter
    data_envs: int = 64
    # env steps run before the adapter's samples are kept, each env's first episode cut short
    # after a random number of steps up to it (staggered starts; `adapter.collect`): 0 on a CPU
    data_burn_in: int = 0
    adapter: adapter_lib.AdapterConfig = adapter_lib.AdapterConfig()
    # No SAC stage by default (num_timesteps=0: the policy is the oracle regression, actor_init):
    # in the SAC runs v4 and v5 the selected actor was the regressed one
    # (docs/results-estimator.md);
    # `--set sac.num_timesteps=1000000` runs SAC with those runs' settings (TRAINED_SAC)
    sac: sac.SacConfig = dataclasses.replace(TRAINED_SAC, num_timesteps=0)
    eval_episodes: int = 64
    # env steps of 20 ms per evaluation episode; None: the task's episode length (reaching 1000,
    # pushing 500: `EnvConfig.episode_length`, as `dpc-mjx eval`)
    eval_steps: int | None = None
    eval_controllers: tuple[str, ...] = tuple(Controller)  # every one, the tables' order
    eval_chunk: int = 50  # env steps per compiled evaluation chunk at most (`run.eval.evaluate`)
    # How SAC's actor starts: "random" (the paper) or "oracle_regression" (ours: regressed on
    # the oracle's u over the adapter's samples, `policy.regression`; then SAC as usual)
    actor_init: str = "oracle_regression"
    # What the policy observes (`policy.policy.POLICY_INPUTS`): "paper" [s_body, z], or "observer"
    # [s_body, z, u_obs], the disturbance observer's estimate too (better with exact sensors,
    # worse with the robot's: docs/results-estimator.md, the ablation)
    policy_input: str = "paper"
    # DAgger after the regression: rounds of `dagger_samples` states visited by the current
    # actor, labelled with the oracle's u, added to the data before regressing again
    dagger_rounds: int = 0
    dagger_samples: int = 20_000
    # With env.u_base='observer': s, one number or (force, torque); the regression target leaves
    # out the part of u_oracle - u_obs slower than this (its exponential average along each
    # episode), so that the observer keeps the slow part, its integral action on the legs' model
    # error included; 0: the whole residual (`policy.regression.regression_target`)
    residual_slow_s: float | tuple[float, float] = 0.0
    # With env.u_base='model': what of the unmodelled wrench the regression fits
    # (`policy.regression.MODEL_TARGETS`): 'unmodelled' (the shipped form: the pushes and the
    # payload as the mount feels them), 'payload' (the payloads' weight alone, the part that
    # pays where it is known exactly: docs/results-arm-model.md, "The bounds") or 'felt' (what the
    # mount feels beyond the model wrench of the servos' motion, the controller's own model)
    model_target: str = "unmodelled"
    # the run's one seed; `adapter.seed` and `sac.seed` follow it (the module's docstring)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.adapter.seed != self.seed:
            object.__setattr__(self, "adapter", dataclasses.replace(self.adapter, seed=self.seed))
        if self.sac.seed != self.seed:
            object.__setattr__(self, "sac", dataclasses.replace(self.sac, seed=self.seed))

    @property
    def episode_steps(self) -> int:
        """Env steps per evaluation episode: `eval_steps`, else the task's episode length."""
        if self.eval_steps is not None:
            return self.eval_steps
        return get_config(self.task, **self.env_overrides).episode_length

    @property
    def splits_residual(self) -> bool:
        """Whether the regression leaves a slow part of the residual to the observer
        (`residual_slow_s` > 0 for the force or the torque)."""
        slow = self.residual_slow_s
        return any(slow) if isinstance(slow, tuple) else bool(slow)

    def validate(self) -> None:
        get_config(self.task, **self.env_overrides)  # task name and overrides
        Controller.parse_all(self.eval_controllers)
        if not isinstance(self.seed, int) or isinstance(self.seed, bool):
            raise DpcError(f"RunConfig.seed must be an int, got {self.seed!r}.")
        if not isinstance(self.dagger_rounds, int) or self.dagger_rounds < 0:
            raise DpcError(
                f"RunConfig.dagger_rounds must be an int >= 0, got {self.dagger_rounds!r}."
            )
        if self.dagger_rounds and self.actor_init != "oracle_regression":
            raise DpcError(
                "dagger_rounds needs actor_init='oracle_regression' (the oracle labels)."
            )
        positive = ("samples", "data_envs", "eval_episodes", "eval_steps", "eval_chunk")
        for name in (*positive, "dagger_samples", "data_burn_in"):
            v, least = getattr(self, name), int(name != "data_burn_in")
            if (v is not None or name != "eval_steps") and (not isinstance(v, int) or v < least):
                raise DpcError(f"RunConfig.{name} must be an int >= {least}, got {v!r}.")
        self.adapter.validate()
        self.sac.validate()
        self._validate_family()
        self._validate_residual()
        if self.actor_init not in ACTOR_INITS:
            raise DpcError(f"actor_init={self.actor_init!r} is not one of {list(ACTOR_INITS)}.")
        sac.inputs_named(self.policy_input)
        if self.sac.critic_privileged and self.actor_init != "random":
            raise DpcError(
                "sac.critic_privileged (the asymmetric critic) needs actor_init='random': the "
                "oracle regression's data has no privileged values for the critics."
            )
        if self.actor_init == "random" and self.sac.num_timesteps == 0:
            raise DpcError(
                "actor_init='random' with sac.num_timesteps=0 trains nothing: set "
                "sac.num_timesteps (e.g. 1000000) or actor_init='oracle_regression'."
            )

    def _validate_residual(self) -> None:
        check_number_or_pair("RunConfig.residual_slow_s (s)", self.residual_slow_s, 0.0, 60.0)
        u_base = get_config(self.task, **self.env_overrides).u_base
        if self.model_target not in MODEL_TARGETS:
            raise DpcError(
                f"RunConfig.model_target={self.model_target!r} is not one of {list(MODEL_TARGETS)}."
            )
        if self.model_target != "unmodelled" and u_base != "model":
            raise DpcError(
                "model_target chooses what DPC on the arms' model learns: it needs "
                "env.u_base=model (`--set env.u_base=model`), or model_target=unmodelled."
            )
        if self.splits_residual and u_base != "observer":
            raise DpcError(
                "residual_slow_s splits the residual u_oracle - u_obs: it needs "
                "env.u_base=observer (`--set env.u_base=observer`), or residual_slow_s=0."
            )
        if self.splits_residual and self.actor_init != "oracle_regression":
            raise DpcError(
                "residual_slow_s shapes the oracle regression's target: it needs "
                "actor_init='oracle_regression'."
            )

    def _validate_family(self) -> None:
        self.arm_family.validate()
        if not self.arm_family.count:
            return
        if self.sac.num_timesteps or self.dagger_rounds:
            raise DpcError(
                "arm_family trains the adapter and the oracle regression over the family; a SAC "
                "stage or DAgger would run on the run's arm alone. Set sac.num_timesteps=0 and "
                "dagger_rounds=0, or arm_family.count=0."
            )
        arms = resolve(self.arm).arms
        if len(arms) != 1:
            raise DpcError(
                f"arm_family varies one parametric arm; {self.arm!r} carries {len(arms)}. "
                "Train on regular, longer, heavier or pusher, or set arm_family.count=0."
            )
        self.arm_family.members(arms[0], self.seed)  # a URDF arm is refused here

    def to_json(self) -> dict:
        return jsonable(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, d: dict) -> RunConfig:
        try:
            d = tuples(d)  # JSON's lists back to tuples (residual_slow_s)
            d["adapter"] = adapter_lib.AdapterConfig(**tuples(d["adapter"]))
            d["sac"] = sac.SacConfig(**tuples(d["sac"]))
            d["arm_family"] = ArmFamily(**tuples(d.get("arm_family", {})))  # older: none
            d["eval_controllers"] = tuple(d["eval_controllers"])
            d["env_overrides"] = tuples(d["env_overrides"])
            return cls(**d)
        except (KeyError, TypeError) as e:
            raise DpcError(f"Not a RunConfig ({e}); start a new run folder.") from e

    def replace(self, **dotted: Any) -> RunConfig:
        """A copy with overrides by dotted name: `arm='longer'`, `sac.num_envs=32`,
        `adapter.epochs=20`, `env.push_force=(0, 60)`; the seeds of the adapter and SAC
        follow `seed` and are not options of their own."""
        top, sub = {}, {"adapter": {}, "sac": {}, "env": {}, "arm_family": {}}
        for key, value in dotted.items():
            if key in _SUB_SEEDS:
                raise DpcError(
                    f"{key} is the run's seed: a run has one, set `seed` instead (dpc-mjx train "
                    f"--set seed={value}); the adapter and SAC use it."
                )
            head, _, rest = key.partition(".")
            if rest and head in sub:
                sub[head][rest] = value
            elif not rest and head in {f.name for f in dataclasses.fields(self)}:
                top[key] = value
            else:
                raise DpcError(
                    f"Unknown run option {key!r}; use a RunConfig field "
                    f"({[f.name for f in dataclasses.fields(self)]}) or adapter.<field>, "
                    "sac.<field>, env.<field>, arm_family.<field>."
                )
        out = dataclasses.replace(self, **tuples(top))
        try:
            out = dataclasses.replace(
                out,
                adapter=dataclasses.replace(out.adapter, **sub["adapter"]),
                sac=dataclasses.replace(out.sac, **sub["sac"]),
                arm_family=dataclasses.replace(out.arm_family, **tuples(sub["arm_family"])),
                env_overrides={**out.env_overrides, **sub["env"]},
            )
        except TypeError as e:
            raise DpcError(f"Unknown option in {sorted(dotted)}: {e}.") from e
        out.validate()
        return out


def read_run_config(run_dir: str | pathlib.Path) -> RunConfig:
    """The `RunConfig` a run folder was started with."""
    path = pathlib.Path(run_dir) / CONFIG_FILE
    return RunConfig.from_json(read_json(path, "run config", hint="is this a run folder?"))


def start_run(config: RunConfig, run_dir: pathlib.Path, *, resume: bool) -> None:
    """Write the run's config (process 0); when resuming, check that it is the one the folder
    holds."""
    run_dir = pathlib.Path(run_dir)
    path = run_dir / CONFIG_FILE
    if resume:
        saved = read_json(path, "run config", hint="start the run without --resume")
        if saved != config.to_json() and _as_run(saved) != _as_run(config.to_json()):
            raise DpcError(
                f"{path} holds another configuration than this run's; resume with the same "
                "options, or start a new run folder."
            )
    elif path.exists():
        raise DpcError(f"{run_dir} already holds a run; resume it or pick another folder.")
    barrier("run folder checked")  # by every process, before process 0 writes into it
    if is_writer():
        write_json(path, config.to_json())


def _as_run(saved: dict) -> dict | None:
    """A saved config as the run it makes: read as today's `RunConfig` (sub-seeds following the
    run's seed) with the evaluation's episode length resolved, so that a folder written by an
    earlier version (sub-seeds of their own, `eval_steps` 1000) resumes under the same options;
    None if `saved` is no `RunConfig`."""
    try:
        config = RunConfig.from_json(saved)
        return dataclasses.replace(config, eval_steps=config.episode_steps).to_json()
    except DpcError:
        return None
