"""dpc_mjx.control.balance: the balance QP (model, constraints, physics) and its solution."""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_qp import N_PROBLEMS, _solve_batch, check_against_reference, osqp_reference

from dpc_mjx import rotations
from dpc_mjx.control import balance, qp

PARAMS = balance.default_params()
MASS = float(PARAMS.mass)
WEIGHT = MASS * balance.GRAVITY  # N

# Tolerances of the physics checks (N, N·m), against the rigid-body statics.
_SUM_FORCE_TOL = 2e-3 * WEIGHT  # on the summed force, about the expected support below
_FOOT_SPREAD_TOL = 1e-2  # |front / back - 1| and |left / right - 1| of f_z, the COM centred
_SHIFT_TOL = 0.02  # relative error of the force / moment shift by -f_a / -tau_a
_SHIFT_ABS_TOL = 0.3  # N or N·m, added to the relative one
# Internal forces (the 6-D null space of M: feet pushing against each other) are set only by R,
# whose curvature is ~1e-7 of P's largest eigenvalue: float32 resolves them to ~1 N (OSQP in
# float64 on the same float32 P gives exactly 0 horizontal force when standing). The same holds for
# the vertical null-space mode, the diagonal pairs FR+RL against FL+RR.
_INTERNAL_FORCE_TOL = 0.05 * WEIGHT / 4  # N, ~5 % of a foot's load

_build_batch = jax.jit(jax.vmap(lambda s: balance.build_balance_qp(PARAMS, **s)))
_solve_balance = jax.jit(lambda s: balance.solve_balance(PARAMS, **s))


def expected_support(n_stance: int) -> float:
    """The vertical support (N) minimising Q_z (F/m - g)^2 + R sum f_i^2 with F split equally over
    n_stance feet: m g / (1 + R m^2 / (n Q_z)), a 0.5 % (4 feet) to 0.9 % (2 feet) sag for R = 1e-4.
    """
    r, q_z = float(PARAMS.R[0]), float(PARAMS.Q[2])
    return WEIGHT / (1.0 + r * MASS**2 / (n_stance * q_z))


def standing_state(**overrides) -> dict[str, jax.Array]:
    """The A1 standing still on flat ground, COM centred above the four feet, zero errors."""
    com = np.array([0.0, 0.0, 0.27])
    feet = np.array(
        [[0.18, -0.13, 0.0], [0.18, 0.13, 0.0], [-0.18, -0.13, 0.0], [-0.18, 0.13, 0.0]]
    )
    state = dict(
        com_pos=com,
        com_vel=np.zeros(3),
        rot=np.eye(3),
        ang_vel=np.zeros(3),
        com_pos_des=com,
        com_vel_des=np.zeros(3),
        rot_des=np.eye(3),
        ang_vel_des=np.zeros(3),
        foot_pos=feet,
        contact=np.ones(4, bool),
        f_a=np.zeros(3),
        tau_a=np.zeros(3),
    )
    state.update(overrides)
    return {k: jp.asarray(v, bool if k == "contact" else jp.float32) for k, v in state.items()}


@pytest.fixture(scope="module")
def balance_problems():
    states = balance.sample_states(np.random.default_rng(0), N_PROBLEMS)
    prob = _build_batch(states)
    P, q, G, h = (np.asarray(a) for a in (prob.P, prob.q, prob.G, prob.h))
    x_star = osqp_reference(P, q, G, h)
    return states, prob, x_star


_solve_batch_pattern = jax.jit(jax.vmap(lambda *a: qp.solve(*a, g_pattern=balance.G_PATTERN)))


@pytest.mark.parametrize("sparse", [False, True], ids=["dense", "G_PATTERN"])
def test_balance_qps_match_osqp(balance_problems, sparse):
    """Dense, and with the pattern of G the controller passes (balance.G_PATTERN)."""
    states, prob, x_star = balance_problems
    res = (_solve_batch_pattern if sparse else _solve_batch)(prob.P, prob.q, prob.G, prob.h)
    check_against_reference(res, (prob.P, prob.q, prob.G, prob.h), x_star)
    # swing feet: the optimum is exactly 0; the float32 solve leaves them tiny
    swing = ~np.asarray(states["contact"])
    x = np.asarray(res.x).reshape(-1, 4, 3)
    assert np.abs(x[swing]).max() <= 1e-3 * float(PARAMS.f_max)


