"""Where a SAC epoch's time goes: the paper recipe's pieces timed on their own (issue 26, item 5).

    .venv/bin/python experiments/profile_sac.py [--steps 16] [--repeats 3] [--recipe paper]
        [--only PREFIX ...]

Builds the recipe's trainer (`run.config.recipe`, default the paper's: 64 envs, 16 gradient
steps of batch 512 per actor step, the privileged critic) on the shipped export's `regular`
encoder, fills its replay buffer to `max_replay_size` with the env's own transitions (the
steady state of every epoch after the first ~12), then times, each as its own jitted program
run `--steps` actor steps at a time (`lax.scan`):

- `epoch`: the trainer's own training step (acting, insert, 16 gradient steps), as an epoch
  runs it;
- `acting`: one `acting.actor_step` of the 64 envs with the stochastic policy;
- `insert`: `buffer.insert` of 64 transitions into the full buffer;
- `sample`: `buffer.sample` of 16 x 512 transitions;
- `gradient steps`: 16 `sgd_step`s on sampled transitions (temperature, critics, actor, targets);
  and inside one, its `alpha`, `critic` and `actor` losses with their gradients.

Table: ms per actor step (per gradient step for the losses), best and median of `--repeats`
calls timed in turn (every program once per round, so a drift of this shared machine's speed
hits every row alike), the share of the `epoch` row, and each program's compile time. Times:
`dpc_mjx.timing`. `epoch, before` is the step as it ran before the ring buffer (brax's queue,
the sample inside the cond): the two epoch rows side by side are the change's measure.
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jp
import numpy as np
from brax.training import acting, replay_buffers
from brax.training.acme import running_statistics

from dpc_mjx.io.load import load
from dpc_mjx.io.shipped import shipped_for
from dpc_mjx.run import config as run_config
from dpc_mjx.run.pipeline import _sac_setup
from dpc_mjx.sac import trainer as sac_trainer
from dpc_mjx.timing import Stopwatch, run_calls


class _Adapter:
    """The shipped export's adapter parts that `_sac_setup` reads."""

    def __init__(self, art, arm: str):
        self.config, self.encoder = art.adapter_config, art.encoder(arm)


