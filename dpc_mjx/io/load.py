"""Reading an export: `load` checks the sidecar against itself (`sidecar_checks.check`), then every
size it declares against the msgpack file that holds it, then restores the networks.

A file check names the file, the sidecar field, the size the sidecar declares, the size the file
has (with the leaf that has it) and what to do:

    .../decoder.msgpack (decoder) does not match dpc.json: decoder.latent_size + s_body
    (decoder.sees_body=true) is 13 there but 14 in the file (leaf 'params.params.mlp.hidden_0.
    kernel' is float32 (14, 128), expected float32 (13, 128)); re-export the artefacts ...

Anything else that differs (a dtype, a leaf too many) is caught when the file is restored into
the networks the sizes describe (`serialization.restore`), and last the file's sha256.
"""

from __future__ import annotations

import dataclasses
import pathlib
import re
from typing import Any

from dpc_mjx import serialization as ser
from dpc_mjx.adapter.networks import (
    AdapterConfig,
    DecoderState,
    EncoderState,
    decoder_template,
    encoder_template,
)
from dpc_mjx.errors import DpcError
from dpc_mjx.io import arm_dynamics, sidecar, sidecar_checks
from dpc_mjx.io.sidecar import REEXPORT, SIDECAR
from dpc_mjx.io.sidecar_checks import Declared
from dpc_mjx.policy.policy import PolicyState, dpc_policy, policy_template
from dpc_mjx.robots.spec_json import ArmLike, arm_from_json

_POLICY = "params.params"  # brax's policy MLP: hidden_0 .. hidden_k (the last is the output)
_MLP = "params.params.mlp"  # the adapter's MLPs: hidden_0 .. hidden_{k-1}, then out
_HIDDEN = re.compile(r"^hidden_\d+$")


@dataclasses.dataclass(frozen=True)
class Artefacts:
    """A loaded export: everything `dpc_policy` needs, plus the sidecar."""

    adapter_config: AdapterConfig
    policy: PolicyState
    decoder: DecoderState
    encoders: dict[str, EncoderState]  # arm name -> its encoder
    meta: dict  # the sidecar

    def encoder(self, arm: str) -> EncoderState:
        if arm not in self.encoders:
            raise DpcError(
                f"This export has no encoder for arm {arm!r}; it has {sorted(self.encoders)}. "
                "Transfer one (dpc_mjx.adapter) and add it with dpc_mjx.io.add_encoder."
            )
        return self.encoders[arm]

    def arm_spec(self, arm: str) -> ArmLike:
        """The arm the encoder of `arm` was trained on (variant name or spec)."""
        self.encoder(arm)
        return arm_from_json(self.meta["encoders"][arm]["arm_spec"])

    def dpc_policy(self, arm: str):
        """(obs (B, n_in) of the raw env of `arm`, key) -> action (B, action_size) in [-1, 1]."""
        return dpc_policy(self.adapter_config, self.encoder(arm), self.policy)


def load(out_dir: str | pathlib.Path) -> Artefacts:
    """Read an export written by `export`. The sidecar's version, keys and fields are checked
    against each other, every size against its file, every file against its sha256; any
    disagreement raises `DpcError` saying which and what to do."""
    out = pathlib.Path(out_dir)
    d = sidecar_checks.check(sidecar.read(out), out / SIDECAR)
    policy = _read(out, _policy_file(d))
    decoder = _read(out, _decoder_file(d))
    encoders = {arm: _read(out, _encoder_file(d, arm)) for arm in d.input_sizes}
    for arm in d.input_sizes:
        _check_arm_model(out, d, arm)
    sidecar_checks.check_records(d)
    return Artefacts(d.config, policy, decoder, encoders, d.meta)


# --------------------------------------------------------------------------- sizes vs files


@dataclasses.dataclass(frozen=True)
class _Size:
    """A size the sidecar declares and the leaves of the file that have it."""

    field: str  # the sidecar field(s), as a message names them
    value: int  # the size they declare
    leaves: tuple[tuple[str, int], ...]  # (dotted leaf path in the file, axis)


