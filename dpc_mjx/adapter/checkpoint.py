"""A trained adapter on disk: `adapter.json` (config, sizes, training history) beside
`encoder.msgpack` and `decoder.msgpack` (`dpc_mjx.serialization`: atomic, checked, no pickle),
and `adapter_log.csv` (the per-epoch losses, for reading).

This is the adapter stage's output inside a run folder, so a run can stop after the adapter and
resume with SAC; the deployable export of a whole run is `dpc_mjx.io.export`.
"""

from __future__ import annotations

import dataclasses
import pathlib

from dpc_mjx.adapter.networks import AdapterConfig, decoder_template, encoder_template
from dpc_mjx.adapter.train import Adapter
from dpc_mjx.errors import DpcError
from dpc_mjx.serialization import read_json, read_msgpack, write_json, write_msgpack

RECORD, ENCODER, DECODER = "adapter.json", "encoder.msgpack", "decoder.msgpack"
LOG = "adapter_log.csv"
_HINT = "train the adapter again (dpc-mjx train-adapter)"


def save(folder: str | pathlib.Path, adapter: Adapter) -> pathlib.Path:
    """Write `adapter` into `folder` (created); returns the folder."""
    folder = pathlib.Path(folder)
    n_in = int(adapter.encoder.input_norm.mean.shape[0])
    record = {
        "config": dataclasses.asdict(adapter.config),
        "input_size": n_in,
        "history": adapter.history,
        ENCODER: write_msgpack(folder / ENCODER, adapter.encoder),
        DECODER: write_msgpack(folder / DECODER, adapter.decoder),
    }
    write_json(folder / RECORD, record)  # last: it names the hashes of the two files
    _write_log(folder / LOG, adapter.history)
    return folder


def _write_log(path: pathlib.Path, history: dict) -> None:
    """Per-epoch train and validation NLL as CSV (the same numbers as the record's history)."""
    rows = zip(history["train_nll"], history["val_nll"], strict=True)
    lines = ["epoch,train_nll,val_nll", *(f"{i + 1},{t},{v}" for i, (t, v) in enumerate(rows))]
    path.write_text("\n".join(lines) + "\n")


def load(folder: str | pathlib.Path) -> Adapter:
    """The adapter saved in `folder`; `DpcError` if anything is missing, corrupt or mismatched."""
    folder = pathlib.Path(folder)
    record = read_json(folder / RECORD, "adapter record", hint=_HINT)
    try:
        fields = {k: tuple(v) if isinstance(v, list) else v for k, v in record["config"].items()}
        config = AdapterConfig(**fields)
        n_in = int(record["input_size"])
    except (KeyError, TypeError, ValueError) as e:
        raise DpcError(f"{folder / RECORD} is not an adapter record ({e}); {_HINT}.") from e
    config.validate()
    enc, dec = encoder_template(config, n_in), decoder_template(config)
    encoder = read_msgpack(folder / ENCODER, enc, "adapter encoder", sha256=record.get(ENCODER))
    decoder = read_msgpack(folder / DECODER, dec, "adapter decoder", sha256=record.get(DECODER))
    return Adapter(config=config, encoder=encoder, decoder=decoder, history=record["history"])
