"""The convex MPC (Di Carlo et al., IROS 2018): ground forces planned over a horizon, a sibling of
the one-tick balance QP (`balance.py`) whose model, friction pyramids and force bounds it shares.

Frames and units: world frame (z up; m, m/s, rad, rad/s, N, N·m) unless named otherwise.

State (12,) and its model, the single rigid body of the balance QP linearised about the yaw::

    x = (Theta (3) roll, pitch, yaw (rad); p (3) COM position; omega (3) world angular velocity;
         v (3) COM velocity)
    Theta' = R_z(psi)^T omega          (small roll and pitch)
    p'     = v
    omega' = I_w^-1 (sum_i r_i x f_i + tau_a)   I_w^-1 = R_z I_B^-1 R_z^T (`balance.wrench_matrix`)
    v'     = (sum_i f_i + f_a) / m + (0, 0, -g)

i.e. x' = A_c x + B_c f + D_c w + g_c, with f (12,) the stance feet's forces (FR, FL, RR, RL) and
w = (f_a, tau_a) (6,) the arms' wrench about the base's COM (the balance QP's u). A_c^2 = 0, so the
zero-order hold over a step of `dt` is exact and cheap::

    x_{k+1} = A_k x_k + B_k f_k + D_k w_k + g_k,   A_k = I + A_c dt,
    (B_k, D_k, g_k) = (dt I + A_c dt^2 / 2) (B_c, D_c, g_c)

Along the horizon (k = 0 .. N-1, t_k = k dt from now): psi_k the desired yaw, the lever arms r_i
from the desired COM p_ref,k to foot i (where it stands now if it stays in stance through step k,
else below its hip moved by the desired velocity, `levers`), the stance mask c_k from the gait at
t_k (`gait.contact_schedule`). A swing foot's columns of B_k are zero and its forces are boxed by
+-f_max, as in the balance QP (the optimum is then exactly f = 0, and the shapes never change).

Cost and its condensed QP (forces only, F = (f_0 .. f_{N-1}) (12 N,); X = (x_1 .. x_N))::

    J(F) = sum_{k=1..N} ||x_k - x_ref,k||_Q^2 + sum_{k=0..N-1} ||f_k||_R^2
    X = Gamma F + X_free     (`condense`: Gamma (12 N, 12 N) lower block-triangular)
    1/2 F'PF + q'F + const = J / 2,   P = Gamma' Q Gamma + R,  q = Gamma' Q (X_free - X_ref)

Constraints: per step the balance QP's 24 rows (`balance.friction_constraints`), G block-diagonal
(24 N, 12 N), passed to `qp.solve` as its static pattern and its 40 N entries. Solved by our
interior point with a fixed number of iterations from a cold start (warm from the plan 20 ms
old, 10 iterations ended up to 160 N from the optimum on pushed trots: docs/results-mpc.md), each
Newton system by a Riccati recursion over the model's steps (`mpc_kkt`), which also gives P x:
P (12 N, 12 N) is never formed (`MPCQP.P` forms it for a reference solver).

Numbers (`MPCConfig`): N = 10 steps of dt = 30 ms (a 0.3 s horizon: one trot period), re-solved
every 5 control ticks of 4 ms (20 ms: the first tick of every 50 Hz env step). Between re-solves
the balance QP tracks the plan (`tracked_acceleration`): it asks, at every tick, for the body
acceleration that the plan's forces of the current step give with this tick's lever arms and the
plan's wrench, so the QP reproduces the plan's forces while the feet and u are as planned, and
moves the forces where the present u or contacts differ from the plan's; plus eq. 9's feedback
toward the state the plan predicts for the tick (`MPCPlan.states`): it acts on what happened
since the solve, e.g. a push (docs/results-mpc.md).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

from dpc_mjx.control import balance, gait, mpc_kkt, qp
from dpc_mjx.control.state import BodyState
from dpc_mjx.errors import DpcError
from dpc_mjx.rotations import rot_z

N_STATE = 12  # (Theta, p, omega, v)
N_WRENCH = 6  # (f_a, tau_a)


@struct.dataclass
class MPCConfig:
    """The MPC's numbers (module doc). Q (12,): weights of the state error per step, in the
    state's order and units (1/rad^2, 1/m^2, s^2/rad^2, s^2/m^2); R () 1/N^2: weight of each
    force component, for a base of the A1's mass (`make_controller` divides it by the squared
    mass ratio, as the balance QP's R). Di Carlo et al.'s weights (MIT's open-source convex
    MPC: Theta 0.25, 0.25, 10; p 2, 2, 50; omega 0, 0, 0.3; v 0.2, 0.2, 0.1; R 4e-5) let the
    A1 with an arm roll over while standing (3 of 4 envs within 2 s, MBC, native): with them
    roll and pitch matter less than the COM's place. Here roll and pitch weigh most, as in the
    balance QP's gains, and decay at about sqrt(Q_theta / Q_omega) = 10 rad/s when forces are
    cheap (R 10x lower). Half these roll and pitch weights let 3 of 16 envs fall standing for
    10 s; these, 0 of 16, standing and trotting, on the A1 with and without the `regular` arm
    (tests/test_mpc.py holds the check on every named base)."""

    Q: jax.Array = struct.field(
        default_factory=lambda: jp.array(
            [100.0, 100.0, 10.0, 10.0, 10.0, 50.0, 1.0, 1.0, 0.3, 1.0, 1.0, 1.0], jp.float32
        )
    )
    R: float = 4e-6  # 1/N^2
    dt: float = 0.03  # s, one step of the horizon
    steps: int = struct.field(pytree_node=False, default=10)  # N
    every: int = struct.field(pytree_node=False, default=5)  # control ticks between re-solves
    iterations: int = struct.field(pytree_node=False, default=10)  # interior-point iterations

    @property
    def n_vars(self) -> int:
        return self.steps * 3 * balance.N_FEET

    @property
    def n_rows(self) -> int:
        return self.steps * balance.N_ROWS


@struct.dataclass
class MPCPlan:
    """The last solve, carried in `ControllerState.mpc` (fixed shapes, N = steps).

    forces: (N, 4, 3) N, world, the planned forces of each step (swing feet 0).
    wrench: (N, 6) the arms' wrench w_k the plan was made for (N, N·m; world, about the COM).
    states: (N + 1, 12) the states x_0 .. x_N the plan predicts (x_0 the state at the solve;
      `state_vector`'s order), which the balance QP tracks between solves.
    t0: () s, controller time of the solve.  qp: its QPResult (`valid`: whether it holds).
    """

    forces: jax.Array
    wrench: jax.Array
    states: jax.Array
    t0: jax.Array
    qp: qp.QPResult

    @classmethod
    def zeros(cls, config: MPCConfig) -> MPCPlan:
        """No plan yet (`qp.valid` False): the first tick solves."""
        n = config.steps
        return cls(
            forces=jp.zeros((n, balance.N_FEET, 3)),
            wrench=jp.zeros((n, N_WRENCH)),
            states=jp.zeros((n + 1, N_STATE)),
            t0=jp.zeros(()),
            qp=qp.QPResult.zeros(config.n_vars, config.n_rows),
        )


@struct.dataclass
class MPCQP:
    """The condensed QP `min 1/2 F'PF + q'F + const  s.t.  G F <= h` and its model.

    q (n,), h (m,), const (): n = 12 N, m = 24 N. g_blocks (N, 24, 12): the diagonal blocks of
    G (m, n) (`G`, `g_entries`). x0 (12,) the state now; gamma (12 N, 12 N) and x_free (12 N,):
    X = (x_1 .. x_N) = gamma F + x_free.
    contact (N, 4) bool: the stance schedule. A (N, 12, 12), B (N, 12, 12): the model's steps
    (`step_model`), from which `mpc_kkt` solves the interior point's Newton systems and forms
    P x; Q (12,), R (): the weights (`MPCConfig`) of P = gamma' diag(Q tiled) gamma + R I (`P`,
    formed only for a reference solver). (Any leading batch axes before these shapes.)
    """

    q: jax.Array
    g_blocks: jax.Array
    h: jax.Array
    const: jax.Array
    gamma: jax.Array
    x0: jax.Array
    x_free: jax.Array
    contact: jax.Array
    A: jax.Array
    B: jax.Array
    Q: jax.Array
    R: jax.Array

    @property
    def P(self) -> jax.Array:
        """(n, n) P = gamma' diag(Q tiled) gamma + R I (for a reference solver; `solve_mpc`
        never forms it)."""
        n = self.gamma.shape[-1]
        q_diag = jp.tile(self.Q, n // N_STATE)  # (..., 12 N)
        P = jp.swapaxes(self.gamma, -1, -2) @ (q_diag[..., None] * self.gamma)
        return P + self.R[..., None, None] * jp.eye(n, dtype=P.dtype)

    @property
    def G(self) -> jax.Array:
        """(m, n) G, block-diagonal (for a reference solver; `solve_mpc` reads `g_entries`)."""
        n, rows, cols = self.g_blocks.shape[-3:]
        eye = jp.eye(n, dtype=self.g_blocks.dtype)
        G = jp.einsum("kl,...kij->...kilj", eye, self.g_blocks)
        return G.reshape(self.g_blocks.shape[:-3] + (n * rows, n * cols))

    @property
    def g_entries(self) -> jax.Array:
        """(K,) the entries of G's pattern (`g_pattern`), row-major: each block's in turn."""
        blocks = self.g_blocks.reshape(self.g_blocks.shape[:-2] + (-1,))
        entries = blocks[..., np.flatnonzero(balance.G_PATTERN)]  # (..., N, 40)
        return entries.reshape(entries.shape[:-2] + (-1,))


def step_model(params: balance.BalanceParams, dt: float, yaw, com, feet, contact):
    """(A (12, 12), B (12, 12), D (12, 6), g (12,)) of one step (exact zero-order hold, module
    doc) for the desired yaw () rad, the COM (3,) m, the feet (4, 3) m and stance (4,) bool."""
    rz = rot_z(yaw)
    M, inertia_w_inv = balance.wrench_matrix(params, com, rz, feet, contact)  # (6, 12)
    z3 = jp.zeros((3, 3))
    a_c = jp.zeros((N_STATE, N_STATE))
    a_c = a_c.at[0:3, 6:9].set(rz.T).at[3:6, 9:12].set(jp.eye(3))  # Theta' = R_z'w, p' = v
    b_c = jp.concatenate([jp.zeros((6, 12)), M[3:], M[:3]])  # rows omega', v'
    d_c = jp.block([[z3, z3], [z3, z3], [z3, inertia_w_inv], [jp.eye(3) / params.mass, z3]])
    g_c = jp.zeros(N_STATE).at[11].set(-balance.GRAVITY)
    hold = dt * jp.eye(N_STATE) + 0.5 * dt * dt * a_c  # int_0^dt exp(A_c s) ds (A_c^2 = 0)
    return jp.eye(N_STATE) + dt * a_c, hold @ b_c, hold @ d_c, hold @ g_c


def condense(A: jax.Array, B: jax.Array, e: jax.Array, x0: jax.Array):
    """(gamma (12 N, n_f N), x_free (12 N,)) with X = (x_1 .. x_N) = gamma F + x_free for the
    model x_{k+1} = A_k x_k + B_k f_k + e_k: A (N, 12, 12), B (N, 12, n_f), e (N, 12), x0 (12,).
    Block (k, j) of gamma is A_k .. A_{j+1} B_j for j <= k, else 0."""
    n, nx, nf = B.shape
    rows, free = [], []
    row, x = jp.zeros((nx, n * nf)), x0
    for k in range(n):
        row = (A[k] @ row).at[:, k * nf : (k + 1) * nf].set(B[k])
        x = A[k] @ x + e[k]
        rows.append(row)
        free.append(x)
    return jp.concatenate(rows), jp.concatenate(free)


def levers(config: MPCConfig, stance, foot_pos, hip_pos, vel_des):
    """(N, 4, 3) m, where each foot pushes at step k: where it stands now (`foot_pos` (4, 3),
    contact points) while it stays in stance from now through step k (`stance` (N, 4) bool),
    else below its hip (`hip_pos` (4, 3)) moved by the desired velocity `vel_des` (3,) m/s."""
    t = config.dt * jp.arange(config.steps)  # (N,) s
    staying = jp.cumprod(stance.astype(jp.int32), axis=0).astype(bool)  # (N, 4)
    nominal = hip_pos.at[:, 2].set(0.0)[None] + t[:, None, None] * vel_des  # (N, 4, 3)
    return jp.where(staying[..., None], foot_pos[None], nominal)


def schedule(config: MPCConfig, gait_: gait.Gait, t: jax.Array) -> jax.Array:
    """(N, 4) bool: the stance of each step k, the gait's at controller time t + k dt."""
    times = t + config.dt * jp.arange(config.steps)
    return jax.vmap(lambda tk: gait.contact_schedule(gait_, tk)[0])(times)


