"""A whole DPC run as one function: data -> adapter -> policy (oracle regression, then SAC if
asked) -> export -> evaluation.

    config = RunConfig(arm="regular")        # the shipped recipe (docs/results-estimator.md)
    summary = train_and_evaluate(config, "runs/regular")
    config.replace(**{"sac.num_timesteps": 500_000})   # with a SAC stage after the regression

The run folder (every file written atomically; `resume=True` continues a killed run):

    config.json          the RunConfig
    adapter/             the trained adapter (`adapter.checkpoint`): adapter.json, *.msgpack
    sac/                 warm_start.json (the regression), sac_log.csv and the SAC checkpoint
    export/              the deployable artefacts (`dpc_mjx.io.export`; `dpc-mjx eval --run`)
    plots/               adapter_loss.png, posture_prediction.png, training_curve.png
    tensorboard/         TensorBoard event files of the same numbers (`run.tensorboard`)
    eval.md              MBC / observer / DPC / oracle table (`dpc_mjx.run.eval` protocol)
    summary.json         wall time of every stage, sample counts, the evaluation

In a run of several processes only process 0 writes (`dpc_mjx.writer`).
"""

from __future__ import annotations

import dataclasses
import pathlib
import time

import numpy as np

from dpc_mjx import adapter as adapter_lib
from dpc_mjx import io, sac
from dpc_mjx.adapter import checkpoint as adapter_checkpoint
from dpc_mjx.controllers import Controller
from dpc_mjx.envs.registry import DEFAULT_TASK, get_config, make
from dpc_mjx.io.shipped import (  # noqa: F401 (SHIPPED, SHIPPED_PAPER: their old path)
    SHIPPED,
    SHIPPED_PAPER,
    env_overrides,
    export_cells,
)
from dpc_mjx.policy.regression import regress_actor, target_name
from dpc_mjx.robots.spec_json import arm_argument
from dpc_mjx.robots.variants import Arm, arm_name
from dpc_mjx.run import plots
from dpc_mjx.run.config import RunConfig, read_run_config, start_run
from dpc_mjx.run.eval import CHUNK, CONTROLLERS, CellResult, evaluate_table
from dpc_mjx.run.tensorboard import NO_EVENTS, RunEvents, run_events
from dpc_mjx.run.training_arms import collect_training_data
from dpc_mjx.serialization import write_json
from dpc_mjx.writer import barrier, is_writer

DATA_FILE = "data.npz"  # the adapter's samples, in the run's adapter folder
SUMMARY_FILE = "summary.json"
EPISODES_FILE = "eval_episodes.csv"  # the evaluation, one row per episode


def train_and_evaluate(
    config: RunConfig,
    run_dir: str | pathlib.Path,
    *,
    resume: bool = False,
    progress: bool = True,
    logdir: str | pathlib.Path | None = None,
) -> dict:
    """Run every stage into `run_dir`; returns the summary (also `summary.json`). TensorBoard
    events: in `run_dir/tensorboard`, or `logdir/<run folder's name>` (`tensorboard.logdir_of`)."""
    config.validate()
    run_dir = pathlib.Path(run_dir)
    start_run(config, run_dir, resume=resume)
    events = run_events(config, run_dir, logdir)
    timings: dict[str, float] = {}
    adapter = train_adapter(
        config, run_dir, resume=resume, progress=progress, timings=timings, events=events
    )
    result = train_policy(config, run_dir, adapter, resume=resume, progress=progress, events=events)
    timings.update(
        {f"sac_{k}": v for k, v in result.timing.items()},
        sac_wall_seconds=result.history[-1]["wall_seconds"] if result.history else 0.0,
    )
    export_dir = export(config, run_dir, adapter, result)
    t0 = time.perf_counter()
    events.eval(cells := evaluate_run(config, run_dir, export_dir))
    timings["eval_seconds"] = time.perf_counter() - t0
    summary = {
        "config": config.to_json(),
        "samples": adapter.history["samples"],
        "adapter_env_steps": adapter.history["env_steps"],
        "sac_env_steps": result.history[-1]["env_steps"] if result.history else 0,
        "sac_grad_steps": result.history[-1]["grad_steps"] if result.history else 0,
        "sac_selected_epoch": result.selected_epoch,
        "timings_seconds": timings,
        "eval": [c.summary() for c in cells],
    }
    if is_writer():
        write_json(run_dir / SUMMARY_FILE, summary)
    return summary


