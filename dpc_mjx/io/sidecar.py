"""The sidecar `dpc.json` of an export: its keys, building it, and reading it back
(`sidecar_checks.py` checks every size and layout field against the others and against this
library; `load.py` then checks the msgpack files against it).

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
                    `policy.policy.POLICY_INPUTS`; absent: [s_body, z]), observation_size (their
                    sizes), observation_layout (s_body's names, z_0 .., then u_obs's names),
                    activation, input, output}
    decoder         {file, sha256, latent_size, out_size, sees_body, target_layout}
    encoders        {arm: {file, input_size, input_layout, arm_spec, sha256, arm_model}}:
                    arm_model {file: arm_model_<arm>.json, sha256, joints} where
                    action_scaling.base is 'model' (the arm's rigid-body model, `export.
                    arm_model_json`, that `arm_dynamics.py` computes u_model from; absent in
                    exports written before it: the robot passes u_model)
    action_scaling  {u_scale (action_size,): N for f_a, N·m for tau_a; frame: 'yaw' or 'world'
                    (env_config.u_frame; absent: world); base: 'zero', 'observer', 'gravity'
                    or 'model' (env_config.u_base; absent: zero), with 'observer' also
                    observer {gain, aligned, sensor_delay}: u = u_obs + u_scale * a; with
                    'gravity' u = u_gravity + u_scale * a (the arms' weight at their pose);
                    with 'model' u = u_model + u_scale * a (the arms' inverse dynamics from the
                    measured states, `control/arm_estimate.py`); u: in words}
    onnx            {opset, input, output, ...}: the graph `dpc-mjx onnx` writes of an arm
                    (`onnx_graph.py`); absent in sidecars written before it: `ONNX`
    env_config, sac_config, extra   as given to `export`, or null
"""

from __future__ import annotations

import dataclasses
import datetime
import pathlib
import re

from dpc_mjx._version import __version__
from dpc_mjx.adapter.networks import DRP_SIZE, AdapterConfig
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.observations import S_BODY_NAMES, U_OBS_NAMES, ObsLayout
from dpc_mjx.errors import DpcError
from dpc_mjx.io import onnx_arm
from dpc_mjx.policy.policy import observation_size
from dpc_mjx.robots.spec_json import ArmLike, arm_to_json
from dpc_mjx.serialization import read_json

FORMAT_VERSION = 1  # of the export folder; bump when its files or sidecar keys change meaning
SIDECAR = "dpc.json"
POLICY_FILE = "policy.msgpack"
DECODER_FILE = "decoder.msgpack"
# The decoder's target: s_body's roll and pitch rate one env step later (rad/s, trunk frame).
DECODER_TARGET = ("roll_rate", "pitch_rate")
REEXPORT = "re-export the artefacts with dpc_mjx.io.export"
# The ONNX graph of an arm's encoder and the policy (`onnx_graph.py`): its opset, its input (the
# raw env observation, float32 (batch, input_size + 6)) and its output (u, float32 (batch, 6))
ONNX = {"opset": 17, "input": "obs", "output": "u"}
ONNX_SHAPES = (  # the graph's tensors, as the sidecar's `onnx.shapes` describes them
    "obs float32 (batch, encoders.<arm>.input_size + 6): the raw env observation; u float32 "
    "(batch, 6): [f_a (N), tau_a (N m)], action_scaling.frame"
)
ONNX_MODEL_SHAPES = (  # and, on the arms' model (action_scaling.base 'model'), its inputs
    "; with the arms' model (action_scaling.base 'model') five more inputs, each required: "
    + "; ".join(
        f"{key} (batch, {', '.join(map(str, shape))}): {words}"
        for key, (shape, words) in onnx_arm.MEASURED.items()
    )
    + "; u is then u_model + the policy's u, and u_world float32 (batch, 6) the same in the world "
    "frame"
)
_ARM_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_REQUIRED = (
    *("format_version", "library_version", "adapter_config", "policy", "decoder", "encoders"),
    "action_scaling",
)


# --------------------------------------------------------------------------- building


def action_scaling(env_config: EnvConfig) -> dict:
    """The sidecar's `action_scaling`: u_scale, frame, base (`EnvConfig.u_base`; with
    'observer' also the observer the policy's u is added to) and u in words."""
    frame, base = env_config.u_frame, env_config.u_base
    entry = {"u_scale": list(env_config.u_scale), "frame": frame, "base": base}
    words = f"u_scale * a (per component), {frame} frame, about the base's COM"
    if base == "observer":
        words = f"u_obs + {words} (u_obs: the observation's last 6 entries)"
        entry["observer"] = {
            "gain": env_config.observer_gain,  # rad/s, all axes or (force, torque)
            "aligned": env_config.observer_aligned,
            "sensor_delay": env_config.sensor_delay,  # 4 ms ticks
        }
    if base == "gravity":
        words = f"u_gravity + {words} (u_gravity: the arms' weight and its torque at their pose)"
    if base == "model":
        words = f"u_model + {words} (u_model: the arms' inverse dynamics from measured states)"
    return entry | {"u": f"[f_a (N), tau_a (N m)] = {words}"}


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


def arm_model_file(arm: str) -> str:
    """The name of `arm`'s arm-model file (`encoders.<arm>.arm_model.file`)."""
    return f"arm_model_{arm}.json"


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
            "observation_layout": policy_layout(policy_inputs, latent),
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
        "action_scaling": action_scaling(scaling),
        "onnx": {
            **ONNX,
            "shapes": ONNX_SHAPES + (ONNX_MODEL_SHAPES if scaling.u_base == "model" else ""),
            "command": "dpc-mjx onnx --export DIR --arm ARM --out policy.onnx",
        },
        "env_config": dataclasses.asdict(env_config) if env_config is not None else None,
        "sac_config": sac_config,
        "extra": extra,
    }


def policy_layout(inputs: tuple[str, ...], latent: int) -> list[str]:
    """The names of the policy's observation entries."""
    names = {
        "s_body": list(S_BODY_NAMES),
        "z": [f"z_{i}" for i in range(latent)],
        "u_obs": list(U_OBS_NAMES),
    }
    return [n for block in inputs for n in names[block]]


def now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


# --------------------------------------------------------------------------- reading


def read(out: pathlib.Path) -> dict:
    """The sidecar of the export folder `out`: JSON, the required keys, a format and library
    version this dpc_mjx reads. Its fields are checked by `sidecar_checks.check`."""
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
