"""The arms' own rigid-body model: the wrench they exert on the base, from their file's masses,
COMs and inertias and the robot's state (DESIGN.md 5c), by recursive Newton-Euler in JAX.

What it reads, per env (unbatched; vmap at the call site), world frame unless said:

    BaseMotion   the trunk's rotation R (trunk -> world), angular velocity w_B and acceleration
                 dw_B (rad/s, rad/s^2), the specific acceleration of its origin a_B - g (m/s^2,
                 what an accelerometer at the trunk's origin reads, turned to the world), and the
                 base's COM relative to the trunk's origin (m; the balance QP's reference point)
    q, qd, qdd   the arms' joint positions, velocities and accelerations (n,), in `Layout`'s
                 arm-joint order (rad, rad/s, rad/s^2; m for a finger)

Forward pass, from the trunk outwards, body j after its parent p (MuJoCo's tree order): a hinge
turns about its axis u (world) through its anchor A, a slide moves along u:

    w_j = w_p + u qd                       dw_j = dw_p + u qdd + w_p x u qd         (hinge)
    a(x) = a_p + dw_p x (x - o_p) + w_p x (w_p x (x - o_p))   for a point x fixed to the parent
    a_j  = a(A) + dw_j x (o_j - A) + w_j x (w_j x (o_j - A))                        (hinge)
    a_j  = a(o_j) + 2 w_p x u qd + u qdd                                            (slide)

with every linear acceleration the specific one (a - g: gravity enters through the base's, as
an accelerometer reads it). The wrench the arms exert on the base (force, N; torque about the
base's COM c, N·m), the rate of the arms' momentum less their weight, negated:

    f   = -sum_j m_j (a_cj - g)
    tau = -sum_j [ (c_j - c) x m_j (a_cj - g) + I_j dw_j + w_j x I_j w_j ]

a_cj, c_j: body j's COM acceleration and position; I_j its inertia about its COM, world frame.
This is the mount wrench MuJoCo's force/torque sensors read (`state.oracle_u`) when nothing
but the base and gravity acts on the arms; it misses what no model of the arm knows: forces on
the gripper (pushes, a payload, a grasped object) and model error. Standing still it is the
arms' weight and its moment (`state.gravity_u`). The joint torques of the same motion
(`joint_torques`: each joint's axis against the moment of the bodies beyond it) give the arms'
mass matrix and, with the servo law, the joint accelerations the servos cause (`servo_qdd`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from flax import struct

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.layout import Layout

_HINGE, _SLIDE = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
_WELD = -1  # a body fixed to its parent
_STICK_SPEED = 1e-3  # rad/s (m/s): slower, a joint's dry friction may hold it


@struct.dataclass
class BaseMotion:
    """The trunk's motion at one tick (world frame; see the module docstring)."""

    rot: jax.Array  # (3, 3) trunk -> world
    ang_vel: jax.Array  # (3,) rad/s
    ang_acc: jax.Array  # (3,) rad/s^2
    lin_acc: jax.Array  # (3,) m/s^2, specific: the trunk origin's acceleration minus gravity
    com: jax.Array  # (3,) m, the base's COM minus the trunk's origin


