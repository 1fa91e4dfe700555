"""Standing without a controller: leg position servos, home controls, perturbed home poses.

The library's controllers command leg torques. For standing tests, benchmarks and the demo we want
the physics alone to keep the robot up, in MuJoCo C (`mujoco.rollout`) and MJX alike, with no
controller in the loop: this turns each leg motor into `tau = kp (ctrl - q) - kd qdot`, clamped
to the motor's torque limit, with `ctrl` the target joint angle.
"""

from __future__ import annotations

import mujoco
import numpy as np

from dpc_mjx.robots.layout import layout

STAND_KP = 60.0  # N·m/rad
STAND_KD = 2.0  # N·m·s/rad


def with_leg_servos(
    model: mujoco.MjModel, kp: float = STAND_KP, kd: float = STAND_KD
) -> mujoco.MjModel:
    """A copy of `model` with PD leg servos; use the home keyframe's leg angles as ctrl."""
    out = model.__copy__()
    lay = layout(model)
    for a, j in zip(lay.leg_act, model.actuator_trnid[lay.leg_act, 0], strict=True):
        torque = np.abs(model.actuator_ctrlrange[a]).max()  # N·m, the motor's limit
        out.actuator_gainprm[a, :3] = [kp, 0, 0]
        out.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
        out.actuator_biasprm[a, :3] = [0, -kp, -kd]
        out.actuator_ctrlrange[a] = model.jnt_range[j]
        out.actuator_forcelimited[a] = True
        out.actuator_forcerange[a] = [-torque, torque]
    return out


def home_ctrl(model: mujoco.MjModel) -> np.ndarray:
    """(nu,) ctrl of the home keyframe with leg targets at the home angles (for servo models)."""
    lay = layout(model)
    ctrl = model.key_ctrl[0].copy()
    ctrl[lay.leg_act] = model.key_qpos[0][lay.leg_qpos]
    return ctrl


def perturbed_home(
    model: mujoco.MjModel, batch: int, seed: int = 0, joint_noise: float = 0.05
) -> np.ndarray:
    """(batch, nq) home poses, joints offset by U(-joint_noise, joint_noise) rad, trunk raised by
    U(0, 0.01) m, so a batch of standing robots is not a batch of copies."""
    rng = np.random.default_rng(seed)
    qpos = np.tile(model.key_qpos[0], (batch, 1))
    qpos[:, 7:] += rng.uniform(-joint_noise, joint_noise, size=(batch, model.nq - 7))
    qpos[:, 2] += rng.uniform(0.0, 0.01, size=batch)
    return qpos
