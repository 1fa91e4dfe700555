"""Saved artefacts as data: msgpack files plus a JSON sidecar, never pickle (DESIGN §9).

The files are written and read with `dpc_mjx.serialization` (atomic, checked, never pickle).

An export is a folder:

    dpc.json                 the sidecar: format and library version, sizes, layouts, scaling,
                             configs, per file its sha256 (see `export` for the keys)
    policy.msgpack           `PolicyState` (actor params, observation statistics)
    decoder.msgpack          `DecoderState`
    encoder_<arm>.msgpack    `EncoderState`, one per arm

`load` rebuilds empty networks from the sidecar's sizes and checks every file against them, so a
stale, truncated or mismatched file fails with a message saying what to do. `dpc_mjx/inference.py`
reads the same folder with numpy only, on a robot.
"""

from __future__ import annotations

import dataclasses
import datetime
import pathlib
import re
from collections.abc import Mapping

import numpy as np

from dpc_mjx.adapter.networks import (
    DRP_SIZE,
    AdapterConfig,
    DecoderState,
    EncoderState,
    decoder_template,
    encoder_template,
)
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.observations import S_BODY_SIZE
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.spec_json import ArmLike, arm_from_json, arm_to_json
from dpc_mjx.sac.policy import PolicyState, dpc_policy, policy_template
from dpc_mjx.serialization import check_tree, read_json, read_msgpack, write_json, write_msgpack

FORMAT_VERSION = 1  # of the export folder; bump when its files or sidecar keys change meaning
SIDECAR = "dpc.json"
POLICY_FILE = "policy.msgpack"
DECODER_FILE = "decoder.msgpack"
S_BODY_NAMES = (
    *("roll", "pitch"),  # rad
    *("wx", "wy", "wz"),  # rad/s, trunk frame
    *("vx", "vy", "vz"),  # m/s, yaw frame
    *("cmd_vx", "cmd_vy", "cmd_yaw"),  # m/s, m/s (yaw frame), rad/s
)
REEXPORT = "re-export the artefacts with dpc_mjx.io.export"
_ARM_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


# --------------------------------------------------------------------------- export / load


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


def _encoder_entry(
    config: AdapterConfig, arm: str, encoder: EncoderState, arm_spec: ArmLike
) -> dict:
    if not isinstance(arm, str) or not _ARM_NAME.match(arm):
        raise DpcError(
            f"Arm name {arm!r} cannot name a file; use letters, digits, '_', '-' or '.'."
        )
    shape = np.shape(encoder.input_norm.mean)
    if len(shape) != 1:
        raise DpcError(
            f"The encoder for arm {arm!r} has input_norm.mean of shape {shape}, expected (n_in,); "
            "pass one (unbatched) EncoderState per arm."
        )
    n_in = int(shape[0])
    check_tree(
        encoder,
        encoder_template(config, n_in),
        f"encoder for arm {arm!r}",
        f"Its output must have adapter_config.latent_size={config.latent_size} entries and its "
        f"hidden sizes be {list(config.hidden)}; pass the encoder trained with this adapter.",
    )
    return {
        "file": f"encoder_{arm}.msgpack",
        "input_size": n_in,
        "input_layout": "[s_body (11), s_arm (n joint positions, then n velocities), p_arm "
        "(n_act servo targets)], the raw observation of this arm's env",
        "arm_spec": arm_to_json(arm_spec),
    }


