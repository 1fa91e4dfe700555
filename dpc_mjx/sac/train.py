"""Training the high-level estimator with SAC: the host loop (`train`), ours around brax's SAC.

The jitted pieces (brax's SAC in our epoch, the evaluation) are `sac.trainer`'s, the
hyperparameters `sac.config`'s, the log `sac.log`'s, the checkpoint `sac.checkpoint`'s. The loop is
ours, not brax's `sac.train`, because brax 0.14.2's cannot resume (its `restore_checkpoint_path`
restores only the policy, restarts the step counter and empties the replay buffer), runs a
128-episode evaluation at each log point and pmaps over devices. Here, after each jitted epoch
the host:

    logs       one CSV row (returns, fall rate, losses, env steps/s, gradient steps/s)
    evaluates  every `eval_every` epochs: the deterministic policy on fixed episodes, the same
               episodes with u = 0 as reference, and keeps the best policy so far (`keep_best`)
    saves      a full checkpoint (every parameter and optimiser state, the replay buffer, the
               counters, the key, the best policy), from which `train(..., resume=True)`
               continues after a kill; envs are reset on resume (their physics state is not saved)

`restore_policy` reads a run's policy back without training.

    env = LatentObsWrapper(make("reaching", arm="regular"), adapter.config, adapter.encoder)
    result = train(env, SacConfig(num_timesteps=500_000), run_dir="runs/x")
"""

from __future__ import annotations

import dataclasses
import pathlib
import time
from collections.abc import Callable

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import Env

from dpc_mjx.adapter.networks import Normalizer
from dpc_mjx.errors import DpcError
from dpc_mjx.policy.policy import PolicyState
from dpc_mjx.progress import bar
from dpc_mjx.sac import checkpoint, log
from dpc_mjx.sac.config import SacConfig
from dpc_mjx.sac.trainer import BestPolicy, Carry, Trainer, TrainingState, make_trainer
from dpc_mjx.writer import barrier, is_writer


@dataclasses.dataclass(frozen=True)
class TrainResult:
    policy: PolicyState
    history: list[dict]  # one row per epoch, the CSV's columns
    config: SacConfig
    timing: dict  # s: 'compile_seconds' of the epoch, 'train_seconds' of every epoch run here
    selected_epoch: int = -1  # epochs trained before the returned policy (0: the start)


def train(
    env: Env | Trainer,
    config: SacConfig | None = None,
    run_dir: str | pathlib.Path | None = None,
    *,
    resume: bool = False,
    progress: bool = True,
    on_epoch: Callable[[dict], None] | None = None,
    actor_init: Callable[[Trainer, Carry], Carry] | None = None,
) -> TrainResult:
    """Train SAC on `env` (one unbatched env with the policy's observation, e.g. a
    `LatentObsWrapper`), or with a `Trainer` built before (which keeps its compiled epoch across
    calls). With `run_dir`, every epoch appends to `sac_log.csv` and rewrites the checkpoint there;
    `resume=True` continues from that checkpoint (same config but `num_timesteps` required).
    `actor_init(trainer, carry) -> carry` changes the starting point of a new run (e.g.
    `warm_start.regress_actor`); with evaluations on, the starting policy is scored as epoch 0.
    In a run of several processes only process 0 writes the log and checkpoints there."""
    trainer = _trainer_for(env, config)
    config = trainer.config
    run_dir = pathlib.Path(run_dir) if run_dir is not None else None
    if resume and run_dir is None:
        raise DpcError("resume=True needs the run_dir of the run to continue.")

    carry = trainer.init(jax.random.PRNGKey(config.seed))
    history: list[dict] = []
    meta = _meta(trainer)
    if resume:
        carry, history = checkpoint.restore(run_dir, carry, meta)
        barrier("sac restored")  # every process read the checkpoint before process 0 writes one
    elif actor_init is not None:
        carry = actor_init(trainer, carry)
    start_epoch = int(carry.epoch)
    log_dir = run_dir if is_writer() else None  # where the log and checkpoints are written
    if log_dir is not None:
        log.rewrite(log_dir, history)
    total = config.epochs
    if start_epoch < total:  # no epoch to run (sac.num_timesteps=0): no env reset compiled
        env_state = trainer.reset(jax.random.fold_in(carry.key, start_epoch))
        epoch_fn = trainer.compiled("epoch", carry, env_state)
    eval_key = jax.random.PRNGKey(config.seed + 12345)  # the same episodes at every evaluation
    baseline = {}
    if config.eval_every and start_epoch < total:
        baseline = zero_action_baseline(trainer, carry, eval_key)
        if start_epoch == 0:  # the starting policy, a candidate for the best like any other
            carry = _evaluate_start(trainer, carry, eval_key, baseline, history, log_dir)
    t0 = time.perf_counter()
    with bar(total * config.env_steps_per_epoch, "sac", "step", progress and total > 0) as pb:
        pb.update(start_epoch * config.env_steps_per_epoch)
        for epoch in range(start_epoch + 1, total + 1):
            t_epoch, grads_before = time.perf_counter(), int(carry.training.grad_steps)
            carry, env_state, metrics = epoch_fn(carry, env_state)
            metrics = jax.device_get(metrics)
            seconds = time.perf_counter() - t_epoch
            grads = int(carry.training.grad_steps) - grads_before
            row = log.epoch_row(carry, metrics, seconds, grads, config, time.perf_counter() - t0)
            if config.eval_every and (epoch % config.eval_every == 0 or epoch == total):
                carry = _evaluate(trainer, carry, row, eval_key)
                row.update({f"eval_mbc_{k}": v for k, v in baseline.items()})
            history.append(row)
            if log_dir is not None:
                log.append(log_dir, row)
                checkpoint.save(log_dir, carry, meta, history)
            if on_epoch is not None:
                on_epoch(row)
            pb.set_postfix(ret=f"{row['mean_return']:.1f}", fall=f"{row['fall_rate']:.2f}")
            pb.update(config.env_steps_per_epoch)
    timing = {
        "compile_seconds": trainer.compile_seconds.get("epoch", 0.0),
        "eval_compile_seconds": trainer.compile_seconds.get("evaluate", 0.0),
        "train_seconds": time.perf_counter() - t0,
    }
    return TrainResult(
        result_policy(trainer, carry), history, config, timing, _selected_epoch(trainer, carry)
    )


