"""The jitted pieces of one SAC run (`make_trainer`): brax's SAC in our epoch, and an evaluation.

The paper trains the high-level estimator with SAC (§III-C). The algorithm is brax's
(`brax.training.agents.sac`): its actor and twin critics (built in `sac.networks`), its losses
(clipped double-Q targets, entropy temperature tuned towards -action_size/2), its uniform replay
buffer (written in place as a ring, `sac.replay`) and `acting.actor_step`; `sgd_step` updates
temperature, critics, actor and the Polyak-averaged target critics as brax's does. Ours: the
epoch (`epoch_steps` env steps in one jitted `lax.scan`, each actor step followed by
`grad_updates_per_step` gradient steps once the buffer holds `min_replay_size` transitions), the
critic warm-up (`actor_warmup_steps`), the initial temperature, and `evaluate`: deterministic
episodes (actions times a `gate`, 0 giving the same episodes with u = 0) on the library's one
rollout core, `envs.rollout.scan_steps`.

On several devices of its process (`devices.mesh(local=True)`) the env batch is sharded over them:
each device steps its envs (`devices.constrain` on the env state after every step), the networks,
the replay buffer and the gradient steps are replicated (the transitions gathered into the
buffer). `num_envs` must be a multiple of the device count; the evaluation pads `eval_envs`.

What an epoch carries (`Carry`, a pytree that a checkpoint holds) is `sac.state`'s. The host loop
around these pieces is `sac.train`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import jax
import jax.numpy as jp
import optax
from brax.training import acting
from brax.training.acme import running_statistics
from brax.training.agents.sac import losses as sac_losses
from brax.training.agents.sac import networks as sac_networks
from brax.training.types import Transition

from dpc_mjx import devices
from dpc_mjx.envs import rollout
from dpc_mjx.envs.wrappers import wrap_for_training
from dpc_mjx.policy.policy import PAPER_INPUTS
from dpc_mjx.sac.config import SacConfig
from dpc_mjx.sac.env import PrivilegedCriticWrapper
from dpc_mjx.sac.networks import make_networks
from dpc_mjx.sac.replay import RingSamplingQueue
from dpc_mjx.sac.state import NO_SCORE, BestPolicy, Carry, TrainingState


@dataclasses.dataclass(frozen=True)
class Trainer:
    """The jitted pieces of one SAC run on one env (see `make_trainer`)."""

    config: SacConfig
    observation_size: int  # the actor's (policy) observation
    critic_observation_size: int  # what the replay buffer and the critics hold (>= the actor's)
    action_size: int
    policy_inputs: tuple[str, ...]  # the blocks of the observation (`policy.policy.POLICY_INPUTS`)
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


@dataclasses.dataclass(frozen=True)
class _Parts:
    """What the jitted pieces of one run close over, built once by `make_trainer`."""

    config: SacConfig
    mesh: jax.sharding.Mesh
    env: object  # the unbatched env (with the critics' privileged values when asked)
    batched: object  # `env` behind the training wrappers (auto-reset, episode limit)
    obs_size: int  # what the replay buffer and the critics hold
    action_size: int
    nets: sac_networks.SACNetworks
    make_policy: Callable  # (normalizer, policy params), deterministic -> policy
    losses: tuple[Callable, Callable, Callable]  # brax's alpha, critic and actor losses
    policy_opt: optax.GradientTransformation
    q_opt: optax.GradientTransformation
    alpha_opt: optax.GradientTransformation
    buffer: RingSamplingQueue


def _parts(env, config: SacConfig, mesh, policy_obs_size: int) -> _Parts:
    """The networks, losses, optimizers and replay buffer of a run on `env` (its actor seeing
    the first `policy_obs_size` values of the observation)."""
    batched = wrap_for_training(env)
    obs_size, action_size = env.observation_size, env.action_size  # obs_size: what is stored
    nets = make_networks(
        policy_obs_size,
        action_size,
        config.hidden,
        config.normalize_observations,
        critic_extra=obs_size - policy_obs_size,
    )
    make_policy = sac_networks.make_inference_fn(nets)
    losses = sac_losses.make_losses(nets, config.reward_scaling, config.discounting, action_size)
    policy_opt = optax.adam(config.actor_learning_rate or config.learning_rate)
    q_opt = optax.adam(config.learning_rate)
    alpha_opt = optax.adam(3e-4)  # brax's choice
    dummy_obs = jp.zeros((obs_size,))
    buffer = RingSamplingQueue(
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
    return _Parts(
        config=config,
        mesh=mesh,
        env=env,
        batched=batched,
        obs_size=obs_size,
        action_size=action_size,
        nets=nets,
        make_policy=make_policy,
        losses=tuple(losses),
        policy_opt=policy_opt,
        q_opt=q_opt,
        alpha_opt=alpha_opt,
        buffer=buffer,
    )


def make_trainer(env, config: SacConfig) -> Trainer:
    """Build the SAC run on `env` (one unbatched env, e.g. a `LatentObsWrapper`; with
    `config.critic_privileged`, the trainer extends its observation with the privileged values
    for the critics, `PrivilegedCriticWrapper`)."""
    config.validate()
    mesh = devices.mesh(local=True)  # SAC trains within one process, on its own devices
    devices.check_divisible(config.num_envs, "sac.num_envs", mesh)
    policy_obs_size = env.observation_size  # the actor's input
    if config.critic_privileged:  # the privileged values come from the DpcEnv inside
        env = PrivilegedCriticWrapper(env)
    p = _parts(env, config, mesh, policy_obs_size)
    return Trainer(
        config=config,
        observation_size=policy_obs_size,
        critic_observation_size=p.obs_size,
        policy_inputs=tuple(getattr(env, "policy_inputs", PAPER_INPUTS)),
        action_size=p.action_size,
        networks=p.nets,
        policy_optimizer=p.policy_opt,
        init=jax.jit(_init_fn(p)),
        reset=jax.jit(_reset_fn(p)),
        epoch=jax.jit(_epoch_fn(p), donate_argnums=(0, 1)),
        evaluate=jax.jit(_evaluate_fn(p)),
    )


def _init_fn(p: _Parts) -> Callable:
    """key -> Carry: the networks at their random start, empty buffer, no best policy yet."""

    def init(key: jax.Array) -> Carry:
        k_pi, k_q, k_buf, key = jax.random.split(key, 4)
        policy_params = p.nets.policy_network.init(k_pi)
        q_params = p.nets.q_network.init(k_q)
        log_alpha = jp.log(jp.asarray(p.config.init_alpha, jp.float32))
        training = TrainingState(
            policy_params=policy_params,
            policy_opt=p.policy_opt.init(policy_params),
            q_params=q_params,
            q_opt=p.q_opt.init(q_params),
            target_q_params=q_params,
            log_alpha=log_alpha,
            alpha_opt=p.alpha_opt.init(log_alpha),
            normalizer=running_statistics.init_state(
                jax.ShapeDtypeStruct((p.obs_size,), jp.float32)
            ),
            env_steps=jp.zeros((), jp.int32),
            grad_steps=jp.zeros((), jp.int32),
        )
        best = BestPolicy(
            policy_params,
            training.normalizer,
            jp.asarray(NO_SCORE, jp.float32),
            jp.full((), -1, jp.int32),
        )
        return Carry(training, p.buffer.init(k_buf), key, jp.zeros((), jp.int32), best)

    return init


def _reset_fn(p: _Parts) -> Callable:
    """key -> the batched env state, each env on its device."""

    def reset(key: jax.Array):
        state = p.batched.reset(jax.random.split(key, p.config.num_envs))
        return devices.constrain(state, p.config.num_envs, p.mesh)

    return reset


def _sgd_step_fn(p: _Parts) -> Callable:
    """((TrainingState, key), transitions) -> ((TrainingState, key), losses): one gradient step
    of the temperature, the critics, the actor and the target critics (brax's `sgd_step`)."""
    alpha_loss, critic_loss, actor_loss = p.losses
    config, policy_opt, q_opt, alpha_opt = p.config, p.policy_opt, p.q_opt, p.alpha_opt

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

    return sgd_step


def _episode_stats(env_state) -> dict[str, jax.Array]:
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


def _training_step_fn(p: _Parts) -> Callable:
    """((Carry, env_state), _) -> ((Carry, env_state), stats): one actor step of every env, then
    `grad_updates_per_step` gradient steps once the buffer holds enough transitions."""
    config, buffer, sgd_step = p.config, p.buffer, _sgd_step_fn(p)

    def experience(ts: TrainingState, env_state, buf, key):
        policy = p.make_policy((ts.normalizer, ts.policy_params))
        env_state, tr = acting.actor_step(
            p.batched, env_state, policy, key, extra_fields=("truncation",)
        )
        env_state = devices.constrain(env_state, config.num_envs, p.mesh)  # each env on its device
        normalizer = ts.normalizer
        if config.normalize_observations:
            normalizer = running_statistics.update(normalizer, tr.observation)
        ts = ts.replace(normalizer=normalizer, env_steps=ts.env_steps + config.num_envs)
        return ts, env_state, buffer.insert(buf, tr)

    def learn(ts, transitions, key):  # transitions: (grad_updates_per_step * batch_size, ...)
        transitions = jax.tree.map(
            lambda x: x.reshape((config.grad_updates_per_step, -1) + x.shape[1:]), transitions
        )
        (ts, _), losses = jax.lax.scan(sgd_step, (ts, key), transitions)
        return ts, jax.tree.map(jp.mean, losses)

    def skip(ts, transitions, key):
        del transitions, key
        zero = jp.zeros(())
        losses = {"critic_loss": zero, "actor_loss": zero, "alpha_loss": zero}
        return ts, losses | {"alpha": jp.exp(ts.log_alpha)}

    def training_step(carry, _):
        c, env_state = carry
        key, k_exp, k_sgd = jax.random.split(c.key, 3)
        ts, env_state, buf = experience(c.training, env_state, c.buffer, k_exp)
        ready = buffer.size(buf) >= max(config.min_replay_size, config.batch_size)
        # Sampled on every step, outside the cond, so that the cond's operands do not hold the
        # 57 MB buffer (XLA may copy a cond's operands); the buffer's key moves on only when the
        # sample is used, so the samples are those drawn inside the cond before.
        sampled, transitions = buffer.sample(buf)
        buf = buf.replace(key=jp.where(ready, sampled.key, buf.key))
        ts, losses = jax.lax.cond(ready, learn, skip, ts, transitions, k_sgd)
        c = c.replace(training=ts, buffer=buf, key=key)
        stats = _episode_stats(env_state) | losses | {"learning": ready.astype(jp.float32)}
        return (c, env_state), stats

    return training_step


def _epoch_fn(p: _Parts) -> Callable:
    """(Carry, env_state) -> (Carry, env_state, metrics): `actor_steps_per_epoch` training steps
    in one `lax.scan`; metrics: episode sums, losses averaged over the steps that learned."""
    training_step = _training_step_fn(p)

    def epoch(c: Carry, env_state):
        (c, env_state), stats = jax.lax.scan(
            training_step, (c, env_state), None, length=p.config.actor_steps_per_epoch
        )
        sums = ("episodes", "return_sum", "falls", "nan_resets", "length_sum")
        learning = jp.maximum(jp.sum(stats["learning"]), 1.0)
        metrics = {  # losses: means over the steps that learned
            k: jp.sum(v) if k in sums else jp.sum(v * stats["learning"]) / learning
            for k, v in stats.items()
            if k != "learning"
        }
        return c.replace(epoch=c.epoch + 1), env_state, metrics

    return epoch


def _evaluate_fn(p: _Parts) -> Callable:
    """(TrainingState, key, gate) -> {'return', 'fall_rate'} (see `Trainer.evaluate`)."""
    env, config, mesh = p.env, p.config, p.mesh
    eval_steps = env.unwrapped.config.episode_length

    def evaluate(ts: TrainingState, key: jax.Array, gate: jax.Array) -> dict[str, jax.Array]:
        """`eval_envs` episodes of the deterministic policy (actions x `gate`), ended at their
        first done."""
        policy = p.make_policy((ts.normalizer, ts.policy_params), deterministic=True)
        n, size = config.eval_envs, devices.padded(config.eval_envs, mesh)  # copies past n
        keys = devices.pad(jax.random.split(key, n), size)
        state = devices.constrain(jax.vmap(env.reset)(keys), size, mesh)
        carry = (state, rollout.Tally.zeros(size))

        def act(obs, _):  # deterministic: the key is not used
            return gate * policy(obs, key)[0]

        def step(state, action):
            return devices.constrain(jax.vmap(env.step)(state, action), size, mesh)

        keys = jax.random.split(key, eval_steps)
        (_, tally), _ = rollout.scan_steps(step, act, carry, keys)
        return {"return": jp.mean(tally.ret[:n]), "fall_rate": jp.mean(tally.fell[:n])}

    return evaluate


__all__ = ["NO_SCORE", "BestPolicy", "Carry", "Trainer", "TrainingState", "make_trainer"]
