"""Data on disk, never pickle: atomic writes, flax msgpack trees and JSON, each read back with
every failure (missing, truncated, corrupt, mismatched) turned into a `DpcError` that says what to
do. Used by the exports (`dpc_mjx.io`) and the training checkpoints (`sac.checkpoint`,
`adapter.checkpoint`); depends on nothing else of the library.

    write_msgpack(path, tree) -> sha256    flax serialization, atomic (temp file + os.replace)
    read_msgpack(path, template, what)     a tree like `template`; every leaf's path, shape and
                                           dtype checked (= read_state, then restore, for a
                                           caller that inspects the raw state in between)
    write_json(path, obj) / read_json(path, what)     atomic; invalid JSON is a `DpcError`
    write_bytes, replace_file, sha256_bytes, jsonable  the pieces a checkpoint protocol needs
    tuples(d)                              a dict read from JSON with its lists as tuples again
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pathlib
import tempfile
from typing import Any

import jax
import jax.numpy as jp
import numpy as np
from flax import serialization

from dpc_mjx.errors import DpcError

_MAX_REPORTED = 5  # mismatching leaves listed in one message


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~_umask()  # what open() would give (mkstemp's temp files are 0600)


def write_bytes(path: str | pathlib.Path, data: bytes) -> None:
    """Write `data` atomically: a temp file in the same folder, fsync, then `os.replace`. A kill
    leaves either the old file or the new one, never a mix; the folder is created if needed."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, _FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        pathlib.Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def replace_file(src: str | pathlib.Path, dst: str | pathlib.Path) -> None:
    """Atomically rename `src` to `dst` (same folder), durably."""
    os.replace(src, dst)
    _fsync_dir(pathlib.Path(dst).parent)


def _fsync_dir(folder: pathlib.Path) -> None:
    """Make a rename durable (POSIX); a no-op where folders cannot be opened."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_msgpack(path: str | pathlib.Path, tree: Any) -> str:
    """Serialize `tree` (flax structs, dicts, optax states, arrays) with flax's msgpack format,
    atomically. Returns the sha256 (hex) of the bytes written."""
    data = serialization.to_bytes(tree)
    write_bytes(path, data)
    return sha256_bytes(data)


def read_msgpack(
    path: str | pathlib.Path,
    template: Any,
    what: str,
    *,
    sha256: str | None = None,
    hint: str = "re-create it with the code that wrote it",
) -> Any:
    """The tree stored at `path`, restored into the structure of `template`.

    `template`'s leaves may be arrays or `jax.ShapeDtypeStruct`s; the file must hold the same leaf
    paths with the same shapes and dtypes. Leaves come back as jax arrays where the template has
    jax arrays or shape structs (on the template array's sharding), numpy arrays otherwise. With
    `sha256`, the file's bytes must also hash to it. Every failure (missing, unreadable, truncated,
    corrupt, mismatched) raises `DpcError` naming `what`, the file, and `hint` (what to do).
    """
    data, state = read_state(path, what, hint=hint)
    return restore(path, data, state, template, what, sha256=sha256, hint=hint)


def read_state(path: str | pathlib.Path, what: str, *, hint: str) -> tuple[bytes, Any]:
    """The bytes at `path` and the state dict they decode to (nested dicts of numpy arrays), to
    inspect before `restore`; `DpcError` if missing, unreadable, truncated or corrupt."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise DpcError(f"{path} ({what}) does not exist; {hint}.")
    try:
        data = path.read_bytes()
    except OSError as e:
        raise DpcError(f"Cannot read {path} ({what}): {e}; {hint}.") from e
    try:
        state = serialization.msgpack_restore(data)
    except Exception as e:  # msgpack raises several types for truncated or corrupt input
        raise DpcError(
            f"{path} ({what}) is truncated or corrupt (msgpack: {type(e).__name__}: {e}); {hint}."
        ) from e
    return data, state


def restore(
    path: str | pathlib.Path,
    data: bytes,
    state: Any,
    template: Any,
    what: str,
    *,
    sha256: str | None = None,
    hint: str,
) -> Any:
    """`state` (read from `path` by `read_state`, with its bytes `data`) as a tree like
    `template`, checked as `read_msgpack` describes."""
    problems = _compare_specs(template_specs(template), _leaf_specs(state))
    if problems:
        raise DpcError(f"{path} ({what}) does not match: {_join(problems)}; {hint}.")
    if sha256 is not None and sha256_bytes(data) != sha256:
        raise DpcError(
            f"{path} ({what}) is not the file recorded with it: its sha256 differs, so it was "
            f"modified or replaced since, or its save was interrupted; {hint}."
        )
    tree = serialization.from_state_dict(template, state)
    return jax.tree.map(_like, template, tree)


