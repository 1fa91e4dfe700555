"""The body state the low-level controller sees, read from MJX data (privileged, noise-free).

Frames: world (z up). Data fields read after `mjx.step` mix the new qvel with kinematics of the
previous step (positions are 4 ms old), as a real sensor pipeline would. Also the weights the
controllers count as known, as wrenches about the base's COM (`legs_weight_wrench`,
`gravity_u`, and any forces at points, `forces_u`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from flax import struct

from dpc_mjx.control.balance import GRAVITY
from dpc_mjx.robots.layout import Layout, mount_wrench


@struct.dataclass
class BodyState:
    com_pos: jax.Array  # (3,) m, COM of the base (trunk + legs, no arm)
    com_vel: jax.Array  # (3,) m/s
    rot: jax.Array  # (3, 3) trunk orientation, body -> world
    ang_vel: jax.Array  # (3,) rad/s, world frame
    foot_pos: jax.Array  # (4, 3) foot sphere centres, m
    foot_vel: jax.Array  # (4, 3) m/s
    hip_pos: jax.Array  # (4, 3) thigh joint positions, m
    foot_jac: jax.Array  # (4, 3, 3) d(foot pos)/d(leg joint angles), per leg, m/rad


@dataclasses.dataclass(frozen=True)
class StateIndex:
    """Static indices (numpy) used to read a `BodyState` from data."""

    trunk: int
    feet: np.ndarray  # (4,) site ids
    thighs: np.ndarray  # (4,) body ids
    leg_dof: np.ndarray  # (4, 3) dof addresses per leg
    chain_dof: np.ndarray  # (4, 9) root dofs 0..5 + the leg's 3 dofs
    com_offset: np.ndarray  # (3,) the base's COM in the trunk frame at home, m
    base_mass: float  # kg, trunk + legs
    base_inertia: np.ndarray  # (3, 3) kg·m², about the base's COM, trunk frame, at home
    home_height: float  # m, the trunk's origin above the floor at home
    leg_length: float  # m, mean over legs of thigh joint -> knee joint -> foot centre at home
    leg_bodies: np.ndarray  # (4, 3) the bodies the leg joints move, hip to knee
    leg_axes: np.ndarray  # (4, 3, 3) each joint's axis in its body's frame
    leg_anchors: np.ndarray  # (4, 3, 3) m, each joint's position in its body's frame
    leg_subtree_mass: np.ndarray  # (4, 3) kg: the leg's links beyond each of its joints


def state_index(model: mujoco.MjModel, lay: Layout) -> StateIndex:
    """Indices and the base's (arm-free) rigid-body model at its home pose."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    arm_bodies = set()
    for arm in lay.arms:
        arm_bodies.update(int(b) for b in arm.bodies)
    # the robot's own tree (a task's objects and tables are other trees), without its arms
    robot = model.body_rootid[lay.trunk]
    bodies = [
        b for b in range(1, model.nbody) if model.body_rootid[b] == robot and b not in arm_bodies
    ]
    mass = float(model.body_mass[bodies].sum())
    com = sum(model.body_mass[b] * data.xipos[b] for b in bodies) / mass
    inertia = np.zeros((3, 3))
    for b in bodies:  # parallel-axis sum about the base's COM, world frame (trunk level, yaw 0)
        rot = data.ximat[b].reshape(3, 3)
        r = data.xipos[b] - com
        inertia += rot @ np.diag(model.body_inertia[b]) @ rot.T
        inertia += model.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    trunk = lay.trunk
    trunk_rot = data.xmat[trunk].reshape(3, 3)
    leg_dof = lay.leg_dof.reshape(4, 3)
    anchors = data.xanchor[lay.leg_joints].reshape(4, 3, 3)  # (leg, hip/thigh/knee, xyz) m
    feet = data.site_xpos[lay.foot_sites]  # (4, 3) m
    thigh = np.linalg.norm(anchors[:, 2] - anchors[:, 1], axis=1)
    shank = np.linalg.norm(feet - anchors[:, 2], axis=1)
    return StateIndex(
        trunk=trunk,
        feet=lay.foot_sites,
        thighs=model.jnt_bodyid[lay.leg_joints[1::3]],  # the bodies the thigh joints move
        leg_dof=leg_dof,
        chain_dof=np.concatenate([np.tile(np.arange(6), (4, 1)), leg_dof], axis=1),
        com_offset=trunk_rot.T @ (com - data.xpos[trunk]),
        base_mass=mass,
        base_inertia=trunk_rot.T @ inertia @ trunk_rot,
        home_height=float(model.key_qpos[0][model.jnt_qposadr[model.body_jntadr[trunk]] + 2]),
        leg_length=float(np.mean(thigh + shank)),
        leg_bodies=model.jnt_bodyid[lay.leg_joints].reshape(4, 3),
        leg_axes=model.jnt_axis[lay.leg_joints].reshape(4, 3, 3),
        leg_anchors=model.jnt_pos[lay.leg_joints].reshape(4, 3, 3),
        leg_subtree_mass=model.body_subtreemass[model.jnt_bodyid[lay.leg_joints]].reshape(4, 3),
    )


