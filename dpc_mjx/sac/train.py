"""Training the high-level estimator with SAC: brax's algorithm, our loop.

The algorithm is brax's (`brax.training.agents.sac`): its networks, its losses (twin critics,
target network with Polyak averaging, automatic entropy tuning), its uniform replay buffer and its
`acting.actor_step`. The loop around them is ours, because brax 0.14.2's `sac.train` cannot
resume (its `restore_checkpoint_path` restores only the policy, restarts the step counter and
empties the replay buffer), runs a 128-episode evaluation at each log point (minutes on a CPU)
and pmaps over devices. Here one jitted epoch is `epoch_steps` env steps with their gradient
steps; after each epoch the host logs a CSV row (returns, fall rate, losses, env steps/s, gradient
steps/s) and writes a full checkpoint (every parameter and optimiser state, the replay buffer,
the counters and the key), from which `train(..., resume=True)` continues after a kill. Envs are
reset on resume (their physics state is not saved).

    env = LatentObsWrapper(make("a1_arm/reaching", arm="regular"), adapter.config, adapter.encoder)
    result = train(env, SacConfig(num_timesteps=500_000), run_dir="runs/x")
"""

from __future__ import annotations

import csv
import dataclasses
import math
import pathlib
import time
from collections.abc import Callable

import jax
import jax.numpy as jp
import numpy as np
import optax
from brax.envs.base import Env
from brax.training import acting, replay_buffers
from brax.training.acme import running_statistics
from brax.training.agents.sac import losses as sac_losses
from brax.training.agents.sac import networks as sac_networks
from brax.training.types import Transition
from flax import struct

from dpc_mjx.adapter.networks import Normalizer
from dpc_mjx.envs.wrappers import wrap_for_training
from dpc_mjx.errors import DpcError
from dpc_mjx.progress import bar
from dpc_mjx.sac import checkpoint
from dpc_mjx.sac.networks import HIDDEN, make_networks
from dpc_mjx.sac.policy import PolicyState

LOG_FILE = "sac_log.csv"