def template_specs(template: Any) -> dict[str, str]:
    """{dotted leaf path: 'float32 (3, 4)'} of a tree (as its file's state dict would have)."""
    return _leaf_specs(serialization.to_state_dict(template))


def state_specs(state: Any) -> dict[str, str]:
    """{dotted leaf path: 'float32 (3, 4)'} of a state dict from `read_state`."""
    return _leaf_specs(state)


def _like(t: Any, x: Any) -> Any:
    """A restored leaf `x` as the kind of array its template leaf `t` is."""
    if isinstance(t, jax.Array):
        if t.weak_type and t.ndim == 0:
            # a Python scalar through jit (brax's `std_eps`): keep it weakly typed, so that a step
            # compiled for the template's types also takes the restored tree
            return jax.device_put(jp.asarray(np.asarray(x).item()), t.sharding)
        return jax.device_put(np.array(x), t.sharding)
    if isinstance(t, jax.ShapeDtypeStruct):
        return jp.asarray(x)
    if isinstance(t, np.ndarray):
        return np.array(x)  # writable copy (msgpack's buffer is read-only)
    return x


def _spec(x: Any) -> str:
    """'float32 (3, 4)' for an array or shape struct, the type name for any other leaf."""
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        return f"{np.dtype(x.dtype).name} {tuple(x.shape)}"
    if isinstance(x, dict) and not x:
        return "{}"
    return type(x).__name__


def _leaf_specs(state: Any, prefix: str = "") -> dict[str, str]:
    """{dotted leaf path: spec} of a state dict (nested dicts of leaves)."""
    if isinstance(state, dict) and state:
        out = {}
        for k, v in state.items():
            out |= _leaf_specs(v, f"{prefix}.{k}" if prefix else str(k))
        return out
    return {prefix or "<root>": _spec(state)}


def _join(problems: list[str]) -> str:
    more = len(problems) - _MAX_REPORTED
    return "; ".join(problems[:_MAX_REPORTED]) + (f" (and {more} more)" if more > 0 else "")


def _compare_specs(expected: dict[str, str], found: dict[str, str]) -> list[str]:
    problems = [f"missing leaf {k!r} ({expected[k]})" for k in expected if k not in found]
    problems += [f"unexpected leaf {k!r} ({found[k]})" for k in found if k not in expected]
    problems += [
        f"leaf {k!r} is {found[k]}, expected {expected[k]}"
        for k in expected
        if k in found and found[k] != expected[k]
    ]
    return problems


def check_tree(tree: Any, template: Any, what: str, hint: str) -> None:
    """`DpcError` if `tree`'s leaves differ from `template`'s in path, shape or dtype."""
    problems = _compare_specs(template_specs(template), template_specs(tree))
    if problems:
        raise DpcError(f"The {what} is inconsistent: {_join(problems)}. {hint}")


def write_json(path: str | pathlib.Path, obj: Any) -> None:
    """Write `obj` as indented JSON, atomically. numpy/jax numbers and arrays, dataclasses and
    paths are converted; anything else that JSON cannot hold raises `DpcError`."""
    try:
        text = json.dumps(obj, indent=2, default=_json_default)
    except (TypeError, ValueError) as e:
        raise DpcError(
            f"Cannot write {path} as JSON ({e}); pass only numbers, strings, lists and dicts."
        ) from e
    write_bytes(path, (text + "\n").encode())


def jsonable(obj: Any) -> Any:
    """`obj` as `read_json` would return it after `write_json` (tuples become lists, numpy
    numbers Python numbers): the form to compare a value with a saved one."""
    return json.loads(json.dumps(obj, default=_json_default))


def tuples(d: dict) -> dict:
    """`d` with its list values as tuples: a dict of config fields as it was before JSON (which
    holds tuples as lists)."""
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


def _json_default(x: Any) -> Any:
    if isinstance(x, (np.ndarray, np.generic, jax.Array)):
        return np.asarray(x).tolist()
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return dataclasses.asdict(x)
    if isinstance(x, pathlib.PurePath):
        return str(x)
    raise TypeError(f"{type(x).__name__} is not JSON serializable")


def read_json(path: str | pathlib.Path, what: str, *, hint: str = "re-create it") -> Any:
    """The JSON at `path`; `DpcError` naming `what` and `hint` if missing or not valid JSON."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise DpcError(f"The {what} {path} does not exist; {hint}.")
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DpcError(f"The {what} {path} is not valid JSON ({e}); {hint}.") from e