def train_adapter(
    config: RunConfig,
    run_dir: pathlib.Path,
    *,
    resume: bool = False,
    progress: bool = True,
    timings: dict | None = None,
    events: RunEvents = NO_EVENTS,
) -> adapter_lib.Adapter:
    """Collect random-motion data with MBC and train the adapter (or load it when resuming);
    its losses also as TensorBoard `events`."""
    folder = run_dir / "adapter"
    if resume and (folder / adapter_checkpoint.RECORD).exists():
        print(f"adapter: loading {folder}", flush=True)
        loaded = adapter_checkpoint.load(folder)
        events.adapter(loaded.history)
        return loaded
    data = collect_training_data(config, progress)  # the run's arm and its family's
    cfg = config.adapter  # its seed is the run's (`RunConfig.seed`)
    trained = adapter_lib.train(data, cfg, progress=progress)
    if is_writer():
        data.save(folder / DATA_FILE)  # kept for the actor's warm start (and for analysis)
        adapter_checkpoint.save(folder, trained)
    barrier("adapter saved")  # the other processes read data.npz next
    h = trained.history
    print(
        f"adapter: {h['samples']:,} samples from {h['env_steps']:,} env steps in "
        f"{h['collect_seconds']:.0f} s; trained {h['epochs']} epochs in {h['seconds']:.0f} s; "
        f"held-out NLL {min(h['val_nll']):.3f} (constant predictor "
        f"{h['constant_val_nll']:.3f}, s_body alone {h.get('body_only_val_nll', np.nan):.3f})",
        flush=True,
    )
    if timings is not None:
        timings.update(data_seconds=h["collect_seconds"], adapter_seconds=h["seconds"])
    events.adapter(h)
    if is_writer():
        plots.adapter_loss(h, run_dir / "plots" / "adapter_loss.png")
        _, held_out = data.split(cfg.val_fraction)
        posture_figure(trained, held_out, run_dir / "plots" / "posture_prediction.png")
    return trained


def posture_figure(trained: adapter_lib.Adapter, data: adapter_lib.Dataset, path, seconds=6.0):
    """The paper's predicted-vs-real posture change, for the first env found in `data`."""
    rows = np.flatnonzero(data.env_id == data.env_id[0])[: round(seconds / 0.02)]
    part = data.take(rows)
    z = adapter_lib.encode(trained.config, trained.encoder, part.encoder_input)
    mean, std = adapter_lib.decode(trained.config, trained.decoder, z, part.s_body)
    t = 0.02 * np.arange(len(rows))
    return plots.posture_prediction(t, part.s_drp_next, np.asarray(mean), np.asarray(std), path)


def train_policy(
    config: RunConfig,
    run_dir: pathlib.Path,
    adapter: adapter_lib.Adapter,
    *,
    resume: bool = False,
    progress: bool = True,
    events: RunEvents = NO_EVENTS,
) -> sac.TrainResult:
    """The policy: the oracle regression (`actor_init`), then SAC on the policy-observation env
    of the run's arm (none when `sac.num_timesteps` is 0, the default); its numbers also as
    TensorBoard `events`."""
    latent_env, sac_config = _sac_setup(config, adapter)
    folder = run_dir / "sac"
    has_checkpoint = (folder / "checkpoint.json").exists()
    if sac_config.num_timesteps == 0:
        print("sac: no SAC stage (sac.num_timesteps=0): the policy is the first actor", flush=True)
    else:
        print(
            f"sac: {'resuming' if resume and has_checkpoint else 'training'} to "
            f"{sac_config.num_timesteps:,} env steps ({sac_config.num_envs} envs)",
            flush=True,
        )
    actor_init = None
    if config.actor_init == "oracle_regression":
        actor_init = _oracle_regression(
            config, run_dir, adapter, latent_env.unwrapped.config, events
        )
    result = sac.train(
        latent_env,
        sac_config,
        folder,
        resume=resume and has_checkpoint,
        progress=progress,
        on_epoch=events.sac_row,
        actor_init=actor_init,
    )
    events.sac(result.history)
    if result.history and is_writer():
        plots.training_curve(result.history, run_dir / "plots" / "training_curve.png")
    return result


