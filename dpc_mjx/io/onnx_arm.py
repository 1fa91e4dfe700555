"""The arms' model wrench u_model as ONNX nodes (`model_wrench`), for the graph of `onnx_graph`:
what `arm_dynamics.servo_motion` computes on `arm_dynamics.base_motion` (qdd 'servo', base_acc
'desired'), in float32, vectorised over the batch (B) and the arm's bodies (b), its n joints in
the arm-model file's order. The file's numbers are initializers; the nodes are standard ONNX of
opset 13 on (no solve, no Atan2, no loop). This module imports no onnx: the graph builder
(`onnx_graph._Graph`: `const`, `op`) is passed in. World frame; positions from the trunk's origin.

Inputs, float32, batch-first (`MEASURED`): q, qd (B, n) (the observation's s_arm), targets
(B, n), rot R (B, 3, 3) trunk -> world, ang_vel w (B, 3) rad/s, desired [a_c, dw] (B, 6) m/s^2
and rad/s^2, com c (B, 3) m. With anc (b, b) the ancestor-or-self matrix (anc @ x sums x over
each body's chain), p(j) a body's parent (the trunk: R, w, dw, the point 0, a_B), u_j, A_j, c_j
a body's world axis, anchor and COM, K_j the skew matrix of its joint axis (0 unless a hinge):

    base       dw_B = dw, a_B = a_c - dw x c - w x (w x c) + (0, 0, GRAVITY)   (specific)
    rotations  R_j = R_p(j) rot_j Rod_j, Rod = I + sin(q - q_ref) K + (1 - cos(q - q_ref)) K^2:
               a MatMul per body, in tree order, the only sequential part
    origins    o = anc @ (R_p (pos - rot (Rod - I) anchor + rot axis (q - q_ref) [slide]))
    velocities w_j = w + anc @ (u qd [hinge]), dw_j = dw_B + anc @ (w_p x u qd [hinge])
    points     P_j the anchor (a slide: the origin), a_P = a_B + anc @ (dw_p x d + w_p x (w_p x d
               + 2 u qd [slide])), d = P - P_p; a_c = a_P + dw x (c - P) + w x (w x (c - P))
    wrenches   F = m a_c, N = c x F + I_w dw + w x I_w w, I_w = R I R' (about the trunk origin)
    h_i        u_i . (S_i F) [slide], u_i . (S_i N - A_i x S_i F) [hinge]; S_i the subtree of i
    M          J Y' + diag(armature), J = [J_v, J_w], Y = [m J_v, I_w J_w], (B, n, 6 b) each:
               J_v[i, k] = S_ik (u_i x (c_k - A_i) [hinge], u_i [slide]), J_w[i, k] = S_ik u_i
    servo      T = clip(targets), tau = clip(kp (T - q) - kv qd, +-limit) - damping qd - h
               - friction sign(qd) [|qd| > STICK_SPEED]; qdd_free = M^-1 tau
    held       (q <= q_min and qdd_free < 0) or (q >= q_max and qdd_free > 0) or
               (|qd| <= STICK_SPEED and |tau| <= friction): its row and column of M the
               identity's, its tau 0; qdd = M^-1 tau again
    u_model    = -[sum F, sum N - c x sum F] (N, N·m about the base's COM) at a_c + J_v qdd,
               dw + J_w qdd

Each solve is Gauss-Jordan elimination without pivoting, unrolled over the n columns (M is
symmetric positive definite, so no pivot is needed). A bound of +-inf is left out, or where
only some joints have one, is float32's largest number. The heading of R (`heading_turn`) is
(c, s) = (R_00, R_10) / sqrt(R_00^2 + R_10^2), no Atan2.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dpc_mjx.io.arm_dynamics import GRAVITY, STICK_SPEED, ArmModel

# graph input: (its shape after the batch axis, 'n' the arm's joints; words) (arm_dynamics')
MEASURED = {
    "targets": (("n",), "the arm servo targets this tick commands, rad (m), s_arm's order"),
    "rot": ((3, 3), "trunk -> world rotation"),
    "ang_vel": ((3,), "trunk angular velocity, rad/s, world"),
    "desired": ((6,), "the balance QP's desired COM (m/s^2, no g) and angular (rad/s^2) acc."),
    "com": ((3,), "the base's COM minus the trunk's origin, m, world"),
}
_BIG = float(np.finfo(np.float32).max)  # an infinite bound among finite ones
_NEXT, _PREV = (1, 2, 0), (2, 0, 1)  # a x b = a[_NEXT] b[_PREV] - a[_PREV] b[_NEXT]


class _Ops:
    """Shorthands over a graph builder (`const`, `op`); integer constants made once."""

    def __init__(self, graph: Any) -> None:
        self.g, self._ints = graph, {}

    def f(self, array, hint: str = "arm") -> str:
        """A float32 constant."""
        return self.g.const(hint, np.asarray(array, np.float32))

    def i(self, values) -> str:
        """An int64 constant (a scalar for an int), made once per value."""
        array = np.asarray(values, np.int64)
        key = (array.shape, tuple(array.ravel()))
        if key not in self._ints:
            self._ints[key] = self.g.const("index", array)
        return self._ints[key]

    def op(self, name: str, *xs: str, **attrs) -> str:
        return self.g.op(name, *xs, **attrs)

    def add(self, *xs: str) -> str:
        out = xs[0]
        for x in xs[1:]:
            out = self.op("Add", out, x)
        return out

    def sub(self, a: str, b: str) -> str:
        return self.op("Sub", a, b)

    def mul(self, a: str, b: str) -> str:
        return self.op("Mul", a, b)

    def mm(self, a: str, b: str) -> str:
        return self.op("MatMul", a, b)

    def take(self, x: str, index, axis: int) -> str:
        """Gather: x's entries `index` (an int drops the axis) along `axis`."""
        return self.op("Gather", x, self.i(index), axis=axis)

    def part(self, x: str, start: int, stop: int, axis: int) -> str:
        """x[start:stop] along `axis`."""
        return self.op("Slice", x, self.i([start]), self.i([stop]), self.i([axis]))

    def unsq(self, x: str, *axes: int) -> str:
        return self.op("Unsqueeze", x, self.i(list(axes)))

    def squeeze(self, x: str, axis: int) -> str:
        return self.op("Squeeze", x, self.i([axis]))

    def cat(self, axis: int, *xs: str) -> str:
        return self.op("Concat", *xs, axis=axis)

    def reshape(self, x: str, *shape: int) -> str:
        """Reshape; 0 keeps the axis (the batch), -1 the rest."""
        return self.op("Reshape", x, self.i(list(shape)))

    def cross(self, a: str, b: str) -> str:
        """a x b along the last axis (3), broadcast."""
        ab = self.mul(self.take(a, _NEXT, -1), self.take(b, _PREV, -1))
        return self.sub(ab, self.mul(self.take(a, _PREV, -1), self.take(b, _NEXT, -1)))

    def matvec(self, m: str, v: str) -> str:
        """m @ v, m (..., 3, 3), v (..., 3)."""
        return self.squeeze(self.mm(m, self.unsq(v, -1)), -1)


