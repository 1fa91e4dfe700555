"""Balance QPs recorded from real controller states (the robot simulated in MuJoCo C, the native
engine), solved by our solver vs OSQP."""

import jax
import jax.numpy as jp
import numpy as np
import osqp
import pytest
import scipy.sparse as sp

from dpc_mjx import sim
from dpc_mjx.control import balance, gait, qp
from dpc_mjx.control.closed_loop import init_loop
from dpc_mjx.control.controller import make_controller
from dpc_mjx.physics import NativePhysics
from dpc_mjx.robots import build
from dpc_mjx.robots.standing import perturbed_home

_OBJ_GAP_TOL = 1e-3  # relative objective gap vs OSQP
_VIOLATION_TOL = 1e-3  # max(G x - h), relative to the force scale max(1, |h|_inf)
_BATCH = 4
_TICKS = 150  # 0.6 s of trotting: two full gait cycles, every contact pattern


@pytest.fixture(scope="module")
def recorded():
    """(n, ...) P, q, G, h of the balance QPs a trotting `regular` robot solved, with random u."""
    model = build("regular")
    mx = sim.put_model(model)
    physics = NativePhysics(model)
    ctl = make_controller(model, gait_=gait.trot())
    data = sim.batched_data(
        mx, perturbed_home(model, _BATCH, seed=7), np.tile(model.key_ctrl[0], (_BATCH, 1))
    )
    ls = init_loop(ctl, data)
    rng = np.random.default_rng(0)
    # u ~ U(-20, 20) N and U(-5, 5) N·m per env, held for the run
    u = jp.asarray(
        np.concatenate(
            [rng.uniform(-20, 20, (_BATCH, 3)), rng.uniform(-5, 5, (_BATCH, 3))], axis=1
        ),
        jp.float32,
    )
    command = jp.array([0.4, 0.0, 0.3])

    def run(cs, d, uu):
        def tick(carry, _):
            cs, d = carry
            prob = ctl.balance_qp(ctl.plan(cs, d, command), uu)
            cs, ctrl = ctl.step(cs, d, command, uu)
            return (cs, physics.step(d.replace(ctrl=ctrl))), (prob.P, prob.q, prob.G, prob.h)

        return jax.lax.scan(tick, (cs, d), None, length=_TICKS)[1]

    P, q, G, h = jax.jit(jax.vmap(run))(ls.ctrl, ls.data, u)
    return [np.asarray(x).reshape(-1, *x.shape[2:]) for x in (P, q, G, h)]


def _osqp(P, q, G, h):
    solver = osqp.OSQP()
    solver.setup(
        sp.csc_matrix(np.triu(P)),
        q,
        sp.csc_matrix(G),
        -np.inf * np.ones_like(h),
        h,
        eps_abs=1e-9,
        eps_rel=1e-9,
        polishing=True,
        verbose=False,
        max_iter=200000,
    )
    return solver.solve(raise_error=False).x


def test_solver_matches_osqp_on_recorded_controller_qps(recorded):
    """Solved as the controller solves them (with balance.G_PATTERN), cold."""
    P, q, G, h = recorded
    assert P.shape[0] == _BATCH * _TICKS
    solve = jax.jit(jax.vmap(lambda *a: qp.solve(*a, g_pattern=balance.G_PATTERN)))
    res = solve(*(jp.asarray(x) for x in recorded))
    x = np.asarray(res.x, np.float64)
    gaps, viols = [], []
    for i in range(P.shape[0]):
        xr = _osqp(
            P[i].astype(np.float64),
            q[i].astype(np.float64),
            G[i].astype(np.float64),
            h[i].astype(np.float64),
        )
        obj = 0.5 * x[i] @ P[i] @ x[i] + q[i] @ x[i]
        ref = 0.5 * xr @ P[i] @ xr + q[i] @ xr
        gaps.append(abs(obj - ref) / max(1.0, abs(ref)))
        viols.append(max(0.0, np.max(G[i] @ x[i] - h[i])) / max(1.0, np.abs(h[i]).max()))
    assert max(gaps) <= _OBJ_GAP_TOL, f"worst relative objective gap {max(gaps):.2e}"
    assert max(viols) <= _VIOLATION_TOL, f"worst violation {max(viols):.2e}"
    assert bool(np.all(res.valid))
