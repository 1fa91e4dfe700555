"""Training the latent dynamic adapter (`train`) and transferring it to a new arm (`transfer`).

`train` fits encoder and decoder together by maximum likelihood (eq. 1, `losses.gaussian_nll`)
with Adam on minibatches, a held-out validation split (the last `val_fraction` of the samples),
and keeps the parameters of the best validation epoch (early stopping after `patience` epochs
without improvement, within a budget of `epochs`).

`transfer` trains only a *new* encoder for another arm against a frozen decoder (paper §III-C):
the decoder's parameters are closed over as constants, never handed to the optimiser, so they come
back bit-for-bit unchanged, and the new encoder learns to map the new arm's states to latents that
the old decoder (and so the old policy) reads the same way.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from dpc_mjx import fitting
from dpc_mjx.adapter import losses
from dpc_mjx.adapter.data import Dataset, collect
from dpc_mjx.adapter.networks import (
    AdapterConfig,
    DecoderState,
    EncoderState,
    Normalizer,
    decoder_module,
    decoder_template,
    encoder_module,
)
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.errors import DpcError
from dpc_mjx.serialization import check_tree


@struct.dataclass
class Adapter:
    """A trained encoder-decoder pair and how training went."""

    config: AdapterConfig = struct.field(pytree_node=False)
    encoder: EncoderState
    decoder: DecoderState
    history: dict = struct.field(pytree_node=False)  # see `_fit`


def train(
    data: Dataset | DpcEnv,
    config: AdapterConfig | None = None,
    *,
    samples: int = 100_000,
    n_envs: int = 64,
    progress: bool = True,
) -> Adapter:
    """Train encoder and decoder on `data` (a `Dataset`, or an env to `collect` `samples` from)."""
    config = config or AdapterConfig()
    config.validate()
    data = _as_dataset(data, samples, n_envs, config.seed, progress)
    tr, va = data.split(config.val_fraction)
    enc_norm = Normalizer.fit(tr.encoder_input)
    dec_fixed = DecoderState(
        params={}, body_norm=Normalizer.fit(tr.s_body), target_norm=Normalizer.fit(tr.s_drp_next)
    )
    k_enc, k_dec, k_fit = jax.random.split(jax.random.PRNGKey(config.seed), 3)
    params = {
        "encoder": _init_encoder(config, k_enc, tr.encoder_input.shape[1]),
        "decoder": _init_decoder(config, k_dec),
    }

    def loss(p, batch):
        return _nll(config, p["encoder"], p["decoder"], batch)

    best, history = _fit(config, loss, params, enc_norm, dec_fixed, tr, va, k_fit, progress)
    history["samples"], history["env_steps"] = len(data), data.env_steps
    history["collect_seconds"] = data.seconds
    if config.decoder_sees_body:
        history["body_only_val_nll"] = _body_only_nll(config, enc_norm, dec_fixed, tr, va, k_dec)
    return Adapter(
        config=config,
        encoder=EncoderState(params=best["encoder"], input_norm=enc_norm),
        decoder=dec_fixed.replace(params=best["decoder"]),
        history=history,
    )


def transfer(
    data: Dataset | DpcEnv,
    decoder: DecoderState,
    config: AdapterConfig | None = None,
    *,
    samples: int = 30_000,
    n_envs: int = 64,
    progress: bool = True,
) -> tuple[EncoderState, dict]:
    """A new encoder for another arm, trained against the frozen `decoder` (whose statistics and
    parameters are left untouched). Returns the encoder and its training history."""
    config = config or AdapterConfig()
    config.validate()
    data = _as_dataset(data, samples, n_envs, config.seed, progress)
    tr, va = data.split(config.val_fraction)
    enc_norm = Normalizer.fit(tr.encoder_input)
    _check_decoder(config, decoder)
    k_enc, k_fit = jax.random.split(jax.random.PRNGKey(config.seed + 1))
    params = {"encoder": _init_encoder(config, k_enc, tr.encoder_input.shape[1])}
    frozen = decoder.params  # a constant of the loss: no gradient, no update

    def loss(p, batch):
        return _nll(config, p["encoder"], frozen, batch)

    best, history = _fit(config, loss, params, enc_norm, decoder, tr, va, k_fit, progress)
    history["samples"], history["env_steps"] = len(data), data.env_steps
    history["collect_seconds"] = data.seconds
    return EncoderState(params=best["encoder"], input_norm=enc_norm), history


def nll(adapter_config: AdapterConfig, enc: EncoderState, dec: DecoderState, data: Dataset):
    """Mean NLL (standardised units) of `data` under an encoder-decoder pair, and the constant
    predictor's on the same data: (model, constant)."""
    batch = _standardise(data, enc.input_norm, dec)
    model = _nll(adapter_config, enc.params, dec.params, batch)
    return float(model), float(losses.constant_nll(batch[2]))