def _skew(v) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _constants(arm: ArmModel) -> dict[str, np.ndarray]:
    """The model's numbers as the nodes use them (float64; masks 0/1)."""
    kinds = np.array(arm.joint)
    hinge, slide = (kinds == "hinge") * 1.0, (kinds == "slide") * 1.0
    body_of = np.array([arm.qadr.index(k) for k in range(arm.n)])  # each joint's body
    skew = np.array([_skew(a) for a in arm.axis]) * hinge[:, None, None]
    skew2 = skew @ skew
    anchor = arm.anchor[:, :, None]
    return {
        "hinge": hinge,
        "slide": slide,
        "qadr": np.maximum(np.array(arm.qadr), 0),  # a weld's: any joint, masked
        "parent": np.array(arm.parent) + 1,  # 0 the trunk
        "body_of": body_of,
        "anc": arm.subtree.T,
        "subtree": arm.subtree[body_of],  # (n, b)
        "skew": skew,
        "skew2": skew2,
        "rk_a": (arm.rot @ skew @ anchor)[..., 0],  # (b, 3): rot K anchor
        "rk2_a": (arm.rot @ skew2 @ anchor)[..., 0],
        "slide_axis": (arm.rot @ arm.axis[:, :, None])[..., 0] * slide[:, None],
        "points": np.stack([arm.anchor, arm.com, arm.axis * (hinge + slide)[:, None]], -1),
        "mass": arm.mass,
        "inertia": arm.inertia,
        "armature": arm.armature,
    }


