"""The balance QP of the whole-body controller (paper eqs. 5-10, corrected), apart from its solver.

Frames and units: every vector is in the world frame (z up, m, m/s, rad/s, N, N·m) unless named
otherwise; `rot` matrices map body-frame vectors to the world frame.

Rigid-body model of the trunk (a single rigid body of mass m and body-frame inertia I_B about its
COM), eq. 5 with the sign convention written once here::

    qdd = M f + A f_a + B tau_a - g~          qdd = (COM linear acc (3), world angular acc (3))
    M   = [ I3/m      ...  I3/m      ]        (6, 12); f = (f_FR, f_FL, f_RR, f_RL), the forces
          [ I_w^-1 [r_1]x ... [r_4]x ]                 the ground exerts on the feet (N)
    A   = [I3/m; 0],  B = [0; I_w^-1]         f_a, tau_a: force and torque about the COM applied by
    g~  = (0, 0, g, 0, 0, 0), g = 9.81 > 0             the arm / payload (world frame)

`r_i` is foot i minus the COM. The world inertia I_w = R I_B R^T is replaced by the yaw-only
approximation I_w ~ R_z I_B R_z^T (Di Carlo et al. 2018), R_z the yaw part of R: exact for a level
trunk, and the paper's `R_z^T I_B^-1` rows are this approximation written in the yaw frame. The
gyroscopic term w x I w is neglected, as in the paper.

Desired acceleration (eq. 9), gains diagonal per axis::

    qdd_d = Kp * (q_d - q) + Kd * (qd_d - qd)
    pose error = (com_pos_des - com_pos, log(R_des R^T))   rotation vector in the world frame (rad)
    vel error  = (com_vel_des - com_vel, ang_vel_des - ang_vel)

Cost (eq. 10) and its QP form (the QP objective is half the paper's cost, same minimiser)::

    J(f) = || M f - b ||_Q^2 + || f ||_R^2,     b = qdd_d + g~ - A f_a - B tau_a
    1/2 f' P f + q' f + const = J(f) / 2,       P = M' Q M + R,  q = -M' Q b,  const = b' Q b / 2

Constraints (6 rows per foot, fixed size 24 for every env; `G f <= h`), for a stance foot::

    f_min <= f_z <= f_max,   |f_x| <= mu f_z,   |f_y| <= mu f_z      (the friction pyramid)

The paper's printed pyramid inequality is misprinted; this is the standard one. A swing foot
must carry no force. Its columns of M are zeroed, so its only cost is R |f_i|^2, and its rows become
the symmetric box |f_x|, |f_y|, |f_z| <= f_max: then f_i = 0 is the exact optimum, the stance
solution is exactly that of the stance-only problem, and the feasible set keeps an interior. (Tight
bounds 0 <= f_z <= 0, |f_x|, |f_y| <= 0 give the same optimum but an empty interior, on which an
interior-point method converges more slowly and with exploding duals; the solver still handles
them, see tests.) `solve_balance` also multiplies the forces by the contact mask.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

from dpc_mjx.control import qp
from dpc_mjx.errors import DpcError
from dpc_mjx.rotations import matrix_from_rotvec_np, rotvec_from_matrix, skew, yaw_rotation

GRAVITY = 9.81  # m/s^2
N_FEET = 4
ROWS_PER_FOOT = 6
N_VARS = 3 * N_FEET  # 12
N_ROWS = ROWS_PER_FOOT * N_FEET  # 24


@struct.dataclass
class BalanceParams:
    """Configuration of the balance QP. All fields are arrays (jit/vmap friendly).

    Fields (shapes, units):
      mass: ()            kg, whole robot including the arm.
      inertia: (3, 3)     kg m^2, body-frame inertia about the COM.
      mu: ()              friction coefficient of the pyramid.
      f_min, f_max: ()    N, bounds of a stance foot's normal force.
      kp: (6,)            1/s^2, pose gains (x, y, z, roll, pitch, yaw) of eq. 9.
      kd: (6,)            1/s, velocity gains.
      Q: (6,)             weights of the acceleration error (linear m/s^2, angular rad/s^2).
      R: (12,)            weights of the forces, (m/s^2 / N)^2.
    """

    mass: jax.Array
    inertia: jax.Array
    mu: jax.Array
    f_min: jax.Array
    f_max: jax.Array
    kp: jax.Array
    kd: jax.Array
    Q: jax.Array
    R: jax.Array


DEFAULTS: dict[str, float | tuple[float, ...]] = dict(
    mass=13.5,  # kg: A1 12.5 kg + ~1 kg arm
    inertia=(0.07, 0.26, 0.24),  # kg m^2, whole-body diagonal about the COM
    mu=0.6,
    f_min=5.0,  # N
    f_max=180.0,  # N, ~1.4 x the weight on one foot
    kp=(50.0, 50.0, 100.0, 300.0, 300.0, 100.0),  # 1/s^2: x, y, z, roll, pitch, yaw
    kd=(10.0, 10.0, 20.0, 30.0, 30.0, 20.0),  # 1/s (damping ratios 0.7 .. 1)
    Q=(1.0, 1.0, 1.0, 10.0, 10.0, 1.0),
    R=1e-4,  # (m/s^2 / N)^2, scalar or (12,)
)


def default_params(**overrides: float | tuple[float, ...] | jax.Array) -> BalanceParams:
    """BalanceParams from DEFAULTS (an A1 with a ~1 kg arm), with fields overridden by name.

    `inertia` may be a diagonal (3,) or a matrix (3, 3); `R` a scalar or (12,).
    R = 1e-4 regularises the forces (it spreads them, and makes P positive definite): it lowers
    the support force by the factor 1 / (1 + R m^2 / (n_stance Q_z)), 0.5 % on four feet, 0.9 % on
    two, i.e. a steady sag of < 1 mm with kp_z = 100.
    """
    unknown = set(overrides) - set(DEFAULTS)
    if unknown:
        raise DpcError(f"Unknown balance parameter(s) {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    v = {**DEFAULTS, **overrides}
    inertia = jp.asarray(v["inertia"], jp.float32)
    return BalanceParams(
        mass=jp.asarray(v["mass"], jp.float32),
        inertia=jp.diag(inertia) if inertia.ndim == 1 else inertia,
        mu=jp.asarray(v["mu"], jp.float32),
        f_min=jp.asarray(v["f_min"], jp.float32),
        f_max=jp.asarray(v["f_max"], jp.float32),
        kp=jp.asarray(v["kp"], jp.float32),
        kd=jp.asarray(v["kd"], jp.float32),
        Q=jp.asarray(v["Q"], jp.float32),
        R=jp.broadcast_to(jp.asarray(v["R"], jp.float32), (N_VARS,)),
    )


@struct.dataclass
class BalanceQP:
    """The balance QP `min 1/2 f'Pf + q'f + const  s.t.  G f <= h` and the model behind it.

    P: (12, 12), q: (12,), G: (24, 12), h: (24,), const: () (so the objective equals J/2).
    M: (6, 12) and b: (6,) of the cost || M f - b ||_Q^2; qdd_des: (6,) the eq. 9 acceleration.
    contact: (4,) bool, the stance mask the QP was built for (solve_balance zeroes swing forces).
    """

    P: jax.Array
    q: jax.Array
    G: jax.Array
    h: jax.Array
    const: jax.Array
    M: jax.Array
    b: jax.Array
    qdd_des: jax.Array
    contact: jax.Array


def friction_constraints(
    mu: jax.Array, f_min: jax.Array, f_max: jax.Array, contact: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """G (24, 12), h (24,) of the friction pyramids (stance) and the swing boxes.

    Rows of a stance foot i (variables f_i = (fx, fy, fz)):  fz <= f_max,  -fz <= -f_min,
    fx - mu fz <= 0,  -fx - mu fz <= 0,  fy - mu fz <= 0,  -fy - mu fz <= 0.
    A swing foot gets the symmetric box |fx|, |fy|, |fz| <= f_max instead (mu -> 0 in the rows).
    With its columns of M zeroed its only cost is R |f_i|^2, so f_i = 0 exactly at the optimum,
    and, unlike tight bounds 0 <= fz <= 0, the box leaves the feasible set an interior (see the
    module doc).
    """
    c = contact.astype(mu.dtype)  # (4,)
    one, zero = jp.ones_like(c), jp.zeros_like(c)
    mu_i = mu * c  # (4,)
    rows = [  # each (4, 3): the row of foot i acting on (fx, fy, fz)
        jp.stack([zero, zero, one], -1),
        jp.stack([zero, zero, -one], -1),
        jp.stack([one, zero, -mu_i], -1),
        jp.stack([-one, zero, -mu_i], -1),
        jp.stack([zero, one, -mu_i], -1),
        jp.stack([zero, -one, -mu_i], -1),
    ]
    block = jp.stack(rows, axis=1)  # (4, 6, 3)
    eye = jp.eye(N_FEET, dtype=mu.dtype)
    G = (eye[:, None, :, None] * block[:, :, None, :]).reshape(N_ROWS, N_VARS)  # block diagonal
    swing_box = f_max * (1.0 - c)
    h = jp.stack([f_max * one, -f_min * c + swing_box] + [swing_box] * 4, axis=-1)  # (4, 6)
    return G, h.reshape(N_ROWS)


def _g_pattern() -> np.ndarray:
    """(24, 12) bool: the entries of friction_constraints' G that can be nonzero."""
    rows = np.array([[0, 0, 1], [0, 0, 1], [1, 0, 1], [1, 0, 1], [0, 1, 1], [0, 1, 1]], bool)
    return np.kron(np.eye(N_FEET, dtype=bool), rows)