def reference(config: MPCConfig, pos_des, vel_des, yaw_des, yaw_rate) -> jax.Array:
    """(N, 12) x_ref,k for k = 1 .. N: level, heading yaw_des + yaw_rate t_k (rad), COM at
    pos_des + vel_des t_k (m), moving at vel_des (m/s) and turning at yaw_rate (rad/s)."""
    t = config.dt * jp.arange(1, config.steps + 1)[:, None]  # (N, 1) s
    zero = jp.zeros_like(t)
    theta = jp.concatenate([zero, zero, yaw_des + yaw_rate * t], axis=1)
    omega = jp.concatenate([zero, zero, jp.full_like(t, yaw_rate)], axis=1)
    return jp.concatenate([theta, pos_des + vel_des * t, omega, jp.tile(vel_des, (len(t), 1))], 1)


def state_vector(com_pos, com_vel, rot, ang_vel, yaw_ref) -> jax.Array:
    """(12,) x from the measured state: roll, pitch, yaw (ZYX Euler angles of `rot`, body ->
    world; the yaw unwrapped to within pi of `yaw_ref`), COM position, angular velocity, COM
    velocity."""
    roll = jp.arctan2(rot[2, 1], rot[2, 2])
    pitch = -jp.arcsin(jp.clip(rot[2, 0], -1.0, 1.0))
    yaw = jp.arctan2(rot[1, 0], rot[0, 0])
    yaw = yaw_ref + jp.mod(yaw - yaw_ref + jp.pi, 2 * jp.pi) - jp.pi
    return jp.concatenate([jp.stack([roll, pitch, yaw]), com_pos, ang_vel, com_vel])