def _fill(p, trainer, carry):
    """The buffer filled to max_replay_size with transitions of the env under the initial
    policy (max_replay_size / num_envs actor steps)."""
    cfg = p.config

    def one(c, key):
        ts, env_state, buf = c
        policy = p.make_policy((ts.normalizer, ts.policy_params))
        env_state, tr = acting.actor_step(p.batched, env_state, policy, key, ("truncation",))
        return (ts, env_state, p.buffer.insert(buf, tr)), None

    steps = -(-cfg.max_replay_size // cfg.num_envs)
    env_state = trainer.reset(jax.random.PRNGKey(1))
    keys = jax.random.split(jax.random.PRNGKey(2), steps)
    fill = jax.jit(lambda c, k: jax.lax.scan(one, c, k)[0])
    with Stopwatch() as sw:
        _, env_state, buf = jax.block_until_ready(
            fill((carry.training, env_state, carry.buffer), keys)
        )
    print(
        f"buffer filled with {steps * cfg.num_envs:,} transitions in {sw.seconds:.0f} s", flush=True
    )
    return carry.replace(buffer=buf), env_state


def _step_before(p):
    """The training step as `sac.trainer` ran it before the ring buffer (commit dcb6a7a): brax's
    queue (a full one rolls on every insert) and the sample inside the `lax.cond`, which then
    holds the whole buffer. A reference for the epoch row only."""
    cfg, sgd_step = p.config, sac_trainer._sgd_step_fn(p)
    zeros = jp.zeros((1, p.buffer._data_shape[1]))  # one stored transition, as a pytree
    dummy = jax.tree.map(lambda x: x[0], p.buffer._unflatten_fn(zeros))
    queue = replay_buffers.UniformSamplingQueue(
        cfg.max_replay_size, dummy, cfg.batch_size * cfg.grad_updates_per_step
    )

    def learn(ts, buf, key):
        buf, tr = queue.sample(buf)
        tr = jax.tree.map(lambda x: x.reshape((cfg.grad_updates_per_step, -1) + x.shape[1:]), tr)
        (ts, _), losses = jax.lax.scan(sgd_step, (ts, key), tr)
        return ts, buf, jax.tree.map(jp.mean, losses)

    def skip(ts, buf, key):
        zero = jp.zeros(())
        losses = {"critic_loss": zero, "actor_loss": zero, "alpha_loss": zero}
        return ts, buf, losses | {"alpha": jp.exp(ts.log_alpha)}

    def step(x):
        c, env_state = x
        key, k_exp, k_sgd = jax.random.split(c.key, 3)
        ts = c.training
        policy = p.make_policy((ts.normalizer, ts.policy_params))
        env_state, tr = acting.actor_step(p.batched, env_state, policy, k_exp, ("truncation",))
        normalizer = ts.normalizer
        if cfg.normalize_observations:
            normalizer = running_statistics.update(normalizer, tr.observation)
        ts = ts.replace(normalizer=normalizer, env_steps=ts.env_steps + cfg.num_envs)
        buf = queue.insert(c.buffer, tr)
        ready = queue.size(buf) >= max(cfg.min_replay_size, cfg.batch_size)
        ts, buf, _ = jax.lax.cond(ready, learn, skip, ts, buf, k_sgd)
        return c.replace(training=ts, buffer=buf, key=key), env_state

    return step


def _programs(p, steps: int) -> dict:
    """name -> (fn(x) -> x, jitted, scanning `steps` times; x from (carry, env_state))."""
    cfg, buffer, sgd_step = p.config, p.buffer, sac_trainer._sgd_step_fn(p)
    training_step = sac_trainer._training_step_fn(p)
    alpha_loss, critic_loss, actor_loss = p.losses

    def scan(body):
        return jax.jit(lambda x: jax.lax.scan(lambda c, _: (body(c), None), x, None, steps)[0])

    def acting_body(c):
        ts, env_state, key = c
        key, k = jax.random.split(key)
        policy = p.make_policy((ts.normalizer, ts.policy_params))
        env_state, _ = acting.actor_step(p.batched, env_state, policy, k, ("truncation",))
        return ts, env_state, key

    def insert_body(c):
        buf, tr = c
        return buffer.insert(buf, tr), tr

    def sample_body(c):
        buf, acc = c
        buf, tr = buffer.sample(buf)
        return buf, acc + tr.reward[0]

    def learn_body(c):
        ts, buf, key = c
        key, k = jax.random.split(key)
        buf, tr = buffer.sample(buf)
        tr = jax.tree.map(lambda x: x.reshape((cfg.grad_updates_per_step, -1) + x.shape[1:]), tr)
        (ts, _), _ = jax.lax.scan(sgd_step, (ts, k), tr)
        return ts, buf, key

    def loss_body(loss, which):  # one loss and its gradient, applied with a negligible step
        def body(c):
            ts, tr, key = c
            key, k = jax.random.split(key)
            alpha = jp.exp(ts.log_alpha)
            args = {
                "log_alpha": (ts.policy_params, ts.normalizer, tr, k),
                "q_params": (ts.policy_params, ts.normalizer, ts.target_q_params, alpha, tr, k),
                "policy_params": (ts.normalizer, ts.q_params, alpha, tr, k),
            }[which]
            g = jax.grad(loss)(getattr(ts, which), *args)
            new = jax.tree.map(lambda a, b: a - 1e-9 * b, getattr(ts, which), g)
            return ts.replace(**{which: new}), tr, key

        return body

    def one_batch(c, e):  # batch_size transitions, as one gradient step reads them
        return jax.tree.map(lambda x: x[: cfg.batch_size], buffer.sample(c.buffer)[1])

    k0 = jax.random.PRNGKey(3)
    before = _step_before(p)
    return {
        "epoch (the trainer's step)": (
            scan(lambda c: training_step(c, None)[0]),
            lambda c, e: (c, e),
        ),
        "epoch, before (brax's queue, cond)": (scan(before), lambda c, e: (c, e)),
        "acting (64 env steps)": (scan(acting_body), lambda c, e: (c.training, e, k0)),
        "insert": (scan(insert_body), lambda c, e: (c.buffer, _transitions(p, c, e))),
        "sample": (scan(sample_body), lambda c, e: (c.buffer, jp.zeros(()))),
        "gradient steps (sample + 16 sgd steps)": (
            scan(learn_body),
            lambda c, e: (c.training, c.buffer, k0),
        ),
        "  alpha loss + grad, one": (
            scan(loss_body(alpha_loss, "log_alpha")),
            lambda c, e: (c.training, one_batch(c, e), k0),
        ),
        "  critic loss + grad, one": (
            scan(loss_body(critic_loss, "q_params")),
            lambda c, e: (c.training, one_batch(c, e), k0),
        ),
        "  actor loss + grad, one": (
            scan(loss_body(actor_loss, "policy_params")),
            lambda c, e: (c.training, one_batch(c, e), k0),
        ),
    }


def _transitions(p, carry, env_state):
    """One actor step's transitions (num_envs of them)."""
    policy = p.make_policy((carry.training.normalizer, carry.training.policy_params))
    key = jax.random.PRNGKey(4)
    return acting.actor_step(p.batched, env_state, policy, key, ("truncation",))[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--recipe", default="paper")
    ap.add_argument("--steps", type=int, default=16, help="actor steps per timed call")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", nargs="*", help="names (prefixes) of the programs to time")
    args = ap.parse_args()
    config = run_config.recipe(args.recipe)
    art = load(shipped_for(None))
    latent_env, sac_config = _sac_setup(config, _Adapter(art, config.arm))
    trainer = sac_trainer.make_trainer(latent_env, sac_config)
    env = (
        sac_trainer.PrivilegedCriticWrapper(latent_env)
        if sac_config.critic_privileged
        else latent_env
    )
    p = sac_trainer._parts(
        env, sac_config, sac_trainer.devices.mesh(local=True), trainer.observation_size
    )
    carry = trainer.init(jax.random.PRNGKey(0))
    carry, env_state = _fill(p, trainer, carry)
    print(
        f"recipe {args.recipe}: {sac_config.num_envs} envs, "
        f"{sac_config.grad_updates_per_step} gradient steps of batch {sac_config.batch_size} "
        f"per actor step; {args.steps} actor steps per call"
    )
    programs = {
        name: entry
        for name, entry in _programs(p, args.steps).items()
        if not args.only or any(name.strip().startswith(o) for o in args.only)
    }
    compiled, compile_s, times = {}, {}, {}
    for name, (fn, make_x) in programs.items():
        x = make_x(carry, env_state)
        with Stopwatch() as sw:
            program = fn.lower(x).compile()
        compile_s[name] = sw.seconds
        compiled[name] = (program, jax.block_until_ready(program(x)))
        print(f"  compiled {name} in {sw.seconds:.1f} s", flush=True)
    for _ in range(args.repeats):  # interleaved: a drift of the machine's speed hits every row
        for name, (program, x) in compiled.items():
            times.setdefault(name, []).append(run_calls(program, x, 1)[0])
    best = {name: min(t) for name, t in times.items()}
    epoch_ms = 1e3 * best.get(next(iter(best)), float("nan")) / args.steps
    print(
        "| piece | ms per actor step, best (a loss: per gradient step) | median | "
        "share of the epoch (best) | compile s |"
    )
    print("|---|---:|---:|---:|---:|")
    for name, seconds in best.items():
        ms, median = 1e3 * seconds / args.steps, 1e3 * np.median(times[name]) / args.steps
        share = f"{100 * ms / epoch_ms:.0f} %"
        print(f"| {name} | {ms:.2f} | {median:.2f} | {share} | {compile_s[name]:.1f} |")
    losses = [1e3 * best[n] / args.steps for n in best if "loss" in n]
    if len(losses) == 3:
        floor = sac_config.grad_updates_per_step * sum(losses)
        print(
            f"\nthe three losses and their gradients alone, "
            f"x {sac_config.grad_updates_per_step}: {floor:.1f} ms per actor step"
        )


if __name__ == "__main__":
    main()