def export(
    out_dir: str | pathlib.Path,
    *,
    adapter_config: AdapterConfig,
    policy: PolicyState,
    decoder: DecoderState,
    encoders: Mapping[str, EncoderState],
    arms: Mapping[str, ArmLike],
    env_config: EnvConfig | None = None,
    sac_config: dict | None = None,
    extra: dict | None = None,
) -> pathlib.Path:
    """Write the policy, decoder and one encoder per arm to `out_dir`, then the sidecar `dpc.json`
    (last: a killed export leaves no sidecar, or the previous one, whose sha256s then reject the
    files replaced since). Returns `out_dir`.

    Sidecar keys: format_version, library, library_version, created (UTC ISO; `add_encoder`
    adds updated), adapter_config, policy {file, sha256, hidden, action_size, observation_size,
    observation_layout, activation, input, output}, decoder {file, sha256, latent_size, out_size,
    sees_body, target_layout}, encoders {arm: {file, input_size, input_layout, arm_spec, sha256}},
    action_scaling {u_scale, u}, env_config, sac_config, extra.
    """
    import dpc_mjx  # for __version__ (a module-level import would be circular)

    adapter_config.validate()
    if set(encoders) != set(arms):
        raise DpcError(
            f"encoders has arms {sorted(encoders)} but arms has {sorted(arms)}; give every "
            "encoder's arm spec (a variant name or an ArmSpec/UrdfArm/RobotSpec) under the same "
            "key."
        )
    if not encoders:
        raise DpcError("No encoder given; export at least one arm's encoder.")
    latent = adapter_config.latent_size
    obs_size = S_BODY_SIZE + latent
    hidden = tuple(int(h) for h in policy.hidden)
    check_tree(
        policy,
        policy_template(obs_size, hidden, policy.action_size),
        "policy",
        f"The policy observes [s_body ({S_BODY_SIZE}), z ({latent})]; pass the policy trained "
        "with this adapter.",
    )
    check_tree(
        decoder,
        decoder_template(adapter_config),
        "decoder",
        "Pass the decoder trained with this adapter config.",
    )
    entries = {
        arm: _encoder_entry(adapter_config, arm, encoders[arm], arms[arm]) for arm in encoders
    }
    scaling = env_config or EnvConfig()

    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for arm, entry in entries.items():
        entry["sha256"] = write_msgpack(out / entry["file"], encoders[arm])
    meta = {
        "format_version": FORMAT_VERSION,
        "library": "dpc_mjx",
        "library_version": dpc_mjx.__version__,
        "created": _now(),
        "adapter_config": dataclasses.asdict(adapter_config),
        "policy": {
            "file": POLICY_FILE,
            "sha256": write_msgpack(out / POLICY_FILE, policy),
            "hidden": list(hidden),
            "action_size": int(policy.action_size),
            "observation_size": obs_size,
            "observation_layout": [*S_BODY_NAMES, *(f"z_{i}" for i in range(latent))],
            "activation": "relu",
            "input": "(observation - obs_norm.mean) / obs_norm.std, obs_norm in policy.msgpack",
            "output": "action = tanh(first action_size outputs), in [-1, 1]",
        },
        "decoder": {
            "file": DECODER_FILE,
            "sha256": write_msgpack(out / DECODER_FILE, decoder),
            "latent_size": latent,
            "out_size": DRP_SIZE,
            "sees_body": adapter_config.decoder_sees_body,
            "target_layout": ["roll_rate", "pitch_rate"],  # next step, rad/s, trunk frame
        },
        "encoders": entries,
        "action_scaling": {
            "u_scale": list(scaling.u_scale),
            "u": "[f_a (N), tau_a (N m)] = u_scale * a (per component), world frame, about the "
            "A1 COM",
        },
        "env_config": dataclasses.asdict(env_config) if env_config is not None else None,
        "sac_config": sac_config,
        "extra": extra,
    }
    write_json(out / SIDECAR, meta)
    return out


def add_encoder(
    out_dir: str | pathlib.Path,
    arm: str,
    encoder: EncoderState,
    arm_spec: ArmLike,
    *,
    replace: bool = False,
) -> None:
    """Add the encoder of one more arm (e.g. after a transfer) to an existing export, and record
    it in the sidecar (rewritten atomically). `replace=True` overwrites an arm already there."""
    out = pathlib.Path(out_dir)
    meta = _read_sidecar(out)
    config = _adapter_config(meta, out / SIDECAR)
    if arm in meta["encoders"] and not replace:
        raise DpcError(
            f"The export {out} already has an encoder for arm {arm!r}; pass replace=True to "
            "overwrite it, or add it under another name."
        )
    entry = _encoder_entry(config, arm, encoder, arm_spec)
    entry["sha256"] = write_msgpack(out / entry["file"], encoder)
    meta["encoders"] = {**meta["encoders"], arm: entry}
    meta["updated"] = _now()
    write_json(out / SIDECAR, meta)