def _sac_setup(config: RunConfig, adapter: adapter_lib.Adapter):
    """The run's policy-observation env (its arm, u from the policy) and its SAC config."""
    env = make(config.task, arm=config.arm, controller=Controller.DPC, **config.env_overrides)
    inputs = sac.inputs_named(config.policy_input)
    latent_env = sac.LatentObsWrapper(env, adapter.config, adapter.encoder, inputs)
    return latent_env, config.sac  # its seed is the run's (`RunConfig.seed`)


def _oracle_regression(config: RunConfig, run_dir: pathlib.Path, adapter, env_config, events):
    """The `actor_init` of `sac.train` that regresses the actor on the oracle's u (in the
    env's `u_frame`, scaled by its `u_scale`) over the adapter's MBC samples, then
    `config.dagger_rounds` times over those plus the student's own states (DAgger: the current
    actor drives a 'policy' env, the oracle's u labels each state it visits)."""

    def init(trainer, carry):
        data = adapter_lib.Dataset.load(run_dir / "adapter" / DATA_FILE)
        reports = []
        for round_ in range(config.dagger_rounds + 1):
            if round_:
                student = sac.dpc_policy(
                    adapter.config,
                    adapter.encoder,
                    sac.policy_state(
                        trainer, carry.training.policy_params, carry.training.normalizer
                    ),
                )
                env = make(
                    config.task, arm=config.arm, controller=Controller.DPC, **config.env_overrides
                )
                print(
                    f"dagger {round_}/{config.dagger_rounds}: {config.dagger_samples:,} states of "
                    "the student, labelled with the oracle's u",
                    flush=True,
                )
                own = adapter_lib.collect(
                    env,
                    config.dagger_samples,
                    n_envs=config.data_envs,
                    seed=config.seed + round_,
                    policy=student,
                )
                data = adapter_lib.Dataset.concatenate([data, own])
            carry, report = regress_actor(
                trainer,
                carry,
                adapter.config,
                adapter.encoder,
                data,
                env_config.u_scale,
                u_frame=env_config.u_frame,
                u_base=env_config.u_base,
                slow_s=config.residual_slow_s,
                step_s=env_config.policy_dt,
                model_target=config.model_target,
                seed=config.seed,
            )
            reports.append(report)
            target = target_name(env_config.u_base, config.model_target)
            slow = f" less its slow part ({config.residual_slow_s} s)" * config.splits_residual
            r2 = ", ".join("constant" if v is None else f"{v:.2f}" for v in report["r2"])
            print(
                f"sac: actor regressed on {target}{slow} ({report['samples']:,} samples; "
                f"held-out R^2 per u component {r2})",
                flush=True,
            )
        if is_writer():
            write_json(run_dir / "sac" / "warm_start.json", reports[-1] | {"rounds": reports})
        events.regression(reports)
        return carry

    return init


def export(
    config: RunConfig,
    run_dir: pathlib.Path,
    adapter: adapter_lib.Adapter,
    result: sac.TrainResult,
    out: str | pathlib.Path | None = None,
) -> pathlib.Path:
    """The run's deployable artefacts in `out` (default `run_dir/export`), written by process 0;
    every process returns once they are on disk."""
    out = io.export(
        run_dir / "export" if out is None else out,
        adapter_config=adapter.config,
        policy=result.policy,
        decoder=adapter.decoder,
        encoders={config.arm: adapter.encoder},
        arms={config.arm: config.arm},
        env_config=get_config(config.task, **config.env_overrides),
        sac_config=dataclasses.asdict(result.config),
        extra={
            "task": config.task,
            "run": str(run_dir),
            "sac_selected_epoch": result.selected_epoch,
            "sac_env_steps": result.history[-1]["env_steps"] if result.history else 0,
            "actor_init": config.actor_init,
            "policy_input": config.policy_input,
            # the arms the adapter and the policy learnt from besides `arms` (robots.arms.family)
            **({"arm_family": config.arm_family} if config.arm_family.count else {}),
            **({"residual_slow_s": config.residual_slow_s} if config.splits_residual else {}),
        },
    )
    barrier("export written")  # the other processes read it next (the evaluation)
    return out