def restore_policy(env: Env, config: SacConfig, run_dir: str | pathlib.Path) -> TrainResult:
    """The policy and history saved in `run_dir`'s checkpoint, without training (nothing of the
    env is compiled). `env` and `config` must be those of the run (for the checkpoint's shapes)."""
    trainer = make_trainer(env, config)
    carry, history = checkpoint.restore(
        pathlib.Path(run_dir), trainer.init(jax.random.PRNGKey(config.seed)), _meta(trainer)
    )
    return TrainResult(
        result_policy(trainer, carry), history, config, {}, _selected_epoch(trainer, carry)
    )


def policy_state(trainer: Trainer, policy_params: dict, normalizer) -> PolicyState:
    """The deployable actor: its parameters and observation statistics (brax running stats)."""
    n = trainer.observation_size  # the actor's part of the statistics (asymmetric critic)
    if trainer.config.normalize_observations:
        norm = Normalizer(mean=normalizer.mean[..., :n], std=normalizer.std[..., :n])
    else:
        norm = Normalizer(mean=jp.zeros(n), std=jp.ones(n))
    return PolicyState(
        params=policy_params,
        obs_norm=norm,
        hidden=tuple(trainer.config.hidden),
        action_size=trainer.action_size,
        inputs=trainer.policy_inputs,
    )


def _selected_epoch(trainer: Trainer, carry: Carry) -> int:
    best = int(carry.best.epoch)
    return best if trainer.config.keep_best and best >= 0 else int(carry.epoch)


def result_policy(trainer: Trainer, carry: Carry) -> PolicyState:
    """The best evaluated policy with `keep_best` (once one was evaluated), else the last."""
    if trainer.config.keep_best and int(carry.best.epoch) >= 0:
        return policy_state(trainer, carry.best.policy_params, carry.best.normalizer)
    return policy_state(trainer, carry.training.policy_params, carry.training.normalizer)


def _trainer_for(env: Env | Trainer, config: SacConfig | None) -> Trainer:
    if not isinstance(env, Trainer):
        return make_trainer(env, config or SacConfig())
    if config is not None and config != env.config:
        raise DpcError("Pass no config with a Trainer: it was built with its own.")
    return env


def _evaluate(trainer: Trainer, carry: Carry, row: dict, key: jax.Array) -> Carry:
    """Score the current policy into `row`; keep it as the best if it beats the best so far."""
    eval_fn = trainer.compiled("evaluate", carry.training, key, _ONE)
    scores = jax.device_get(eval_fn(carry.training, key, _ONE))
    row.update(eval_return=float(scores["return"]), eval_fall_rate=float(scores["fall_rate"]))
    if row["eval_return"] > float(carry.best.score):
        carry = carry.replace(best=_best(carry, row["eval_return"]))
    return carry


def _evaluate_start(trainer, carry, key, baseline: dict, history: list, run_dir) -> Carry:
    """The starting policy scored as epoch 0: its row appended to `history` (and the log)."""
    row = log.empty_row() | {"epoch": 0, "env_steps": 0, "grad_steps": 0, "episodes": 0}
    carry = _evaluate(trainer, carry, row, key)
    row.update({f"eval_mbc_{k}": v for k, v in baseline.items()})
    history.append(row)
    if run_dir is not None:
        log.append(run_dir, row)
    return carry


_ONE, _ZERO = np.float32(1.0), np.float32(0.0)  # the `gate` of `Trainer.evaluate`


def zero_action_baseline(trainer: Trainer, carry: Carry, key: jax.Array) -> dict[str, float]:
    """The evaluation's episodes with u = 0 (MBC): the reference for `eval_return`."""
    eval_fn = trainer.compiled("evaluate", carry.training, key, _ONE)
    return {k: float(v) for k, v in jax.device_get(eval_fn(carry.training, key, _ZERO)).items()}


def _best(carry: Carry, score: float) -> BestPolicy:
    """The current policy as the best one (copied: the epoch donates its buffers)."""
    ts = carry.training
    return BestPolicy(
        policy_params=jax.tree.map(jp.copy, ts.policy_params),
        normalizer=jax.tree.map(jp.copy, ts.normalizer),
        score=jp.asarray(score, jp.float32),
        epoch=jp.copy(carry.epoch),  # not the same buffer: the next epoch donates both
    )


def _meta(trainer: Trainer) -> dict:
    """What a checkpoint must agree on to be resumed: everything but the run's length
    (`num_timesteps` may grow) and the observation size."""
    config = dataclasses.asdict(trainer.config)
    config.pop("num_timesteps")
    return {"sac_config": config, "observation_size": trainer.observation_size}


__all__ = [  # with the names of `sac.config` and `sac.trainer` imported from here before
    "BestPolicy",
    "Carry",
    "SacConfig",
    "TrainResult",
    "Trainer",
    "TrainingState",
    "make_trainer",
    "policy_state",
    "restore_policy",
    "result_policy",
    "train",
]
