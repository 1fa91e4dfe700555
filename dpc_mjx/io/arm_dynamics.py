"""The arms' model wrench with numpy alone: `dpc_mjx.control.arm_model.servo_motion` fed as
`dpc_mjx.control.arm_estimate.update` feeds it (qdd 'servo', base_acc 'desired'), in float64,
from an export's arm-model file `arm_model_<arm>.json` (`read_arm_model`).

Imports only the standard library and numpy, so it can be copied next to `inference.py`, which
loads it for an export whose `action_scaling.base` is 'model'. World frame unless said; positions
relative to the trunk's origin. At one 4 ms tick (`tick_wrench`):

    q, qd, T   the arm joints' positions, velocities (rad, rad/s; m, m/s for a finger), servo
               targets, (n,) each in the file's `joints` order (the observation's s_arm order)
    R, w       trunk -> world rotation (3, 3) and angular velocity (3,) rad/s (IMU, gyro)
    d = [a_c, dw]  (6,) the balance QP's desired COM (m/s^2) and angular (rad/s^2) accelerations
    c          (3,) m, the base's COM minus the trunk's origin

    base: dw_B = dw, a_B - g = a_c - dw x c - w x (w x c) + (0, 0, GRAVITY)       (`base_motion`)

Forward pass (`_forward`), body j after its parent p, joint axis u (world) through anchor A:

    w_j = w_p + u qd,  dw_j = dw_p + u qdd + w_p x u qd                               (hinge)
    a(x) = a_p + dw_p x (x - o_p) + w_p x (w_p x (x - o_p))     a point x fixed to the parent
    a_j = a(A) + dw_j x (o_j - A) + w_j x (w_j x (o_j - A))                             (hinge)
    a_j = a(o_j) + 2 w_p x u qd + u qdd                                                 (slide)

Body wrenches F_j = m_j (a_cj - g), N_j = (c_j x F_j) + I_j dw_j + w_j x I_j w_j (about the
trunk origin); joint torques tau_i = u_i . (sum over the subtree of i of N_k - A_i x F_k) for
a hinge (u_i . sum F_k for a slide). The servos (`servo_motion`):

    M(q) qdd = clip(kp (clip(T) - q) - kv qd, +-limit) - damping qd - friction sign(qd) - h
    M = sum_k m_k J_vk' J_vk + J_wk' I_k J_wk + diag(armature),  h = tau(qdd = 0)

a joint at its range's end that qdd would push further, or slower than STICK_SPEED with
|torque| <= friction, is held (qdd_i = 0) and the rest solved again. The wrench the arms exert
on the base, about its COM c: f = -sum F_j, tau = -(sum N_j - c x sum F_j), N and N·m.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import pathlib
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

GRAVITY = 9.81  # m/s^2, equal to dpc_mjx.control.balance.GRAVITY; g = (0, 0, -GRAVITY)
STICK_SPEED = 1e-3  # rad/s (m/s): slower, dry friction may hold a joint (arm_model's)
FILE_FORMAT = "dpc_mjx arm model"  # the arm-model file's `format`
FILE_VERSION = 1
JOINT_KINDS = ("hinge", "slide", "weld")  # 'weld': a body fixed to its parent
SHAPES = {  # field: shape, 'b' the bodies, 'n' the joints
    **{k: ("b", 3) for k in ("pos", "axis", "anchor", "com")},
    **{k: ("b", 3, 3) for k in ("rot", "inertia")},
    "mass": ("b",),
    **{k: ("n",) for k in ("q_ref", "kp", "kv", "armature", "damping", "friction")},
}
BOUNDS = ("limit", "target_min", "target_max", "q_min", "q_max")  # (n,), null: unbounded
# what a robot measures at a tick (`tick_wrench`): key -> (shape, words); 'quat', 'gyro' too
MEASURED = {
    "q": ("n", "arm joint positions, rad (m), the file's joint order"),
    "qd": ("n", "arm joint velocities, rad/s (m/s)"),
    "targets": ("n", "the arm servo targets this tick commands, rad (m)"),
    "rot": ((3, 3), "trunk -> world rotation (or 'quat' (4,) w, x, y, z)"),
    "ang_vel": ((3,), "trunk angular velocity, rad/s, world (or 'gyro' (3,), trunk frame)"),
    "desired": (
        (6,),
        "the balance QP's desired accelerations (eq. 9), world: COM m/s^2 (no g), rad/s^2",
    ),
    "com": ((3,), "the base's COM minus the trunk's origin, m, world"),
}


@dataclasses.dataclass(frozen=True)
class ArmModel:
    """Every arm body in tree order (`arm_model.ArmModel`'s fields, in float64): positions and
    rotations in the parent's frame at the joints' reference q_ref; kg, m, kg·m² (about the COM,
    body frame), N·m/rad, N·m·s/rad, N·m (N, N/m for a slide); a bound of ±inf: none."""

    parent: tuple[int, ...]  # (n_b,) body index, -1 the trunk
    joint: tuple[str, ...]  # (n_b,) JOINT_KINDS
    qadr: tuple[int, ...]  # (n_b,) index in q, -1 welded
    subtree: np.ndarray  # (n_b, n_b) 1 where the column's body is in the row's subtree
    joints: tuple[str, ...]  # (n,) the joints' names, q's order
    pos: np.ndarray  # (n_b, 3) m, body origin in the parent's frame
    rot: np.ndarray  # (n_b, 3, 3) body -> parent, at the reference
    axis: np.ndarray  # (n_b, 3) joint axis, body frame (0 welded)
    anchor: np.ndarray  # (n_b, 3) m, joint position, body frame
    mass: np.ndarray  # (n_b,) kg
    com: np.ndarray  # (n_b, 3) m, COM in the body frame
    inertia: np.ndarray  # (n_b, 3, 3) kg·m², about the COM, body frame
    q_ref: np.ndarray  # (n,) rad (m)
    kp: np.ndarray  # (n,) N·m/rad: tau = clip(kp (target - q) - kv qd, +-limit)
    kv: np.ndarray  # (n,) N·m·s/rad
    armature: np.ndarray  # (n,) kg·m² (kg)
    damping: np.ndarray  # (n,) N·m·s/rad
    friction: np.ndarray  # (n,) N·m (N), dry friction
    limit: np.ndarray  # (n,) N·m (N), the servo's torque bound
    target_min: np.ndarray  # (n,) rad (m), targets clipped to [target_min, target_max]
    target_max: np.ndarray
    q_min: np.ndarray  # (n,) rad (m), the joint's range
    q_max: np.ndarray

    @property
    def n(self) -> int:
        return len(self.joints)


class BaseMotion(NamedTuple):
    """The trunk at one tick, world frame (`arm_model.BaseMotion`)."""

    rot: np.ndarray  # (3, 3) trunk -> world
    ang_vel: np.ndarray  # (3,) rad/s
    ang_acc: np.ndarray  # (3,) rad/s^2
    lin_acc: np.ndarray  # (3,) m/s^2, specific: the trunk origin's acceleration minus gravity
    com: np.ndarray  # (3,) m, the base's COM minus the trunk's origin


def arm_model_from_json(data: Mapping, where: str = "arm model") -> ArmModel:
    """The `ArmModel` of an arm-model file's JSON object; `ValueError` naming what is wrong."""
    if not isinstance(data, Mapping) or data.get("format") != FILE_FORMAT:
        raise ValueError(f"{where} is not a {FILE_FORMAT!r} file; copy the export again.")
    if data.get("format_version") != FILE_VERSION:
        raise ValueError(
            f"{where} has format_version {data.get('format_version')!r}, this file reads "
            f"{FILE_VERSION}; copy arm_dynamics.py from the dpc_mjx that wrote the export."
        )
    try:
        parent, qadr = [int(p) for p in data["parent"]], [int(k) for k in data["qadr"]]
        kinds, joints = [str(k) for k in data["joint"]], tuple(str(j) for j in data["joints"])
        n_b, n = len(parent), len(joints)
        arrays = {k: np.array(data[k], np.float64) for k in SHAPES}
        for k in BOUNDS:
            v = [(-np.inf if k.endswith("_min") else np.inf) if x is None else x for x in data[k]]
            arrays[k] = np.array(v, np.float64)
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{where} lacks or mangles a field ({e!r}); copy the export again.") from e
    sizes = {"b": n_b, "n": n}
    bad = [k for k, s in SHAPES.items() if arrays[k].shape != tuple(sizes.get(x, x) for x in s)]
    bad += [k for k in BOUNDS if arrays[k].shape != (n,)]
    bad += [k for k in ("joint", "qadr") if len(data[k]) != n_b]
    tree = all(-1 <= p < i for i, p in enumerate(parent)) and set(kinds) <= set(JOINT_KINDS)
    moving = sorted(k for k, kind in zip(qadr, kinds, strict=False) if kind != "weld")
    finite = all(np.isfinite(arrays[k]).all() for k in SHAPES)
    if bad or not tree or moving != list(range(n)) or not finite:
        raise ValueError(
            f"{where}: fields {bad} have the wrong shapes for {n_b} bodies and {n} joints, or "
            "a number is not finite, or its tree (parent before child, one hinge or slide per "
            "moving body, each joint once) is broken; copy the export again."
        )
    subtree = np.zeros((n_b, n_b))
    for i in range(n_b):
        j = i
        while j >= 0:  # body i is in the subtree of each of its ancestors
            subtree[j, i], j = 1.0, parent[j]
    return ArmModel(tuple(parent), tuple(kinds), tuple(qadr), subtree, joints, **arrays)


def read_arm_model(path: str | pathlib.Path, sha256: str | None = None) -> ArmModel:
    """The `ArmModel` in the arm-model file `path`, checked against its `sha256` if given."""
    path = pathlib.Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ValueError(f"Cannot read {path} ({e}); copy the whole export folder.") from e
    if sha256 is not None and hashlib.sha256(raw).hexdigest() != sha256:
        raise ValueError(
            f"{path} is not the file recorded in dpc.json (sha256 differs): it is truncated, "
            "corrupt or from another export; copy the export folder again."
        )
    try:
        data = json.loads(raw)
    except ValueError as e:
        raise ValueError(f"{path} is not valid JSON ({e}); copy the export again.") from e
    return arm_model_from_json(data, str(path))


def from_export(meta: Mapping, directory: pathlib.Path, arm: str, n_in: int, n_body: int):
    """(the `ArmModel` of `arm`, None) in the export at `directory` with the sidecar `meta`,
    which records it (encoders.<arm>.arm_model), where its u_model reads qdd 'servo' and
    base_acc 'desired' (`arm_estimate`), else (None, why the robot must pass u_model). Its
    joints are checked against the encoder's input [s_body (n_body), q, qd, targets] (n_in)."""
    entry, env = meta["encoders"][arm]["arm_model"], meta.get("env_config") or {}
    estimator = (env.get("arm_qdd", "servo"), env.get("arm_base_acc", "desired"))
    if estimator != ("servo", "desired"):
        return None, (
            f" Its u_model reads qdd {estimator[0]!r} and base_acc {estimator[1]!r}; numpy "
            "computes only 'servo' and 'desired' (arm_dynamics.py)."
        )
    name = str(entry.get("file"))
    if pathlib.PurePath(name).name != name or name in ("", ".", ".."):
        raise ValueError(f"arm model file {name!r} is not a file name in the export folder")
    model = read_arm_model(pathlib.Path(directory) / name, entry.get("sha256"))
    if n_body + 3 * model.n != n_in:
        raise ValueError(
            f"{name} has {model.n} joints, so an input of {n_body + 3 * model.n} [s_body, q, "
            f"qd, targets], but the encoder reads {n_in}; re-export."
        )
    return model, None


def base_motion(rot, ang_vel, desired, com) -> BaseMotion:
    """The trunk's motion from the balance QP's desired accelerations (base_acc 'desired'):
    dw = desired[3:], a_origin = desired[:3] - dw x c - w x (w x c), specific (+GRAVITY z)."""
    rot, w, desired, com = (np.asarray(x, np.float64) for x in (rot, ang_vel, desired, com))
    dw = desired[3:]
    a_origin = desired[:3] - np.cross(dw, com) - np.cross(w, np.cross(w, com))
    return BaseMotion(rot, w, dw, a_origin + np.array([0.0, 0.0, GRAVITY]), com)


def _skew(v) -> np.ndarray:
    """(3, 3) the matrix of v x (3,)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) rotation by `angle` (rad) about the unit `axis` (3,)."""
    k = _skew(axis)
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def quat_rot(quat) -> np.ndarray:
    """(3, 3) rotation of a (4,) w, x, y, z quaternion (normalised here): I + 2 w K + 2 K^2,
    K the matrix of (x, y, z) x."""
    w, *v = np.asarray(quat, np.float64) / np.linalg.norm(quat)
    k = _skew(v)
    return np.eye(3) + 2.0 * w * k + 2.0 * (k @ k)


def _forward(arm: ArmModel, base: BaseMotion, q, qd, qdd) -> dict[str, np.ndarray]:
    """Each body's rot (n_b, 3, 3), ang_vel, ang_acc, com, com_acc (specific), axis (0 where
    welded) and anchor (n_b, 3), world (the module docstring's forward pass)."""
    keys = ("rot", "ang_vel", "ang_acc", "org", "acc", "com", "com_acc", "axis", "anchor")
    out = {k: [] for k in keys}
    for i, (up, kind, k) in enumerate(zip(arm.parent, arm.joint, arm.qadr, strict=True)):
        if up < 0:  # hangs from the trunk: its origin at 0, accelerating as the accelerometer
            r_p, w_p, dw_p, o_p, a_p = (
                base.rot,
                base.ang_vel,
                base.ang_acc,
                np.zeros(3),
                base.lin_acc,
            )
        else:
            r_p, w_p = out["rot"][up], out["ang_vel"][up]
            dw_p, o_p, a_p = out["ang_acc"][up], out["org"][up], out["acc"][up]
        r0 = r_p @ arm.rot[i]  # the body's frame at the joint's reference
        o0 = o_p + r_p @ arm.pos[i]
        u = r0 @ arm.axis[i]
        anchor = o0 + r0 @ arm.anchor[i]

        def rigid(x):  # the acceleration of a point x fixed to the parent
            return a_p + np.cross(dw_p, x - o_p) + np.cross(w_p, np.cross(w_p, x - o_p))

        if kind == "slide":
            r, w, dw = r0, w_p, dw_p
            o = o0 + u * (q[k] - arm.q_ref[k])
            a = rigid(o) + 2.0 * np.cross(w_p, u * qd[k]) + u * qdd[k]
        else:  # a hinge, or welded (no motion of its own)
            angle, rate, acc = (q[k] - arm.q_ref[k], qd[k], qdd[k]) if k >= 0 else (0.0, 0.0, 0.0)
            r = r0 @ _rodrigues(arm.axis[i], angle) if k >= 0 else r0
            w = w_p + u * rate
            dw = dw_p + u * acc + np.cross(w_p, u * rate)
            o = anchor - r @ arm.anchor[i]
            lever = o - anchor
            a = rigid(anchor) + np.cross(dw, lever) + np.cross(w, np.cross(w, lever))
        c = o + r @ arm.com[i]
        a_c = a + np.cross(dw, c - o) + np.cross(w, np.cross(w, c - o))
        u = u * (0.0 if kind == "weld" else 1.0)
        for name, v in zip(keys, (r, w, dw, o, a, c, a_c, u, anchor), strict=True):
            out[name].append(v)
    return {k: np.array(v) for k, v in out.items()}


def _body_wrenches(arm: ArmModel, b: dict) -> tuple[np.ndarray, np.ndarray]:
    """F (n_b, 3) N = m (a_c - g) and N (n_b, 3) N·m about the trunk's origin, world."""
    force = arm.mass[:, None] * b["com_acc"]
    inertia = b["rot"] @ arm.inertia @ np.swapaxes(b["rot"], 1, 2)  # (n_b, 3, 3) world
    iw = np.einsum("bij,bj->bi", inertia, b["ang_vel"])
    spin = np.einsum("bij,bj->bi", inertia, b["ang_acc"]) + np.cross(b["ang_vel"], iw)
    return force, np.cross(b["com"], force) + spin


def _base_wrench(arm: ArmModel, base: BaseMotion, b: dict) -> np.ndarray:
    """(6,) [f (N), tau (N·m) about the base's COM], world: the arms' wrench on the base."""
    force, torque = _body_wrenches(arm, b)
    f = force.sum(0)
    return -np.concatenate([f, torque.sum(0) - np.cross(base.com, f)])


def _joint_torques(arm: ArmModel, b: dict) -> np.ndarray:
    """(n,) each joint's axis against the wrench of the bodies beyond it (N·m; N a slide)."""
    force, torque = _body_wrenches(arm, b)
    sub_f = arm.subtree @ force
    sub_tau = arm.subtree @ torque - np.cross(b["anchor"], sub_f)  # about each anchor
    slide = np.array([kind == "slide" for kind in arm.joint])[:, None]
    per_body = np.sum(np.where(slide, sub_f, sub_tau) * b["axis"], axis=-1)
    out = np.zeros(arm.n)
    for i, k in enumerate(arm.qadr):
        if k >= 0:
            out[k] = per_body[i]
    return out


def _jacobians(arm: ArmModel, b: dict) -> tuple[np.ndarray, np.ndarray]:
    """(J_v, J_w), each (n_b, n, 3): d(COM velocity)/d(qd), d(angular velocity)/d(qd); a hinge
    j moves the bodies beyond it by u_j x (c_k - A_j) and turns them by u_j, a slide by u_j."""
    beyond = arm.subtree[:, :, None]  # (j, k, 1): body k beyond body j's joint
    axis = b["axis"][:, None, :]
    hinge_v = np.cross(axis, b["com"][None, :, :] - b["anchor"][:, None, :])
    slide = np.array([kind == "slide" for kind in arm.joint])[:, None, None]
    lin, ang = beyond * np.where(slide, axis, hinge_v), beyond * np.where(slide, 0.0, axis)
    order = [arm.qadr.index(k) for k in range(arm.n)]  # the body of each joint, q's order
    return np.swapaxes(lin[order], 0, 1), np.swapaxes(ang[order], 0, 1)


def model_wrench(arm: ArmModel, base: BaseMotion, q, qd, qdd) -> np.ndarray:
    """(6,) the arms' wrench on the base (N, N·m about its COM, world) at q, qd, qdd (n,)."""
    return _base_wrench(arm, base, _forward(arm, base, *_f64(q, qd, qdd)))


def servo_motion(arm: ArmModel, base: BaseMotion, q, qd, targets) -> tuple[np.ndarray, ...]:
    """(the arms' model wrench (6,), their joint accelerations qdd (n,)) while their position
    servos track `targets` (n,) from (q, qd) (the module docstring's servo law and solves)."""
    q, qd, targets = _f64(q, qd, targets)
    b0 = _forward(arm, base, q, qd, np.zeros(arm.n))
    h = _joint_torques(arm, b0)
    jac_v, jac_w = _jacobians(arm, b0)
    inertia = b0["rot"] @ arm.inertia @ np.swapaxes(b0["rot"], 1, 2)
    mass = np.einsum("k,kqi,kri->qr", arm.mass, jac_v, jac_v)
    mass = mass + np.einsum("kqi,kij,krj->qr", jac_w, inertia, jac_w) + np.diag(arm.armature)
    targets = np.clip(targets, arm.target_min, arm.target_max)
    servo = np.clip(arm.kp * (targets - q) - arm.kv * qd, -arm.limit, arm.limit)
    moving = np.abs(qd) > STICK_SPEED
    torque = servo - arm.damping * qd - h - np.where(moving, arm.friction * np.sign(qd), 0.0)
    free = np.linalg.solve(mass, torque)
    held = ((q <= arm.q_min) & (free < 0)) | ((q >= arm.q_max) & (free > 0))  # at a limit
    held = held | (~moving & (np.abs(torque) <= arm.friction))
    mass = np.where(held[:, None] | held[None, :], np.eye(arm.n), mass)
    qdd = np.linalg.solve(mass, np.where(held, 0.0, torque))
    b0["com_acc"] = b0["com_acc"] + np.einsum("kqi,q->ki", jac_v, qdd)
    b0["ang_acc"] = b0["ang_acc"] + np.einsum("kqi,q->ki", jac_w, qdd)
    return _base_wrench(arm, base, b0), qdd


def _f64(*xs) -> list[np.ndarray]:
    return [np.asarray(x, np.float64) for x in xs]


def tick_inputs(arm: ArmModel, measured: Mapping) -> dict[str, np.ndarray]:
    """`measured` (MEASURED's keys, 'quat' for 'rot' and 'gyro' for 'ang_vel' allowed) checked
    and completed: float64 arrays of MEASURED's shapes with leading batch axes (...) alike;
    `ValueError` naming every missing key and every wrong shape."""
    if not isinstance(measured, Mapping):
        raise ValueError(f"measured must be a dict of {list(MEASURED)}, got {type(measured)}")
    given = {k: np.asarray(v, np.float64) for k, v in measured.items()}
    quat = given.get("quat")
    if "rot" not in given and quat is not None and quat.shape[-1:] == (4,):
        rots = [quat_rot(x) for x in quat.reshape(-1, 4)]
        given["rot"] = np.reshape(rots, quat.shape[:-1] + (3, 3))
    if "ang_vel" not in given and "gyro" in given and "rot" in given:
        given["ang_vel"] = np.einsum("...ij,...j->...i", given["rot"], given["gyro"])
    missing = [k for k in MEASURED if k not in given]
    unknown = sorted(set(given) - set(MEASURED) - {"quat", "gyro"})
    shapes = {k: (arm.n,) if s == "n" else s for k, (s, _) in MEASURED.items()}
    wrong = [k for k in MEASURED if k in given and given[k].shape[-len(shapes[k]) :] != shapes[k]]
    bad = [k for k in MEASURED if k in given and not np.isfinite(given[k]).all()]
    if missing or unknown or wrong or bad:
        raise ValueError(
            "The arms' model wrench (u_model) needs the tick's measured inputs, measured="
            f"{{{', '.join(MEASURED)}}} (q, qd: the observation's s_arm by default): "
            + "; ".join(f"{k} {shapes[k]}: {MEASURED[k][1]}" for k in missing + wrong)
            + (f" (missing {missing})" if missing else "")
            + (f" (wrong shape: {[(k, given[k].shape) for k in wrong]})" if wrong else "")
            + (f" (unknown keys {unknown})" if unknown else "")
            + (f" (NaN/inf in {bad}: check the robot's state estimate)" if bad else "")
        )
    return {k: given[k] for k in MEASURED}


def tick_wrench(arm: ArmModel, measured: Mapping) -> np.ndarray:
    """(..., 6) the arms' model wrench of a tick, world frame, N and N·m about the base's COM:
    `servo_motion`'s, on `base_motion` (`tick_inputs`' keys; leading axes: one per row)."""
    x = tick_inputs(arm, measured)
    trailing = {k: 2 if k == "rot" else 1 for k in x}
    batch = np.broadcast_shapes(*(v.shape[: v.ndim - trailing[k]] for k, v in x.items()))
    rows = {k: np.broadcast_to(v, batch + v.shape[v.ndim - trailing[k] :]) for k, v in x.items()}
    out = np.zeros(batch + (6,))
    for i in np.ndindex(*batch):
        r = {k: v[i] for k, v in rows.items()}
        base = base_motion(r["rot"], r["ang_vel"], r["desired"], r["com"])
        out[i] = servo_motion(arm, base, r["q"], r["qd"], r["targets"])[0]
    return out