def build_mpc_qp(params, config: MPCConfig, x0, x_ref, feet, contact, wrench) -> MPCQP:
    """The condensed QP of one env (unbatched; vmap it). `params` the balance QP's (mass,
    inertia, mu, force bounds); x0 (12,) the state now; x_ref (N, 12) of steps 1 .. N; feet
    (N, 4, 3) m where each foot pushes at step k (`levers`); contact (N, 4) bool; wrench (N, 6)
    the arms' w_0 .. w_{N-1} (N, N·m; world, about the COM)."""
    n = config.steps
    # linearised about the state now at step 0, about the reference after (psi_k, p_k at t_k)
    yaws = jp.concatenate([x0[2:3], x_ref[:-1, 2]])  # (N,) rad
    coms = jp.concatenate([x0[None, 3:6], x_ref[:-1, 3:6]])  # (N, 3) m
    step = functools.partial(step_model, params, config.dt)
    A, B, D, g = jax.vmap(step)(yaws, coms, feet, contact)
    e = jp.einsum("kij,kj->ki", D, wrench) + g  # (N, 12)
    gamma, x_free = condense(A, B, e, x0)
    q_diag = jp.tile(config.Q, n)  # (12 N,)
    err = x_free - x_ref.reshape(-1)
    G, h = jax.vmap(balance.friction_constraints, (None, None, None, 0))(
        params.mu, params.f_min, params.f_max, contact
    )  # (N, 24, 12), (N, 24)
    return MPCQP(
        q=gamma.T @ (q_diag * err), g_blocks=G, h=h.reshape(-1),
        const=0.5 * jp.sum(q_diag * err * err), gamma=gamma, x0=x0, x_free=x_free,
        contact=contact, A=A, B=B, Q=config.Q, R=jp.asarray(config.R, gamma.dtype),
    )  # fmt: skip