@struct.dataclass
class ArmModel:
    """Every arm body of a compiled robot (all arms, bodies in tree order): its tree, joints and
    inertia, from the model (`arm_model`). Positions and rotations in the parent's frame at the
    joints' reference (qpos0); arrays float32."""

    parent: tuple[int, ...] = struct.field(pytree_node=False)  # (n_b,) body index, -1 trunk
    joint: tuple[int, ...] = struct.field(pytree_node=False)  # (n_b,) _HINGE, _SLIDE, _WELD
    qadr: tuple[int, ...] = struct.field(pytree_node=False)  # (n_b,) index in q, -1: welded
    subtree: np.ndarray = struct.field(pytree_node=False)  # (n_b, n_b) 1: column in row's subtree
    structure: _Structure = struct.field(pytree_node=False)  # where its numbers are read from
    pos: jax.Array  # (n_b, 3) m, body origin in the parent's frame
    rot: jax.Array  # (n_b, 3, 3) body -> parent, at the reference
    axis: jax.Array  # (n_b, 3) joint axis, body frame (unit)
    anchor: jax.Array  # (n_b, 3) m, joint position, body frame
    q_ref: jax.Array  # (n,) rad (m): each joint's reference, qpos0
    mass: jax.Array  # (n_b,) kg
    com: jax.Array  # (n_b, 3) m, COM in the body frame
    inertia: jax.Array  # (n_b, 3, 3) kg·m², about the COM, body frame
    # the joints' servos and passive terms (n,): tau = clip(kp (target - q) - kv qd, +-limit),
    # the target clipped to [target_min, target_max]
    kp: jax.Array  # N·m/rad (N/m)
    kv: jax.Array  # N·m·s/rad
    limit: jax.Array  # N·m (N)
    target_min: jax.Array  # rad (m)
    target_max: jax.Array  # rad (m)
    armature: jax.Array  # kg·m² (kg), rotor inertia on the joint
    damping: jax.Array  # N·m·s/rad
    friction: jax.Array  # N·m (N), dry friction (MuJoCo's frictionloss)
    q_min: jax.Array  # rad (m), the joint's range (-inf, inf: unlimited)
    q_max: jax.Array

    def on(self, m) -> ArmModel:
        """This model with the numbers of `m`, a model of the same structure (an `mjx.Model` of
        a batch of arms, `robots.arms.params`, inside `jax.vmap`)."""
        return self.replace(**_numbers(m, self.structure))


def arm_model(model: mujoco.MjModel, lay: Layout) -> ArmModel:
    """The `ArmModel` of a compiled robot (`robots.build`); every arm body hangs from the trunk
    through hinges and slides, one joint a body at most."""
    bodies = [int(b) for b in lay.arm_bodies]
    index = {b: i for i, b in enumerate(bodies)}
    dofs = [int(a) for a in lay.arm_dof]
    parent, joint, qadr = [], [], []
    for b in bodies:
        up = int(model.body_parentid[b])
        if up not in index and up != lay.trunk:
            raise DpcError(f"Arm body {model.body(b).name!r} hangs from a body not of the trunk.")
        parent.append(index.get(up, -1))
        kinds = [int(model.jnt_type[j]) for j in range(model.njnt) if model.jnt_bodyid[j] == b]
        if len(kinds) > 1 or any(k not in (_HINGE, _SLIDE) for k in kinds):
            raise DpcError(
                f"Arm body {model.body(b).name!r} has joints {kinds}; the arms' model takes one "
                "hinge or slide a body (a URDF's revolute, continuous or prismatic joints)."
            )
        joint.append(kinds[0] if kinds else _WELD)
        qadr.append(dofs.index(int(model.jnt_dofadr[model.body_jntadr[b]])) if kinds else -1)
    subtree = np.zeros((len(bodies), len(bodies)))
    for i in range(len(bodies)):
        j = i
        while j >= 0:  # body i is in the subtree of each of its ancestors
            subtree[j, i], j = 1.0, parent[j]
    structure = _Structure(
        bodies=np.array(bodies),
        joints=np.array([max(int(model.body_jntadr[b]), 0) for b in bodies]),
        moving=np.array([k != _WELD for k in joint]),
        qpos=np.asarray(lay.arm_qpos),
        dofs=np.array(dofs),
        acts=np.asarray(lay.arm_act),
    )
    return ArmModel(
        parent=tuple(parent),
        joint=tuple(joint),
        qadr=tuple(qadr),
        subtree=subtree,
        structure=structure,
        **_numbers(model, structure),
    )


