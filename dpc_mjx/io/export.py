"""Writing an export: `export` (policy, decoder, one encoder per arm, the sidecar) and
`add_encoder` (one more arm). The networks are checked against each other and the sidecar
against itself (`sidecar_checks.check`, what `load` checks) before any file is written.
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping

import numpy as np

from dpc_mjx.adapter.networks import (
    AdapterConfig,
    DecoderState,
    EncoderState,
    decoder_template,
    encoder_template,
)
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.errors import DpcError
from dpc_mjx.io import sidecar, sidecar_checks
from dpc_mjx.policy.policy import PolicyState, policy_template
from dpc_mjx.robots.spec_json import ArmLike
from dpc_mjx.serialization import check_tree, jsonable, write_json, write_msgpack
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
    if not is_writer():
        return out
    out.mkdir(parents=True, exist_ok=True)
    for arm, entry in entries.items():
        entry["sha256"] = write_msgpack(out / entry["file"], encoders[arm])
    meta["policy"]["sha256"] = write_msgpack(out / sidecar.POLICY_FILE, policy)
    meta["decoder"]["sha256"] = write_msgpack(out / sidecar.DECODER_FILE, decoder)
    write_json(out / sidecar.SIDECAR, meta)
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
    meta = sidecar.read(out)
    declared = sidecar_checks.check(meta, out / sidecar.SIDECAR)
    sidecar_checks.check_records(declared)
    if arm in meta["encoders"] and not replace:
        raise DpcError(
            f"The export {out} already has an encoder for arm {arm!r}; pass replace=True to "
            "overwrite it, or add it under another name."
        )
    entry = _encoder_entry(declared.config, arm, encoder, arm_spec)
    entry["sha256"] = write_msgpack(out / entry["file"], encoder)
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