@functools.cache
def g_pattern(steps: int) -> np.ndarray:
    """(24 N, 12 N) bool: the block-diagonal pattern of the MPC's G (`balance.G_PATTERN` per
    step), for `qp.solve(..., g_pattern=...)`."""
    return np.kron(np.eye(steps, dtype=bool), balance.G_PATTERN)


def solve_mpc(config: MPCConfig, prob: MPCQP, warm_start: qp.QPResult | None = None):
    """(forces (N, 4, 3) N, world, swing feet exactly 0; the QPResult) of a built MPCQP, by our
    interior point with `config.iterations` iterations, the block-diagonal pattern of G and the
    Newton systems solved by a Riccati recursion over the model's steps (`mpc_kkt`)."""
    settings = qp.QPSettings(iterations=config.iterations)
    pattern = g_pattern(config.steps)
    data = (prob.A, prob.B, config.Q, jp.asarray(config.R, prob.q.dtype))
    res = qp.solve(None, prob.q, prob.g_entries, prob.h, warm_start=warm_start, settings=settings,
                   g_pattern=pattern, normal_solver=mpc_kkt.RiccatiSolver(config.steps),
                   normal_data=data)  # fmt: skip
    forces = res.x.reshape(config.steps, balance.N_FEET, 3) * prob.contact[..., None]
    return forces, res


