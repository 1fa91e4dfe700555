"""The sidecar `dpc.json` of an export: building it, and reading it back with every size and
layout field checked against the others and against this library (`load.py` then checks the
msgpack files against it).

Keys (format_version 1; `export` writes them all):

    format_version, library ("dpc_mjx"), library_version, created (UTC ISO), updated (set by
    `add_encoder`)
    observation     the observation layout, from `dpc_mjx.envs.observations`: {s_body: {start,
                    stop, names}: s_body = obs[start:stop] of every encoder's input; encoder_input,
                    policy_input: the blocks in words}. Sidecars written before it was recorded
                    lack it; they meant `observation_meta()`, which is then used
    adapter_config  `AdapterConfig`'s fields (latent_size, hidden, decoder_sees_body shape the
                    encoders and the decoder)
    policy          {file, sha256, hidden, action_size, inputs (the observation's blocks,
                    `sac.policy.POLICY_INPUTS`; absent: [s_body, z]), observation_size (their
                    sizes), observation_layout (s_body's names, z_0 .., then u_obs's names),
                    activation, input, output}
    decoder         {file, sha256, latent_size, out_size, sees_body, target_layout}
    encoders        {arm: {file, input_size, input_layout, arm_spec, sha256}}
    action_scaling  {u_scale (action_size,): N for f_a, N·m for tau_a; frame: 'yaw' or 'world'
                    (env_config.u_frame; absent: world); u: in words}
    env_config, sac_config, extra   as given to `export`, or null
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import pathlib
import re
from typing import Any

from dpc_mjx._version import __version__
from dpc_mjx.adapter.networks import DRP_SIZE, AdapterConfig
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.observations import S_BODY_NAMES, U_OBS_NAMES, ObsLayout
from dpc_mjx.errors import DpcError
from dpc_mjx.io.serialization import read_json
from dpc_mjx.robots.spec_json import ArmLike, arm_to_json
from dpc_mjx.sac.policy import PAPER_INPUTS, POLICY_INPUTS, observation_size

FORMAT_VERSION = 1  # of the export folder; bump when its files or sidecar keys change meaning
SIDECAR = "dpc.json"
POLICY_FILE = "policy.msgpack"
DECODER_FILE = "decoder.msgpack"
# The decoder's target: s_body's roll and pitch rate one env step later (rad/s, trunk frame).
DECODER_TARGET = ("roll_rate", "pitch_rate")
REEXPORT = "re-export the artefacts with dpc_mjx.io.export"
_ARM_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_REQUIRED = (
    *("format_version", "library_version", "adapter_config", "policy", "decoder", "encoders"),
    "action_scaling",
)
_SIZES = ("latent_size", "hidden", "decoder_sees_body")  # adapter_config keys that shape networks
_BOUNDS = ("max_force", "max_torque")  # env_config keys that give action_scaling.u_scale


@dataclasses.dataclass(frozen=True)
class Declared:
    """The sizes a sidecar declares, checked against each other (`check`), not yet the files."""

    path: pathlib.Path  # the sidecar
    meta: dict  # the sidecar as read
    config: AdapterConfig
    s_body: slice  # of every encoder's input
    policy_hidden: tuple[int, ...]
    action_size: int
    observation_size: int  # the policy's input, the blocks `policy_inputs`
    decoder_out: int  # next roll and pitch rate
    input_sizes: dict[str, int]  # arm -> its encoder's input size [s_body, s_arm, p_arm]
    policy_inputs: tuple[str, ...]  # the blocks of the policy's observation, in order


# --------------------------------------------------------------------------- building


def observation_meta() -> dict:
    """The observation layout as the sidecar records it (`dpc_mjx.envs.observations`)."""
    s_body = ObsLayout(n_arm_joints=0, n_arm_act=0).s_body  # the same in every arm's layout
    return {
        "s_body": {"start": s_body.start, "stop": s_body.stop, "names": list(S_BODY_NAMES)},
        "u_obs": {"names": list(U_OBS_NAMES), "frame": "yaw"},
        "encoder_input": "[s_body, s_arm (n joint positions, then n velocities), p_arm (n_act "
        "servo targets)]: the first encoders.<arm>.input_size entries of the raw observation of "
        "the arm's env; u_obs (the disturbance observer's estimate) follows them",
        "policy_input": "policy.inputs of s_body, z (adapter_config.latent_size), u_obs: "
        "policy.observation_layout",
    }


def encoder_entry(arm: str, input_size: int, arm_spec: ArmLike) -> dict:
    """The sidecar's record of one arm's encoder (its sha256 is added once the file is written)."""
    if not isinstance(arm, str) or not _ARM_NAME.match(arm):
        raise DpcError(
            f"Arm name {arm!r} cannot name a file; use letters, digits, '_', '-' or '.'."
        )
    return {
        "file": f"encoder_{arm}.msgpack",
        "input_size": input_size,
        "input_layout": f"[s_body ({len(S_BODY_NAMES)}), s_arm (n joint positions, then n "
        "velocities), p_arm (n_act servo targets)], the raw observation of this arm's env",
        "arm_spec": arm_to_json(arm_spec),
    }


def build(
    *,
    adapter_config: AdapterConfig,
    policy_hidden: tuple[int, ...],
    action_size: int,
    policy_inputs: tuple[str, ...],
    encoders: dict[str, dict],
    env_config: EnvConfig | None,
    sac_config: dict | None,
    extra: dict | None,
) -> dict:
    """The sidecar of an export, its files' sha256s still None (`export` sets them)."""
    latent = adapter_config.latent_size
    observation = observation_meta()
    scaling = env_config or EnvConfig()
    return {
        "format_version": FORMAT_VERSION,
        "library": "dpc_mjx",
        "library_version": __version__,
        "created": now(),
        "observation": observation,
        "adapter_config": dataclasses.asdict(adapter_config),
        "policy": {
            "file": POLICY_FILE,
            "sha256": None,  # set once the file is written
            "hidden": list(policy_hidden),
            "action_size": action_size,
            "inputs": list(policy_inputs),
            "observation_size": observation_size(policy_inputs, latent),
            "observation_layout": _policy_layout(policy_inputs, latent),
            "activation": "relu",
            "input": "(observation - obs_norm.mean) / obs_norm.std, obs_norm in policy.msgpack",
            "output": "action = tanh(first action_size outputs), in [-1, 1]",
        },
        "decoder": {
            "file": DECODER_FILE,
            "sha256": None,  # set once the file is written
            "latent_size": latent,
            "out_size": DRP_SIZE,
            "sees_body": adapter_config.decoder_sees_body,
            "target_layout": list(DECODER_TARGET),  # next step, rad/s, trunk frame
        },
        "encoders": encoders,
        "action_scaling": {
            "u_scale": list(scaling.u_scale),
            "frame": scaling.u_frame,
            "u": f"[f_a (N), tau_a (N m)] = u_scale * a (per component), {scaling.u_frame} "
            "frame, about the A1 COM",
        },
        "env_config": dataclasses.asdict(env_config) if env_config is not None else None,
        "sac_config": sac_config,
        "extra": extra,
    }


