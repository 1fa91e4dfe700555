"""The field checks of the env's configuration (`envs/config.py`): each raises `DpcError` naming
the field, what it must be and the value it got."""

from __future__ import annotations

import math
from typing import Any

from dpc_mjx.errors import DpcError


def check_choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise DpcError(f"{name}={value!r} is not valid; choose one of {list(choices)}.")


def check_int(name: str, value: Any, low: int, high: float = math.inf) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise DpcError(f"{name} must be an int in [{low}, {high}], got {value!r}.")


def check_number_or_pair(name: str, value: Any, low: float, high: float) -> None:
    """`DpcError` unless `value` is a number in [low, high], or a (force, torque) pair of them."""
    if isinstance(value, tuple) and len(value) != 2:
        raise DpcError(f"{name} must be a number or a (force, torque) pair, got {value!r}.")
    for v in value if isinstance(value, tuple) else (value,):
        check_number(name, v, low, high)


def check_bool(name: str, value: Any) -> None:
    if not isinstance(value, bool):
        raise DpcError(f"{name} must be True or False, got {value!r}.")


def check_number(name: str, value: Any, low: float = -math.inf, high: float = math.inf) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or not low <= value <= high:
        raise DpcError(f"{name} must be a finite number in [{low}, {high}], got {value!r}.")


def check_positive(name: str, value: Any) -> None:
    check_number(name, value)
    if value <= 0:
        raise DpcError(f"{name} must be > 0, got {value!r}.")


def per_axis(value: float | tuple[float, ...]) -> tuple[float, float, float]:
    return tuple(float(v) for v in value) if isinstance(value, tuple) else (float(value),) * 3


def check_axes(name: str, value: Any) -> None:
    """A positive number, or an (x, y, z) tuple of them."""
    values = value if isinstance(value, tuple) else (value,)
    if isinstance(value, tuple) and len(value) != 3:
        raise DpcError(f"{name} must be a number or an (x, y, z) tuple, got {value!r}.")
    for v in values:
        check_positive(name, v)


def check_range(name: str, value: Any, low: float = -math.inf) -> None:
    if not (isinstance(value, tuple) and len(value) == 2):
        raise DpcError(f"{name} must be a (low, high) tuple, got {value!r}.")
    for v in value:
        check_number(name, v, low=low)
    if value[0] > value[1]:
        raise DpcError(f"{name} must have low <= high, got {value!r}.")