def controller_qp(config, params, gait_, t, s: BodyState, feet, desired, wrench) -> MPCQP:
    """The MPC's QP at a controller tick (`update`'s arguments): the state, the schedule from
    the gait at time t, the reference from `desired`, the lever arms from `feet` and the hips."""
    pos_des, vel_des, yaw_des, yaw_rate = desired
    stance = schedule(config, gait_, t)
    x_ref = reference(config, pos_des, vel_des, yaw_des, yaw_rate)
    x0 = state_vector(s.com_pos, s.com_vel, s.rot, s.ang_vel, yaw_des)
    at = levers(config, stance, feet, s.hip_pos, vel_des)
    return build_mpc_qp(params, config, x0, x_ref, at, stance, wrench)


def update(  # noqa: PLR0913 (the controller's pieces of one tick)
    config: MPCConfig,
    params: balance.BalanceParams,
    gait_: gait.Gait,
    plan: MPCPlan,
    t: jax.Array,
    s: BodyState,
    feet: jax.Array,
    desired: tuple,
    wrench: Callable[[], jax.Array],
    replan: bool | jax.Array,
) -> tuple[MPCPlan, jax.Array]:
    """One control tick of the MPC: (the plan, re-solved where `replan`; qdd (6,) the balance
    QP's target, `tracked_acceleration`). `t` () s controller time; `s` the measured state;
    `feet` (4, 3) m the contact points now; `desired` (pos_des (3,), vel_des (3,), yaw_des (),
    yaw_rate ()) of this tick's plan; `wrench()` (N, 6) w_0 .. w_{N-1}, called only to
    re-solve (inside the solve's branch); `replan` a bool, or a
    traced () bool (a `lax.cond`: one branch runs where the bool is the same for the whole
    batch, e.g. a tick index; under vmap a batched one runs both). Where the plan is not valid
    (`qp.valid`: a non-finite state, a failed solve) the QP asks for eq. 9's acceleration."""
    pos_des, vel_des, yaw_des, yaw_rate = desired

    def solve_now() -> MPCPlan:
        w = wrench()
        prob = controller_qp(config, params, gait_, t, s, feet, desired, w)
        forces, res = solve_mpc(config, prob)  # cold: module doc
        kept = jp.where(res.valid, w, 0.0)  # finite, as the forces (0 where not valid)
        ahead = (prob.gamma @ forces.reshape(-1) + prob.x_free).reshape(-1, N_STATE)  # x_1..x_N
        states = jp.where(res.valid, jp.concatenate([prob.x0[None], ahead]), 0.0)
        return MPCPlan(forces=forces, wrench=kept, states=states, t0=t, qp=res)

    if isinstance(replan, bool):
        plan = solve_now() if replan else plan
    else:
        plan = jax.lax.cond(replan, solve_now, lambda: plan)
    tracked = tracked_acceleration(config, params, plan, t, s, feet)
    state = (s.com_pos, s.com_vel, s.rot, s.ang_vel)
    own = (pos_des, vel_des, rot_z(yaw_des), jp.array([0.0, 0.0, yaw_rate]))  # eq. 9's targets
    return plan, jp.where(plan.qp.valid, tracked, balance.desired_acceleration(params, state, own))