def _base(o: _Ops, x: dict[str, str]) -> tuple[str, str, str]:
    """(w, dw, a_B) (B, 1, 3) each: the trunk's rates and its origin's specific acceleration."""
    w, com = x["ang_vel"], x["com"]
    dw, a_c = o.part(x["desired"], 3, 6, 1), o.part(x["desired"], 0, 3, 1)
    a_b = o.sub(a_c, o.add(o.cross(dw, com), o.cross(w, o.cross(w, com))))
    a_b = o.add(a_b, o.f([0.0, 0.0, GRAVITY], "gravity"))
    return o.unsq(w, 1), o.unsq(dw, 1), o.unsq(a_b, 1)


def _frames(o: _Ops, arm: ArmModel, k: dict, rot: str, q: str) -> dict[str, str]:
    """Each body's rotation R and its parent's R_p (B, b, 3, 3), origin o, anchor A, COM c and
    world axis u (B, b, 3; u 0 where welded), from q (B, n) (the docstring's rotations, origins)."""
    angle = o.take(o.sub(q, o.f(arm.q_ref, "q_ref")), k["qadr"], 1)  # (B, b)
    sin, one_cos = o.op("Sin", angle), o.sub(o.f(1.0), o.op("Cos", angle))
    rod = o.add(
        o.f(np.eye(3)),
        o.mul(o.unsq(sin, 2, 3), o.f(k["skew"], "skew")),
        o.mul(o.unsq(one_cos, 2, 3), o.f(k["skew2"], "skew2")),
    )
    turn = o.mm(o.f(arm.rot, "rot"), rod)  # (B, b, 3, 3): rot_j Rod_j
    frames = [rot]
    for j, p in enumerate(k["parent"]):
        frames.append(o.mm(frames[p], o.take(turn, j, 1)))
    ext = o.cat(1, *(o.unsq(r, 1) for r in frames))  # (B, b + 1, 3, 3), 0 the trunk
    r, r_p = o.part(ext, 1, len(frames), 1), o.take(ext, k["parent"], 1)
    sin, one_cos, angle = (o.unsq(v, 2) for v in (sin, one_cos, angle))
    local = o.sub(o.f(arm.pos, "pos"), o.mul(sin, o.f(k["rk_a"], "rk_a")))
    local = o.sub(local, o.mul(one_cos, o.f(k["rk2_a"], "rk2_a")))
    local = o.add(local, o.mul(angle, o.f(k["slide_axis"], "slide_axis")))
    origin = o.mm(o.f(k["anc"], "anc"), o.matvec(r_p, local))  # (B, b, 3)
    points = o.mm(r, o.f(k["points"], "points"))  # (B, b, 3, 3): R [anchor, com, axis]
    anchor, com = (o.add(origin, o.take(points, i, 3)) for i in (0, 1))
    return {"R": r, "R_p": r_p, "o": origin, "A": anchor, "c": com, "u": o.take(points, 2, 3)}


def _motion(o: _Ops, k: dict, b: dict, base: tuple[str, str, str], qd: str) -> dict[str, str]:
    """b with each body's w, dw and its COM's specific acceleration a_c (B, b, 3) at qdd = 0
    (the docstring's velocities, points)."""
    w0, dw0, a0 = base
    anc, parent = o.f(k["anc"], "anc"), k["parent"]
    u_qd = o.mul(b["u"], o.unsq(o.take(qd, k["qadr"], 1), 2))  # (B, b, 3)
    spin = o.mul(u_qd, o.f(k["hinge"][:, None], "hinge"))
    slide = o.mul(u_qd, o.f(2.0 * k["slide"][:, None], "slide"))  # 2 u qd [slide]
    w = o.add(w0, o.mm(anc, spin))
    w_p = o.take(o.cat(1, w0, w), parent, 1)
    dw = o.add(dw0, o.mm(anc, o.cross(w_p, spin)))
    dw_p = o.take(o.cat(1, dw0, dw), parent, 1)
    point = o.add(b["A"], o.mul(o.f(k["slide"][:, None]), o.sub(b["o"], b["A"])))
    pads = o.i([0, 1, 0, 0, 0, 0])  # the trunk's point: its origin, 0
    d = o.sub(point, o.take(o.op("Pad", point, pads), parent, 1))
    t = o.add(o.cross(dw_p, d), o.cross(w_p, o.add(o.cross(w_p, d), slide)))
    a_p = o.add(a0, o.mm(anc, t))
    rc = o.sub(b["c"], point)
    a_c = o.add(a_p, o.cross(dw, rc), o.cross(w, o.cross(w, rc)))
    inertia = o.mm(
        o.mm(b["R"], o.f(k["inertia"], "inertia")), o.op("Transpose", b["R"], perm=[0, 1, 3, 2])
    )
    gyro = o.cross(w, o.matvec(inertia, w))
    return {**b, "w": w, "dw": dw, "a_c": a_c, "I": inertia, "gyro": gyro}