@dataclasses.dataclass(frozen=True)
class SacConfig:
    """SAC hyperparameters (the env's own options live in its `EnvConfig`)."""

    num_timesteps: int = 500_000  # env steps in all (rounded up to whole epochs)
    num_envs: int = 64  # envs stepped together; one actor step = num_envs env steps
    batch_size: int = 256  # transitions per gradient step
    grad_updates_per_step: int = 16  # gradient steps per actor step (update-to-data 1/4)
    learning_rate: float = 3e-4  # Adam, critics (and the actor unless actor_learning_rate)
    actor_learning_rate: float | None = None  # Adam, actor; None: learning_rate
    discounting: float = 0.99
    # Per-step rewards are <= 0.34 and a fall costs -1000 (`EnvConfig.fall_penalty`); scaled by
    # 0.1 the critics' targets stay within about [-100, 3.4].
    reward_scaling: float = 0.1
    tau: float = 0.005  # Polyak rate of the target critics
    init_alpha: float = 1.0  # initial entropy temperature (brax: 1), tuned towards -action/2
    actor_warmup_steps: int = 0  # gradient steps that train the critics only
    # Env steps collected (with the initial policy) before the first gradient step; they are
    # part of the first epoch(s), whose gradient steps are skipped until then.
    min_replay_size: int = 8192
    max_replay_size: int = 200_000  # bounded explicitly (brax defaults it to num_timesteps)
    hidden: tuple[int, ...] = HIDDEN
    normalize_observations: bool = True
    epoch_steps: int = 16_384  # env steps per jitted epoch: one log row and one checkpoint
    # Every `eval_every` epochs (0: never) the deterministic policy runs `eval_envs` episodes of
    # the env's episode length from fixed seeds (the same ones each time, so checkpoints are
    # compared on equal terms); with `keep_best`, the result is the best policy so evaluated.
    eval_every: int = 2
    eval_envs: int = 32
    keep_best: bool = True
    seed: int = 0

    def validate(self) -> None:
        for name in ("eval_every", "actor_warmup_steps"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise DpcError(f"SacConfig.{name} must be an int >= 0, got {v!r}.")
        for name in (
            "eval_envs",
            "num_timesteps",
            "num_envs",
            "batch_size",
            "grad_updates_per_step",
            "max_replay_size",
            "epoch_steps",
        ):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise DpcError(f"SacConfig.{name} must be an int >= 1, got {v!r}.")
        if self.min_replay_size < 0 or self.min_replay_size >= self.num_timesteps:
            raise DpcError(
                f"SacConfig.min_replay_size={self.min_replay_size} must be >= 0 and below "
                f"num_timesteps={self.num_timesteps}, or no learning happens."
            )
        if self.max_replay_size < max(self.min_replay_size, self.batch_size):
            raise DpcError(
                f"SacConfig.max_replay_size={self.max_replay_size} must hold at least "
                f"min_replay_size={self.min_replay_size} and batch_size={self.batch_size}."
            )
        for name in ("learning_rate", "reward_scaling", "tau", "init_alpha"):
            if not getattr(self, name) > 0:
                raise DpcError(f"SacConfig.{name} must be > 0, got {getattr(self, name)}.")
        lr = self.actor_learning_rate
        if lr is not None and not lr > 0:
            raise DpcError(f"SacConfig.actor_learning_rate must be > 0 or None, got {lr}.")
        if not 0.0 <= self.discounting < 1.0:
            raise DpcError(f"SacConfig.discounting must be in [0, 1), got {self.discounting}.")

    @property
    def actor_steps_per_epoch(self) -> int:
        return max(1, self.epoch_steps // self.num_envs)

    @property
    def env_steps_per_epoch(self) -> int:
        return self.actor_steps_per_epoch * self.num_envs

    @property
    def epochs(self) -> int:
        """Epochs to reach `num_timesteps` env steps."""
        return max(1, math.ceil(self.num_timesteps / self.env_steps_per_epoch))


@struct.dataclass
class TrainingState:
    """Everything that learns, and the counters."""

    policy_params: dict
    policy_opt: optax.OptState
    q_params: dict
    q_opt: optax.OptState
    target_q_params: dict
    log_alpha: jax.Array  # () log of the entropy temperature
    alpha_opt: optax.OptState
    normalizer: running_statistics.RunningStatisticsState  # over the observation
    env_steps: jax.Array  # () env steps so far
    grad_steps: jax.Array  # () gradient steps so far


@struct.dataclass
class BestPolicy:
    """The best policy the periodic evaluations have seen."""

    policy_params: dict
    normalizer: running_statistics.RunningStatisticsState
    score: jax.Array  # () mean evaluation return (NO_SCORE before the first evaluation)
    epoch: jax.Array  # () epochs trained before it was evaluated (-1: none yet; 0: the start)


NO_SCORE = -1e9  # finite on purpose: every array of a checkpoint stays finite


@struct.dataclass
class Carry:
    """What one epoch hands to the next; a checkpoint holds all of it but `env_state`."""

    training: TrainingState
    buffer: replay_buffers.ReplayBufferState
    key: jax.Array
    epoch: jax.Array  # () epochs done
    best: BestPolicy


@dataclasses.dataclass(frozen=True)
class TrainResult:
    policy: PolicyState
    history: list[dict]  # one row per epoch, the CSV's columns
    config: SacConfig
    timing: dict  # s: 'compile_seconds' of the epoch, 'train_seconds' of every epoch run here
    selected_epoch: int = -1  # epochs trained before the returned policy (0: the start)


@dataclasses.dataclass(frozen=True)
class Trainer:
    """The jitted pieces of one SAC run on one env (see `make_trainer`)."""

    config: SacConfig
    observation_size: int
    action_size: int
    networks: sac_networks.SACNetworks
    policy_optimizer: optax.GradientTransformation
    init: Callable  # key -> Carry
    reset: Callable  # key -> batched env state
    epoch: Callable  # (Carry, env_state) -> (Carry, env_state, metrics), jitted
    # (TrainingState, key, gate) -> {'return', 'fall_rate'}: deterministic policy, actions times
    # `gate` (1: the policy; 0: u = 0, i.e. MBC on the same episodes), jitted
    evaluate: Callable
    _compiled: dict = dataclasses.field(default_factory=dict, repr=False)
    compile_seconds: dict = dataclasses.field(default_factory=dict)  # name -> s, first compile

    def compiled(self, name: str, *args) -> Callable:
        """`epoch` or `evaluate` compiled ahead of time for these arguments, once per trainer
        (its compile time goes into `compile_seconds`)."""
        if name not in self._compiled:
            t0 = time.perf_counter()
            self._compiled[name] = getattr(self, name).lower(*args).compile()
            self.compile_seconds[name] = time.perf_counter() - t0
        return self._compiled[name]


def make_trainer(env, config: SacConfig) -> Trainer:
    """Build the SAC run on `env` (one unbatched env, e.g. a `LatentObsWrapper`)."""
    config.validate()
    batched = wrap_for_training(env)
    obs_size, action_size = env.observation_size, env.action_size
    nets = make_networks(obs_size, action_size, config.hidden, config.normalize_observations)
    make_policy = sac_networks.make_inference_fn(nets)
    alpha_loss, critic_loss, actor_loss = sac_losses.make_losses(
        nets, config.reward_scaling, config.discounting, action_size
    )
    policy_opt = optax.adam(config.actor_learning_rate or config.learning_rate)
    q_opt = optax.adam(config.learning_rate)
    alpha_opt = optax.adam(3e-4)  # brax's choice
    dummy_obs = jp.zeros((obs_size,))
    buffer = replay_buffers.UniformSamplingQueue(
        max_replay_size=config.max_replay_size,
        dummy_data_sample=Transition(
            observation=dummy_obs,
            action=jp.zeros((action_size,)),
            reward=0.0,
            discount=0.0,
            next_observation=dummy_obs,
            extras={"state_extras": {"truncation": 0.0}, "policy_extras": {}},
        ),
        sample_batch_size=config.batch_size * config.grad_updates_per_step,
    )

    def init(key: jax.Array) -> Carry:
        k_pi, k_q, k_buf, key = jax.random.split(key, 4)
        policy_params = nets.policy_network.init(k_pi)
        q_params = nets.q_network.init(k_q)
        log_alpha = jp.log(jp.asarray(config.init_alpha, jp.float32))
        training = TrainingState(
            policy_params=policy_params,
            policy_opt=policy_opt.init(policy_params),
            q_params=q_params,
            q_opt=q_opt.init(q_params),
            target_q_params=q_params,
            log_alpha=log_alpha,
            alpha_opt=alpha_opt.init(log_alpha),
            normalizer=running_statistics.init_state(jax.ShapeDtypeStruct((obs_size,), jp.float32)),
            env_steps=jp.zeros((), jp.int32),
            grad_steps=jp.zeros((), jp.int32),
        )
        best = BestPolicy(
            policy_params,
            training.normalizer,
            jp.asarray(NO_SCORE, jp.float32),
            jp.full((), -1, jp.int32),
        )
        return Carry(training, buffer.init(k_buf), key, jp.zeros((), jp.int32), best)

    def reset(key: jax.Array):
        return batched.reset(jax.random.split(key, config.num_envs))

    def experience(ts: TrainingState, env_state, buf, key):
        policy = make_policy((ts.normalizer, ts.policy_params))
        env_state, tr = acting.actor_step(
            batched, env_state, policy, key, extra_fields=("truncation",)
        )
        normalizer = ts.normalizer
        if config.normalize_observations:
            normalizer = running_statistics.update(normalizer, tr.observation)
        ts = ts.replace(normalizer=normalizer, env_steps=ts.env_steps + config.num_envs)
        return ts, env_state, buffer.insert(buf, tr)

    def sgd_step(carry, transitions):
        ts, key = carry
        key, k_alpha, k_critic, k_actor = jax.random.split(key, 4)
        a_loss, grads = jax.value_and_grad(alpha_loss)(
            ts.log_alpha, ts.policy_params, ts.normalizer, transitions, k_alpha
        )
        upd, alpha_state = alpha_opt.update(grads, ts.alpha_opt)
        log_alpha = optax.apply_updates(ts.log_alpha, upd)
        alpha = jp.exp(ts.log_alpha)
        c_loss, grads = jax.value_and_grad(critic_loss)(
            ts.q_params,
            ts.policy_params,
            ts.normalizer,
            ts.target_q_params,
            alpha,
            transitions,
            k_critic,
        )
        upd, q_state = q_opt.update(grads, ts.q_opt)
        q_params = optax.apply_updates(ts.q_params, upd)
        p_loss, grads = jax.value_and_grad(actor_loss)(
            ts.policy_params, ts.normalizer, ts.q_params, alpha, transitions, k_actor
        )
        upd, p_state = policy_opt.update(grads, ts.policy_opt)
        policy_params = optax.apply_updates(ts.policy_params, upd)
        # Critic warm-up: the actor and the temperature wait `actor_warmup_steps` gradient steps
        # (for a warm-started actor, so that a critic still at its random start does not undo it)
        learn_actor = ts.grad_steps >= config.actor_warmup_steps
        policy_params, p_state, log_alpha, alpha_state = jax.tree.map(
            lambda new, old: jp.where(learn_actor, new, old),
            (policy_params, p_state, log_alpha, alpha_state),
            (ts.policy_params, ts.policy_opt, ts.log_alpha, ts.alpha_opt),
        )
        target = jax.tree.map(
            lambda t, q: t * (1 - config.tau) + q * config.tau, ts.target_q_params, q_params
        )
        ts = ts.replace(
            policy_params=policy_params,
            policy_opt=p_state,
            q_params=q_params,
            q_opt=q_state,
            target_q_params=target,
            log_alpha=log_alpha,
            alpha_opt=alpha_state,
            grad_steps=ts.grad_steps + 1,
        )
        losses = {"critic_loss": c_loss, "actor_loss": p_loss, "alpha_loss": a_loss}
        return (ts, key), losses | {"alpha": jp.exp(log_alpha)}

    def episode_stats(env_state) -> dict[str, jax.Array]:
        """Sums over the envs whose episode ended at this step."""
        done = env_state.info["episode_done"]
        em = env_state.info["episode_metrics"]
        return {
            "episodes": jp.sum(done),
            "return_sum": jp.sum(done * em["sum_reward"]),
            "falls": jp.sum(done * em["fall"]),
            "nan_resets": jp.sum(done * em["nan_resets"]),
            "length_sum": jp.sum(done * em["length"]),
        }

    def learn(ts, buf, key):
        buf, transitions = buffer.sample(buf)
        transitions = jax.tree.map(
            lambda x: x.reshape((config.grad_updates_per_step, -1) + x.shape[1:]), transitions
        )
        (ts, _), losses = jax.lax.scan(sgd_step, (ts, key), transitions)
        return ts, buf, jax.tree.map(jp.mean, losses)

    def skip(ts, buf, key):
        del key
        zero = jp.zeros(())
        losses = {"critic_loss": zero, "actor_loss": zero, "alpha_loss": zero}
        return ts, buf, losses | {"alpha": jp.exp(ts.log_alpha)}

    def training_step(carry, _):
        c, env_state = carry
        key, k_exp, k_sgd = jax.random.split(c.key, 3)
        ts, env_state, buf = experience(c.training, env_state, c.buffer, k_exp)
        ready = buffer.size(buf) >= max(config.min_replay_size, config.batch_size)
        ts, buf, losses = jax.lax.cond(ready, learn, skip, ts, buf, k_sgd)
        c = c.replace(training=ts, buffer=buf, key=key)
        stats = episode_stats(env_state) | losses | {"learning": ready.astype(jp.float32)}
        return (c, env_state), stats

    def epoch(c: Carry, env_state):
        (c, env_state), stats = jax.lax.scan(
            training_step, (c, env_state), None, length=config.actor_steps_per_epoch
        )
        sums = ("episodes", "return_sum", "falls", "nan_resets", "length_sum")
        learning = jp.maximum(jp.sum(stats["learning"]), 1.0)
        metrics = {  # losses: means over the steps that learned
            k: jp.sum(v) if k in sums else jp.sum(v * stats["learning"]) / learning
            for k, v in stats.items()
            if k != "learning"
        }
        return c.replace(epoch=c.epoch + 1), env_state, metrics

    eval_steps = env.unwrapped.config.episode_length

    def evaluate(ts: TrainingState, key: jax.Array, gate: jax.Array) -> dict[str, jax.Array]:
        """`eval_envs` episodes of the deterministic policy (actions x `gate`), ended at their
        first done."""
        policy = make_policy((ts.normalizer, ts.policy_params), deterministic=True)
        state = jax.vmap(env.reset)(jax.random.split(key, config.eval_envs))
        zero = jp.zeros(config.eval_envs)

        def one(carry, _):
            state, ret, fell, ended = carry
            live = 1.0 - ended
            state = jax.vmap(env.step)(state, gate * policy(state.obs, key)[0])
            ret = ret + live * state.reward
            fell = jp.maximum(fell, live * state.metrics["fall"])
            return (state, ret, fell, jp.maximum(ended, live * state.done)), None

        carry = jax.lax.scan(one, (state, zero, zero, zero), None, length=eval_steps)[0]
        return {"return": jp.mean(carry[1]), "fall_rate": jp.mean(carry[2])}

    return Trainer(
        config=config,
        observation_size=obs_size,
        action_size=action_size,
        networks=nets,
        policy_optimizer=policy_opt,
        init=jax.jit(init),
        reset=jax.jit(reset),
        epoch=jax.jit(epoch, donate_argnums=(0, 1)),
        evaluate=jax.jit(evaluate),
    )


def policy_state(trainer: Trainer, policy_params: dict, normalizer) -> PolicyState:
    """The deployable actor: its parameters and observation statistics (brax running stats)."""
    n = trainer.observation_size
    if trainer.config.normalize_observations:
        norm = Normalizer(mean=normalizer.mean, std=normalizer.std)
    else:
        norm = Normalizer(mean=jp.zeros(n), std=jp.ones(n))
    return PolicyState(
        params=policy_params,
        obs_norm=norm,
        hidden=tuple(trainer.config.hidden),
        action_size=trainer.action_size,
    )


def _selected_epoch(trainer: Trainer, carry: Carry) -> int:
    best = int(carry.best.epoch)
    return best if trainer.config.keep_best and best >= 0 else int(carry.epoch)


def result_policy(trainer: Trainer, carry: Carry) -> PolicyState:
    """The best evaluated policy with `keep_best` (once one was evaluated), else the last."""
    if trainer.config.keep_best and int(carry.best.epoch) >= 0:
        return policy_state(trainer, carry.best.policy_params, carry.best.normalizer)
    return policy_state(trainer, carry.training.policy_params, carry.training.normalizer)


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
    `warm_start.regress_actor`); with evaluations on, the starting policy is scored as epoch 0."""
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
    elif actor_init is not None:
        carry = actor_init(trainer, carry)
    start_epoch = int(carry.epoch)
    env_state = trainer.reset(jax.random.fold_in(carry.key, start_epoch))
    if run_dir is not None:
        _rewrite_log(run_dir, history)
    total = config.epochs
    if start_epoch < total:
        epoch_fn = trainer.compiled("epoch", carry, env_state)
    eval_key = jax.random.PRNGKey(config.seed + 12345)  # the same episodes at every evaluation
    baseline = {}
    if config.eval_every and start_epoch < total:
        baseline = zero_action_baseline(trainer, carry, eval_key)
        if start_epoch == 0:  # the starting policy, a candidate for the best like any other
            row = _empty_row() | {"epoch": 0, "env_steps": 0, "grad_steps": 0, "episodes": 0}
            carry = _evaluate(trainer, carry, row, eval_key)
            row.update({f"eval_mbc_{k}": v for k, v in baseline.items()})
            history.append(row)
            if run_dir is not None:
                _append_csv(run_dir / LOG_FILE, row)
    t0 = time.perf_counter()
    with bar(total * config.env_steps_per_epoch, "sac", "step", progress) as pb:
        pb.update(start_epoch * config.env_steps_per_epoch)
        for epoch in range(start_epoch + 1, total + 1):
            t_epoch, grads_before = time.perf_counter(), int(carry.training.grad_steps)
            carry, env_state, metrics = epoch_fn(carry, env_state)
            metrics = jax.device_get(metrics)
            seconds = time.perf_counter() - t_epoch
            grads = int(carry.training.grad_steps) - grads_before
            row = _log_row(carry, metrics, seconds, grads, config, time.perf_counter() - t0)
            if config.eval_every and (epoch % config.eval_every == 0 or epoch == total):
                carry = _evaluate(trainer, carry, row, eval_key)
                row.update({f"eval_mbc_{k}": v for k, v in baseline.items()})
            history.append(row)
            if run_dir is not None:
                _append_csv(run_dir / LOG_FILE, row)
                checkpoint.save(run_dir, carry, meta, history)
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


def _trainer_for(env: Env | Trainer, config: SacConfig | None) -> Trainer:
    if not isinstance(env, Trainer):
        return make_trainer(env, config or SacConfig())
    if config is not None and config != env.config:
        raise DpcError("Pass no config with a Trainer: it was built with its own.")
    return env


def _rewrite_log(run_dir: pathlib.Path, history: list[dict]) -> None:
    """The log holds exactly the checkpoint's epochs (a kill may have left a row after the last
    checkpoint)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / LOG_FILE).unlink(missing_ok=True)
    for row in history:
        _append_csv(run_dir / LOG_FILE, row)