def tracked_acceleration(config, params, plan: MPCPlan, t, s: BodyState, feet) -> jax.Array:
    """(6,) qdd (m/s^2, rad/s^2; COM linear, world angular): what the plan's forces f_j and
    wrench w_j of the step j holding time t (s) give with this tick's lever arms (`feet` (4, 3)
    m), plus eq. 9's feedback toward the state the plan predicts for t (`MPCPlan.states`,
    linear between its steps; the balance QP's gains):

        qdd = M f_j + (f_w / m, I_w^-1 tau_w) - g~ + Kp (x_plan(t) - x) + Kd (xd_plan(t) - xd)

    (`balance.wrench_matrix`, every foot's column kept: where this tick's stance differs from the
    plan's, the QP moves that force to the stance feet; the feedback is 0 at the solve and acts
    on what happened since, a push between two solves). `update` asks for eq. 9's acceleration
    toward the desired state instead where the plan is not valid."""
    ahead = jp.clip((t - plan.t0) / config.dt, 0.0, config.steps)  # steps since the solve
    j = jp.minimum(jp.floor(ahead), config.steps - 1).astype(jp.int32)
    M, inertia_w_inv = balance.wrench_matrix(params, s.com_pos, s.rot, feet, jp.ones(4, bool))
    w = plan.wrench[j]
    g_tilde = jp.array([0.0, 0.0, balance.GRAVITY, 0.0, 0.0, 0.0])
    x = plan.states[j] + (ahead - j) * (plan.states[j + 1] - plan.states[j])  # (12,) at t
    predicted = (x[3:6], x[9:12], euler_matrix(x[0:3]), x[6:9])
    feedback = balance.desired_acceleration(
        params, (s.com_pos, s.com_vel, s.rot, s.ang_vel), predicted
    )
    return (
        M @ plan.forces[j].reshape(-1)
        + jp.concatenate([w[:3] / params.mass, inertia_w_inv @ w[3:]])
        - g_tilde
        + feedback
    )


def euler_matrix(theta: jax.Array) -> jax.Array:
    """(3, 3) body -> world rotation of ZYX Euler angles `theta` (3,) (roll, pitch, yaw; rad):
    R = R_z(yaw) R_y(pitch) R_x(roll), the inverse of `state_vector`'s angles."""
    cr, cp = jp.cos(theta[0]), jp.cos(theta[1])
    sr, sp = jp.sin(theta[0]), jp.sin(theta[1])
    rx = jp.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = jp.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    return rot_z(theta[2]) @ ry @ rx


LOW_LEVELS = ("qp", "mpc")  # `EnvConfig.low_level`, `make_controller(low_level=...)`


def low_level(name) -> str:
    """`name` if it is a low level (LOW_LEVELS), else `DpcError` saying which there are."""
    if name not in LOW_LEVELS:
        raise DpcError(
            f"low_level={name!r} is not a low-level controller; choose 'qp' (the one-tick "
            "balance QP, the default) or 'mpc' (the convex MPC over a horizon, control/mpc.py)."
        )
    return name