G_PATTERN = _g_pattern()  # for qp.solve(..., g_pattern=G_PATTERN): 40 of G's 288 entries


def wrench_matrix(
    params: BalanceParams, com_pos: jax.Array, rot: jax.Array, foot_pos: jax.Array, contact
) -> tuple[jax.Array, jax.Array]:
    """M (6, 12) of eq. 5, rows (COM linear acc, world angular acc) per N of the stance feet's
    forces (swing feet's columns zeroed), and I_w^-1 (3, 3), the yaw-frame approximation
    R_z I_B^-1 R_z^T (1/(kg m^2), world). `com_pos` (3,) m, `rot` (3, 3) body -> world (only
    its yaw is read), `foot_pos` (4, 3) m where the forces act, `contact` (4,) bool."""
    dtype = jp.float32
    rz = yaw_rotation(rot)
    inertia_w_inv = rz @ jp.linalg.inv(params.inertia) @ rz.T  # (3, 3) yaw-frame approximation
    r = foot_pos - com_pos  # (4, 3) lever arms
    c = contact.astype(dtype)
    lin = jp.tile(jp.eye(3, dtype=dtype) / params.mass, (1, N_FEET))  # (3, 12)
    ang = jp.concatenate([inertia_w_inv @ skew(r[i]) for i in range(N_FEET)], axis=1)  # (3, 12)
    M = jp.concatenate([lin, ang], axis=0) * jp.repeat(c, 3)[None, :]  # swing columns zeroed
    return M, inertia_w_inv