def _wrenches(o: _Ops, k: dict, b: dict, a_c: str, dw: str) -> tuple[str, str]:
    """(F, N) (B, b, 3): each body's m a_c (N) and its moment about the trunk's origin (N·m)."""
    force = o.mul(a_c, o.f(k["mass"][:, None], "mass"))
    torque = o.add(o.cross(b["c"], force), o.matvec(b["I"], dw), b["gyro"])
    return force, torque


def _joint_space(o: _Ops, k: dict, b: dict, n: int) -> tuple[str, str, str]:
    """(h (B, n) the bias torques at qdd = 0, M (B, n, n), J (B, n, 6 b) = [J_v, J_w] per body)."""
    force, torque = _wrenches(o, k, b, b["a_c"], b["dw"])
    sub = o.f(k["subtree"], "subtree")
    sub_f, sub_n = o.mm(sub, force), o.mm(sub, torque)  # (B, n, 3)
    anchor, axis = o.take(b["A"], k["body_of"], 1), o.take(b["u"], k["body_of"], 1)
    hinge, slide = (o.f(k[m][k["body_of"]][:, None], m) for m in ("hinge", "slide"))
    about = o.mul(hinge, o.sub(sub_n, o.cross(anchor, sub_f)))
    h = o.mm(o.mul(o.add(about, o.mul(slide, sub_f)), axis), o.f(np.ones(3)))
    beyond = k["subtree"][:, :, None]  # (n, b, 1)
    beyond_h, beyond_s = (
        o.f(beyond * k[m][k["body_of"]][:, None, None], m) for m in ("hinge", "slide")
    )
    axis = o.unsq(axis, 2)  # (B, n, 1, 3)
    lever = o.sub(o.unsq(b["c"], 1), o.unsq(anchor, 2))  # (B, n, b, 3): c_k - A_i
    jac_v = o.add(o.mul(beyond_h, o.cross(axis, lever)), o.mul(beyond_s, axis))
    jac_w = o.mul(beyond_h, axis)
    y_v = o.mul(jac_v, o.f(k["mass"][:, None], "mass"))
    y_w = o.squeeze(o.mm(o.unsq(jac_w, 3), o.unsq(b["I"], 1)), 3)  # (I_w J_w)' (I_w symmetric)
    jac, y = (o.reshape(o.cat(3, v, w), 0, n, -1) for v, w in ((jac_v, jac_w), (y_v, y_w)))
    mass = o.add(o.mm(jac, o.op("Transpose", y, perm=[0, 2, 1])), o.f(np.diag(k["armature"])))
    return h, mass, jac


def _solve(o: _Ops, mat: str, rhs: str, n: int) -> str:
    """x (B, n) with mat x = rhs: Gauss-Jordan elimination on [mat, rhs] (B, n, n + 1), no
    pivoting (mat symmetric positive definite); row k: row k / pivot, the others less their
    column k times it."""
    aug = o.cat(2, mat, o.unsq(rhs, 2))
    for j in range(n):
        row = o.part(aug, j, j + 1, 1)  # (B, 1, n + 1)
        row = o.op("Div", row, o.part(row, j, j + 1, 2))
        col = o.sub(o.part(aug, j, j + 1, 2), o.f(np.eye(n)[:, j : j + 1], "unit"))
        aug = o.sub(aug, o.mul(col, row))
    return o.squeeze(o.part(aug, n, n + 1, 2), 2)


def _bounded(o: _Ops, x: str, low: np.ndarray, high: np.ndarray, hint: str) -> str:
    """clip(x, low, high) per joint, an infinite bound left out (float32's largest where only
    some joints have one)."""
    if np.isfinite(low).any():
        x = o.op("Max", x, o.f(np.maximum(low, -_BIG), f"{hint}_min"))
    if np.isfinite(high).any():
        x = o.op("Min", x, o.f(np.minimum(high, _BIG), f"{hint}_max"))
    return x