@dataclasses.dataclass(frozen=True)
class _Structure:
    """Where an `ArmModel`'s numbers live in a model's arrays (static)."""

    bodies: np.ndarray  # (n_b,) body ids
    joints: np.ndarray  # (n_b,) each body's joint id (0 where welded: masked by `moving`)
    moving: np.ndarray  # (n_b,) bool, the body has a joint
    qpos: np.ndarray  # (n,) qpos addresses
    dofs: np.ndarray  # (n,) dof addresses
    acts: np.ndarray  # (n,) servo actuator ids

    def __hash__(self) -> int:  # static data of a jitted closure: by identity
        return id(self)


def _numbers(m, s: _Structure) -> dict[str, jax.Array]:
    """The `ArmModel` fields read from `m`, a `mujoco.MjModel` or an `mjx.Model` (the same field
    names; jax arrays, traced where `m` is one model of a batch, `envs.model_batch`)."""
    f32 = lambda x: jp.asarray(x, jp.float32)  # noqa: E731
    moving = s.moving[:, None]
    limited = jp.asarray(m.actuator_forcelimited[s.acts]).astype(bool)
    ctrl_limited = jp.asarray(m.actuator_ctrllimited[s.acts]).astype(bool)
    ctrl_range = f32(m.actuator_ctrlrange[s.acts])
    arm_joints = s.joints[s.moving]  # (n,) in q's order: bodies are in tree order, as q is
    jnt_limited = jp.asarray(m.jnt_limited[arm_joints]).astype(bool)
    jnt_range = f32(m.jnt_range[arm_joints])
    principal = _quat_mat(f32(m.body_iquat[s.bodies]))  # (n_b, 3, 3) principal axes -> body
    diag = jax.vmap(jp.diag)(f32(m.body_inertia[s.bodies]))
    return {
        "pos": f32(m.body_pos[s.bodies]),
        "rot": _quat_mat(f32(m.body_quat[s.bodies])),
        "axis": jp.where(moving, f32(m.jnt_axis[s.joints]), 0.0),
        "anchor": jp.where(moving, f32(m.jnt_pos[s.joints]), 0.0),
        "q_ref": f32(m.qpos0[s.qpos]),
        "mass": f32(m.body_mass[s.bodies]),
        "com": f32(m.body_ipos[s.bodies]),
        "inertia": principal @ diag @ jp.swapaxes(principal, 1, 2),
        "kp": f32(m.actuator_gainprm[s.acts, 0]),
        "kv": -f32(m.actuator_biasprm[s.acts, 2]),
        "limit": jp.where(limited, f32(m.actuator_forcerange[s.acts, 1]), jp.inf),
        "target_min": jp.where(ctrl_limited, ctrl_range[:, 0], -jp.inf),
        "target_max": jp.where(ctrl_limited, ctrl_range[:, 1], jp.inf),
        "armature": f32(m.dof_armature[s.dofs]),
        "damping": f32(m.dof_damping[s.dofs]),
        "friction": f32(m.dof_frictionloss[s.dofs]),
        "q_min": jp.where(jnt_limited, jnt_range[:, 0], -jp.inf),
        "q_max": jp.where(jnt_limited, jnt_range[:, 1], jp.inf),
    }


def _quat_mat(quat: jax.Array) -> jax.Array:
    """(..., 3, 3) rotation matrices of (..., 4) wxyz unit quaternions."""
    w, x, y, z = (quat[..., i] for i in range(4))
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return jp.stack([jp.stack(r, -1) for r in rows], -2)


class _Bodies(struct.PyTreeNode):
    """The forward pass's result, world frame, positions relative to the trunk's origin."""

    rot: jax.Array  # (n_b, 3, 3) body -> world
    ang_vel: jax.Array  # (n_b, 3) rad/s
    ang_acc: jax.Array  # (n_b, 3) rad/s^2
    com: jax.Array  # (n_b, 3) m, COM position
    com_acc: jax.Array  # (n_b, 3) m/s^2, specific COM acceleration (a - g)
    axis: jax.Array  # (n_b, 3) joint axis (zero for a welded body)
    anchor: jax.Array  # (n_b, 3) m, joint anchor