def _evaluate(trainer: Trainer, carry: Carry, row: dict, key: jax.Array) -> Carry:
    """Score the current policy into `row`; keep it as the best if it beats the best so far."""
    eval_fn = trainer.compiled("evaluate", carry.training, key, _ONE)
    scores = jax.device_get(eval_fn(carry.training, key, _ONE))
    row.update(eval_return=float(scores["return"]), eval_fall_rate=float(scores["fall_rate"]))
    if row["eval_return"] > float(carry.best.score):
        carry = carry.replace(best=_best(carry, row["eval_return"]))
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


def _meta(trainer: Trainer) -> dict:
    """What a checkpoint must agree on to be resumed: everything but the run's length
    (`num_timesteps` may grow) and the observation size."""
    config = dataclasses.asdict(trainer.config)
    config.pop("num_timesteps")
    return {"sac_config": config, "observation_size": trainer.observation_size}


def _log_row(carry: Carry, m: dict, seconds: float, grads: int, config: SacConfig, wall: float):
    """One CSV row: counters, returns and falls of the episodes that ended in the epoch, mean
    losses, and the epoch's env steps/s and gradient steps/s (env and learning together)."""
    episodes = float(m["episodes"])
    steps = config.env_steps_per_epoch

    def per_episode(key):
        return float(m[key]) / episodes if episodes else float("nan")

    return _empty_row() | {
        "epoch": int(carry.epoch),
        "env_steps": int(carry.training.env_steps),
        "grad_steps": int(carry.training.grad_steps),
        "episodes": int(episodes),
        "mean_return": per_episode("return_sum"),
        "fall_rate": per_episode("falls"),
        "nan_resets": int(m["nan_resets"]),
        "mean_length": per_episode("length_sum"),
        "critic_loss": float(m["critic_loss"]),
        "actor_loss": float(m["actor_loss"]),
        "alpha": float(m["alpha"]),
        "env_steps_per_s": steps / seconds,
        "grad_steps_per_s": grads / seconds,
        "epoch_seconds": seconds,
        "wall_seconds": wall,
    }


LOG_COLUMNS = (
    *("epoch", "env_steps", "grad_steps", "episodes", "mean_return", "fall_rate", "nan_resets"),
    *("mean_length", "critic_loss", "actor_loss", "alpha", "env_steps_per_s", "grad_steps_per_s"),
    *("epoch_seconds", "wall_seconds"),
    # the deterministic evaluation (on evaluation epochs), and its episodes with u = 0 (MBC)
    *("eval_return", "eval_fall_rate", "eval_mbc_return", "eval_mbc_fall_rate"),
)


def _empty_row() -> dict:
    return dict.fromkeys(LOG_COLUMNS, float("nan"))


def _append_csv(path: pathlib.Path, row: dict) -> None:
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)


__all__ = [
    "SacConfig",
    "TrainResult",
    "Trainer",
    "make_trainer",
    "policy_state",
    "restore_policy",
    "result_policy",
    "train",
]