def _servo_qdd(o: _Ops, arm: ArmModel, h: str, mass: str, q: str, qd: str, targets: str) -> str:
    """qdd (B, n): the servo law, the free solve, the held joints, the second solve."""
    n = arm.n
    target = _bounded(o, targets, arm.target_min, arm.target_max, "target")
    servo = o.sub(o.mul(o.f(arm.kp, "kp"), o.sub(target, q)), o.mul(o.f(arm.kv, "kv"), qd))
    servo = _bounded(o, servo, -arm.limit, arm.limit, "limit")
    moving = o.op("Greater", o.op("Abs", qd), o.f(STICK_SPEED, "stick_speed"))
    friction = o.f(arm.friction, "friction")
    dry = o.op("Where", moving, o.mul(friction, o.op("Sign", qd)), o.f(0.0))
    tau = o.sub(o.sub(servo, o.mul(o.f(arm.damping, "damping"), qd)), o.add(h, dry))
    free = _solve(o, mass, tau, n)
    zero = o.f(0.0)
    held = o.op("And", o.op("Not", moving), o.op("LessOrEqual", o.op("Abs", tau), friction))
    for bound, side, push in (
        (arm.q_min, "LessOrEqual", "Less"),
        (arm.q_max, "GreaterOrEqual", "Greater"),
    ):
        if np.isfinite(bound).any():
            limit = o.f(np.clip(bound, -_BIG, _BIG), "q_bound")
            pushed = o.op("And", o.op(side, q, limit), o.op(push, free, zero))
            held = o.op("Or", held, pushed)
    rows = o.op("Or", o.unsq(held, 2), o.unsq(held, 1))  # (B, n, n)
    mass = o.op("Where", rows, o.f(np.eye(n)), mass)
    return _solve(o, mass, o.op("Where", held, zero, tau), n)


def model_wrench(graph: Any, arm: ArmModel, q: str, qd: str, inputs: dict[str, str]) -> str:
    """u_model (B, 6), world frame: [f (N), tau (N·m) about the base's COM], the arms' model
    wrench on the base (the docstring's), from q, qd (B, n) and `inputs` {MEASURED key: tensor
    name} in `graph` (`onnx_graph._Graph`)."""
    o = _Ops(graph)
    k = _constants(arm)
    base = _base(o, inputs)
    body = _motion(o, k, _frames(o, arm, k, inputs["rot"], q), base, qd)
    h, mass, jac = _joint_space(o, k, body, arm.n)
    qdd = _servo_qdd(o, arm, h, mass, q, qd, inputs["targets"])
    extra = o.reshape(o.mm(o.unsq(qdd, 1), jac), 0, len(arm.parent), 6)  # (B, b, 6): J qdd
    a_c = o.add(body["a_c"], o.part(extra, 0, 3, 2))
    dw = o.add(body["dw"], o.part(extra, 3, 6, 2))
    force, torque = _wrenches(o, k, body, a_c, dw)
    ones = o.f(np.ones(len(arm.parent)))
    f, tau = o.mm(ones, force), o.mm(ones, torque)  # (B, 3): sums over the bodies
    return o.cat(1, o.op("Neg", f), o.sub(o.cross(inputs["com"], f), tau))


def heading_turn(graph: Any, rot: str, u: str, to_world: bool) -> str:
    """u (B, 6) = [f, tau] turned about z by the heading of `rot` (B, 3, 3) (`to_world`: from
    the yaw frame to the world, R_z(yaw) per vector; else R_z(-yaw)); cos and sin of the heading
    (R_00, R_10) / sqrt(R_00^2 + R_10^2)."""
    o = _Ops(graph)
    first = o.part(o.part(rot, 0, 2, 1), 0, 1, 2)  # (B, 2, 1): R_00, R_10
    norm = o.op("Sqrt", o.op("ReduceSum", o.mul(first, first), o.i([1]), keepdims=1))
    cs = o.op("Div", first, norm)
    cos, sin = o.part(cs, 0, 1, 1), o.part(cs, 1, 2, 1)  # (B, 1, 1)
    turn = o.add(  # R_z(yaw) (B, 3, 3)
        o.mul(cos, o.f(np.diag([1.0, 1.0, 0.0]))),
        o.mul(sin, o.f([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])),
        o.f(np.diag([0.0, 0.0, 1.0])),
    )
    turn = o.op("Transpose", turn, perm=[0, 2, 1]) if to_world else turn  # rows: v' R_z(yaw)'
    return o.reshape(o.mm(o.reshape(u, 0, 2, 3), turn), 0, 6)


__all__ = ["MEASURED", "heading_turn", "model_wrench"]
