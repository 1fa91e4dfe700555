"""Arm specs as JSON: a variant name as itself, an `ArmSpec`/`UrdfArm`/`RobotSpec` as a dict of
its fields tagged with `"type"`. Reading builds only these dataclasses, never arbitrary types."""

from __future__ import annotations

import dataclasses
from typing import Any

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.variants import RobotSpec, resolve

ArmLike = str | ArmSpec | UrdfArm | RobotSpec
_FIX = "re-export the artefacts with dpc_mjx.io.export"


_ARM_TYPES = {cls.__name__: cls for cls in (ArmSpec, UrdfArm, RobotSpec, Mount)}


def arm_to_json(arm: ArmLike) -> str | dict:
    """A variant name as itself; an `ArmSpec`/`UrdfArm`/`RobotSpec` as a dict of its fields tagged
    with `"type"` (nested `Mount`s and arms tagged too). Validated first."""
    resolve(arm)
    if isinstance(arm, str):
        return arm
    return _dataclass_to_json(arm)


def _dataclass_to_json(x: Any) -> Any:
    if dataclasses.is_dataclass(x) and type(x).__name__ in _ARM_TYPES:
        fields = {f.name: _dataclass_to_json(getattr(x, f.name)) for f in dataclasses.fields(x)}
        return {"type": type(x).__name__, **fields}
    if isinstance(x, (tuple, list)):
        return [_dataclass_to_json(v) for v in x]
    return x


def arm_from_json(obj: Any) -> ArmLike:
    """Inverse of `arm_to_json` (only the arm dataclasses are ever built, never arbitrary
    types); `DpcError` if `obj` is not such a spec."""
    spec = _dataclass_from_json(obj)
    if not isinstance(spec, (str, ArmSpec, UrdfArm, RobotSpec)):
        raise DpcError(f"{obj!r} is not an arm spec; {_FIX}.")
    resolve(spec)
    return spec


def _dataclass_from_json(obj: Any) -> Any:
    if isinstance(obj, list):
        return tuple(_dataclass_from_json(v) for v in obj)
    if not isinstance(obj, dict):
        return obj
    kind = obj.get("type")
    if kind not in _ARM_TYPES:
        raise DpcError(f"Arm spec type {kind!r} is not one of {sorted(_ARM_TYPES)}; {_FIX}.")
    cls = _ARM_TYPES[kind]
    fields = {k: _dataclass_from_json(v) for k, v in obj.items() if k != "type"}
    names = {f.name for f in dataclasses.fields(cls)}
    if set(fields) - names:
        raise DpcError(
            f"Arm spec {kind} has unknown fields {sorted(set(fields) - names)} (written by a newer "
            f"dpc_mjx?); {_FIX}."
        )
    return cls(**fields)
