"""Gait phase scheduling: which feet are in stance, and how far each swing has progressed.

A gait is a period T (s), a duty factor D (fraction of the period in stance) and a phase offset
per foot (FR, FL, RR, RL). Foot i's phase is phi_i = frac(t / T + offset_i); it is in stance while
phi_i < D and in swing for the rest, with swing progress s_i = (phi_i - D) / (1 - D) in [0, 1).
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from dpc_mjx.errors import DpcError


@struct.dataclass
class Gait:
    period: float  # s
    duty: float  # stance fraction of the period, in (0, 1]; 1 = always in stance
    offsets: jax.Array  # (4,) phase offsets of FR, FL, RR, RL, in [0, 1)

    @property
    def stance_time(self) -> jax.Array:
        """Duration (s) of one stance phase."""
        return self.duty * self.period

    @property
    def swing_time(self) -> jax.Array:
        """Duration (s) of one swing phase."""
        return (1.0 - self.duty) * self.period


def trot(period: float = 0.3, duty: float = 0.6) -> Gait:
    """Diagonal pairs (FR+RL, FL+RR) alternate."""
    return make_gait(period, duty, (0.0, 0.5, 0.5, 0.0))


def stand() -> Gait:
    """All four feet always in stance."""
    return make_gait(1.0, 1.0, (0.0, 0.0, 0.0, 0.0))


def make_gait(period: float, duty: float, offsets) -> Gait:
    if not (period > 0 and 0 < duty <= 1):
        raise DpcError(
            f"Gait needs period > 0 s and duty in (0, 1], got period={period}, duty={duty}."
        )
    return Gait(period=period, duty=duty, offsets=jp.asarray(offsets, jp.float32))


def phase(gait: Gait, t: jax.Array) -> jax.Array:
    """(4,) phase in [0, 1) of each foot at time t (s)."""
    return jp.mod(t / gait.period + gait.offsets, 1.0)


def contact_schedule(gait: Gait, t: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(4,) bool: planned stance; (4,) swing progress in [0, 1] (0 for stance feet)."""
    phi = phase(gait, t)
    stance = phi < gait.duty
    progress = jp.where(stance, 0.0, (phi - gait.duty) / jp.maximum(1.0 - gait.duty, 1e-6))
    return stance, jp.clip(progress, 0.0, 1.0)
