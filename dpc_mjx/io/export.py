"""Writing an export: `export` (policy, decoder, one encoder per arm, the sidecar) and
`add_encoder` (one more arm). The networks are checked against each other and the sidecar
against itself (`sidecar_checks.check`, what `load` checks) before any file is written.

An export on the arms' model wrench (`action_scaling.base` 'model') also holds each arm's
rigid-body model, `arm_model_<arm>.json` (`arm_model_json`: `control.arm_model.ArmModel`'s
numbers, the env's, for `io/arm_dynamics.py`, which computes the wrench with numpy alone),
recorded as `encoders.<arm>.arm_model` {file, sha256}; `add_arm_models` writes them into an
export written before they were.
"""

from __future__ import annotations

import json
import pathlib
from collections.abc import Mapping

import mujoco
import numpy as np

from dpc_mjx.adapter.networks import (
    AdapterConfig,
    DecoderState,
    EncoderState,
    decoder_template,
    encoder_template,
)
from dpc_mjx.control.arm_model import arm_model
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.errors import DpcError
from dpc_mjx.io import arm_dynamics, sidecar, sidecar_checks
from dpc_mjx.policy.policy import PolicyState, policy_template
from dpc_mjx.robots import build, layout
from dpc_mjx.robots.spec_json import ArmLike, arm_from_json
from dpc_mjx.robots.variants import on_base, resolve
from dpc_mjx.serialization import (
    check_tree,
    jsonable,
    sha256_bytes,
    write_bytes,
    write_json,
    write_msgpack,
)
from dpc_mjx.writer import is_writer


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
    files replaced since). Returns `out_dir`. The sidecar's keys: `dpc_mjx.io.sidecar`. In a run
    of several processes only process 0 writes (`dpc_mjx.writer`; the others check and return).

    `arms` gives each encoder's arm (a variant name or an ArmSpec/UrdfArm/RobotSpec), under the
    same key; `env_config` the action scaling (default `EnvConfig()`'s); `sac_config` and `extra`
    are recorded as they are.
    """
    adapter_config.validate()
    if set(encoders) != set(arms):
        raise DpcError(
            f"encoders has arms {sorted(encoders)} but arms has {sorted(arms)}; give every "
            "encoder's arm spec (a variant name or an ArmSpec/UrdfArm/RobotSpec) under the same "
            "key."
        )
    if not encoders:
        raise DpcError("No encoder given; export at least one arm's encoder.")
    hidden = tuple(int(h) for h in policy.hidden)
    entries = {
        arm: _encoder_entry(adapter_config, arm, encoders[arm], arms[arm]) for arm in encoders
    }
    meta = sidecar.build(
        adapter_config=adapter_config,
        policy_hidden=hidden,
        action_size=int(policy.action_size),
        policy_inputs=tuple(policy.inputs),
        encoders=entries,
        env_config=env_config,
        sac_config=sac_config,
        extra=extra,
    )
    out = pathlib.Path(out_dir)
    try:
        as_read = jsonable(meta)  # what `load` will read back
    except (TypeError, ValueError) as e:
        raise DpcError(
            f"Cannot write the sidecar as JSON ({e}); pass sac_config and extra with only "
            "numbers, strings, lists and dicts."
        ) from e
    declared = sidecar_checks.check(as_read, out / sidecar.SIDECAR)
    sidecar_checks.check_records(declared)
    check_tree(
        policy,
        policy_template(
            declared.observation_size, hidden, declared.action_size, declared.policy_inputs
        ),
        "policy",
        f"The policy observes {list(declared.policy_inputs)} ({declared.observation_size} "
        f"values, z of {adapter_config.latent_size}); pass the policy trained with this adapter.",
    )
    check_tree(
        decoder,
        decoder_template(adapter_config),
        "decoder",
        "Pass the decoder trained with this adapter config.",
    )
    models = _arm_models(arms, env_config or EnvConfig())  # before any file is written
    if not is_writer():
        return out
    out.mkdir(parents=True, exist_ok=True)
    for arm, entry in entries.items():
        entry["sha256"] = write_msgpack(out / entry["file"], encoders[arm])
    _record_arm_models(out, entries, models)
    meta["policy"]["sha256"] = write_msgpack(out / sidecar.POLICY_FILE, policy)
    meta["decoder"]["sha256"] = write_msgpack(out / sidecar.DECODER_FILE, decoder)
    write_json(out / sidecar.SIDECAR, meta)
    return out


def _arm_models(arms: Mapping[str, ArmLike], env_config: EnvConfig) -> dict[str, dict]:
    """Each arm's `arm_model_json` where the policy's u is added to the arms' model wrench."""
    if env_config.u_base != "model":
        return {}
    return {arm: arm_model_json(arm, spec, env_config.base) for arm, spec in arms.items()}


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
    meta = sidecar.read(out)
    declared = sidecar_checks.check(meta, out / sidecar.SIDECAR)
    sidecar_checks.check_records(declared)
    if arm in meta["encoders"] and not replace:
        raise DpcError(
            f"The export {out} already has an encoder for arm {arm!r}; pass replace=True to "
            "overwrite it, or add it under another name."
        )
    entry = _encoder_entry(declared.config, arm, encoder, arm_spec)
    model = None
    if meta["action_scaling"].get("base") == "model":
        model = arm_model_json(arm, arm_spec, _base_of(meta))
    entry["sha256"] = write_msgpack(out / entry["file"], encoder)
    if model is not None:
        entry["arm_model"] = _write_arm_model(out, arm, model)
    meta["encoders"] = {**meta["encoders"], arm: entry}
    meta["updated"] = sidecar.now()
    write_json(out / sidecar.SIDECAR, meta)


def _encoder_entry(
    config: AdapterConfig, arm: str, encoder: EncoderState, arm_spec: ArmLike
) -> dict:
    """The sidecar entry of `arm`'s encoder, checked against `config`."""
    shape = np.shape(encoder.input_norm.mean)
    if len(shape) != 1:
        raise DpcError(
            f"The encoder for arm {arm!r} has input_norm.mean of shape {shape}, expected (n_in,); "
            "pass one (unbatched) EncoderState per arm."
        )
    entry = sidecar.encoder_entry(arm, int(shape[0]), arm_spec)
    check_tree(
        encoder,
        encoder_template(config, entry["input_size"]),
        f"encoder for arm {arm!r}",
        f"Its output must have adapter_config.latent_size={config.latent_size} entries and its "
        f"hidden sizes be {list(config.hidden)}; pass the encoder trained with this adapter.",
    )
    return entry


def add_arm_models(out_dir: str | pathlib.Path, *, replace: bool = False) -> list[str]:
    """Write the arm-model file of every arm of an export on the arms' model wrench
    (`action_scaling.base` 'model') that lacks one (`replace=True`: every arm), from its
    sidecar's arm spec and base, and record it in the sidecar (rewritten atomically; the
    networks' files untouched). Returns the arms written."""
    out = pathlib.Path(out_dir)
    meta = sidecar.read(out)
    sidecar_checks.check(meta, out / sidecar.SIDECAR)
    if meta["action_scaling"].get("base") != "model":
        raise DpcError(
            f"The export {out} adds its policy's u to {meta['action_scaling'].get('base')!r}, "
            "not the arms' model wrench (action_scaling.base 'model'): it needs no arm model."
        )
    todo = [a for a, e in meta["encoders"].items() if replace or "arm_model" not in e]
    models = {
        a: arm_model_json(a, arm_from_json(meta["encoders"][a]["arm_spec"]), _base_of(meta))
        for a in todo
    }
    _record_arm_models(out, meta["encoders"], models)
    if todo:
        meta["updated"] = sidecar.now()
        write_json(out / sidecar.SIDECAR, meta)
    return todo


def arm_model_json(arm: str, arm_spec: ArmLike, base: str) -> dict:
    """The arm-model file of `arm_spec` on `base` (`io/arm_dynamics.py` reads it): the
    `ArmModel` the env's controller uses (`control.controller.make_controller`: `arm_model` of
    the compiled robot), its float32 numbers exactly, each joint's kind and name; a bound of
    ±inf is null (none)."""
    model = build(on_base(resolve(arm_spec), base))
    lay = layout(model)
    if not lay.arms or len(lay.arm_act) != len(lay.arm_dof):
        raise DpcError(
            f"Arm {arm!r} has {len(lay.arm_dof)} joints and {len(lay.arm_act)} servos: the arms' "
            "model wrench needs an arm with one position servo per joint."
        )
    am = arm_model(model, lay)
    kind = {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_SLIDE): "slide"}
    numbers = {k: np.asarray(getattr(am, k), np.float64).tolist() for k in arm_dynamics.SHAPES}
    bounds = {
        k: [None if np.isinf(v) else float(v) for v in np.asarray(getattr(am, k), np.float64)]
        for k in arm_dynamics.BOUNDS
    }
    names = lambda ids, of: [of(int(i)).name for i in ids]  # noqa: E731
    return {
        "format": arm_dynamics.FILE_FORMAT,
        "format_version": arm_dynamics.FILE_VERSION,
        "arm": arm,
        "base": str(base),
        "about": "dpc_mjx.control.arm_model.ArmModel of the arms on the base: bodies in tree "
        "order, positions and rotations in the parent's frame at q_ref; SI units (kg, m, rad, "
        "N·m); a null bound: none. Read by dpc_mjx/io/arm_dynamics.py",
        "joints": names(lay.arm_dof, lambda i: model.joint(model.dof_jntid[i])),
        "actuators": names(lay.arm_act, model.actuator),
        "bodies": names(lay.arm_bodies, model.body),
        "parent": list(am.parent),
        "joint": [kind[j] if k >= 0 else "weld" for j, k in zip(am.joint, am.qadr, strict=True)],
        "qadr": list(am.qadr),
        **numbers,
        **bounds,
    }


def _record_arm_models(out: pathlib.Path, entries: dict, models: dict[str, dict]) -> None:
    """Write each arm's model (`arm_model_json`) and record it in its sidecar entry."""
    for arm, model in models.items():
        entries[arm]["arm_model"] = _write_arm_model(out, arm, model)


def _write_arm_model(out: pathlib.Path, arm: str, model: dict) -> dict:
    """Write `model` (`arm_model_json`) as `arm_model_<arm>.json`: its sidecar entry."""
    arm_dynamics.arm_model_from_json(model, f"arm model of {arm!r}")  # what the reader accepts
    name = sidecar.arm_model_file(arm)
    data = (json.dumps(model, indent=1, allow_nan=False) + "\n").encode()
    write_bytes(out / name, data)
    return {"file": name, "sha256": sha256_bytes(data), "joints": model["joints"]}


def _base_of(meta: dict) -> str:
    """The base an export was trained on (its env_config's; none recorded: the A1)."""
    return str((meta.get("env_config") or {}).get("base", EnvConfig().base))