@dataclasses.dataclass(frozen=True)
class _File:
    """What the sidecar says one of its files holds."""

    entry: dict  # its sidecar entry {file, sha256, ...}
    where: str  # that entry's key path in the sidecar
    what: str  # the network, for messages
    template: Any  # the tree the declared sizes describe
    layers: tuple[str, int, str]  # (the sidecar's words, its count of hidden_* layers, MLP path)
    sizes: list[_Size]
    hint: str  # what to do when the file disagrees


def _policy_file(d: Declared) -> _File:
    n = len(d.policy_hidden)
    out = f"{_POLICY}.hidden_{n}"
    return _File(
        d.meta["policy"],
        "policy",
        "policy",
        policy_template(d.observation_size, d.policy_hidden, d.action_size, d.policy_inputs),
        (
            f"policy.hidden lists {n} hidden layers, so {n + 1} layers hidden_* with the output",
            n + 1,
            _POLICY,
        ),
        [
            _Size(
                "policy.observation_size",
                d.observation_size,
                (("obs_norm.mean", 0), ("obs_norm.std", 0), (f"{_POLICY}.hidden_0.kernel", 0)),
            ),
            *_chain(
                _POLICY, [f"hidden_{i}" for i in range(n + 1)], d.policy_hidden, "policy.hidden"
            ),
            _Size(
                "2 * policy.action_size",
                2 * d.action_size,
                ((f"{out}.kernel", 1), (f"{out}.bias", 0)),
            ),
        ],
        REEXPORT,
    )


def _decoder_file(d: Declared) -> _File:
    config, n_body = d.config, d.s_body.stop - d.s_body.start
    if config.decoder_sees_body:
        field = "decoder.latent_size + s_body (decoder.sees_body=true)"
        n_in = config.latent_size + n_body
    else:
        field, n_in = "decoder.latent_size (decoder.sees_body=false)", config.latent_size
    return _File(
        d.meta["decoder"],
        "decoder",
        "decoder",
        decoder_template(config),
        _mlp_layers(config),
        [
            _Size(field, n_in, ((f"{_MLP}.hidden_0.kernel", 0),)),
            *_mlp_chain(config),
            _Size(
                "2 * decoder.out_size",
                2 * d.decoder_out,
                ((f"{_MLP}.out.kernel", 1), (f"{_MLP}.out.bias", 0)),
            ),
            _Size(
                "decoder.out_size", d.decoder_out, (("target_norm.mean", 0), ("target_norm.std", 0))
            ),
            _Size(
                "observation.s_body (stop - start)",
                n_body,
                (("body_norm.mean", 0), ("body_norm.std", 0)),
            ),
        ],
        REEXPORT,
    )


def _encoder_file(d: Declared, arm: str) -> _File:
    config, n_in = d.config, d.input_sizes[arm]
    return _File(
        d.meta["encoders"][arm],
        f"encoders.{arm}",
        f"encoder for arm {arm!r}",
        encoder_template(config, n_in),
        _mlp_layers(config),
        [
            _Size(
                f"encoders.{arm}.input_size",
                n_in,
                (("input_norm.mean", 0), ("input_norm.std", 0), (f"{_MLP}.hidden_0.kernel", 0)),
            ),
            *_mlp_chain(config),
            _Size(
                "adapter_config.latent_size",
                config.latent_size,
                ((f"{_MLP}.out.kernel", 1), (f"{_MLP}.out.bias", 0)),
            ),
        ],
        f"use the encoder trained for this arm (input size {n_in}) with this adapter "
        f"(dpc_mjx.io.add_encoder) or {REEXPORT}",
    )


def _chain(prefix: str, names: list[str], widths: tuple[int, ...], field: str) -> list[_Size]:
    """The width of each hidden layer of an MLP: its kernel's columns, its bias, and the next
    layer's kernel's rows. `names` are the layers in order (the hidden ones, then the output)."""
    return [
        _Size(
            f"{field}[{i}]",
            w,
            (
                (f"{prefix}.{names[i]}.kernel", 1),
                (f"{prefix}.{names[i]}.bias", 0),
                (f"{prefix}.{names[i + 1]}.kernel", 0),
            ),
        )
        for i, w in enumerate(widths)
    ]