def _policy_layout(inputs: tuple[str, ...], latent: int) -> list[str]:
    """The names of the policy's observation entries."""
    names = {
        "s_body": list(S_BODY_NAMES),
        "z": [f"z_{i}" for i in range(latent)],
        "u_obs": list(U_OBS_NAMES),
    }
    return [n for block in inputs for n in names[block]]


def now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


# --------------------------------------------------------------------------- reading, checking


def read(out: pathlib.Path) -> dict:
    """The sidecar of the export folder `out`: JSON, the required keys, a format and library
    version this dpc_mjx reads. Its fields are checked by `check`."""
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
            f"{path} has format_version {version!r}, this dpc_mjx {__version__} reads "
            f"format_version {FORMAT_VERSION}; {REEXPORT} (or load it with the dpc_mjx version "
            f"{meta['library_version']!r} that wrote it)."
        )
    theirs = str(meta["library_version"])
    major = theirs.partition(".")[0]
    if major != __version__.partition(".")[0]:
        raise DpcError(
            f"{path} was written by dpc_mjx {theirs}, this is {__version__} (another major "
            f"version); load it with dpc_mjx {major}.x or {REEXPORT}."
        )
    for key in ("adapter_config", "policy", "decoder", "encoders", "action_scaling"):
        if not isinstance(meta[key], dict):
            raise DpcError(f"{path}: {key} must be a JSON object; {REEXPORT}.")
    return meta