def desired_acceleration(params: BalanceParams, state: tuple, desired: tuple) -> jax.Array:
    """(6,) qdd_d = Kp (q_d - q) + Kd (qd_d - qd) (eq. 9): the COM's acceleration (m/s^2) and
    the trunk's angular acceleration (rad/s^2) the QP asks for, world frame. `state` and
    `desired`: (COM position (3,) m, COM velocity (3,) m/s, trunk rotation (3, 3) body -> world,
    angular velocity (3,) rad/s), as measured and as the plan asks."""
    (com_pos, com_vel, rot, ang_vel), (pos_des, vel_des, rot_des, ang_vel_des) = state, desired
    pose_err = jp.concatenate([pos_des - com_pos, rotvec_from_matrix(rot_des @ rot.T)])
    vel_err = jp.concatenate([vel_des - com_vel, ang_vel_des - ang_vel])
    return params.kp * pose_err + params.kd * vel_err


def build_balance_qp(  # noqa: PLR0913, PLR0917 (state, desired state, contacts, disturbance)
    params: BalanceParams,
    com_pos: jax.Array,
    com_vel: jax.Array,
    rot: jax.Array,
    ang_vel: jax.Array,
    com_pos_des: jax.Array,
    com_vel_des: jax.Array,
    rot_des: jax.Array,
    ang_vel_des: jax.Array,
    foot_pos: jax.Array,
    contact: jax.Array,
    f_a: jax.Array,
    tau_a: jax.Array,
    qdd_des: jax.Array | None = None,
) -> BalanceQP:
    """The balance QP of one env (unbatched; vmap it). World frame throughout.

    Args:
      params: the configuration (see BalanceParams).
      com_pos: (3,) COM position (m).
      com_vel: (3,) COM velocity (m/s).
      rot: (3, 3) trunk orientation, body -> world.
      ang_vel: (3,) world angular velocity (rad/s).
      com_pos_des: (3,) the desired COM position (m).
      com_vel_des: (3,) the desired COM velocity (m/s).
      rot_des: (3, 3) the desired trunk orientation.
      ang_vel_des: (3,) the desired world angular velocity (rad/s).
      foot_pos: (4, 3) foot positions (m), order FR, FL, RR, RL.
      contact: (4,) bool, True for a stance foot.
      f_a: (3,) force (N) and tau_a: (3,) torque about the COM (N·m) applied to the trunk by the
        arm / payload.
      qdd_des: (6,) the acceleration to ask for (m/s^2, rad/s^2) in place of eq. 9's from the
        desired state (None), e.g. the one an MPC's planned forces give (`control/mpc.py`).
    """
    M, inertia_w_inv = wrench_matrix(params, com_pos, rot, foot_pos, contact)
    if qdd_des is None:
        state = (com_pos, com_vel, rot, ang_vel)
        qdd_des = desired_acceleration(
            params, state, (com_pos_des, com_vel_des, rot_des, ang_vel_des)
        )
    g_tilde = jp.array([0.0, 0.0, GRAVITY, 0.0, 0.0, 0.0], jp.float32)
    wrench_a = jp.concatenate([f_a / params.mass, inertia_w_inv @ tau_a])  # A f_a + B tau_a
    b = qdd_des + g_tilde - wrench_a  # (6,)

    MtQ = M.T * params.Q[None, :]  # (12, 6)
    P = MtQ @ M + jp.diag(params.R)
    P = 0.5 * (P + P.T)
    q = -MtQ @ b
    const = 0.5 * jp.sum(params.Q * b * b)
    G, h = friction_constraints(params.mu, params.f_min, params.f_max, contact)
    return BalanceQP(P=P, q=q, G=G, h=h, const=const, M=M, b=b, qdd_des=qdd_des, contact=contact)


