"""The latent dynamic adapter's networks (paper §III-B): encoder E_phi and decoder D_psi.

    z_t = E_phi(s_body_t, s_arm_t, p_arm_t)                      z in (-1, 1)^latent_size
    (mean, log_std) = D_psi(z_t)            or D_psi(z_t, s_body_t) (`decoder_sees_body`)
    s_drp_{t+1} ~ N(mean, exp(log_std)^2)   next roll and pitch rate (rad/s, trunk frame)

Both are MLPs with 2 hidden layers of 128 ReLU units (the paper's sizes). Every input and the
target are standardised with statistics of the training data (`Normalizer`), which travel with the
parameters: the encoder's input statistics belong to the encoder (a new arm brings its own), the
decoder's s_body and target statistics to the decoder (frozen with it in a transfer).

z is squashed by tanh so the policy always sees a bounded latent, whatever the arm.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jp
import numpy as np
from flax import linen as nn
from flax import struct

from dpc_mjx.envs.observations import S_BODY_SIZE
from dpc_mjx.errors import DpcError

DRP_SIZE = 2  # the decoder's target: next roll and pitch rate (rad/s, trunk frame)
LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0  # bounds of the decoder's log std (standardised units)
MIN_STD = 1e-3  # floor of a normaliser's std, so constant inputs do not blow up


@dataclasses.dataclass(frozen=True)
class AdapterConfig:
    """Sizes and training budget of the latent dynamic adapter."""

    latent_size: int = 2  # dim of z (the paper: 2)
    hidden: tuple[int, ...] = (128, 128)  # both networks (the paper: 2 x 128 ReLU)
    # The decoder also sees s_body: z then only has to carry what the arm adds to the body's own
    # motion (not re-encode the body's current roll and pitch rate), which is what the policy and
    # a transferred encoder should agree on. `False` is the paper's D(z).
    decoder_sees_body: bool = True
    learning_rate: float = 1e-3  # Adam
    batch_size: int = 256
    epochs: int = 60  # budget; the parameters of the best validation epoch are kept
    patience: int = 10  # stop after this many epochs without a better validation loss
    val_fraction: float = 0.1  # held out (the last samples, in time order)
    seed: int = 0  # initialisation and batch order; in a run, `RunConfig.seed`

    def validate(self) -> None:
        ints = ("latent_size", "batch_size", "epochs", "patience")
        for name in ints:
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise DpcError(f"AdapterConfig.{name} must be an int >= 1, got {v!r}.")
        if not self.hidden or any(not isinstance(h, int) or h < 1 for h in self.hidden):
            raise DpcError(f"AdapterConfig.hidden must be positive ints, got {self.hidden!r}.")
        if not 0.0 < self.val_fraction < 1.0:
            raise DpcError(
                f"AdapterConfig.val_fraction must be in (0, 1), got {self.val_fraction}."
            )
        if not self.learning_rate > 0:
            raise DpcError(f"AdapterConfig.learning_rate must be > 0, got {self.learning_rate}.")


@struct.dataclass
class Normalizer:
    """Standardisation x -> (x - mean) / std, per feature."""

    mean: jax.Array  # (n,)
    std: jax.Array  # (n,), >= MIN_STD

    @classmethod
    def fit(cls, x: np.ndarray) -> Normalizer:
        """Statistics of (N, n) data."""
        x = np.asarray(x, np.float64)
        return cls(
            mean=jp.asarray(x.mean(axis=0), jp.float32),
            std=jp.asarray(np.maximum(x.std(axis=0), MIN_STD), jp.float32),
        )

    @classmethod
    def template(cls, n: int) -> Normalizer:
        """Shapes only (n features), to restore a saved one against."""
        return cls(mean=_shape(n), std=_shape(n))

    def __call__(self, x: jax.Array) -> jax.Array:
        return (x - self.mean) / self.std

    def inverse(self, y: jax.Array) -> jax.Array:
        return y * self.std + self.mean


class MLP(nn.Module):
    """ReLU MLP with a linear output layer."""

    hidden: Sequence[int]
    out: int

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for i, h in enumerate(self.hidden):
            x = nn.relu(nn.Dense(h, name=f"hidden_{i}")(x))
        return nn.Dense(self.out, name="out")(x)


class Encoder(nn.Module):
    """Standardised [s_body, s_arm, p_arm] (..., n_in) -> z (..., latent_size) in (-1, 1)."""

    latent_size: int
    hidden: Sequence[int]

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        return jp.tanh(MLP(self.hidden, self.latent_size, name="mlp")(x))


class Decoder(nn.Module):
    """z (..., latent) [and standardised s_body (..., 11)] -> mean, log_std (..., out_size) of the
    standardised next roll/pitch rate."""

    out_size: int
    hidden: Sequence[int]

    @nn.compact
    def __call__(self, z: jax.Array, s_body: jax.Array | None = None):
        x = z if s_body is None else jp.concatenate([z, s_body], axis=-1)
        y = MLP(self.hidden, 2 * self.out_size, name="mlp")(x)
        mean, raw = jp.split(y, 2, axis=-1)
        # soft bounds keep the NLL finite and its gradient alive at the edges
        log_std = LOG_STD_MIN + 0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (jp.tanh(raw) + 1.0)
        return mean, log_std


@struct.dataclass
class EncoderState:
    """A trained encoder: what a policy needs at run time, for one arm."""

    params: dict  # flax params of `Encoder`
    input_norm: Normalizer  # over [s_body, s_arm, p_arm] (n_in,)


@struct.dataclass
class DecoderState:
    """A trained decoder with its frozen statistics (shared by every arm's encoder)."""

    params: dict  # flax params of `Decoder`
    body_norm: Normalizer  # over s_body (11,); used only if the decoder sees the body
    target_norm: Normalizer  # over s_drp_{t+1} (2,)


def encoder_module(config: AdapterConfig) -> Encoder:
    return Encoder(config.latent_size, tuple(config.hidden))


def decoder_module(config: AdapterConfig) -> Decoder:
    return Decoder(DRP_SIZE, tuple(config.hidden))


def _shape(n: int) -> jax.ShapeDtypeStruct:
    return jax.ShapeDtypeStruct((n,), jp.float32)


def encoder_template(config: AdapterConfig, input_size: int) -> EncoderState:
    """Shapes of an `EncoderState` of `config` for an arm observation of `input_size` entries."""
    key = jax.random.PRNGKey(0)
    params = jax.eval_shape(encoder_module(config).init, key, _shape(input_size))
    return EncoderState(params=params, input_norm=Normalizer.template(input_size))


def decoder_template(config: AdapterConfig) -> DecoderState:
    """Shapes of a `DecoderState` of `config`."""
    key = jax.random.PRNGKey(0)
    body = _shape(S_BODY_SIZE) if config.decoder_sees_body else None
    params = jax.eval_shape(decoder_module(config).init, key, _shape(config.latent_size), body)
    return DecoderState(
        params=params,
        body_norm=Normalizer.template(S_BODY_SIZE),
        target_norm=Normalizer.template(DRP_SIZE),
    )


def encode(config: AdapterConfig, enc: EncoderState, obs: jax.Array) -> jax.Array:
    """z (..., latent_size) from the arm observation `[s_body, s_arm, p_arm]` (..., n_in): the
    first n_in entries of a raw env observation."""
    return encoder_module(config).apply(enc.params, enc.input_norm(obs))


def decode(
    config: AdapterConfig, dec: DecoderState, z: jax.Array, s_body: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Predicted next roll/pitch rate in rad/s: (mean, std), each (..., 2)."""
    body = dec.body_norm(s_body) if config.decoder_sees_body else None
    mean, log_std = decoder_module(config).apply(dec.params, z, body)
    return dec.target_norm.inverse(mean), jp.exp(log_std) * dec.target_norm.std
