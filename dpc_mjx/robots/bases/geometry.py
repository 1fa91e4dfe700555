"""Geometry of a base read from its file (`dpc_mjx.robots.bases.file`), on a MuJoCo model of the
base alone whose trunk is welded at the world origin, so that world coordinates are trunk-frame
coordinates (m): the trunk's box and inertia, a leg's length and the home pose of a leg.

The home pose puts each foot under its hip: the foot's centre straight below the leg's second
joint (the thigh joint, where the leg swings fore and aft) as that joint sits at the zero pose, at
`height - foot_radius` below the trunk's origin, so that the foot touches a floor `height` below
the trunk. It is solved by damped least squares from the zero pose clipped into the joints' ranges
(the knee bends the way its range allows).
"""

from __future__ import annotations

import mujoco
import numpy as np

HOME_TOL = 1e-6  # m: the solved foot centre lies this close to its target
_IK_ITERS = 100
_IK_DAMPING = 1e-6  # m², Levenberg-Marquardt damping of the least-squares step


def geom_box(model: mujoco.MjModel, data: mujoco.MjData, geoms: list[int]) -> np.ndarray:
    """(2, 3) lower and upper corners (m, world frame) of the axis-aligned box around `geoms`
    (after `mj_kinematics`): a mesh by its vertices, a primitive by the corners of its own box."""
    points = []
    for g in geoms:
        rot = data.geom_xmat[g].reshape(3, 3)
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            mesh = model.geom_dataid[g]
            start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            local = model.mesh_vert[start : start + count]  # (n, 3), m, geom frame
        else:
            center, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
            local = center + signs * half  # (8, 3), m, geom frame
        points.append(local @ rot.T + data.geom_xpos[g])
    points = np.concatenate(points)
    return np.stack([points.min(axis=0), points.max(axis=0)])


def rigid_inertia(model: mujoco.MjModel, data: mujoco.MjData, bodies: list[int]) -> tuple:
    """Mass (kg), COM (3,) (m, world frame) and inertia (3, 3) (kg·m², about the COM, world
    axes) of `bodies` taken as one rigid body (after `mj_kinematics`; parallel-axis theorem)."""
    masses = model.body_mass[bodies]  # (n,) kg
    com = masses @ data.xipos[bodies] / masses.sum()
    inertia = np.zeros((3, 3))
    for body, m in zip(bodies, masses, strict=True):
        rot, d = data.ximat[body].reshape(3, 3), data.xipos[body] - com
        inertia += rot @ np.diag(model.body_inertia[body]) @ rot.T
        inertia += m * (d @ d * np.eye(3) - np.outer(d, d))
    return float(masses.sum()), com, inertia


def joint_anchors(model: mujoco.MjModel, data: mujoco.MjData, joints: tuple[str, ...]):
    """(n, 3) world positions (m) of the joints' anchors (after `mj_kinematics`)."""
    return np.array([data.xanchor[model.joint(name).id] for name in joints])


def leg_length(anchors: np.ndarray, foot: np.ndarray) -> float:
    """Length (m) of the leg below its first joint: from its second joint through the others to
    the foot's centre `foot` (3,), summed link by link (the straight leg's reach)."""
    points = np.vstack([anchors[1:], foot])
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def solve_leg(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    joints: tuple[str, ...],
    foot: tuple[int, np.ndarray],
    target: np.ndarray,
) -> tuple[np.ndarray, float]:
    """The leg's joint angles (rad) putting the foot's centre at `target` (3,), m, world frame,
    and the distance (m) left. `foot` is (body id, the centre's offset (3,) in that body's frame);
    `data.qpos` holds the start (the zero pose clipped into range) and is left at the solution."""
    body, offset = foot
    ids = [model.joint(name).id for name in joints]
    qadr = np.array([model.jnt_qposadr[j] for j in ids])
    dadr = np.array([model.jnt_dofadr[j] for j in ids])
    lo = np.where(model.jnt_limited[ids], model.jnt_range[ids, 0], -np.inf)
    hi = np.where(model.jnt_limited[ids], model.jnt_range[ids, 1], np.inf)
    jacp = np.zeros((3, model.nv))
    error = np.inf
    for _ in range(_IK_ITERS):
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        point = data.xpos[body] + data.xmat[body].reshape(3, 3) @ offset
        residual = target - point
        error = float(np.linalg.norm(residual))
        if error < HOME_TOL / 10:
            break
        mujoco.mj_jac(model, data, jacp, None, point, body)
        jac = jacp[:, dadr]  # (3, n)
        step = np.linalg.solve(jac.T @ jac + _IK_DAMPING * np.eye(len(ids)), jac.T @ residual)
        data.qpos[qadr] = np.clip(data.qpos[qadr] + step, lo, hi)
    return data.qpos[qadr].copy(), error


__all__ = ["HOME_TOL", "geom_box", "joint_anchors", "leg_length", "rigid_inertia", "solve_leg"]