def _rodrigues(axis: jax.Array, angle: jax.Array) -> jax.Array:
    """(3, 3) rotation by `angle` (rad) about the unit `axis` (3,)."""
    k = jp.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return jp.eye(3) + jp.sin(angle) * k + (1.0 - jp.cos(angle)) * (k @ k)


def _forward(arm: ArmModel, base: BaseMotion, q, qd, qdd) -> _Bodies:
    """Each arm body's rotation, angular velocity and acceleration, COM position and specific
    COM acceleration (module docstring), unrolled over the bodies (a static tree)."""
    zero = jp.zeros(3)
    out = {k: [] for k in ("rot", "ang_vel", "ang_acc", "org", "acc", "com", "com_acc", "u", "A")}
    for i, (up, kind, k) in enumerate(zip(arm.parent, arm.joint, arm.qadr, strict=True)):
        if up < 0:  # hangs from the trunk: its origin at 0, accelerating as the accelerometer
            r_p, w_p, dw_p, o_p, a_p = base.rot, base.ang_vel, base.ang_acc, zero, base.lin_acc
        else:
            r_p, w_p = out["rot"][up], out["ang_vel"][up]
            dw_p, o_p, a_p = out["ang_acc"][up], out["org"][up], out["acc"][up]
        r0 = r_p @ arm.rot[i]  # the body's frame at the joint's reference
        o0 = o_p + r_p @ arm.pos[i]
        u = r0 @ arm.axis[i]  # (3,) world
        anchor = o0 + r0 @ arm.anchor[i]

        def rigid(x, a_p=a_p, dw_p=dw_p, w_p=w_p, o_p=o_p):  # a point fixed to the parent
            return a_p + jp.cross(dw_p, x - o_p) + jp.cross(w_p, jp.cross(w_p, x - o_p))

        if kind == _SLIDE:
            r, w, dw = r0, w_p, dw_p
            o = o0 + u * (q[k] - arm.q_ref[k])
            a = rigid(o) + 2.0 * jp.cross(w_p, u * qd[k]) + u * qdd[k]
        else:  # a hinge, or welded (no motion of its own)
            angle, rate, acc = (q[k] - arm.q_ref[k], qd[k], qdd[k]) if k >= 0 else (0.0, 0.0, 0.0)
            r = r0 @ _rodrigues(arm.axis[i], angle) if k >= 0 else r0
            w = w_p + u * rate
            dw = dw_p + u * acc + jp.cross(w_p, u * rate)
            o = anchor + r @ (-arm.anchor[i])
            lever = o - anchor
            a = rigid(anchor) + jp.cross(dw, lever) + jp.cross(w, jp.cross(w, lever))
        c = o + r @ arm.com[i]
        a_c = a + jp.cross(dw, c - o) + jp.cross(w, jp.cross(w, c - o))
        moving = 0.0 if kind == _WELD else 1.0
        for name, v in zip(out, (r, w, dw, o, a, c, a_c, u * moving, anchor), strict=True):
            out[name].append(v)
    stack = {k: jp.stack(v) for k, v in out.items()}
    return _Bodies(
        rot=stack["rot"],
        ang_vel=stack["ang_vel"],
        ang_acc=stack["ang_acc"],
        com=stack["com"],
        com_acc=stack["com_acc"],
        axis=stack["u"],
        anchor=stack["A"],
    )