def test_problem_shapes_and_structure(balance_problems):
    states, prob, _ = balance_problems
    n = N_PROBLEMS
    assert prob.P.shape == (n, 12, 12) and prob.q.shape == (n, 12)
    assert prob.G.shape == (n, 24, 12) and prob.h.shape == (n, 24)
    assert prob.M.shape == (n, 6, 12) and prob.b.shape == (n, 6) and prob.const.shape == (n,)
    P = np.asarray(prob.P, np.float64)
    assert np.allclose(P, np.swapaxes(P, 1, 2))
    assert np.linalg.eigvalsh(P).min() > 0.0  # R makes it positive definite
    # the objective + const is half the paper's cost || M f - b ||_Q^2 + ||f||_R^2
    f = np.random.default_rng(2).normal(size=(n, 12)) * 30.0
    M, b = np.asarray(prob.M, np.float64), np.asarray(prob.b, np.float64)
    paper = np.einsum(
        "bk,k,bk->b", (r := np.einsum("bkj,bj->bk", M, f) - b), np.asarray(PARAMS.Q), r
    ) + np.einsum("bj,j,bj->b", f, np.asarray(PARAMS.R), f)
    ours = (
        0.5 * np.einsum("bi,bij,bj->b", f, P, f)
        + np.einsum("bi,bi->b", prob.q, f)
        + np.asarray(prob.const)
    )
    assert np.allclose(ours, 0.5 * paper, rtol=1e-4)
    # G is zero outside balance.G_PATTERN, which the controller passes to qp.solve
    assert np.all(np.asarray(prob.G)[:, ~balance.G_PATTERN] == 0.0)
    assert balance.G_PATTERN.sum() == 40
    # swing feet have zero columns in M
    swing_cols = np.repeat(~np.asarray(states["contact"]), 3, axis=1)
    assert np.all(np.asarray(prob.M).transpose(0, 2, 1)[swing_cols] == 0.0)


def test_friction_pyramid_rows():
    mu, f_min, f_max = jp.float32(0.6), jp.float32(5.0), jp.float32(180.0)
    G, h = balance.friction_constraints(mu, f_min, f_max, jp.array([True, False, True, True]))
    G, h = np.asarray(G), np.asarray(h)

    def feasible(f):
        return bool(np.all(G @ f <= h + 1e-6))

    stance_ok = np.array([0.5 * 0.6 * 50, -0.5 * 0.6 * 50, 50.0])
    assert feasible(np.concatenate([stance_ok, np.zeros(3), stance_ok, stance_ok]))
    outside = np.array([0.61 * 50, 0.0, 50.0])  # |fx| > mu fz
    assert not feasible(np.concatenate([outside, np.zeros(3), stance_ok, stance_ok]))
    assert not feasible(np.concatenate([[0, 0, 2.0], np.zeros(3), stance_ok, stance_ok]))  # < f_min
    assert not feasible(np.concatenate([[0, 0, 181.0], np.zeros(3), stance_ok, stance_ok]))
    # swing foot: a symmetric box, 0 inside
    assert feasible(np.concatenate([stance_ok, [10.0, -10.0, -10.0], stance_ok, stance_ok]))


def test_standing_forces_balance_gravity():
    forces, res = _solve_balance(standing_state())
    forces = np.asarray(forces, np.float64)
    assert bool(res.valid) and bool(res.converged)
    total = forces.sum(0)
    assert np.allclose(total, [0.0, 0.0, expected_support(4)], atol=_SUM_FORCE_TOL), total
    fr, fl, rr, rl = forces[:, 2]  # f_z, the feet in the order FR, FL, RR, RL
    assert abs((fr + fl) / (rr + rl) - 1.0) <= _FOOT_SPREAD_TOL, forces  # pitch balance
    assert abs((fl + rl) / (fr + rr) - 1.0) <= _FOOT_SPREAD_TOL, forces  # roll balance
    assert abs(fr + rl - fl - rr) / 2.0 <= _INTERNAL_FORCE_TOL, forces  # the null-space mode
    assert np.abs(forces[:, :2]).max() <= _INTERNAL_FORCE_TOL, forces


def _moment(forces: np.ndarray, state) -> np.ndarray:
    r = np.asarray(state["foot_pos"], np.float64) - np.asarray(state["com_pos"], np.float64)
    return np.cross(r, forces).sum(0)


