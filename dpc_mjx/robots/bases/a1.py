"""The Unitree A1, the default base: its names and numbers.

It is built from its URDF (example-robot-data's, shipped in `dpc_mjx/descriptions/`) like every
base, by `robots.bases.model` from `robots.bases.file.read_base("a1")`; what is here is what the
library's A1 has always been, kept as the reference the other bases are scaled from
(`control.base_scaling`) and for the tests that check the A1 is read as it was built by hand.
"""

from __future__ import annotations

import mujoco
import numpy as np

from dpc_mjx.robots.bases.file import LEGS, read_base
from dpc_mjx.robots.bases.model import A1_HOME_HEIGHT, A1_HOME_LEG, IMU_SITE, base_mjspec

LEG_JOINTS = tuple(f"{leg}_{part}_joint" for leg in LEGS for part in ("hip", "thigh", "calf"))
FOOT_SITES = tuple(f"{leg}_foot" for leg in LEGS)
TRUNK = "trunk"

# Home pose: trunk height (m) above the floor and leg joint angles (rad) per leg (hip, thigh, calf).
HOME_HEIGHT = A1_HOME_HEIGHT
HOME_LEG = A1_HOME_LEG

# Trunk collision box of the URDF: half extents (m) in the trunk frame; the named arms' mounts are
# written on it (`robots.variants`).
TRUNK_HALF_EXTENTS = (0.1335, 0.097, 0.057)

FOOT_RADIUS = 0.02  # m, the URDF's foot sphere


def a1_spec() -> mujoco.MjSpec:
    """The A1 as a spec: trunk with a free joint, leg motors, sites, sensors; no floor."""
    return base_mjspec(read_base("a1"))


def home_leg_qpos() -> np.ndarray:
    """(12,) leg joint angles of the home pose, rad, in `LEG_JOINTS` order."""
    return np.tile(np.asarray(HOME_LEG), len(LEGS))


__all__ = [
    "FOOT_RADIUS",
    "FOOT_SITES",
    "HOME_HEIGHT",
    "HOME_LEG",
    "IMU_SITE",
    "LEGS",
    "LEG_JOINTS",
    "TRUNK",
    "TRUNK_HALF_EXTENTS",
    "a1_spec",
    "home_leg_qpos",
]
