"""Beyond the paper: start the high-level estimator from a privileged regression.

The paper trains SAC from scratch. On our reaching task SAC from scratch did not beat MBC within 1e6
env steps on a CPU (docs/results-estimator.md), while a policy regressed on the oracle's u did. So
the actor may start from that regression, a teacher-student warm start: the teacher is the oracle
(the measured mount wrench, privileged), the student sees only what DPC sees (its observation,
`policy.POLICY_INPUTS`); SAC then trains it on the paper's reward as usual
(`SacConfig.actor_warmup_steps` lets the critics learn its value first).

    carry, report = regress_actor(trainer, carry, adapter, data, u_scale)

Fit: the actor's mean action tanh(loc) to clip(u_oracle / u_scale, -0.95, 0.95) (MSE; u_oracle in
the policy's frame, `EnvConfig.u_frame`: turned into the yaw frame by the row's heading), and its
exploration scale softplus(.) + 1e-3 to `init_std` (pre-tanh), on the adapter's random-motion
samples (`Dataset.u_oracle`, collected with MBC; with `EnvConfig.u_base` 'observer' the target is
u_oracle - u_obs, the part of u the observer's estimate misses, in the same frame and scale, with
'gravity' u_oracle - u_gravity, the part the arms' weight at their pose leaves, and
with 'model' u_unmodelled, what the arms' model cannot know (the oracle's u minus the model
wrench on the simulator's exact state and accelerations: the pushes and the payload as the mount
feels them; privileged labels, `Dataset.u_unmodelled`; with `model_target` 'payload' only its
slow part, the payloads' weight, `Dataset.u_payload`; with 'felt' the oracle's u minus the model
wrench of the servos' motion, `Dataset.u_felt`), and
with `slow_s` > 0 only its fast part: minus its exponential average over `slow_s` seconds along
each episode, `regression_target`); the
observation statistics start from the same samples. The last `val_fraction` of the samples are
held out (`Dataset.split`): the epoch with the lowest held-out loss is kept (`fitting.fit`: at
most `epochs`, stopping after `patience` without improvement), so components of u that the
observation does not predict stay near their mean instead of fitting noise, and the report gives
the held-out R^2 per component.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jp
import numpy as np
from brax.training.acme import running_statistics

from dpc_mjx import fitting
from dpc_mjx.adapter.data import Dataset
from dpc_mjx.adapter.networks import AdapterConfig, EncoderState
from dpc_mjx.errors import DpcError
from dpc_mjx.policy.policy import observation_size, policy_observation
from dpc_mjx.stats import r2

U_CLIP = 0.95  # targets stay inside tanh's range
# A target component whose held-out std is below this (action units: 0.015 N of a 15 N bound)
# does not vary (no push along it); its R^2 is reported as None, not 1 - resid / ~0
_CONSTANT_STD = 1e-3
# What the actor is fitted to, in words, by `EnvConfig.u_base` (`regression_target`)
REGRESSION_TARGETS = {
    "zero": "the oracle's u",
    "observer": "u_oracle - u_obs",
    "gravity": "u_oracle - u_gravity",
    "model": "u_unmodelled (u_oracle - the model wrench on the exact state)",
}
# What of the unmodelled wrench u_base 'model' learns (`RunConfig.model_target`)
MODEL_TARGETS = {
    "unmodelled": REGRESSION_TARGETS["model"],
    "payload": "u_payload (the payloads' weight at the grippers and its moment)",
    "felt": "u_felt (u_oracle - the model wrench of the servos' motion on the exact state)",
}


def target_name(u_base: str, model_target: str = "unmodelled") -> str:
    """What the actor is fitted to, in words, for `EnvConfig.u_base` and `model_target`."""
    return MODEL_TARGETS[model_target] if u_base == "model" else REGRESSION_TARGETS[u_base]


# `trainer` is SAC's (`sac.trainer.Trainer`, `Carry`), taken by what it has, so that this layer
# imports no SAC: trainer.observation_size, .critic_observation_size, .action_size,
# .policy_inputs, .networks.policy_network, .policy_optimizer; carry.training.policy_params,
# .normalizer (and `.replace`).
_Trainer = Any
_Carry = Any


def regress_actor(
    trainer: _Trainer,
    carry: _Carry,
    adapter_config: AdapterConfig,
    encoder: EncoderState,
    data: Dataset,
    u_scale,
    *,
    u_frame: str = "yaw",
    u_base: str = "zero",
    slow_s: float | tuple[float, float] = 0.0,
    step_s: float = 0.02,
    model_target: str = "unmodelled",
    epochs: int = 30,
    patience: int = 5,
    batch_size: int = 256,
    learning_rate: float = 1e-3,
    init_std: float = 0.1,
    val_fraction: float = 0.1,
    seed: int = 0,
) -> tuple[_Carry, dict]:
    """`carry` with its actor and observation statistics fitted to the oracle's u on `data`
    (in `u_frame`, the env's `EnvConfig.u_frame`; with `u_base` 'observer' the residual
    u_oracle - u_obs, `EnvConfig.u_base`, its fast part with `slow_s` > 0; `step_s` s between
    a row and the next of its episode, the env step; `model_target` with u_base 'model'), and a
    report {'r2': per u component on held-out samples, 'val_mse', 'samples'}."""
    _check_trainer(trainer, adapter_config)
    # (N, 6) over the whole data (the slow part runs along episodes), then split as the rows
    target = regression_target(data, u_scale, u_frame, u_base, slow_s, step_s, model_target)
    target = jp.asarray(target)

    def arrays(part: Dataset, rows: slice) -> tuple[jax.Array, jax.Array]:
        """(obs (N, observation_size) the policy's, target (N, 6) in action units)."""
        obs = policy_observation(
            adapter_config, encoder, jp.asarray(part.observation), trainer.policy_inputs
        )
        return obs, target[rows]

    train_part, val_part = data.split(val_fraction)
    train = arrays(train_part, slice(0, len(train_part)))
    val = arrays(val_part, slice(len(train_part), None))
    normalizer = running_statistics.update(carry.training.normalizer, train[0])
    predict = _predictor(trainer.networks.policy_network, normalizer)

    def loss(params, batch):
        obs, target = batch
        mean, std = predict(params, obs)
        return jp.mean((mean - target) ** 2) + jp.mean((std - init_std) ** 2)

    params, history = fitting.fit(
        loss,
        carry.training.policy_params,
        train,
        val,
        learning_rate=learning_rate,
        batch_size=batch_size,
        epochs=epochs,
        patience=patience,
        key=jax.random.PRNGKey(seed),
        diverged_hint="lower the learning_rate of regress_actor or check the data for NaN.",
        desc="actor regression",
    )
    report = _report(predict, params, val, history, len(data), trainer.action_size)
    training = carry.training.replace(
        policy_params=params,
        policy_opt=trainer.policy_optimizer.init(params),
        normalizer=normalizer,
    )
    return carry.replace(training=training), report


def regression_target(  # noqa: PLR0913, PLR0917 (the data, its units, and the target's form)
    data: Dataset,
    u_scale,
    u_frame: str,
    u_base: str,
    slow_s: float | tuple[float, float] = 0.0,
    step_s: float = 0.02,
    model_target: str = "unmodelled",
) -> np.ndarray:
    """(N, 6) what the actor's mean action is fitted to, in action units: clip(u / u_scale,
    -U_CLIP, U_CLIP) with u = u_oracle in `u_frame`, minus the observer's estimate u_obs (the
    same frame) where `u_base` is 'observer' (`EnvConfig.u_base`), minus the arms' gravity
    wrench u_gravity (`Dataset.u_gravity`) where it is 'gravity', and only what the arms' model
    cannot know (`Dataset.u_unmodelled`) where it is 'model': not u_oracle minus the model
    wrench the controller computes, whose difference also holds the arms' reaction to the
    trunk's actual acceleration, which the controller leaves to the balance QP on purpose (a
    policy that learns it feeds it back an env step late: docs/results-arm-model.md); with
    `model_target` 'payload' only the payloads' weight wrench (`Dataset.u_payload`), its slow
    part, leaving the pushes to the balance QP's feedback; with 'felt' what the mount feels
    beyond the model wrench of the servos' motion (`Dataset.u_felt`), the wrench the
    controller's own model (servo law, `arm_estimate`) leaves (`MODEL_TARGETS`). With
    `slow_s` > 0 (s; one
    number, or (force, torque) where 0 keeps that part whole; u_base 'observer' only) the
    residual d = u_oracle - u_obs loses its slow part, its exponential average along each
    episode (`slow_part`): u = d - slow(d), the correction of the observer's lag that a policy
    held over one env step can give, while the observer keeps what changes slower (the arm's
    weight, and its bias from the legs' model error, which acts as integral action on the
    balance QP: control/observer.py)."""
    taus = np.repeat(np.broadcast_to(np.asarray(slow_s, np.float32), (2,)), 3)  # (6,) s
    u = data.u_oracle_in(u_frame)
    if u_base == "observer":  # the residual of the observer's estimate
        u = u - data.u_obs_in(u_frame)
        if np.any(taus > 0):
            slow = slow_part(u, data.previous_rows(), step_s / (taus + step_s))
            u = u - np.where(taus > 0, slow, 0.0)
    elif np.any(taus > 0):
        raise DpcError("slow_s splits the observer's residual: it needs u_base='observer'.")
    elif u_base == "gravity":  # what the arms' weight at their pose leaves
        u = u - data.u_gravity_in(u_frame)
    elif u_base == "model" and model_target == "payload":  # its slow part (privileged labels)
        u = data.u_payload_in(u_frame)
    elif u_base == "model" and model_target == "felt":  # what the mount feels (privileged)
        u = data.u_felt_in(u_frame)
    elif u_base == "model":  # what the arms' model cannot know (privileged labels)
        u = data.u_unmodelled_in(u_frame)
    return np.clip(u / np.asarray(u_scale, np.float32), -U_CLIP, U_CLIP)


def slow_part(values: np.ndarray, previous: np.ndarray, alpha) -> np.ndarray:
    """(N, k) the exponential average of `values` (N, k) along each episode, causal:
    a_j = a_i + alpha (v_j - a_i) with i = previous[j] (the row one step earlier, `previous` from
    `Dataset.previous_rows`, each before its row), a_j = v_j at an episode's first row (-1).
    alpha = dt / (tau + dt): time constant tau for rows dt apart (a number, or (k,) per column)."""
    out = np.empty_like(values)
    for j, i in enumerate(previous.tolist()):
        out[j] = values[j] if i < 0 else out[i] + alpha * (values[j] - out[i])
    return out


def _check_trainer(trainer: _Trainer, adapter_config: AdapterConfig) -> None:
    """`DpcError` unless the trainer's actor observes what the regression feeds it."""
    expected = observation_size(trainer.policy_inputs, adapter_config.latent_size)
    if trainer.observation_size != expected:
        raise DpcError(
            f"The policy observes {trainer.observation_size} values, {trainer.policy_inputs} "
            f"with latent_size {adapter_config.latent_size} make {expected}."
        )
    if trainer.critic_observation_size != trainer.observation_size:
        raise DpcError(
            "The oracle regression cannot start a run with an asymmetric critic "
            "(SacConfig.critic_privileged): its data has no privileged values for the critics' "
            "statistics. Use actor_init='random' or critic_privileged=false."
        )


def _predictor(policy_network, normalizer):
    """params, obs (N, observation_size) -> (mean action tanh(loc), exploration scale), (N, 6)
    each."""

    def predict(params, obs):
        loc, scale = jp.split(policy_network.apply(normalizer, params, obs), 2, axis=-1)
        return jp.tanh(loc), jax.nn.softplus(scale) + 1e-3

    return predict


def _report(predict, params, val, history: dict, samples: int, action_size: int) -> dict:
    """The fit on the held-out samples: per-component R^2 (None where the target is constant,
    e.g. a force no push acts along under u_base 'model'), MSE, the epochs trained."""
    pred = np.asarray(predict(params, val[0])[0])
    y_va = np.asarray(val[1])
    scores = r2(y_va, pred, floor=1e-12)
    constant = np.std(y_va, axis=0) < _CONSTANT_STD  # nothing but float32 rounding to explain
    return {
        "samples": samples,
        "best_epoch": history["best_epoch"] + 1,  # epochs trained
        "val_mse": float(np.mean((pred - y_va) ** 2)),
        "r2": [None if c else float(v) for v, c in zip(scores, constant)][:action_size],
    }
