"""The reaching task (the paper's training task, §IV): walk at the commanded velocity, level,
while the arm reaches random targets and sudden forces hit the gripper.

Protocol (defaults of `default_config`, distributions in `EnvConfig`):
- arm: a new joint-space target every U(1.5, 3) s within half of each joint's range around home,
  reached along a 1 s smooth step;
- pushes on each end effector: vertical (up or down, `push_axis_weights` (0, 0, 1)),
  |F| ~ U(0, 60) N, lasting U(0.2, 1) s, one every U(0.5, 2) s after the last; payload
  ~ U(0, 0.3) kg per gripper (a constant m g downward);
- command: v_x ~ U(0, 0.5) m/s, v_y ~ U(-0.2, 0.2) m/s, yaw rate ~ U(-0.5, 0.5) rad/s, redrawn
  once at t ~ U(5, 15) s;
- reward: paper eq. 4 every step (at most 0.34), a fall ends the episode with `fall_penalty`
  = -1000. The paper does not state its penalty; its Table I MBC returns (-969 for `regular`,
  -730 for `double`) with at most 0.34 reward per step need a penalty of order -1000, so a fall
  dominates the return as there. Episodes last 1000 steps (20 s) unless they fall.

Calibration of the pushes (`experiments/calibrate_reaching.py`, MBC vs the oracle, same seeds;
tables in docs/results.md). Pushes uniform in direction: up to 25-30 N neither controller falls
much (MBC 1/16 episodes of 10 s, the oracle 0/16); from 35 N both fall at similar rates
(15-30%), because a lateral force on a trotting robot makes a moment about the line through its
two stance feet, which no choice of their forces resists and knowing the wrench does not cure.
Sagittal pushes (no lateral part) up to 40 N: no falls for either. Vertical pushes separate the
controllers: up to 60 N, 10 s, `regular`: MBC falls 19%, the oracle 3%; up to 80 N: 47% vs 22%;
with a lateral part (weights (0.3, 0.3, 1)) at 60 N: 56% vs 41%. A vertical force on the gripper
is what lifting, pressing or snagging puts on an arm, and its pitch and roll moments are exactly
what u = [f_a, tau_a] describes, so the default is vertical pushes up to 60 N (a 6 kg load at
most; the shoulder servo's 20 N·m limit is reached near full reach). At 20 s episodes MBC falls
39-72% on the four arms and the oracle 3-33% (docs/results.md).

On another base these numbers are the A1's scaled by its weight (`envs.registry.WEIGHT_SCALED`:
pushes, payloads and u's bounds times the ratio of its trunk + legs mass to the A1's; a Go2 up
to 70 N, a B1 up to 243 N), so that a push is the same share of the robot's weight; calibrated
per base with MBC against the oracle as above (docs/results-transfer.md, "Other bases").
"""

from __future__ import annotations

import mujoco

from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.robots.assemble import build_spec
from dpc_mjx.robots.variants import Arm, RobotSpec, resolve


def default_config() -> EnvConfig:
    """The reaching task's configuration (every field documented in `EnvConfig`): vertical
    end-effector pushes of up to 60 N (see the module doc for the calibration)."""
    return EnvConfig(push_force=(0.0, 60.0), push_axis_weights=(0.0, 0.0, 1.0))


class ReachingEnv(DpcEnv):
    """Reaching: the arm's reference motion and end-effector pushes are the disturbances; the
    scene is the robot on a floor (`DpcEnv.build_model`). Every arm, or none, can reach."""

    TASK = "reaching"
    DEFAULT_ARM = "regular"

    @classmethod
    def scene_spec(cls, arm: str | Arm | RobotSpec | None = None) -> mujoco.MjSpec:
        """The robot on a floor, named `<base>_<variant>_reaching` (the env itself compiles
        `robots.build(arm)`, named `<base>_<variant>`)."""
        robot = resolve(cls.DEFAULT_ARM if arm is None else arm)
        spec = build_spec(robot)
        spec.modelname = f"{spec.modelname}_{cls.TASK}"  # `assemble`'s <base>_<variant>
        return spec
