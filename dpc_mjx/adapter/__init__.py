"""The latent dynamic adapter (paper §III-B): a forward model whose 2-D latent z summarises what
the arm does to the body, and the transfer of that latent to a new arm.

    data = collect(make("reaching", arm="regular", controller="mbc"), samples=100_000)
    adapter = train(data)                                   # encoder + decoder
    enc, hist = transfer(collect(make(..., arm="so100", controller="mbc"), 30_000),
                         adapter.decoder)                   # new encoder, frozen decoder
    z = encode(adapter.config, adapter.encoder, obs)        # obs = [s_body, s_arm, p_arm]
"""

from dpc_mjx.adapter.data import DRP, Dataset, collect
from dpc_mjx.adapter.losses import constant_nll, gaussian_nll
from dpc_mjx.adapter.networks import (
    AdapterConfig,
    DecoderState,
    EncoderState,
    Normalizer,
    decode,
    encode,
)
from dpc_mjx.adapter.train import Adapter, nll, train, transfer

__all__ = [
    "DRP",
    "Adapter",
    "AdapterConfig",
    "Dataset",
    "DecoderState",
    "EncoderState",
    "Normalizer",
    "collect",
    "constant_nll",
    "decode",
    "encode",
    "gaussian_nll",
    "nll",
    "train",
    "transfer",
]
