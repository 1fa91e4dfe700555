"""Training checkpoints of a SAC run (`sac.train`), so a killed run resumes where it stopped.

A checkpoint is two files in the run folder:

    checkpoint.msgpack   the whole `Carry` pytree (flax msgpack): networks, optimiser states,
                         observation statistics, the replay buffer, counters, key
    checkpoint.json      {format_version, library_version, saved, epoch, sha256, bytes, meta,
                         history}: the record of the msgpack it belongs to

Both change together or not at all. `save` writes, each file atomically (temp file, fsync,
`os.replace`):

    1. the new carry to `checkpoint.next.msgpack` (the staging file),
    2. `checkpoint.json` with the staged bytes' sha256 and epoch: the commit point,
    3. renames the staging file to `checkpoint.msgpack`.

A kill before 2 leaves the previous json and msgpack (the staging file's hash matches no record and
is ignored). A kill between 2 and 3 leaves a json whose hash matches the staging file: `restore`
finishes the rename (rolls forward). `restore` always checks the msgpack's sha256 against the json,
so a pair that does not belong together is never loaded.
"""

from __future__ import annotations

import datetime
import pathlib
from typing import Any

from dpc_mjx import serialization as ser
from dpc_mjx._version import __version__
from dpc_mjx.errors import DpcError

FORMAT_VERSION = 1  # of the checkpoint pair
MSGPACK = "checkpoint.msgpack"
STAGED = "checkpoint.next.msgpack"
RECORD = "checkpoint.json"
_FRESH = "to start a fresh run, train without resume=True (or use a new run_dir)"


def save(run_dir: str | pathlib.Path, carry: Any, meta: dict, history: list[dict]) -> None:
    """Checkpoint `carry` (any flax-serializable pytree; its `epoch` is recorded if it has one)
    with `meta` (what must match on resume: the SAC config, the observation size) and the
    per-epoch `history` rows."""
    run_dir = pathlib.Path(run_dir)
    digest = ser.write_msgpack(run_dir / STAGED, carry)
    epoch = getattr(carry, "epoch", None)
    record = {
        "format_version": FORMAT_VERSION,
        "library_version": __version__,
        "saved": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "epoch": None if epoch is None else int(epoch),
        "sha256": digest,
        "bytes": (run_dir / STAGED).stat().st_size,
        "meta": meta,
        "history": history,
    }
    ser.write_json(run_dir / RECORD, record)
    _promote(run_dir)


def _promote(run_dir: pathlib.Path) -> None:
    """Step 3 of `save`: the staged msgpack becomes the checkpoint (an atomic rename)."""
    ser.replace_file(run_dir / STAGED, run_dir / MSGPACK)


def restore(run_dir: str | pathlib.Path, template_carry: Any, meta: dict) -> tuple[Any, list[dict]]:
    """(carry, history) of the checkpoint in `run_dir`, restored into the structure of
    `template_carry` (e.g. a fresh `Trainer.init(key)`), its jax leaves on the template's devices.

    Raises `DpcError` if there is no checkpoint, if `meta` differs from the saved one (naming the
    differing keys), or if the files are corrupt or do not match the template.
    """
    run_dir = pathlib.Path(run_dir)
    path = run_dir / RECORD
    if not path.is_file():
        raise DpcError(f"No checkpoint in {run_dir} ({RECORD} does not exist); {_FRESH}.")
    record = ser.read_json(path, "checkpoint record", hint=f"the checkpoint is damaged; {_FRESH}")
    keys = ("format_version", "sha256", "meta", "history", "epoch")
    if not isinstance(record, dict) or any(k not in record for k in keys):
        raise DpcError(f"{path} is not a checkpoint record (it needs {list(keys)}); {_FRESH}.")
    if record["format_version"] != FORMAT_VERSION:
        raise DpcError(
            f"{path} has checkpoint format_version {record['format_version']!r}, this dpc_mjx "
            f"reads {FORMAT_VERSION}; resume with the dpc_mjx that wrote it, or {_FRESH}."
        )
    diffs = _differences(record["meta"], ser.jsonable(meta))
    if diffs:
        raise DpcError(
            f"The checkpoint in {run_dir} was written with other settings: "
            + "; ".join(diffs)
            + f". Resume with the run's original settings, or {_FRESH}."
        )
    staged = run_dir / STAGED
    if staged.is_file() and ser.sha256_bytes(staged.read_bytes()) == record["sha256"]:
        _promote(run_dir)  # the last save was killed after its commit point: finish it
    carry = ser.read_msgpack(
        run_dir / MSGPACK,
        template_carry,
        "SAC checkpoint",
        sha256=record["sha256"],
        hint=f"the checkpoint is incomplete, damaged or from another run; {_FRESH}",
    )
    epoch = getattr(carry, "epoch", None)
    if record["epoch"] is not None and epoch is not None and int(epoch) != record["epoch"]:
        raise DpcError(
            f"{run_dir / MSGPACK} is at epoch {int(epoch)} but {path} records epoch "
            f"{record['epoch']}; {_FRESH}."
        )
    return carry, list(record["history"])


def _differences(saved: Any, now: Any, prefix: str = "") -> list[str]:
    """'key: saved X, now Y' for every dotted key whose value differs."""
    if isinstance(saved, dict) and isinstance(now, dict):
        out = []
        for k in sorted(set(saved) | set(now), key=str):
            name = f"{prefix}.{k}" if prefix else str(k)
            if k not in now:
                out.append(f"{name}: saved {_short(saved[k])}, now absent")
            elif k not in saved:
                out.append(f"{name}: absent when saved, now {_short(now[k])}")
            else:
                out += _differences(saved[k], now[k], name)
        return out
    return [] if saved == now else [f"{prefix or 'meta'}: saved {_short(saved)}, now {_short(now)}"]


def _short(x: Any, n: int = 60) -> str:
    s = repr(x)
    return s if len(s) <= n else s[: n - 3] + "..."


__all__ = ["FORMAT_VERSION", "restore", "save"]
