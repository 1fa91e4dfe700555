"""dpc_mjx.control.qp: accuracy against OSQP (float64, tight), robustness, warm start, tracing.

OSQP is a test-only reference. All our solves run in float32 with the DEFAULT settings, batched by
one jit(vmap(solve)) per shape.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import numpy as np
import osqp
import pytest
import scipy.sparse as sp

from dpc_mjx.control import qp
from dpc_mjx.errors import DpcError

N_PROBLEMS = 600  # random QPs of the controller's size
N_VARS, N_ROWS = 12, 24

# Tolerances (float32 solver vs float64 reference). Scales: force scale = max(1, |h|_inf);
# objective scale = max(1, |x*'Px*|, |q'x*|), the scale of the solver's own gap tolerance
# (QPSettings): J* = x*'Px*/2 + q'x* can cancel to far below its terms (one of the sparse
# problems: 6855/2 - 3394 = 34), and no float32 method resolves J* better than its terms; dual
# scale = max(1, |q|, |Px|, |G|'|z|) (all inf-norms).
_OBJ_GAP_TOL = 1e-3  # |J - J*| / objective scale
_VIOLATION_TOL = 1e-3  # max(Gx - h, 0) / force scale
_STATIONARITY_TOL = 1e-3  # |Px + q + G'z| / dual scale
_COMPLEMENTARITY_TOL = 1e-3  # max_i z_i |h - Gx|_i / objective scale
_DUAL_FEASIBILITY_TOL = 0.0  # min z >= -tol (the method keeps z > 0)
_CONVERGED_FRACTION = 0.99  # share of problems whose `converged` flag is set
_TIGHT_PAIR_TOL = 1e-3  # |x| of the problem whose bounds pin x = 0
_WARM_ITERATION_RATIO = 0.7  # mean iterations to tolerance, warm / cold
# vmap runs the batch-minor chunked kernel, a single call the same code with no batch axis: the
# same float32 operations, fused differently by XLA (identical on these problems under jax
# 0.9.2; under jax 0.10.2 the objectives agree to 3e-6, x to 1.5% of its scale along directions
# where the objective is flat, P's condition number reaching 4.5e6). So x is compared in the
# objective's own metric, (x_a - x_b)'P(x_a - x_b)/2 (measured up to 1.7e-7 of the objective
# scale under jax 0.10.2), and both layouts are checked against the reference.
_LAYOUT_TOL = 1e-4  # relative to max(1, |J_b|): |J_a - J_b|, and (x_a - x_b)'P(x_a - x_b)/2
# Inside a scan XLA fuses differently again, and warm starts amplify the rounding differences up
# to the solver's own tolerance (eps_rel 1e-3): measured up to 1.1e-4.
_WARM_CHAIN_TOL = 1e-3


def random_qps(
    n_prob: int, seed: int, g_pattern: np.ndarray | None = None
) -> tuple[np.ndarray, ...]:
    """Feasible QPs with a known optimum built from the KKT conditions, float64.

    A third are well conditioned (P = AA'/n + 0.1 I); two thirds are like the balance cost: a rank-6
    Gram matrix with row scales over two decades plus a ridge of 1e-6..1e-4 of its mean eigenvalue.
    0..10 of the 24 random rows are active at x*, with multipliers > 0; scales from 0.1 to 100.
    G is zero outside g_pattern (24, 12) if one is given. Returns P, q, G, h and x* (the unique
    optimum: P is positive definite).
    """
    rng = np.random.default_rng(seed)
    P = np.zeros((n_prob, N_VARS, N_VARS))
    q = np.zeros((n_prob, N_VARS))
    G = np.zeros((n_prob, N_ROWS, N_VARS))
    h = np.zeros((n_prob, N_ROWS))
    x_opt = np.zeros((n_prob, N_VARS))
    for b in range(n_prob):
        if b % 3 == 0:
            A = rng.normal(size=(N_VARS, N_VARS))
            Pb = A @ A.T / N_VARS + 0.1 * np.eye(N_VARS)
        else:
            A = rng.normal(size=(6, N_VARS)) * rng.uniform(0.1, 10.0, size=(6, 1))
            Pb = A.T @ A
            Pb += 10.0 ** rng.uniform(-6, -4) * np.trace(Pb) / N_VARS * np.eye(N_VARS)
        Gb = rng.normal(size=(N_ROWS, N_VARS))
        if g_pattern is not None:
            Gb = Gb * g_pattern
        scale = 10.0 ** rng.uniform(-1, 2)
        x_star = rng.normal(size=N_VARS) * scale
        active = rng.permutation(N_ROWS)[: rng.integers(0, 11)]
        slack = rng.uniform(0.05, 1.0, size=N_ROWS) * scale
        slack[active] = 0.0
        lam = np.zeros(N_ROWS)
        lam[active] = rng.uniform(0.1, 2.0, size=active.size) * scale
        P[b], G[b], h[b], x_opt[b] = Pb, Gb, Gb @ x_star + slack, x_star
        q[b] = -Pb @ x_star - Gb.T @ lam
    return P, q, G, h, x_opt


def osqp_reference(P, q, G, h) -> np.ndarray:
    """(batch, n) x* of each problem by OSQP in float64 (eps 1e-9, polished)."""
    xs = []
    for Pb, qb, Gb, hb in zip(*(np.asarray(a, np.float64) for a in (P, q, G, h)), strict=True):
        solver = osqp.OSQP()
        solver.setup(
            sp.csc_matrix(np.triu(Pb)),
            qb,
            sp.csc_matrix(Gb),
            np.full(hb.shape, -np.inf),
            hb,
            eps_abs=1e-9,
            eps_rel=1e-9,
            polishing=True,
            verbose=False,
            max_iter=200_000,
        )
        res = solver.solve(raise_error=False)
        assert res.info.status == "solved", res.info.status
        xs.append(res.x)
    return np.array(xs)


def check_against_reference(res: qp.QPResult, problems, x_star) -> dict[str, float]:
    """Assert the accuracy and KKT checks of a batch; problems = (P, q, G, h), x_star (batch, n)
    the reference optima; returns the worst figures."""
    P, q, G, h = (np.asarray(a, np.float64) for a in problems)
    x, z = np.asarray(res.x, np.float64), np.asarray(res.z, np.float64)
    x_star = np.asarray(x_star, np.float64)
    j = 0.5 * np.einsum("bi,bij,bj->b", x, P, x) + np.einsum("bi,bi->b", q, x)
    quadratic = np.einsum("bi,bij,bj->b", x_star, P, x_star)
    linear = np.einsum("bi,bi->b", q, x_star)
    j_star = 0.5 * quadratic + linear
    obj_scale = np.maximum.reduce([np.ones(len(x)), np.abs(quadratic), np.abs(linear)])
    force_scale = np.maximum(1.0, np.abs(h).max(1))
    gx = np.einsum("bij,bj->bi", G, x)
    px = np.einsum("bij,bj->bi", P, x)
    stat = np.abs(px + q + np.einsum("bij,bi->bj", G, z)).max(1)
    dual_scale = np.maximum.reduce(
        [
            np.ones(len(x)),
            np.abs(q).max(1),
            np.abs(px).max(1),
            np.einsum("bij,bi->bj", np.abs(G), z).max(1),
        ]
    )
    worst = {
        "gap": float((np.abs(j - j_star) / obj_scale).max()),
        "violation": float((np.maximum(gx - h, 0.0).max(1) / force_scale).max()),
        "stationarity": float((stat / dual_scale).max()),
        "complementarity": float(((z * np.abs(h - gx)).max(1) / obj_scale).max()),
        "min_z": float(z.min()),
    }
    assert np.all(np.asarray(res.valid)), "every feasible problem must give valid=True"
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(z))
    assert worst["gap"] <= _OBJ_GAP_TOL, worst
    assert worst["violation"] <= _VIOLATION_TOL, worst
    assert worst["stationarity"] <= _STATIONARITY_TOL, worst
    assert worst["complementarity"] <= _COMPLEMENTARITY_TOL, worst
    assert worst["min_z"] >= -_DUAL_FEASIBILITY_TOL, worst
    assert np.mean(np.asarray(res.converged)) >= _CONVERGED_FRACTION, worst
    return worst


_TRACES: list[int] = []  # one entry per trace of _counted_solve (a Python side effect)


def _counted_solve(P, q, G, h):
    _TRACES.append(1)
    return qp.solve(P, q, G, h)


# Shared compiled batch solvers (default settings): one compile per batch shape.
_solve_batch = jax.jit(jax.vmap(_counted_solve))
_solve_batch_warm = jax.jit(jax.vmap(lambda P, q, G, h, w: qp.solve(P, q, G, h, warm_start=w)))


@pytest.fixture(scope="module")
def random_problems():
    P, q, G, h, _ = random_qps(N_PROBLEMS, seed=0)
    x_star = osqp_reference(P, q, G, h)
    return P, q, G, h, x_star


def test_random_qps_match_osqp(random_problems):
    P, q, G, h, x_star = random_problems
    args = [jp.asarray(a, jp.float32) for a in (P, q, G, h)]
    res = _solve_batch(*args)
    assert res.x.dtype == jp.float32
    check_against_reference(res, (P, q, G, h), x_star)


def test_result_shapes_and_unbatched_call(random_problems):
    P, q, G, h, _ = random_problems
    res = jax.jit(qp.solve)(*(jp.asarray(a[0], jp.float32) for a in (P, q, G, h)))
    n, m = N_VARS, N_ROWS
    shapes = {f.name: getattr(res, f.name).shape for f in dataclasses.fields(res)}
    assert shapes == {
        "x": (n,),
        "z": (m,),
        "s": (m,),
        "objective": (),
        "primal_residual": (),
        "dual_residual": (),
        "gap": (),
        "iterations": (),
        "converged": (),
        "valid": (),
    }
    assert res.iterations.dtype == jp.int32 and res.valid.dtype == jp.bool_
    assert bool(res.valid) and bool(res.converged)
    assert 0 <= int(res.iterations) <= qp.QPSettings().iterations
    # the cold warm start (`QPResult.zeros`, the controller's first tick) is a result's pytree
    cold = qp.QPResult.zeros(n, m)
    same = jax.tree.map(lambda a, b: (a.shape, a.dtype) == (b.shape, b.dtype), cold, res)
    assert all(jax.tree.leaves(same)) and not bool(cold.valid)


def _degenerate_cases() -> dict[str, tuple[np.ndarray, ...]]:
    n, m = N_VARS, N_ROWS
    eye, zeros_g = np.eye(n), np.zeros((m, n))
    box = np.concatenate([np.eye(n), -np.eye(n)])  # |x_i| <= 1
    cases = {
        "nan_P": (np.full((n, n), np.nan), np.ones(n), box, np.ones(m)),
        "inf_h": (eye, np.ones(n), box, np.full(m, np.inf)),
        "nan_G": (eye, np.ones(n), np.where(box > 0, np.nan, box), np.ones(m)),
        "huge": (eye * 1e30, np.full(n, 1e30), box * 1e30, np.ones(m) * 1e30),
        "all_zero": (np.zeros((n, n)), np.zeros(n), zeros_g, np.zeros(m)),
        # x_0 <= -1 and -x_0 <= -1: empty feasible set
        "infeasible": (
            eye,
            np.ones(n),
            box,
            np.concatenate([[-1.0], np.ones(n - 1), [-1.0], np.ones(n - 1)]),
        ),
        # LP whose objective decreases without bound (no row limits x_0 from above)
        "unbounded": (
            np.zeros((n, n)),
            -np.eye(n)[0],
            np.concatenate([-np.eye(n), -np.eye(n)]),
            np.ones(m),
        ),
        # tight pairs 0 <= x <= 0 (equalities as two inequalities): solution x = 0
        "tight_pairs": (eye, np.ones(n), box, np.zeros(m)),
        "indefinite_P": (-eye, np.zeros(n), box, np.ones(m)),
    }
    return cases


def test_degenerate_inputs_give_finite_flagged_output(random_problems):
    cases = _degenerate_cases()
    stacked = [np.stack([c[i] for c in cases.values()]).astype(np.float32) for i in range(4)]
    # filled up with random problems to _solve_batch's compiled batch (one compile fewer)
    stacked = [np.concatenate([a, b[len(cases) :]]) for a, b in zip(stacked, random_problems)]
    with np.errstate(all="ignore"):
        res = _solve_batch(*(jp.asarray(a, jp.float32) for a in stacked))
    res = jax.tree.map(np.asarray, res)
    for field in dataclasses.fields(res):
        assert np.all(np.isfinite(getattr(res, field.name))), field.name
    flags = {name: (bool(res.valid[i]), bool(res.converged[i])) for i, name in enumerate(cases)}
    for name in ("nan_P", "inf_h", "nan_G", "infeasible"):
        assert flags[name] == (False, False), (name, flags[name])
        assert np.all(res.x[list(cases).index(name)] == 0.0), name
    assert not flags["unbounded"][1], flags["unbounded"]
    assert flags["all_zero"][0], flags["all_zero"]  # x = 0 is optimal
    i_tight = list(cases).index("tight_pairs")
    assert flags["tight_pairs"][0], flags["tight_pairs"]
    assert np.abs(res.x[i_tight]).max() <= _TIGHT_PAIR_TOL, res.x[i_tight]


def test_warm_start_from_previous_solution(random_problems):
    """Re-solving after a small change of q and h from the previous solution: fewer iterations to
    the tolerance; every problem flagged converged is as accurate as a cold solve."""
    P, q, G, h, _ = random_problems
    rng = np.random.default_rng(1)
    q1 = q + 0.01 * np.abs(q).max(1, keepdims=True) * rng.normal(size=q.shape)
    h1 = h + 0.01 * np.abs(h).max(1, keepdims=True) * rng.uniform(size=h.shape)  # stays feasible
    x1 = osqp_reference(P, q1, G, h1)
    first = _solve_batch(*(jp.asarray(a, jp.float32) for a in (P, q, G, h)))
    new = tuple(jp.asarray(a, jp.float32) for a in (P, q1, G, h1))
    cold = _solve_batch(*new)
    warm = _solve_batch_warm(*new, first)
    it_cold, it_warm = np.asarray(cold.iterations), np.asarray(warm.iterations)
    assert np.mean(it_warm) < _WARM_ITERATION_RATIO * np.mean(it_cold), (it_warm, it_cold)
    assert np.median(it_warm) < np.median(it_cold)
    ok = np.asarray(warm.converged)
    assert ok.mean() >= _CONVERGED_FRACTION
    subset = jax.tree.map(lambda a: np.asarray(a)[ok], warm)
    check_against_reference(subset, (P[ok], q1[ok], G[ok], h1[ok]), x1[ok])


def test_invalid_warm_start_is_ignored(random_problems):
    P, q, G, h, x_star = random_problems
    args = [jp.asarray(a, jp.float32) for a in (P, q, G, h)]
    bad = _solve_batch(*args)
    bad = dataclasses.replace(bad, x=jp.full_like(bad.x, jp.nan), valid=jp.zeros_like(bad.valid))
    res = _solve_batch_warm(*args, bad)
    check_against_reference(res, (P, q, G, h), x_star)


def test_batch_is_traced_once(random_problems):
    """The batch solver traces solve once per batch shape, not per problem or per call."""
    P, q, G, h, _ = random_problems
    args = [jp.asarray(a, jp.float32) for a in (P, q, G, h)]
    before = len(_TRACES)
    _solve_batch(*args).x.block_until_ready()
    after_first = len(_TRACES)
    _solve_batch(args[0] * 2.0, *args[1:]).x.block_until_ready()
    assert after_first - before <= 1  # 0 if an earlier test already traced this shape
    assert len(_TRACES) == after_first


def _assert_same_results(a: qp.QPResult, b: qp.QPResult, tol: float, P=None) -> None:
    """a and b (same batch shape) agree: the objective within tol (relative, scale >= 1), x
    within tol relative to |x_b|_inf (or, given the problems' P (batch, n, n), in the
    objective's metric (x_a - x_b)'P(x_a - x_b)/2 relative to the objective's scale), the flags
    exactly, the iteration counts within one."""
    xa, xb = np.asarray(a.x, np.float64), np.asarray(b.x, np.float64)
    ja, jb = np.asarray(a.objective, np.float64), np.asarray(b.objective, np.float64)
    obj_scale = np.maximum(1.0, np.abs(jb))
    assert np.all(np.abs(ja - jb) <= tol * obj_scale), np.abs(ja - jb).max()
    if P is None:
        x_gap = np.abs(xa - xb).max(-1) / np.maximum(1.0, np.abs(xb).max(-1))
    else:
        d = xa - xb
        x_gap = 0.5 * np.einsum("...i,...ij,...j->...", d, np.asarray(P, np.float64), d) / obj_scale
    assert np.all(x_gap <= tol), x_gap.max()
    for flag in ("valid", "converged"):
        assert np.array_equal(np.asarray(getattr(a, flag)), np.asarray(getattr(b, flag))), flag
    assert np.abs(np.asarray(a.iterations) - np.asarray(b.iterations)).max() <= 1


def test_vmap_matches_single_calls(random_problems):
    """The batched kernel against unbatched calls, per problem, on the batch's last two chunks
    (the last one padded: N_PROBLEMS is not a multiple of the chunk); the unbatched calls as
    accurate as the batch (test_random_qps_match_osqp)."""
    P, q, G, h, x_star = random_problems
    assert N_PROBLEMS % qp._CHUNK
    idx = np.arange(N_PROBLEMS - N_PROBLEMS % qp._CHUNK - 3, N_PROBLEMS)
    args = [jp.asarray(a, jp.float32) for a in (P, q, G, h)]
    batched = jax.tree.map(lambda a: np.asarray(a)[idx], _solve_batch(*args))
    single = jax.jit(qp.solve)
    singles = jax.tree.map(lambda *r: jp.stack(r), *(single(*(a[i] for a in args)) for i in idx))
    check_against_reference(singles, (P[idx], q[idx], G[idx], h[idx]), x_star[idx])
    _assert_same_results(batched, singles, _LAYOUT_TOL, P=P[idx])


def test_nested_vmap_and_shared_arguments(random_problems):
    """vmap of vmap is one batch; an argument shared by the batch (in_axes None) is broadcast."""
    P, q, G, h, _ = random_problems
    args = [jp.asarray(a, jp.float32) for a in (P, q, G, h)]  # all N_PROBLEMS: _solve_batch's
    flat = _solve_batch(*args)  # compiled for this shape by test_random_qps_match_osqp
    half = N_PROBLEMS // 2
    pairs = [a.reshape((2, half, *a.shape[1:])) for a in args]
    nested = jax.jit(jax.vmap(jax.vmap(qp.solve)))(*pairs)
    assert nested.x.shape == (2, half, N_VARS) and nested.valid.shape == (2, half)
    whole = jax.tree.map(lambda a: a.reshape((N_PROBLEMS, *a.shape[2:])), nested)
    _assert_same_results(whole, flat, 0.0)

    shared = jax.jit(jax.vmap(qp.solve, in_axes=(None, 0, None, 0)))(
        args[0][0], args[1], args[2][0], args[3]
    )
    tiled = [jp.broadcast_to(args[0][0], args[0].shape), args[1]]
    tiled += [jp.broadcast_to(args[2][0], args[2].shape), args[3]]
    _assert_same_results(shared, _solve_batch(*tiled), 0.0)


def test_warm_started_scan_under_vmap(random_problems):
    """The controller's pattern, jit(vmap(scan(solve warm-started from the previous result))),
    from the controller's first tick (`QPResult.zeros`: no valid warm start, a cold start inside
    the warm-started kernel), against the same steps as single calls."""
    P, q, G, h, _ = random_problems
    args = [jp.asarray(a[:4], jp.float32) for a in (P, q, G, h)]
    scales = jp.array([1.0, 1.01, 0.99, 1.0])  # q changes by 1 % per step after the first
    cold = qp.QPResult.zeros(N_VARS, N_ROWS)

    def run(P, q, G, h):
        def step(prev, scale):
            res = qp.solve(P, q * scale, G, h, warm_start=prev)
            return res, res

        return jax.lax.scan(step, cold, scales)[1]

    batched = jax.jit(jax.vmap(run))(*args)  # fields (4, 4, ...)
    single = jax.jit(lambda P, q, G, h, w: qp.solve(P, q, G, h, warm_start=w))
    for i in range(4):
        prev = cold
        for t, scale in enumerate(np.asarray(scales)):
            prev = single(args[0][i], args[1][i] * scale, args[2][i], args[3][i], prev)
            step = jax.tree.map(lambda a, i=i, t=t: a[i, t], batched)
            _assert_same_results(step, prev, _WARM_CHAIN_TOL)


def random_pattern(seed: int) -> np.ndarray:
    """(24, 12) bool: 1 to 4 nonzeros per row, every column used."""
    rng = np.random.default_rng(seed)
    pattern = np.zeros((N_ROWS, N_VARS), bool)
    for r in range(N_ROWS):
        pattern[r, rng.choice(N_VARS, rng.integers(1, 5), replace=False)] = True
    pattern[np.arange(N_VARS), np.arange(N_VARS)] = True
    return pattern


SPARSE_PATTERN = random_pattern(seed=3)
# the compiled batch solver of the sparse tests (one compile for both)
_solve_sparse_batch = jax.jit(jax.vmap(lambda *a: qp.solve(*a, g_pattern=SPARSE_PATTERN)))


@pytest.fixture(scope="module")
def sparse_problems():
    """Random QPs with G in SPARSE_PATTERN; the reference is the optimum they were built around
    (OSQP at eps 1e-9 hits its iteration limit on some of these)."""
    P, q, G, h, x_opt = random_qps(N_PROBLEMS, seed=4, g_pattern=SPARSE_PATTERN)
    return SPARSE_PATTERN, (P, q, G, h), x_opt


def test_sparse_pattern_matches_osqp(sparse_problems):
    """With g_pattern, only the pattern's products are formed: the same accuracy as dense, in the
    batched kernel (chunks of _CHUNK_SPARSE, the last padded) and in single calls. (The two
    layouts round differently, and on the worst-conditioned problems x then differs by up to
    1e-2 of its scale along directions where the objective is flat; both meet the tolerances.)"""
    pattern, problems, x_opt = sparse_problems
    args = [jp.asarray(a, jp.float32) for a in problems]
    res = _solve_sparse_batch(*args)
    check_against_reference(res, problems, x_opt)
    k = qp._CHUNK_SPARSE + 3
    single = jax.jit(lambda *a: qp.solve(*a, g_pattern=pattern))
    singles = [single(*(a[i] for a in args)) for i in range(k)]
    singles = jax.tree.map(lambda *r: jp.stack(r), *singles)
    check_against_reference(singles, tuple(a[:k] for a in problems), x_opt[:k])


def test_entries_outside_the_pattern_are_never_read(sparse_problems):
    pattern, problems, _ = sparse_problems
    P, q, G, h = (jp.asarray(a, jp.float32) for a in problems)
    clean = _solve_sparse_batch(P, q, G, h)
    noisy = _solve_sparse_batch(P, q, jp.where(pattern, G, jp.nan), h)
    assert bool(jp.all(noisy.valid))
    _assert_same_results(noisy, clean, 0.0)


def test_bad_patterns_are_rejected():
    n, m = N_VARS, N_ROWS
    args = (jp.eye(n), jp.zeros(n), jp.zeros((m, n)), jp.ones(m))
    with pytest.raises(DpcError, match="bool array of G's shape"):
        qp.solve(*args, g_pattern=np.ones((m, n + 1), bool))
    with pytest.raises(DpcError, match="bool array of G's shape"):
        qp.solve(*args, g_pattern=np.ones((m, n)))
    with pytest.raises(DpcError, match="concrete"):
        jax.jit(lambda pat: qp.solve(*args, g_pattern=pat))(jp.ones((m, n), bool))


def test_batch_shapes_are_rejected_outside_vmap():
    n, m = N_VARS, N_ROWS
    with pytest.raises(DpcError, match="jax.vmap"):
        qp.solve(jp.zeros((2, n, n)), jp.zeros((2, n)), jp.zeros((2, m, n)), jp.zeros((2, m)))
    with pytest.raises(DpcError, match="one problem"):
        qp.solve(jp.eye(n), jp.zeros(n), jp.zeros((m, n + 1)), jp.zeros(m))