def solve_balance(
    *args: Any,
    warm_start: qp.QPResult | None = None,
    settings: qp.QPSettings | None = None,
    **kwargs: Any,
) -> tuple[jax.Array, qp.QPResult]:
    """Build and solve the balance QP: foot forces (4, 3) (N, world; swing feet exactly 0).

    `args` and `kwargs` are `build_balance_qp`'s (params, state, desired state, contact, f_a,
    tau_a); `warm_start` and `settings` are `qp.solve`'s. Returns the forces and the QPResult.
    """
    prob = build_balance_qp(*args, **kwargs)
    res = qp.solve(
        prob.P,
        prob.q,
        prob.G,
        prob.h,
        warm_start=warm_start,
        settings=settings,
        g_pattern=G_PATTERN,
    )
    forces = res.x.reshape(N_FEET, 3) * prob.contact.astype(res.x.dtype)[:, None]
    return forces, res


STAND_HEIGHT = 0.27  # m, COM height of the A1 standing
STANCE_PATTERNS = np.array(
    [[1, 1, 1, 1], [1, 0, 0, 1], [0, 1, 1, 0]], dtype=bool
)  # stand, trot pair FR+RL, trot pair FL+RR (order FR, FL, RR, RL)


def sample_states(
    rng: np.random.Generator,
    n: int,
    max_rot_err: float = 0.3,
    max_f_a: float = 50.0,
    max_tau_a: float = 15.0,
) -> dict[str, jax.Array]:
    """Random realistic inputs of `build_balance_qp` for n envs (for tests and benchmarks).

    A1-like stance: feet near (+-0.18, +-0.13) m around the COM (3 cm noise) on the ground, COM at
    STAND_HEIGHT (2 cm noise), any heading; orientation error up to `max_rot_err` rad about a random
    axis; velocity errors ~0.3 m/s and ~1 rad/s; contact pattern stand or trot (diagonal pairs);
    arm force |f_a| <= max_f_a N and torque |tau_a| <= max_tau_a N·m in random directions.
    Returns a dict keyed by the argument names, arrays with a leading axis n.
    """
    nominal_feet = np.array([[0.18, -0.13], [0.18, 0.13], [-0.18, -0.13], [-0.18, 0.13]])
    out: dict[str, list] = {k: [] for k in _STATE_KEYS}

    def rand_dir(scale: float) -> np.ndarray:
        v = rng.normal(size=3)
        return v / np.linalg.norm(v) * rng.uniform(0.0, scale)

    for _ in range(n):
        yaw = rng.uniform(-np.pi, np.pi)
        heading = matrix_from_rotvec_np(np.array([0.0, 0.0, yaw]))  # (3, 3) about world z
        rot_des = heading @ matrix_from_rotvec_np(rand_dir(0.1))
        rot = matrix_from_rotvec_np(rand_dir(max_rot_err)) @ rot_des
        com = np.array([0.0, 0.0, STAND_HEIGHT]) + rng.normal(size=3) * 0.02
        feet_xy = (nominal_feet + rng.normal(size=(4, 2)) * 0.03) @ heading[:2, :2].T
        feet = np.concatenate([feet_xy + com[:2], np.zeros((4, 1))], axis=1)
        values = dict(
            com_pos=com,
            com_vel=rng.normal(size=3) * 0.3,
            rot=rot,
            ang_vel=rng.normal(size=3) * 1.0,
            com_pos_des=np.array([0.0, 0.0, STAND_HEIGHT]) + rng.normal(size=3) * 0.03,
            com_vel_des=rng.normal(size=3) * 0.3,
            rot_des=rot_des,
            ang_vel_des=rng.normal(size=3) * 0.3,
            foot_pos=feet,
            contact=STANCE_PATTERNS[rng.integers(len(STANCE_PATTERNS))],
            f_a=rand_dir(max_f_a),
            tau_a=rand_dir(max_tau_a),
        )
        for k, v in values.items():
            out[k].append(v)
    return {
        k: jp.asarray(np.array(v), bool if k == "contact" else jp.float32) for k, v in out.items()
    }


_STATE_KEYS = (
    "com_pos",
    "com_vel",
    "rot",
    "ang_vel",
    "com_pos_des",
    "com_vel_des",
    "rot_des",
    "ang_vel_des",
    "foot_pos",
    "contact",
    "f_a",
    "tau_a",
)
