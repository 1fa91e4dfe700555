"""The reaching task (the paper's training task, §IV): walk at the commanded velocity, level,
while the arm reaches random targets and sudden forces hit the gripper.

Protocol (defaults of `default_config`, distributions in `EnvConfig`):
- arm: a new joint-space target every U(1.5, 3) s within half of each joint's range around home,
  reached along a 1 s smooth step;
- pushes on each end effector: |F| ~ U(0, 30) N, uniform direction, lasting U(0.2, 1) s, one every
  U(0.5, 2) s after the last; payload ~ U(0, 0.3) kg per gripper (a constant m g downward);
- command: v_x ~ U(0, 0.5) m/s, v_y ~ U(-0.2, 0.2) m/s, yaw rate ~ U(-0.5, 0.5) rad/s, redrawn
  once at t ~ U(5, 15) s;
- reward: paper eq. 4 every step (at most 0.34), a fall ends the episode with `fall_penalty`
  = -1000. The paper does not state its penalty; its Table I MBC returns (-969 for `regular`,
  -730 for `double`) with at most 0.34 reward per step need a penalty of order -1000, so a fall
  dominates the return as there (SAC may want `reward_scaling` or a milder penalty: override
  `fall_penalty`). Episodes last 1000 steps (20 s) unless they fall.

Calibration of the push magnitude (`experiments/calibrate_reaching.py`, 16 episodes of 10 s per
cell, WidowX joint ranges in radians, i.e. with `compiler.degree = False` in `robots/arms.py`;
before that fix the arm joints were limited to about +-3 deg and barely moved): with no
pushes neither MBC nor the oracle falls; up to 25 N the oracle never falls and has 3-4x smaller
roll RMS than MBC (e.g. regular 0.013 vs 0.048 rad), MBC falls 1/16 on longer and double; up to
30 N MBC falls 1/16 (regular) and 5/16 (double), the oracle 0/16 and 1/16; from 35 N up both fall
at similar rates (15-30%): lateral pushes on a trotting robot (two stance feet on a diagonal
cannot resist a moment about that diagonal), which knowing the wrench does not cure. Hence the
default upper bound of 30 N.
"""

from __future__ import annotations

from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.config import EnvConfig


def default_config() -> EnvConfig:
    """The reaching task's configuration (every field documented in `EnvConfig`)."""
    return EnvConfig()


class ReachingEnv(DpcEnv):
    """Reaching: the arm's reference motion and end-effector pushes are the disturbances; the
    scene is the robot on a floor (`DpcEnv.build_model`)."""
