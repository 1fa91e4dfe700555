"""Rotation helpers: quaternions, rotation matrices, rotation vectors, yaw.

Conventions, for every function here:
  * quaternions are (..., 4) wxyz (MuJoCo's convention), unit norm;
  * rotation matrices are (3, 3) body -> world, R v_body = v_world (MuJoCo's `xmat`), with
    leading batch axes (..., 3, 3) where a function says so (else vmap it);
  * rotation vectors are (3,) axis * angle (rad);
  * yaw is the heading of the body x axis about world z (z up), rad, in [-pi, pi].
Functions take numpy or jax arrays and return jax arrays, except the `_np` ones (numpy in, numpy
out, float64, for building test and benchmark inputs outside jit).
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np


def roll_pitch_yaw(quat):
    """(..., 3) ZYX Euler angles (rad): roll about x, pitch about y, yaw about z, of a body->world
    rotation given as a (..., 4) wxyz quaternion."""
    w, x, y, z = (quat[..., i] for i in range(4))
    roll = jp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = jp.arcsin(jp.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = jp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return jp.stack([roll, pitch, yaw], axis=-1)


def yaw_of(rot: jax.Array) -> jax.Array:
    """(...) yaw (rad) of a rotation matrix (..., 3, 3): atan2(R_yx, R_xx), the heading of the
    body x axis projected on the world xy plane."""
    return jp.arctan2(rot[..., 1, 0], rot[..., 0, 0])


def rot_z(yaw: jax.Array) -> jax.Array:
    """(3, 3) rotation about world z by a scalar yaw () (rad)."""
    c, s = jp.cos(yaw), jp.sin(yaw)
    return jp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def to_yaw_frame(v: jax.Array, yaw: jax.Array) -> jax.Array:
    """(3,) a world-frame vector `v` (3,) in the yaw frame (heading-aligned, z up) of heading
    `yaw` () (rad): R_z(yaw)^T v."""
    c, s = jp.cos(yaw), jp.sin(yaw)
    return jp.stack([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


def wrench_to_yaw_frame(u: jax.Array, yaw: jax.Array) -> jax.Array:
    """(..., 6) a world-frame wrench u = [f (N), tau (N·m)] in the yaw frame of heading `yaw`
    (..., ) rad: [R_z(yaw)^T f, R_z(yaw)^T tau] (the same reference point; numpy or jax input)."""
    c, s = jp.cos(yaw), jp.sin(yaw)
    f_x, f_y, f_z, t_x, t_y, t_z = (u[..., i] for i in range(6))
    return jp.stack(
        [c * f_x + s * f_y, -s * f_x + c * f_y, f_z, c * t_x + s * t_y, -s * t_x + c * t_y, t_z],
        axis=-1,
    )


def wrench_to_world(u: jax.Array, yaw: jax.Array) -> jax.Array:
    """(..., 6) a yaw-frame wrench u (heading `yaw` (..., ) rad) in the world frame:
    [R_z(yaw) f, R_z(yaw) tau], the inverse of `wrench_to_yaw_frame`."""
    return wrench_to_yaw_frame(u, -yaw)


def yaw_rotation(rot: jax.Array) -> jax.Array:
    """R_z (3, 3): the rotation about world z by the yaw of `rot` (3, 3) (the same matrix as
    rot_z(yaw_of(rot)), in `rot`'s dtype)."""
    yaw = yaw_of(rot)
    c, s = jp.cos(yaw), jp.sin(yaw)
    o, one = jp.zeros_like(c), jp.ones_like(c)
    return jp.stack([jp.stack([c, -s, o]), jp.stack([s, c, o]), jp.stack([o, o, one])])


def rotvec_from_matrix(rot: jax.Array) -> jax.Array:
    """log(R) as a rotation vector (3,) (rad) of a rotation matrix (3, 3); finite for any input.

    Via the quaternion (Shepperd's branch choice, the largest of w, x, y, z computed from the
    diagonal) so that angles near 0 and near pi are both accurate: theta = 2 atan2(|v|, w), w >= 0.
    """
    r = jp.nan_to_num(rot)
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    # Four candidate (unnormalised) quaternions (w, x, y, z) * 4 * component; pick the stable one.
    sx, sy, sz = r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]  # 4 w (x, y, z)
    pxy, pxz, pyz = r[0, 1] + r[1, 0], r[0, 2] + r[2, 0], r[1, 2] + r[2, 1]
    cand = jp.stack(
        [
            jp.stack([1 + tr, sx, sy, sz]),
            jp.stack([sx, 1 + 2 * r[0, 0] - tr, pxy, pxz]),
            jp.stack([sy, pxy, 1 + 2 * r[1, 1] - tr, pyz]),
            jp.stack([sz, pxz, pyz, 1 + 2 * r[2, 2] - tr]),
        ]
    )
    diag = jp.stack([tr, r[0, 0], r[1, 1], r[2, 2]])
    quat = cand[jp.argmax(diag)]
    quat = quat * jp.where(quat[0] < 0, -1.0, 1.0)  # w >= 0: the short way round
    vnorm = jp.linalg.norm(quat[1:])
    angle = 2.0 * jp.arctan2(vnorm, quat[0])
    safe = jp.where(vnorm > 0, vnorm, 1.0)
    return jp.where(vnorm > 0, quat[1:] * (angle / safe), jp.zeros(3, rot.dtype))


def skew(v: jax.Array) -> jax.Array:
    """[v]x (..., 3, 3) such that [v]x w = v x w, for v (..., 3)."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = jp.zeros_like(x)
    return jp.stack(
        [jp.stack([o, -z, y], -1), jp.stack([z, o, -x], -1), jp.stack([-y, x, o], -1)], -2
    )


def skew_np(v: np.ndarray) -> np.ndarray:
    """[v]x (3, 3) of v (3,), in NumPy."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def matrix_from_rotvec_np(axis_angle: np.ndarray) -> np.ndarray:
    """Rodrigues, in NumPy: the rotation matrix (3, 3) of a rotation vector (3,) (rad);
    R = I + sin(t) K + (1 - cos(t)) K^2, K = [axis]x, t = |axis_angle|."""
    angle = np.linalg.norm(axis_angle)
    if angle == 0.0:
        return np.eye(3)
    k = skew_np(axis_angle / angle)
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
