"""Arm specs as JSON: a variant name as itself, an `ArmSpec`/`UrdfArm`/`RobotSpec` as a dict of
its fields tagged with `"type"`. Reading builds only these dataclasses, never arbitrary types."""

from __future__ import annotations

import dataclasses
import pathlib
from typing import Any

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.arms.file import SUFFIXES
from dpc_mjx.robots.urdf import read_description
from dpc_mjx.robots.variants import VARIANTS, RobotSpec, resolve

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


# Keys of a user's arm description (a JSON object): UrdfArm's fields, `mount` as {"pos", "yaw"}
# and `home` as {joint: value}.
DESCRIPTION_KEYS = ("urdf", "mount", "ee_body", "ee_offset", "home")


def arm_argument(text: str) -> str | UrdfArm:
    """What `--arm` / `--arms` name: a variant (`regular`), an arm file (`my_arm.urdf`, `.xml`) or
    an arm description (`my_arm.json`, see `read_arm_description`); checked (`robots.resolve`)."""
    if text in VARIANTS:
        return text
    suffix = pathlib.Path(text).suffix.lower()
    if suffix == ".json":
        arm = read_arm_description(text)
    elif suffix in SUFFIXES:
        arm = UrdfArm(str(pathlib.Path(text).expanduser().resolve()))
    else:
        raise DpcError(
            f"Unknown arm {text!r}: not a variant ({sorted(VARIANTS)}) nor an arm file (.urdf, "
            "MJCF .xml) or arm description (.json)."
        )
    resolve(arm)
    return arm


def read_arm_description(path: str | pathlib.Path) -> UrdfArm:
    """An arm description: a JSON object such as

        {"urdf": "my_arm.urdf", "ee_body": "link6", "ee_offset": [0, 0, 0.05],
         "mount": {"pos": [0.09, 0, 0.057], "yaw": 0}, "home": {"joint2": 0.5}}

    where only "urdf" (a path relative to the JSON file, or absolute; URDF or MJCF) is needed; the
    others default as in `UrdfArm`."""
    p = pathlib.Path(path).expanduser()
    if not p.is_file():
        raise DpcError(f"Arm description {str(path)!r} does not exist; give the path of its JSON.")
    d = read_description(p, "Arm description", DESCRIPTION_KEYS, "the arm file")
    try:
        mount = d.get("mount", {})
        home = d.get("home", {})
        offset = d.get("ee_offset")
        return UrdfArm(
            urdf=str((p.parent / d["urdf"]).resolve()),
            mount=Mount(
                tuple(float(v) for v in mount.get("pos", Mount().pos)), float(mount.get("yaw", 0.0))
            ),
            ee_body=d.get("ee_body"),
            ee_offset=None if offset is None else tuple(float(v) for v in offset),
            home=tuple((str(k), float(v)) for k, v in home.items()),
        )
    except (AttributeError, TypeError, ValueError) as e:
        raise DpcError(
            f'Arm description {p}: {e}; "mount" is {{"pos": [x, y, z], "yaw": rad}}, '
            '"home" is {joint: value}, "ee_offset" is [x, y, z] (m).'
        ) from e