def _body_wrenches(arm: ArmModel, b: _Bodies) -> tuple[jax.Array, jax.Array]:
    """Each body's rate of momentum less its weight: force (n_b, 3) N and torque about the trunk's
    origin (n_b, 3) N·m, world frame."""
    force = arm.mass[:, None] * b.com_acc  # m (a_c - g)
    inertia = b.rot @ arm.inertia @ jp.swapaxes(b.rot, 1, 2)  # (n_b, 3, 3) world
    spin = jp.einsum("bij,bj->bi", inertia, b.ang_acc) + jp.cross(
        b.ang_vel, jp.einsum("bij,bj->bi", inertia, b.ang_vel)
    )
    return force, jp.cross(b.com, force) + spin


def model_wrench(arm: ArmModel, base: BaseMotion, q, qd, qdd) -> jax.Array:
    """(6,) the wrench the arms exert on the base: [f (N), tau (N·m) about the base's COM], world
    frame (module docstring), for joint states q, qd, qdd (n,)."""
    return _base_wrench(arm, base, _forward(arm, base, q, qd, qdd))


def _base_wrench(arm: ArmModel, base: BaseMotion, b: _Bodies) -> jax.Array:
    force, torque = _body_wrenches(arm, b)
    f, tau_origin = force.sum(0), torque.sum(0)
    return -jp.concatenate([f, tau_origin - jp.cross(base.com, f)])


def joint_torques(arm: ArmModel, base: BaseMotion, q, qd, qdd) -> jax.Array:
    """(n,) the joint torques (N·m; N for a slide) that move the arms by qdd (n,) while the base
    moves by `base`: each joint's axis against the bodies beyond it (no armature, no damping)."""
    return _joint_torques(arm, _forward(arm, base, q, qd, qdd))


def _joint_torques(arm: ArmModel, b: _Bodies) -> jax.Array:
    force, torque = _body_wrenches(arm, b)
    subtree = jp.asarray(arm.subtree, force.dtype)
    sub_f = subtree @ force  # (n_b, 3) N: the bodies beyond each body's joint, theirs
    sub_tau = subtree @ torque - jp.cross(b.anchor, sub_f)  # (n_b, 3) N·m, about its anchor
    slide = np.array([kind == _SLIDE for kind in arm.joint])[:, None]
    per_body = jp.sum(jp.where(slide, sub_f, sub_tau) * b.axis, axis=-1)  # (n_b,) 0 if welded
    moving = [i for i, k in enumerate(arm.qadr) if k >= 0]
    return (
        jp.zeros(len(arm.q_ref), force.dtype)
        .at[np.array(arm.qadr)[moving]]
        .set(per_body[np.array(moving)])
    )


def _jacobians(arm: ArmModel, b: _Bodies) -> tuple[jax.Array, jax.Array]:
    """(J_v, J_w), each (n_b, n, 3): d(body COM velocity)/d(qd) and d(body angular velocity)/d(qd),
    world frame, at the pose of `b`: a hinge j moves the bodies beyond it by u_j x (c_k - A_j)
    and turns them by u_j; a slide moves them by u_j."""
    beyond = jp.asarray(arm.subtree, b.com.dtype)[:, :, None]  # (j, k, 1): k beyond joint j
    hinge_v = jp.cross(b.axis[:, None, :], b.com[None, :, :] - b.anchor[:, None, :])  # (j, k, 3)
    slide = np.array([kind == _SLIDE for kind in arm.joint])[:, None, None]
    lin = beyond * jp.where(slide, b.axis[:, None, :], hinge_v)
    ang = beyond * jp.where(slide, 0.0, b.axis[:, None, :])
    moving = np.array([i for i, k in enumerate(arm.qadr) if k >= 0])  # joint bodies, q's order
    order = np.argsort(np.array(arm.qadr)[moving])
    joints = moving[order]
    return jp.swapaxes(lin[joints], 0, 1), jp.swapaxes(ang[joints], 0, 1)