def evaluate_run(config: RunConfig, run_dir: pathlib.Path, export_dir) -> list[CellResult]:
    """The evaluation protocol on the run's arm; writes `eval.md` and prints the table."""
    return evaluate_table(
        [config.arm],
        list(config.eval_controllers),
        task=config.task,
        episodes=config.eval_episodes,
        steps=config.eval_steps,
        seed=config.seed + 1000,  # other episodes than training's
        dpc_policy_for=io.load(export_dir).dpc_policy,
        overrides=config.env_overrides,
        out=run_dir / "eval.md",
        csv=run_dir / EPISODES_FILE,
        chunk=config.eval_chunk,
    )


def export_run(run_dir: str | pathlib.Path, out: str | pathlib.Path | None = None) -> pathlib.Path:
    """Export a run's saved adapter and latest SAC checkpoint (no training) to `out`
    (default `run_dir/export`)."""
    run_dir = pathlib.Path(run_dir)
    config = read_run_config(run_dir)
    adapter = adapter_checkpoint.load(run_dir / "adapter")
    result = sac.restore_policy(*_sac_setup(config, adapter), run_dir / "sac")
    return export(config, run_dir, adapter, result, out)


def transfer_arm(
    export_dir: str | pathlib.Path,
    arm: str | Arm,
    *,
    samples: int = 30_000,
    task: str = DEFAULT_TASK,
    seed: int = 0,
    n_envs: int = 64,
    progress: bool = True,
    env: dict | None = None,
) -> dict:
    """Paper §III-C: collect `samples` random-motion transitions of a new `arm` (MBC), train its
    encoder against the export's frozen decoder, and add it to the export under the arm's name
    (`robots.arm_name`: `my_arm` for my_arm.urdf). `arm`: a variant name, the path of an arm file
    (.urdf, MJCF .xml) or description (.json; `robots.read_arm_description`), a `UrdfArm` or an
    `ArmSpec`. `env`: env options over the export's, as for `evaluate_export` (e.g.
    `{"engine": "native"}`: collect in MuJoCo C). Returns the encoder's training history."""
    if isinstance(arm, str):
        arm = arm_argument(arm)
    name = arm_name(arm)
    artefacts = io.load(export_dir)
    options = {**env_overrides(artefacts, task), **(env or {})}
    env = make(task, arm=arm, controller=Controller.MBC, **options)
    print(f"transfer: collecting {samples:,} samples ({name}, MBC)", flush=True)
    data = adapter_lib.collect(env, samples, n_envs=n_envs, seed=seed, progress=progress)
    config = dataclasses.replace(artefacts.adapter_config, seed=seed)
    encoder, history = adapter_lib.transfer(data, artefacts.decoder, config, progress=progress)
    if is_writer():
        io.add_encoder(export_dir, name, encoder, arm, replace=True)
    print(
        f"transfer: {name} encoder from {len(data):,} samples ({data.env_steps:,} env steps, "
        f"{data.seconds:.0f} s) trained in {history['seconds']:.0f} s; held-out NLL "
        f"{min(history['val_nll']):.3f} (constant predictor {history['constant_val_nll']:.3f}); "
        f"added to {export_dir}",
        flush=True,
    )
    return history


def evaluate_export(
    export_dir: str | pathlib.Path,
    *,
    arms: list[str] | None = None,
    controllers: list[str] = CONTROLLERS,
    task: str = DEFAULT_TASK,
    episodes: int = 64,
    steps: int | None = None,
    seed: int = 1000,
    out: str | pathlib.Path | None = None,
    csv: str | pathlib.Path | None = None,
    env: dict | None = None,
    chunk: int = CHUNK,
) -> list[CellResult]:
    """The evaluation protocol for the arms of an export (default: the arm its policy was trained
    on, its first encoder; transferred encoders are added after it; an arm is an encoder's name,
    a variant, or an arm file or description as for `transfer_arm`),
    under the env options it was trained with and `env` over them (e.g. exact sensors), for
    `steps` per episode (default: the task's episode length); prints the table (and writes it
    to `out`, and one row per episode to `csv`), in compiled chunks of at most `chunk` steps."""
    artefacts, arms, overrides = export_cells(export_dir, arms, controllers, task, env)
    return evaluate_table(
        arms,
        list(controllers),
        task=task,
        episodes=episodes,
        steps=steps,
        seed=seed,
        dpc_policy_for=artefacts.dpc_policy,
        overrides=overrides,
        out=out,
        csv=csv,
        chunk=chunk,
    )
