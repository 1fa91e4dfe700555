"""A family of arms around one parametric arm: the distribution a policy is trained over.

The paper trains the adapter and the policy on one arm and transfers by a new encoder alone. A
policy that has only seen one arm's u meets a heavy or long arm far outside what it learnt
(docs/results-observer.md, "DPC on the observer"). `ArmFamily` draws `count` arms that keep the
run's arm's structure (joints, end effector, mount: so one encoder reads them all) and vary its
continuous values, each drawn independently per arm:

    upper_arm_length, forearm_length   uniform (m)
    link_mass_scale                    log-uniform; multiplies base, turret, upper-arm,
                                       forearm and wrist masses (kg)
    gripper_mass                       uniform (kg); the end effector (gripper or plate)

    family = ArmFamily(count=8)
    arms = family.members(ArmSpec(), seed=0)      # 8 ArmSpecs, the same for the same seed

The default ranges hold the `regular`, `longer` and `heavier` arms inside (0.14-0.28 m, 0.1-0.5
kg grippers) and reach a total arm mass of about 5 kg, the `z1`'s; the URDF arms (`so100`,
`z1`) and every arm file stay outside the family by construction (other structures).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms.parametric import ArmSpec

LINK_MASSES = ("base_mass", "turret_mass", "upper_arm_mass", "forearm_mass", "wrist_mass")
RANGES = ("upper_arm_length", "forearm_length", "link_mass_scale", "gripper_mass")


@dataclasses.dataclass(frozen=True)
class ArmFamily:
    """`count` arms drawn around a parametric arm (module docstring); 0: no family."""

    count: int = 0
    upper_arm_length: tuple[float, float] = (0.10, 0.30)  # m, uniform
    forearm_length: tuple[float, float] = (0.10, 0.22)  # m, uniform
    link_mass_scale: tuple[float, float] = (0.7, 5.0)  # log-uniform factor on LINK_MASSES
    gripper_mass: tuple[float, float] = (0.1, 1.0)  # kg, uniform

    def validate(self) -> None:
        if not isinstance(self.count, int) or isinstance(self.count, bool) or self.count < 0:
            raise DpcError(f"arm_family.count must be an int >= 0, got {self.count!r}.")
        for name in RANGES:
            pair = getattr(self, name)
            ok = (
                isinstance(pair, (tuple, list))
                and len(pair) == 2
                and all(isinstance(v, (int, float)) and math.isfinite(v) for v in pair)
                and 0 < pair[0] <= pair[1]
            )
            if not ok:
                raise DpcError(
                    f"arm_family.{name} must be (low, high) with 0 < low <= high, got {pair!r} "
                    f"(e.g. --set 'arm_family.{name}=[0.1, 0.3]')."
                )

    def members(self, arm: ArmSpec, seed: int) -> tuple[ArmSpec, ...]:
        """`count` arms: `arm` with its lengths and masses drawn from the ranges (numpy's
        generator seeded with `seed`); structure, mount and link radius are `arm`'s."""
        if not isinstance(arm, ArmSpec):
            raise DpcError(
                f"An arm family varies a parametric ArmSpec arm (regular, longer, heavier, "
                f"pusher), not a {type(arm).__name__}; train on one of those, or set "
                "arm_family.count=0."
            )
        self.validate()
        rng = np.random.default_rng(seed)
        out = []
        for _ in range(self.count):
            u, f, s, g = rng.uniform(size=4)
            scale = _log_uniform(self.link_mass_scale, s)
            out.append(
                dataclasses.replace(
                    arm,
                    upper_arm_length=round(_uniform(self.upper_arm_length, u), 4),
                    forearm_length=round(_uniform(self.forearm_length, f), 4),
                    gripper_mass=round(_uniform(self.gripper_mass, g), 4),
                    **{m: round(getattr(arm, m) * scale, 4) for m in LINK_MASSES},
                )
            )
        return tuple(out)


def describe(arm: ArmSpec) -> str:
    """One line for logs and tables: lengths (m) and masses (kg) of a family member."""
    return (
        f"upper arm {arm.upper_arm_length:.3f} m, forearm {arm.forearm_length:.3f} m, "
        f"gripper {arm.gripper_mass:.2f} kg, arm {arm.mass:.2f} kg"
    )


def _uniform(pair: tuple[float, float], x: float) -> float:
    return pair[0] + (pair[1] - pair[0]) * float(x)


def _log_uniform(pair: tuple[float, float], x: float) -> float:
    return math.exp(_uniform((math.log(pair[0]), math.log(pair[1])), x))
