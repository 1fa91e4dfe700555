"""Can the base hold this arm up? Static balance over the arm's reach, judged like the balance QP.

For arm configurations spread over the joint ranges (the home pose and `SAMPLES` uniform draws,
seed 0; unlimited joints over [-pi, pi]), the base (the A1 by default) standing in its home pose
must carry the whole robot on its four feet with forces that meet the balance QP's constraints
(`control.balance` DEFAULTS, the force bounds scaled to the base by `control.base_scaling`:
friction pyramid mu, f_min <= f_z <= f_max) and leg torques within the motors' limits.
All in the world frame (z up; N, m, N·m)::

    sum_i f_i = m g z_hat,   sum_i (p_i - c) x f_i = 0     static equilibrium (c: the robot's COM,
                                                            p_i: foot i, m: the robot's mass)
    |f_x|, |f_y| <= mu f_z,   f_min <= f_z <= f_max         the QP's friction constraints
    |J_i^T f_i| <= s tau_max                                leg torques (J_i: foot i's position
                                                            Jacobian over its leg's 3 joints)

One linear programme per configuration minimises s, the share of the motors' torque the stance
needs; the arm passes when every configuration is feasible with s <= 1. This is a necessary
condition (standing still); walking and pushes need margin on top of it.

`require_static_balance(robot)` refuses a robot whose arm files fail (the named and parametric
arms pass); `envs.registry.resolve_arm` calls it wherever an arm comes in, before any compile.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import pathlib

import jax.numpy as jp
import mujoco
import numpy as np
from scipy.optimize import linprog

from dpc_mjx.control.balance import GRAVITY, default_params, friction_constraints
from dpc_mjx.control.base_scaling import force_bounds, model_scale
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms import UrdfArm
from dpc_mjx.robots.assemble import assemble
from dpc_mjx.robots.layout import layout
from dpc_mjx.robots.variants import RobotSpec

SAMPLES = 64  # random arm configurations besides the home pose


@dataclasses.dataclass(frozen=True)
class StaticBalance:
    """The worst configuration found: its arm joint values and the torque share it needs."""

    feasible: bool
    torque_share: float  # max over configurations of s (inf where no forces balance the robot)
    worst_arm_qpos: tuple[float, ...]  # rad (m), the arm joints in model order
    com_offset: tuple[float, float]  # m, the robot's COM minus the feet's centre (x, y), worst
    mass: float  # kg, the whole robot


def static_balance(robot) -> StaticBalance:
    """Check a robot (anything `robots.resolve` takes; its files read but no MJX compile)."""
    model = assemble(robot).compile()
    lay = layout(model)
    mass_ratio = model_scale(model).mass  # the base's force bounds (control.base_scaling)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    lo, hi = _arm_ranges(model, lay.arm_qpos, lay.arm_dof)
    configs = [model.key_qpos[0][lay.arm_qpos]]
    configs += list(rng.uniform(lo, hi, size=(SAMPLES, len(lo))))
    worst = (-1.0, configs[0], (0.0, 0.0))
    for arm_q in configs:
        data.qpos[:] = model.key_qpos[0]
        data.qpos[lay.arm_qpos] = arm_q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        s, offset = _torque_share(model, data, lay, mass_ratio)
        if s > worst[0]:
            worst = (s, arm_q, offset)
    s, arm_q, offset = worst
    return StaticBalance(
        feasible=s <= 1.0,
        torque_share=s,
        worst_arm_qpos=tuple(float(q) for q in arm_q),
        com_offset=offset,
        mass=float(model.body_mass.sum()),
    )


def require_static_balance(robot: RobotSpec) -> None:
    """`DpcError` unless the A1 can stand with `robot`'s arms anywhere in their reach, checked
    where an arm is a file (`UrdfArm.is_file`: your URDF/MJCF; the named arms pass)."""
    files = [arm for arm in robot.arms if isinstance(arm, UrdfArm) and arm.is_file]
    if files:
        _require(robot, tuple(pathlib.Path(arm.urdf).stat().st_mtime_ns for arm in files))


@functools.lru_cache(maxsize=32)
def _require(robot: RobotSpec, _file_stamps: tuple = ()) -> None:
    """`require_static_balance`, cached per robot and the arm files' modification times
    (`_file_stamps`)."""
    report = static_balance(robot)
    if report.feasible:
        return
    need = (
        "no foot forces balance it within the friction pyramid"
        if math.isinf(report.torque_share)
        else f"the legs need {report.torque_share:.0%} of their motors' torque"
    )
    raise DpcError(
        f"{robot.name}: the A1 cannot hold this arm up ({report.mass:.1f} kg in all): with the "
        f"arm joints at {[round(q, 2) for q in report.worst_arm_qpos]} (rad) {need}, the robot's "
        f"COM {report.com_offset[0]:+.2f}, {report.com_offset[1]:+.2f} m from the feet's centre. "
        "Use a lighter or shorter arm, mount it nearer the trunk's centre, or narrow its joint "
        "ranges in the file."
    )


def _arm_ranges(model, qpos_adr, dof_adr) -> tuple[np.ndarray, np.ndarray]:
    """(n,) lower and upper values of the arm joints; unlimited ones over [-pi, pi]."""
    joints = model.dof_jntid[dof_adr]
    lo = np.where(model.jnt_limited[joints], model.jnt_range[joints, 0], -np.pi)
    hi = np.where(model.jnt_limited[joints], model.jnt_range[joints, 1], np.pi)
    return lo, hi


def _torque_share(model, data, lay, mass_ratio: float) -> tuple[float, tuple[float, float]]:
    """The LP of the module doc at the current kinematics: min s (inf if infeasible); the force
    bounds of a base `mass_ratio` times the A1's mass."""
    mass = float(model.body_mass.sum())
    com = data.subtree_com[0]
    feet = data.site_xpos[lay.foot_sites]  # (4, 3)
    n = 13  # f (12) then s
    a_eq = np.zeros((6, n))
    for i in range(4):
        a_eq[:3, 3 * i : 3 * i + 3] = np.eye(3)
        a_eq[3:, 3 * i : 3 * i + 3] = _skew(feet[i] - com)
    b_eq = np.array([0.0, 0.0, mass * GRAVITY, 0.0, 0.0, 0.0])
    # the balance QP's own friction pyramids and force bounds (the base's), four feet in stance
    g, h = (np.asarray(a, float) for a in _friction_rows(mass_ratio))
    rows, h = [np.concatenate([g, np.zeros((len(g), 1))], 1)], list(h)
    tau_max = np.abs(model.actuator_ctrlrange[lay.leg_act]).max(axis=1)  # (12,) N·m
    jac = np.zeros((3, model.nv))
    for i in range(4):
        mujoco.mj_jacSite(model, data, jac, None, lay.foot_sites[i])
        jt = jac[:, lay.leg_dof[3 * i : 3 * i + 3]].T  # (3 joints, 3 force components): J^T f
        for j in range(3):
            for sign in (1, -1):  # +-(J^T f)_j - s tau_max_j <= 0
                row = np.zeros(n)
                row[3 * i : 3 * i + 3] = sign * jt[j]
                row[12] = -tau_max[3 * i + j]
                rows.append(row[None])
                h.append(0.0)
    cost = np.zeros(n)
    cost[12] = 1.0
    res = linprog(
        cost, A_ub=np.concatenate(rows), b_ub=np.array(h), A_eq=a_eq, b_eq=b_eq,
        bounds=[(None, None)] * 12 + [(0, None)], method="highs",
    )  # fmt: skip
    offset = tuple(float(v) for v in (com - feet.mean(axis=0))[:2])
    return (float(res.x[12]) if res.status == 0 else math.inf), offset


@functools.cache
def _friction_rows(mass_ratio: float):
    """G (24, 12), h (24,) of `control.balance.friction_constraints` with the force bounds of a
    base `mass_ratio` times the A1's mass (`control.base_scaling`), four feet in stance."""
    f_min, f_max = force_bounds(mass_ratio)
    return friction_constraints(default_params().mu, f_min, f_max, jp.ones(4, bool))


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]x, so that _skew(v) @ f = v x f."""
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