@pytest.mark.parametrize(
    ("f_a", "tau_a"),
    [
        ((10.0, -8.0, -30.0), (0.0, 0.0, 0.0)),
        ((0.0, 0.0, 0.0), (2.0, -3.0, 1.5)),
        ((-20.0, 15.0, 40.0), (-4.0, 2.0, -2.0)),
    ],
)
def test_external_wrench_shifts_the_forces(f_a, tau_a):
    """Rigid-body balance: a known arm wrench (f_a, tau_a) changes the summed foot force by -f_a
    and the moment of the foot forces about the COM by -tau_a."""
    base = standing_state()
    loaded = standing_state(f_a=np.array(f_a), tau_a=np.array(tau_a))
    f0 = np.asarray(_solve_balance(base)[0], np.float64)
    forces, res = _solve_balance(loaded)
    f1 = np.asarray(forces, np.float64)
    assert bool(res.converged)
    for shift, expected in (
        (f1.sum(0) - f0.sum(0), -np.array(f_a)),
        (_moment(f1, loaded) - _moment(f0, base), -np.array(tau_a)),
    ):
        tol = _SHIFT_TOL * np.abs(expected).max() + _SHIFT_ABS_TOL
        assert np.abs(shift - expected).max() <= tol, (shift, expected)


def test_trot_swing_feet_carry_nothing():
    contact = np.array([True, False, False, True])  # FR + RL diagonal
    state = standing_state(contact=contact)
    forces, res = _solve_balance(state)
    forces = np.asarray(forces, np.float64)
    assert bool(res.converged)
    assert np.all(forces[~contact] == 0.0)
    total = forces.sum(0)
    assert np.allclose(total, [0.0, 0.0, expected_support(2)], atol=_SUM_FORCE_TOL), total
    assert np.all(forces[contact, 2] >= float(PARAMS.f_min) - 1e-3)


def test_solve_balance_matches_qp_solution(balance_problems):
    states, prob, _ = balance_problems
    some = jax.tree.map(lambda a: a[:8], states)
    forces, res = jax.vmap(_solve_balance)(some)
    contact = np.asarray(some["contact"])
    expected = np.asarray(res.x).reshape(-1, 4, 3) * contact[..., None]
    assert np.array_equal(np.asarray(forces), expected)
    assert forces.shape == (8, 4, 3)


def test_yaw_frame_inertia_approximation():
    """M's angular rows are I_w^-1 [r_i]x with I_w = R_z I_B R_z^T (exact for a level trunk)."""
    yaw = Rotation.from_euler("z", 0.7).as_matrix()
    state = standing_state(rot=yaw, rot_des=yaw)
    prob = jax.jit(lambda s: balance.build_balance_qp(PARAMS, **s))(state)
    inertia_w = yaw @ np.asarray(PARAMS.inertia) @ yaw.T
    r = np.asarray(state["foot_pos"]) - np.asarray(state["com_pos"])
    ang = np.concatenate([np.linalg.solve(inertia_w, rotations.skew_np(ri)) for ri in r], axis=1)
    assert np.allclose(np.asarray(prob.M)[3:], ang, rtol=1e-4, atol=1e-5)
    assert np.allclose(np.asarray(prob.M)[:3], np.tile(np.eye(3) / MASS, (1, 4)), rtol=1e-6)


def test_rotation_vector_of_matrix():
    rng = np.random.default_rng(4)
    dirs = rng.normal(size=(5, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    vecs = [d * angle for d, angle in zip(dirs, (1e-7, 1e-3, 0.3, 1.0, 3.0), strict=True)]
    vecs += [np.array([np.pi - 1e-4, 0.0, 0.0]), np.array([0.0, 0.0, 0.0])]
    log = jax.jit(jax.vmap(rotations.rotvec_from_matrix))
    mats = np.stack([Rotation.from_rotvec(v).as_matrix() for v in vecs]).astype(np.float32)
    got = np.asarray(log(jp.asarray(mats)))
    assert np.allclose(got, np.stack(vecs), atol=2e-6, rtol=1e-4), got
    assert np.all(np.isfinite(np.asarray(log(jp.full((1, 3, 3), jp.nan)))))


def test_non_finite_state_is_flagged():
    bad = standing_state(com_pos=np.array([np.nan, 0.0, 0.27]))
    forces, res = _solve_balance(bad)
    assert not bool(res.valid)
    assert np.all(np.asarray(forces) == 0.0)


def test_solver_settings_are_used():
    short = qp.QPSettings(iterations=2)
    forces, res = jax.jit(lambda s: balance.solve_balance(PARAMS, **s, settings=short))(
        standing_state()
    )
    assert np.all(np.isfinite(np.asarray(forces)))
    assert int(res.iterations) <= short.iterations + 1
