"""Beyond the paper: start the high-level estimator from a privileged regression.

The paper trains SAC from scratch. On our reaching task SAC from scratch did not beat MBC within
1e6 env steps on a CPU (docs/results.md), while a policy regressed on the oracle's u did. So the
actor may start from that regression, a teacher-student warm start: the teacher is the oracle
(the measured mount wrench, privileged), the student sees only what DPC sees, `[s_body, z]`; SAC
then trains it on the paper's reward as usual (`SacConfig.actor_warmup_steps` lets the critics
learn its value first).

    carry, report = regress_actor(trainer, carry, adapter, data, u_scale)

Fit: the actor's mean action tanh(loc) to clip(u_oracle / u_scale, -0.95, 0.95) (MSE), and its
exploration scale softplus(.) + 1e-3 to `init_std` (pre-tanh), on the adapter's random-motion
samples (`Dataset.u_oracle`, collected with MBC); the observation statistics start from the same
samples. The last `val_fraction` of the samples are held out: the epoch with the lowest held-out
loss is kept (at most `epochs`, stopping after `patience` without improvement), so components of
u that the observation does not predict stay near their mean instead of fitting noise, and the
report gives the held-out R^2 per component.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
import optax
from brax.training.acme import running_statistics

from dpc_mjx.adapter.data import Dataset
from dpc_mjx.adapter.networks import AdapterConfig, EncoderState, encode
from dpc_mjx.errors import DpcError
from dpc_mjx.sac.train import Carry, Trainer

U_CLIP = 0.95  # targets stay inside tanh's range


def regress_actor(
    trainer: Trainer,
    carry: Carry,
    adapter_config: AdapterConfig,
    encoder: EncoderState,
    data: Dataset,
    u_scale,
    *,
    epochs: int = 30,
    patience: int = 5,
    batch_size: int = 256,
    learning_rate: float = 1e-3,
    init_std: float = 0.1,
    val_fraction: float = 0.1,
    seed: int = 0,
) -> tuple[Carry, dict]:
    """`carry` with its actor and observation statistics fitted to the oracle's u on `data`, and
    a report {'r2': per u component on held-out samples, 'val_mse', 'samples'}."""
    if data.u_oracle is None:
        raise DpcError("The dataset has no u_oracle column; collect it with adapter.collect.")
    x = np.asarray(
        jp.concatenate(
            [jp.asarray(data.s_body), encode(adapter_config, encoder, data.encoder_input)], -1
        )
    )  # (N, 11 + latent) the policy's observation [s_body, z]
    if x.shape[1] != trainer.observation_size:
        raise DpcError(
            f"The policy observes {trainer.observation_size} values, [s_body, z] has {x.shape[1]}."
        )
    y = np.clip(data.u_oracle / np.asarray(u_scale, np.float32), -U_CLIP, U_CLIP)  # (N, 6)
    n_val = max(1, round(len(x) * val_fraction))
    x_tr, y_tr, x_va, y_va = x[:-n_val], y[:-n_val], x[-n_val:], y[-n_val:]
    normalizer = running_statistics.update(carry.training.normalizer, jp.asarray(x_tr))
    policy = trainer.networks.policy_network
    action_size = trainer.action_size

    def predict(params, obs):
        loc, scale = jp.split(policy.apply(normalizer, params, obs), 2, axis=-1)
        return jp.tanh(loc), jax.nn.softplus(scale) + 1e-3

    def loss(params, obs, target):
        mean, std = predict(params, obs)
        return jp.mean((mean - target) ** 2) + jp.mean((std - init_std) ** 2)

    opt = optax.adam(learning_rate)
    n, bs = len(x_tr), min(batch_size, len(x_tr))
    xs, ys = jp.asarray(x_tr), jp.asarray(y_tr)

    @jax.jit
    def epoch(params, state, key):
        order = jax.random.permutation(key, n)[: (n // bs) * bs].reshape(-1, bs)

        def step(carry, rows):
            p, s = carry
            grads = jax.grad(loss)(p, xs[rows], ys[rows])
            updates, s = opt.update(grads, s, p)
            return (optax.apply_updates(p, updates), s), None

        return jax.lax.scan(step, (params, state), order)[0]

    val_loss = jax.jit(lambda p: loss(p, jp.asarray(x_va), jp.asarray(y_va)))
    params = best = carry.training.policy_params
    state, best_val, best_epoch = opt.init(params), float(val_loss(params)), 0
    key = jax.random.PRNGKey(seed)
    for i in range(1, epochs + 1):  # early stopping: the best validation epoch is kept
        key, k = jax.random.split(key)
        params, state = epoch(params, state, k)
        value = float(val_loss(params))
        if value < best_val:
            best, best_val, best_epoch = params, value, i
        elif i - best_epoch >= patience:
            break
    params = best
    pred = np.asarray(predict(params, jp.asarray(x_va))[0])
    resid = ((pred - y_va) ** 2).sum(0)
    spread = np.maximum(((y_va - y_va.mean(0)) ** 2).sum(0), 1e-12)
    report = {
        "samples": len(x),
        "best_epoch": best_epoch,
        "val_mse": float(np.mean((pred - y_va) ** 2)),
        "r2": [float(v) for v in 1.0 - resid / spread][:action_size],
    }
    training = carry.training.replace(
        policy_params=params,
        policy_opt=trainer.policy_optimizer.init(params),
        normalizer=normalizer,
    )
    return carry.replace(training=training), report