def servo_motion(arm: ArmModel, base: BaseMotion, q, qd, targets) -> tuple[jax.Array, jax.Array]:
    """(the arms' model wrench (6,), their joint accelerations qdd (n,)) while the arms' position
    servos track `targets` (n,) from (q, qd) and the base moves by `base`:

        M(q) qdd = clip(kp (target - q) - kv qd) - damping qd - friction sign(qd) - h(q, qd)

    M the joint-space inertia (sum_k m_k J_vk' J_vk + J_wk' I_k J_wk, `_jacobians`) plus the
    armature, h the joint torques of qdd = 0. A joint at a limit that this would push further,
    or still with a net torque its dry friction holds, is held (qdd 0) and the others solved
    without it. One forward pass: the bodies' accelerations are linear in qdd (a_c = a_c0 +
    J_v qdd, dw = dw0 + J_w qdd)."""
    n = len(arm.q_ref)
    b0 = _forward(arm, base, q, qd, jp.zeros(n))
    h = _joint_torques(arm, b0)
    jac_v, jac_w = _jacobians(arm, b0)
    inertia = b0.rot @ arm.inertia @ jp.swapaxes(b0.rot, 1, 2)  # (n_b, 3, 3) world
    mass = jp.einsum("k,kqi,kri->qr", arm.mass, jac_v, jac_v)
    mass = mass + jp.einsum("kqi,kij,krj->qr", jac_w, inertia, jac_w) + jp.diag(arm.armature)
    targets = jp.clip(targets, arm.target_min, arm.target_max)
    servo = jp.clip(arm.kp * (targets - q) - arm.kv * qd, -arm.limit, arm.limit)
    moving = jp.abs(qd) > _STICK_SPEED
    torque = servo - arm.damping * qd - h - jp.where(moving, arm.friction * jp.sign(qd), 0.0)
    free = jp.linalg.solve(mass, torque)
    held = ((q <= arm.q_min) & (free < 0)) | ((q >= arm.q_max) & (free > 0))  # MuJoCo's limits
    held = held | (~moving & (jp.abs(torque) <= arm.friction))
    eye = jp.eye(n, dtype=mass.dtype)
    mass = jp.where(held[:, None] | held[None, :], eye, mass)
    qdd = jp.linalg.solve(mass, jp.where(held, 0.0, torque))
    moved = b0.replace(
        com_acc=b0.com_acc + jp.einsum("kqi,q->ki", jac_v, qdd),
        ang_acc=b0.ang_acc + jp.einsum("kqi,q->ki", jac_w, qdd),
    )
    return _base_wrench(arm, base, moved), qdd


def servo_qdd(arm: ArmModel, base: BaseMotion, q, qd, targets) -> jax.Array:
    """(n,) the joint accelerations of `servo_motion`."""
    return servo_motion(arm, base, q, qd, targets)[1]


def exact_inputs(lay: Layout, com_offset, gravity, d) -> tuple[BaseMotion, tuple]:
    """(the trunk's `BaseMotion`, (q, qd, qdd) of the arms) read from a simulator's data `d`
    whose accelerations and kinematics belong to its qpos and qvel (after `mj_forward` or
    `mjx.forward`): privileged, the true accelerations, for the tests and the exact-input rows
    of experiments/arm_model_wrench.py. `com_offset` (3,) m, the base's COM in the trunk frame;
    `gravity` (3,) m/s^2."""
    rot = d.xmat[lay.trunk]  # the free joint's angular terms are in the trunk frame
    base = BaseMotion(
        rot=rot,
        ang_vel=rot @ d.qvel[3:6],
        ang_acc=rot @ d.qacc[3:6],
        lin_acc=d.qacc[0:3] - gravity,  # the free joint's linear terms: its origin, world
        com=rot @ com_offset,
    )
    return base, (d.qpos[lay.arm_qpos], d.qvel[lay.arm_dof], d.qacc[lay.arm_dof])


__all__ = [
    "ArmModel",
    "BaseMotion",
    "arm_model",
    "exact_inputs",
    "joint_torques",
    "model_wrench",
    "servo_motion",
    "servo_qdd",
]