def check(meta: dict, path: pathlib.Path) -> Declared:
    """Every size and layout field of the sidecar `meta` (at `path`) checked against the others
    and against this library's observation layout and decoder; `DpcError` naming the two fields,
    their values and what to do at the first disagreement."""
    config = adapter_config(meta, path)
    latent = config.latent_size
    s_body, names = _s_body(meta, path)
    n_body = s_body.stop - s_body.start

    p = meta["policy"]
    hidden = _ints(p, "hidden", path, "policy")
    action_size = _int(p, "action_size", path, "policy")
    obs_size = _int(p, "observation_size", path, "policy")
    policy_inputs = tuple(p.get("inputs", PAPER_INPUTS))  # older sidecars: [s_body, z]
    if policy_inputs not in POLICY_INPUTS.values():
        raise DpcError(
            f"{path}: policy.inputs is {_json(p.get('inputs'))}; this dpc_mjx knows "
            f"{[list(v) for v in POLICY_INPUTS.values()]}; {REEXPORT}."
        )
    expected = observation_size(policy_inputs, latent)  # s_body is this library's (_s_body)
    if obs_size != expected:
        raise DpcError(
            f"{path}: policy.observation_size={obs_size} but policy.inputs "
            f"{list(policy_inputs)} with s_body ({n_body}) and latent_size ({latent}) make "
            f"{expected}; {REEXPORT}."
        )
    layout = _policy_layout(policy_inputs, latent)
    z_names = f"the names of policy.inputs (z_0..z_{latent - 1}: adapter_config.latent_size)"
    _same(path, "policy.observation_layout", p.get("observation_layout"), layout, z_names)

    d = meta["decoder"]
    _same(path, "decoder.latent_size", d.get("latent_size"), latent, "adapter_config.latent_size")
    sees_body = config.decoder_sees_body
    _same(
        path, "decoder.sees_body", d.get("sees_body"), sees_body, "adapter_config.decoder_sees_body"
    )
    out_size = _int(d, "out_size", path, "decoder")
    if out_size != DRP_SIZE:
        raise DpcError(
            f"{path}: decoder.out_size is {out_size} but this dpc_mjx's decoder predicts "
            f"{DRP_SIZE} values {list(DECODER_TARGET)}; load it with the dpc_mjx version "
            f"{meta['library_version']!r} that wrote it, or {REEXPORT}."
        )
    target = d.get("target_layout")
    if not isinstance(target, list) or len(target) != out_size:
        raise DpcError(
            f"{path}: decoder.target_layout is {_json(target)} but decoder.out_size is "
            f"{out_size}: it must name each of the {out_size} outputs; {REEXPORT}."
        )

    inputs = {}
    for arm, e in meta["encoders"].items():
        if not isinstance(e, dict):
            raise DpcError(f"{path}: encoders.{arm} must be an object; {REEXPORT}.")
        inputs[arm] = _int(e, "input_size", path, f"encoders.{arm}")
        if inputs[arm] < s_body.stop:
            raise DpcError(
                f"{path}: encoders.{arm}.input_size is {inputs[arm]} but observation.s_body ends "
                f"at {s_body.stop}: an encoder's input [s_body, s_arm, p_arm] holds s_body; use "
                f"the encoder trained for this arm or {REEXPORT}."
            )
    _check_scaling(meta, path, action_size)
    return Declared(
        path, meta, config, s_body, hidden, action_size, obs_size, out_size, inputs, policy_inputs
    )


def check_records(d: Declared) -> None:
    """The training configs recorded for information, against the sizes: checked after the files
    (`load`), so a file that disagrees with the sizes is named first."""
    sac = d.meta.get("sac_config")
    if isinstance(sac, dict) and "hidden" in sac:
        hidden = list(d.policy_hidden)
        _same(d.path, "sac_config.hidden", sac["hidden"], hidden, "policy.hidden")


def adapter_config(meta: dict, path: pathlib.Path) -> AdapterConfig:
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