def load(out_dir: str | pathlib.Path) -> Artefacts:
    """Read an export written by `export`, checking the sidecar's version and keys and every
    file's leaves against the networks its sizes describe. Raises `DpcError` on any mismatch."""
    out = pathlib.Path(out_dir)
    meta = _read_sidecar(out)
    sidecar = out / SIDECAR
    config = _adapter_config(meta, sidecar)
    p = meta["policy"]
    hidden = _ints(p, "hidden", sidecar, "policy")
    action_size = _int(p, "action_size", sidecar, "policy")
    obs_size = _int(p, "observation_size", sidecar, "policy")
    if obs_size != S_BODY_SIZE + config.latent_size:
        raise DpcError(
            f"{sidecar}: policy.observation_size={obs_size} but s_body ({S_BODY_SIZE}) + "
            f"latent_size ({config.latent_size}) = {S_BODY_SIZE + config.latent_size}; {REEXPORT}."
        )
    policy = read_msgpack(
        _file(out, p, "policy"),
        policy_template(obs_size, hidden, action_size),
        "policy",
        sha256=p.get("sha256"),
        hint=REEXPORT,
    )
    decoder = read_msgpack(
        _file(out, meta["decoder"], "decoder"),
        decoder_template(config),
        "decoder",
        sha256=meta["decoder"].get("sha256"),
        hint=REEXPORT,
    )
    encoders = {}
    for arm, e in meta["encoders"].items():
        if not isinstance(e, dict):
            raise DpcError(f"{sidecar}: encoders.{arm} must be an object; {REEXPORT}.")
        n_in = _int(e, "input_size", sidecar, f"encoders.{arm}")
        encoders[arm] = read_msgpack(
            _file(out, e, f"encoders.{arm}"),
            encoder_template(config, n_in),
            f"encoder for arm {arm!r}",
            sha256=e.get("sha256"),
            hint=f"use the encoder trained for this arm (input size {n_in}) or {REEXPORT}",
        )
    return Artefacts(config, policy, decoder, encoders, meta)


_REQUIRED = ("format_version", "library_version", "adapter_config", "policy", "decoder", "encoders")
_SIZES = ("latent_size", "hidden", "decoder_sees_body")  # adapter_config keys that shape networks


def _read_sidecar(out: pathlib.Path) -> dict:
    import dpc_mjx

    path = out / SIDECAR
    meta = read_json(
        path,
        "export sidecar",
        hint=f"point at a folder written by dpc_mjx.io.export, or {REEXPORT}",
    )
    if not isinstance(meta, dict):
        raise DpcError(f"{path} must hold a JSON object; {REEXPORT}.")
    missing = [k for k in _REQUIRED if k not in meta]
    if missing:
        raise DpcError(f"{path} lacks the keys {missing}; {REEXPORT}.")
    version = meta["format_version"]
    if version != FORMAT_VERSION:
        raise DpcError(
            f"{path} has format_version {version!r}, this dpc_mjx {dpc_mjx.__version__} reads "
            f"format_version {FORMAT_VERSION}; {REEXPORT} (or load it with the dpc_mjx version "
            f"{meta['library_version']!r} that wrote it)."
        )
    theirs, ours = str(meta["library_version"]), dpc_mjx.__version__
    major = theirs.partition(".")[0]
    if major != ours.partition(".")[0]:
        raise DpcError(
            f"{path} was written by dpc_mjx {theirs}, this is {ours} (another major version); "
            f"load it with dpc_mjx {major}.x or {REEXPORT}."
        )
    for key in ("adapter_config", "policy", "decoder", "encoders"):
        if not isinstance(meta[key], dict):
            raise DpcError(f"{path}: {key} must be a JSON object; {REEXPORT}.")
    return meta


def _adapter_config(meta: dict, path: pathlib.Path) -> AdapterConfig:
    raw = dict(meta["adapter_config"])
    names = {f.name for f in dataclasses.fields(AdapterConfig)}
    if set(raw) - names or set(_SIZES) - set(raw):
        raise DpcError(
            f"{path}: adapter_config has unknown keys {sorted(set(raw) - names)} or lacks "
            f"{sorted(set(_SIZES) - set(raw))}; {REEXPORT}."
        )
    if "hidden" in raw:
        raw["hidden"] = tuple(raw["hidden"]) if isinstance(raw["hidden"], list) else raw["hidden"]
    config = AdapterConfig(**raw)
    config.validate()
    return config


def _int(d: dict, key: str, path: pathlib.Path, where: str) -> int:
    v = d.get(key)
    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
        raise DpcError(f"{path}: {where}.{key} must be an int >= 1, got {v!r}; {REEXPORT}.")
    return v


def _ints(d: dict, key: str, path: pathlib.Path, where: str) -> tuple[int, ...]:
    v = d.get(key)
    ok = isinstance(v, list) and v and all(isinstance(h, int) and h >= 1 for h in v)
    if not ok:
        raise DpcError(f"{path}: {where}.{key} must be a list of ints >= 1, got {v!r}; {REEXPORT}.")
    return tuple(v)


def _file(out: pathlib.Path, entry: dict, where: str) -> pathlib.Path:
    name = entry.get("file")
    if not isinstance(name, str) or pathlib.PurePath(name).name != name or name in ("", ".", ".."):
        raise DpcError(
            f"{out / SIDECAR}: {where}.file must name a file in the export folder, got {name!r}; "
            f"{REEXPORT}."
        )
    return out / name


def _now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


__all__ = [
    "FORMAT_VERSION",
    "SIDECAR",
    "Artefacts",
    "add_encoder",
    "export",
    "load",
]