def read_state(idx: StateIndex, d) -> BodyState:
    """The `BodyState` of one (unbatched) `mjx.Data`."""
    rot = d.xmat[idx.trunk]
    ang_vel = rot @ d.qvel[3:6]  # the free joint's angular velocity is in the trunk frame
    lever = rot @ jp.asarray(idx.com_offset, jp.float32)
    com_pos = d.xpos[idx.trunk] + lever
    com_vel = d.qvel[0:3] + jp.cross(ang_vel, lever)
    foot_pos = d.site_xpos[idx.feet]
    root_com = d.subtree_com[idx.trunk]  # the point MJX's cdof are expressed about

    def chain_jac(point, dofs):  # (9, 3): d(point)/d(qvel[dofs])
        cdof = d.cdof[dofs]
        return cdof[:, 3:] + jp.cross(cdof[:, :3], point - root_com)

    jac = jax.vmap(chain_jac)(foot_pos, jp.asarray(idx.chain_dof))  # (4, 9, 3)
    foot_vel = jp.einsum("fkc,fk->fc", jac, d.qvel[idx.chain_dof])
    return BodyState(
        com_pos=com_pos,
        com_vel=com_vel,
        rot=rot,
        ang_vel=ang_vel,
        foot_pos=foot_pos,
        foot_vel=foot_vel,
        hip_pos=d.xpos[idx.thighs],
        foot_jac=jp.swapaxes(jac[:, 6:, :], 1, 2),  # (4, 3 xyz, 3 joints)
    )


# The fall test, the one used everywhere (env termination, the controller's test bench, demo).
FALL_TILT = 1.0  # rad of roll or pitch: fallen


def has_fallen(trunk_height: jax.Array, roll_pitch: jax.Array, fall_height: float) -> jax.Array:
    """() bool: trunk height (m, world z) below `fall_height` (the base's,
    `control.base_scaling.BaseScale.fall_height`; the A1's 0.15 m) or |roll| or |pitch| (rad,
    `roll_pitch` (..., 2)) above `FALL_TILT`."""
    return (trunk_height < fall_height) | jp.any(jp.abs(roll_pitch) > FALL_TILT, axis=-1)


def legs_weight_wrench(idx: StateIndex, d, s: BodyState, stance: jax.Array, foot_radius: float):
    """(6,) [f (N), tau (N·m) about the base's COM], world: what the legs' own weight adds to the
    ground's force on the stance feet (`stance` (4,) bool), which tau = J^T f does not carry.
    Each leg joint j must hold g_j = -a_j . sum over the links beyond it of (c_k - p_j) x m_k
    g_vec (its gravity torque: axis a_j, anchor p_j; the links' COM and mass as MuJoCo's
    subtree of the joint's body), so a foot pushes the ground with df = J^-T g (per leg, J its
    foot Jacobian) more than asked: the bias of the momentum observer's estimate on a bare base
    (control/observer.py). Positions, axes and COMs from the data's kinematics."""
    mass = jp.asarray(idx.leg_subtree_mass, jp.float32)[..., None]  # (4, 3, 1) kg
    weight = mass * jp.array([0.0, 0.0, -GRAVITY])  # (4, 3, 3) N, world
    rot = d.xmat[idx.leg_bodies]  # (4, 3, 3, 3) body -> world
    anchors = d.xpos[idx.leg_bodies] + jp.einsum("lkij,lkj->lki", rot, idx.leg_anchors)
    axes = jp.einsum("lkij,lkj->lki", rot, idx.leg_axes)  # (4, 3, 3) world
    coms = d.subtree_com[idx.leg_bodies]  # (4, 3, 3) m: the COM of each joint's subtree
    torque = -jp.sum(axes * jp.cross(coms - anchors, weight), axis=-1)  # (4, 3) N·m
    extra = jp.linalg.solve(jp.swapaxes(s.foot_jac, 1, 2), torque[..., None])[..., 0]  # (4, 3)
    extra = extra * stance[:, None]
    contact = s.foot_pos.at[:, 2].add(-foot_radius)
    return jp.concatenate([extra.sum(0), jp.cross(contact - s.com_pos, extra).sum(0)])


def forces_u(forces: jax.Array, points: jax.Array, com_pos: jax.Array) -> jax.Array:
    """(6,) u = sum over i of [f_i, (x_i - c) x f_i] (N, N·m; world frame): the forces `forces`
    (k, 3) N acting at the points `points` (k, 3) m, as one wrench about `com_pos` (3,) m."""
    return jp.concatenate([forces.sum(0), jp.cross(points - com_pos, forces).sum(0)])


def gravity_u(masses: jax.Array, gravity: jax.Array, coms: jax.Array, com_pos: jax.Array):
    """(6,) u = sum over bodies b of [m_b g, (c_b - c) x m_b g] (N, N·m; world frame): the
    weight of the bodies `masses` (n_b,) kg at their COMs `coms` (n_b, 3) m and its torque about
    `com_pos` (3,) m, under `gravity` (3,) m/s^2 (`forces_u`). For the arm bodies at their
    simulated pose, the static part of the mount wrench that `oracle_u` measures (the arm
    encoders' 0.001 rad and the IMU's attitude error are not applied to it)."""
    return forces_u(masses[:, None] * gravity, coms, com_pos)  # weights (n_b, 3) N


def oracle_u(lay: Layout, d, com_pos: jax.Array) -> jax.Array:
    """(6,) u from the measured mount wrenches: total arm force on the trunk (N) and its torque
    about the base's COM (N·m), world frame — the privileged oracle's disturbance estimate."""
    f_a, tau_a = jp.zeros(3), jp.zeros(3)
    for arm in lay.arms:
        force, torque = mount_wrench(arm, d)
        lever = d.site_xpos[arm.mount_site] - com_pos
        f_a = f_a + force
        tau_a = tau_a + torque + jp.cross(lever, force)
    return jp.concatenate([f_a, tau_a])