def _s_body(meta: dict, path: pathlib.Path) -> tuple[slice, list[str]]:
    """observation.s_body as (slice, names), which must be this library's."""
    ours = observation_meta()
    observation = meta.get("observation", ours)  # older sidecars: the layout they were made for
    s = observation.get("s_body") if isinstance(observation, dict) else None
    ok = (
        isinstance(s, dict)
        and all(_is_int(s.get(k)) for k in ("start", "stop"))
        and 0 <= s["start"] < s["stop"]
        and isinstance(s.get("names"), list)
        and all(isinstance(n, str) for n in s["names"])
    )
    if not ok:
        raise DpcError(
            f"{path}: observation.s_body must be {{start, stop, names}} with ints "
            f"0 <= start < stop and a list of names, got {_json(s)}; {REEXPORT}."
        )
    if len(s["names"]) != s["stop"] - s["start"]:
        raise DpcError(
            f"{path}: observation.s_body.names has {len(s['names'])} names but start..stop = "
            f"{s['start']}..{s['stop']} spans {s['stop'] - s['start']} entries; {REEXPORT}."
        )
    if [s[k] for k in ("start", "stop", "names")] != list(ours["s_body"].values()):
        raise DpcError(
            f"{path}: observation.s_body is {_json(s)} but this dpc_mjx's envs observe "
            f"{_json(ours['s_body'])} (dpc_mjx.envs.observations), so the policy would see other "
            f"inputs than it was trained on; load it with the dpc_mjx version "
            f"{meta['library_version']!r} that wrote it, or {REEXPORT}."
        )
    return slice(s["start"], s["stop"]), s["names"]


def _check_scaling(meta: dict, path: pathlib.Path, action_size: int) -> None:
    """action_scaling.u_scale: one positive number per action, as env_config's bounds give."""
    u_scale = meta["action_scaling"].get("u_scale")
    numbers = isinstance(u_scale, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0
        for v in u_scale
    )
    if not numbers:
        raise DpcError(
            f"{path}: action_scaling.u_scale must be a list of positive numbers (N, N·m), got "
            f"{_json(u_scale)}; {REEXPORT}."
        )
    if len(u_scale) != action_size:
        raise DpcError(
            f"{path}: action_scaling.u_scale has {len(u_scale)} entries but policy.action_size "
            f"is {action_size}: u = u_scale * action, per component; {REEXPORT}."
        )
    env = meta.get("env_config")
    if not isinstance(env, dict) or not {"max_force", "max_torque"} <= set(env):
        return
    try:
        bounds = {k: tuple(env[k]) if isinstance(env[k], list) else env[k] for k in _BOUNDS}
        expected = list(EnvConfig(**bounds).u_scale)
    except (TypeError, ValueError) as e:
        raise DpcError(
            f"{path}: env_config.max_force / max_torque must be numbers or (x, y, z) lists, got "
            f"{_json(env['max_force'])} / {_json(env['max_torque'])} ({e}); {REEXPORT}."
        ) from e
    bounds_names = "env_config.max_force, env_config.max_torque (per axis x, y, z)"
    _same(path, "action_scaling.u_scale", u_scale, expected, bounds_names)


def _same(path: pathlib.Path, field: str, value: Any, expected: Any, source: str) -> None:
    """`DpcError` unless the sidecar's `field` equals what `source` (another field) implies."""
    if value != expected or type(value) is not type(expected):
        raise DpcError(
            f"{path}: {field} is {_json(value)} but {source} gives {_json(expected)}; the "
            f"sidecar disagrees with itself: {REEXPORT}."
        )


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _int(d: dict, key: str, path: pathlib.Path, where: str) -> int:
    v = d.get(key)
    if not _is_int(v) or v < 1:
        raise DpcError(f"{path}: {where}.{key} must be an int >= 1, got {v!r}; {REEXPORT}.")
    return v


def _ints(d: dict, key: str, path: pathlib.Path, where: str) -> tuple[int, ...]:
    v = d.get(key)
    ok = isinstance(v, list) and v and all(_is_int(h) and h >= 1 for h in v)
    if not ok:
        raise DpcError(f"{path}: {where}.{key} must be a list of ints >= 1, got {v!r}; {REEXPORT}.")
    return tuple(v)


def _json(v: Any) -> str:
    try:
        return json.dumps(v)
    except (TypeError, ValueError):
        return repr(v)
