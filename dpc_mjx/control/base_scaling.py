"""The low-level controller's numbers on any base: the A1's (tuned by hand) scaled by stated rules.

A base is compared with the A1 by three ratios, each measured the same way on both compiled
models (`control.state.state_index`), so that the A1's are exactly 1 and its numbers unchanged:

    m = mass of trunk + legs / the A1's          (kg / kg)
    l = leg length / the A1's                    (hip pitch joint -> knee -> foot centre, at home)
    h = home trunk height / the A1's             (m / m)

Rules (dynamic similarity under gravity: lengths scale with l, times with sqrt(l), forces with m):

    desired COM height, fall height        x h
    swing apex, COM tracking clamp         x l
    Raibert foothold gain (s)              x sqrt(l)
    stance force bounds f_min, f_max (N)   x m
    swing PD gains kp (N/m), kd (N s/m)    x m / l, x m / sqrt(l)
    force weight R ((m/s^2 / N)^2)         / m^2      (the same share of the cost)
    torque limits                          the model's own motors' ranges (the file's effort)
    mass and inertia of the balance model  the model's own (trunk + legs at home)

The gait keeps its period: a gait is given in seconds (`control.gait`). Observer gains (rad/s)
and the balance QP's acceleration gains and weights are per unit mass already and stay.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax.numpy as jp
import mujoco

from dpc_mjx.control import balance
from dpc_mjx.control.state import StateIndex, state_index
from dpc_mjx.robots import build
from dpc_mjx.robots.layout import Layout, layout

FALL_HEIGHT = 0.15  # m, the A1's: a trunk below this has fallen (x h on another base)


@dataclasses.dataclass(frozen=True)
class BaseScale:
    """The base's ratios to the A1 (module doc)."""

    mass: float  # m
    length: float  # l
    height: float  # h

    @property
    def fall_height(self) -> float:
        """m: a trunk (its origin) below this has fallen."""
        return FALL_HEIGHT * self.height


@functools.cache
def _a1() -> StateIndex:
    """The bare A1's `StateIndex`, the reference of every ratio."""
    model = build("none")
    return state_index(model, layout(model))


def base_scale(idx: StateIndex) -> BaseScale:
    """The ratios of the base whose `StateIndex` is `idx` to the A1's."""
    a1 = _a1()
    return BaseScale(
        mass=idx.base_mass / a1.base_mass,
        length=idx.leg_length / a1.leg_length,
        height=idx.home_height / a1.home_height,
    )


def force_bounds(mass_ratio: float) -> tuple[float, float]:
    """(f_min, f_max) N: a stance foot's normal-force bounds on a base `mass_ratio` times the
    A1's mass (the balance QP's and the static-balance check's)."""
    return balance.DEFAULTS["f_min"] * mass_ratio, balance.DEFAULTS["f_max"] * mass_ratio


def scaled_config(config, scale: BaseScale, lay: Layout, idx: StateIndex):
    """`config` (a `ControllerConfig` with the A1's numbers) scaled to the base (module doc)."""
    m, length = scale.mass, scale.length
    f_min, f_max = force_bounds(m)
    params = balance.default_params(
        mass=idx.base_mass, inertia=(1.0, 1.0, 1.0), f_min=f_min, f_max=f_max,
        R=balance.DEFAULTS["R"] / m**2,
    )  # fmt: skip
    params = dataclasses.replace(params, inertia=jp.asarray(idx.base_inertia, jp.float32))
    return config.replace(
        balance=params,
        body_height=config.body_height * scale.height,
        swing_height=config.swing_height * length,
        max_pos_error=config.max_pos_error * length,
        raibert_k=config.raibert_k * math.sqrt(length),
        swing_kp=config.swing_kp * (m / length),
        swing_kd=config.swing_kd * (m / math.sqrt(length)),
        torque_limit=jp.asarray(lay.torque_limits, jp.float32),
    )


def model_scale(model: mujoco.MjModel) -> BaseScale:
    """`base_scale` of a compiled robot."""
    return base_scale(state_index(model, layout(model)))


__all__ = ["FALL_HEIGHT", "BaseScale", "base_scale", "force_bounds", "model_scale", "scaled_config"]