# internals ------------------------------------------------------------------------------------


def _as_dataset(data, samples, n_envs, seed, progress) -> Dataset:
    if isinstance(data, Dataset):
        return data
    if isinstance(getattr(data, "unwrapped", None), DpcEnv):
        return collect(data, samples, n_envs=n_envs, seed=seed, progress=progress)
    raise DpcError(f"Expected a Dataset or a DPC env, got {type(data).__name__}.")


def _init_encoder(config, key, n_in: int) -> dict:
    return encoder_module(config).init(key, jp.zeros((1, n_in)))


def _init_decoder(config, key) -> dict:
    body = jp.zeros((1, 11)) if config.decoder_sees_body else None
    return decoder_module(config).init(key, jp.zeros((1, config.latent_size)), body)


def _body_only_nll(config, enc_norm, dec_fixed, tr, va, key) -> float:
    """Held-out NLL of the same decoder trained with z = 0 (s_body alone), same budget: how much
    the latent adds to what the body state already predicts."""
    zero_z = jp.zeros((1, config.latent_size))

    def loss(p, batch):
        _, body, y = batch
        z = jp.broadcast_to(zero_z, (body.shape[0], config.latent_size))
        mean, log_std = decoder_module(config).apply(p["decoder"], z, body)
        return losses.gaussian_nll(mean, log_std, y)

    params = {"decoder": _init_decoder(config, key)}
    _, history = _fit(config, loss, params, enc_norm, dec_fixed, tr, va, key, progress=False)
    return min(history["val_nll"])


def _check_decoder(config: AdapterConfig, decoder: DecoderState) -> None:
    """The frozen decoder must take this config's latent (and body) inputs."""
    check_tree(
        decoder,
        decoder_template(config),
        "frozen decoder",
        f"It does not fit this AdapterConfig (latent_size={config.latent_size}, hidden="
        f"{config.hidden}, decoder_sees_body={config.decoder_sees_body}); transfer with the "
        "config the decoder was trained with.",
    )


def _standardise(data: Dataset, enc_norm: Normalizer, dec: DecoderState):
    """(encoder input, decoder body input, target), standardised, as device arrays."""
    x = enc_norm(jp.asarray(data.encoder_input))
    body = dec.body_norm(jp.asarray(data.s_body))
    y = dec.target_norm(jp.asarray(data.s_drp_next))
    return x, body, y


def _nll(config, enc_params, dec_params, batch) -> jax.Array:
    x, body, y = batch
    z = encoder_module(config).apply(enc_params, x)
    mean, log_std = decoder_module(config).apply(
        dec_params, z, body if config.decoder_sees_body else None
    )
    return losses.gaussian_nll(mean, log_std, y)


def _fit(config, loss, params, enc_norm, dec, tr: Dataset, va: Dataset, key, progress):
    """Adam on `loss` over epochs of shuffled minibatches (`fitting.fit`); returns the
    best-validation params and the history {'train_nll', 'val_nll': per epoch,
    'constant_val_nll', 'best_epoch', 'epochs', 'seconds'}."""
    train_b, val_b = _standardise(tr, enc_norm, dec), _standardise(va, enc_norm, dec)
    best, fitted = fitting.fit(
        loss,
        params,
        train_b,
        val_b,
        learning_rate=config.learning_rate,
        batch_size=config.batch_size,
        epochs=config.epochs,
        patience=config.patience,
        key=key,
        diverged_hint="lower AdapterConfig.learning_rate or check the data for NaN.",
        progress=progress,
        desc="adapter",
    )
    history = {
        "train_nll": fitted["train_loss"],
        "val_nll": fitted["val_loss"],
        "constant_val_nll": float(losses.constant_nll(val_b[2])),
    }
    history.update({k: fitted[k] for k in ("best_epoch", "epochs", "seconds")})
    return best, history


__all__ = ["Adapter", "nll", "train", "transfer"]
