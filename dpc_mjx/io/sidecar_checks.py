"""The sidecar's fields checked (`check`): every size and layout field against the others and
against this library (its observation layout, its decoder), so that `load.py` can then check the
msgpack files against the sizes it declares (`Declared`). The keys are `sidecar.py`'s.
"""

from __future__ import annotations

import dataclasses
import json
import math
import pathlib
from typing import Any

from dpc_mjx.adapter.networks import DRP_SIZE, AdapterConfig
from dpc_mjx.envs.config import U_BASES, EnvConfig
from dpc_mjx.errors import DpcError
from dpc_mjx.io.sidecar import DECODER_TARGET, REEXPORT, observation_meta, policy_layout
from dpc_mjx.policy.policy import PAPER_INPUTS, POLICY_INPUTS, observation_size

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
    layout = policy_layout(policy_inputs, latent)
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
        _check_arm_model(meta, arm, path)
    _check_scaling(meta, path, action_size)
    _check_base(meta, path)
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


def _check_base(meta: dict, path: pathlib.Path) -> None:
    """action_scaling.base (absent: 'zero'): one of `U_BASES`, 'observer' only with the yaw
    frame, and env_config.u_base where the env config is recorded."""
    scaling = meta["action_scaling"]
    base, frame = scaling.get("base", "zero"), scaling.get("frame", "world")
    if base not in U_BASES or (base == "observer" and frame != "yaw"):
        raise DpcError(
            f"{path}: action_scaling.base must be one of {list(U_BASES)} ('observer' with "
            f"frame 'yaw'), got {_json(base)} with frame {_json(frame)}; {REEXPORT}."
        )
    env = meta.get("env_config")
    if isinstance(env, dict):
        _same(path, "action_scaling.base", base, env.get("u_base", "zero"), "env_config.u_base")


def _check_arm_model(meta: dict, arm: str, path: pathlib.Path) -> None:
    """encoders.<arm>.arm_model, where present: {file, sha256, ...}, only on base 'model'."""
    entry = meta["encoders"][arm].get("arm_model")
    if entry is None:
        return  # none, or an export written before the arms' models were recorded
    base = meta["action_scaling"].get("base", "zero")
    ok = isinstance(entry, dict) and isinstance(entry.get("file"), str)
    if not ok or not isinstance(entry.get("sha256"), str) or base != "model":
        raise DpcError(
            f"{path}: encoders.{arm}.arm_model is {_json(entry)} with action_scaling.base "
            f"{_json(base)}: it must be {{file, sha256}} and only on base 'model'; {REEXPORT}."
        )


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