def _mlp_layers(config: AdapterConfig) -> tuple[str, int, str]:
    n = len(config.hidden)
    return f"adapter_config.hidden lists {n} hidden layers (hidden_*, then out)", n, _MLP


def _mlp_chain(config: AdapterConfig) -> list[_Size]:
    names = [*(f"hidden_{i}" for i in range(len(config.hidden))), "out"]
    return _chain(_MLP, names, config.hidden, "adapter_config.hidden")


def _read(out: pathlib.Path, f: _File) -> Any:
    """The file `f` describes: its count of layers and every declared size checked against the
    file's leaves, then restored like `f.template` (other leaves, dtypes, sha256 checked)."""
    path = _file(out, f.entry, f.where)
    data, state = ser.read_state(path, f.what, hint=f.hint)
    mismatch = f"{path} ({f.what}) does not match {SIDECAR}"
    declared, count, prefix = f.layers
    node = _node(state, prefix)
    if isinstance(node, dict):
        found = sum(bool(_HIDDEN.match(str(k))) for k in node)
        if found != count:
            raise DpcError(
                f"{mismatch}: {declared} there but the file has {found} ({sorted(node)} under "
                f"{prefix!r}); {f.hint}."
            )
    expected, actual = ser.template_specs(f.template), ser.state_specs(state)
    for size in f.sizes:
        for leaf, axis in size.leaves:
            shape = getattr(_node(state, leaf), "shape", None)
            if shape is None or len(shape) <= axis or leaf not in expected:
                continue  # another structure: `restore` names what differs
            if shape[axis] != size.value:
                raise DpcError(
                    f"{mismatch}: {size.field} is {size.value} there but {shape[axis]} in the "
                    f"file (leaf {leaf!r} is {actual[leaf]}, expected {expected[leaf]}); "
                    f"{f.hint}."
                )
    sha256 = f.entry.get("sha256")
    return ser.restore(path, data, state, f.template, f.what, sha256=sha256, hint=f.hint)


def _check_arm_model(out: pathlib.Path, d: Declared, arm: str) -> None:
    """The arm-model file of `arm`, where the sidecar records one: its sha256, its fields
    (`arm_dynamics.read_arm_model`) and its joints against the encoder's input size."""
    entry = d.meta["encoders"][arm].get("arm_model")
    if entry is None:
        return
    path = _file(out, entry, f"encoders.{arm}.arm_model")
    try:
        model = arm_dynamics.read_arm_model(path, entry["sha256"])
    except ValueError as e:
        raise DpcError(f"{e} (the arm model of {arm!r}); {REEXPORT}.") from e
    n_in = d.s_body.stop + 3 * model.n  # [s_body, q, qd, targets]
    if d.input_sizes[arm] != n_in or entry.get("joints", list(model.joints)) != list(model.joints):
        raise DpcError(
            f"{path} ({arm!r}'s arm model) has the joints {list(model.joints)}, so an input of "
            f"{n_in} [s_body, s_arm (2 n), p_arm (n)], but encoders.{arm}.input_size is "
            f"{d.input_sizes[arm]} (joints {entry.get('joints')}); {REEXPORT}."
        )


def _node(state: Any, dotted: str) -> Any:
    """The entry of a state dict at a dotted path, None if there is none."""
    for key in dotted.split("."):
        if not isinstance(state, dict) or key not in state:
            return None
        state = state[key]
    return state


def _file(out: pathlib.Path, entry: dict, where: str) -> pathlib.Path:
    name = entry.get("file")
    if not isinstance(name, str) or pathlib.PurePath(name).name != name or name in ("", ".", ".."):
        raise DpcError(
            f"{out / SIDECAR}: {where}.file must name a file in the export folder, got {name!r}; "
            f"{REEXPORT}."
        )
    return out / name
