"""dpc_mjx.control.mpc_kkt: the MPC's Riccati normal solver against dense linear algebra.

On the MPC's own QPs (`test_mpc.sampled_problems`): P x and diag(P) of the implicit P against the
dense P that `MPCQP.P` forms, and the Riccati factor's solve of Hs y = b against a dense solve of
the same Hs, at random weights w of G' diag(w) G and random scalings. The solver's end-to-end
accuracy (against OSQP, and closed loop) is tests/test_mpc.py's.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from test_mpc import CONFIG, N, sampled_problems

from dpc_mjx.control import mpc, mpc_kkt
from dpc_mjx.control.qp.normal import NormalParts
from dpc_mjx.control.qp.structure import _structure

_MATVEC_TOL = 1e-5  # |P x - dense| / max |dense|, float32, 10 steps
_SOLVE_TOL = 1e-3  # |Hs y - b| / |b|, float32: Hs spans several decades


def _data(prob: mpc.MPCQP) -> tuple:
    return (prob.A, prob.B, CONFIG.Q, jp.asarray(CONFIG.R, jp.float32))


def test_implicit_p_matches_the_dense_p():
    probs = sampled_problems(8, seed=3)
    solver = mpc_kkt.RiccatiSolver(N)
    x = jp.asarray(np.random.default_rng(0).normal(size=(8, 12 * N)) * 50.0, jp.float32)
    px = jax.vmap(lambda p, x: solver.p_matvec(_data(p), x))(probs, x)
    dense = jp.einsum("bij,bj->bi", probs.P, x)
    assert float(jp.max(jp.abs(px - dense)) / jp.max(jp.abs(dense))) <= _MATVEC_TOL
    diag = jax.vmap(lambda p: solver.p_diagonal(_data(p)))(probs)
    want = jp.diagonal(probs.P, axis1=1, axis2=2)
    np.testing.assert_allclose(diag, want, rtol=_MATVEC_TOL, atol=1e-8)


def test_riccati_solve_matches_a_dense_solve():
    """Hs = c D P D + Gs' W Gs (+ floor diag): the factor's solve against numpy's in float64."""
    rng = np.random.default_rng(1)
    prob = jax.tree.map(lambda a: a[0], sampled_problems(1, seed=4))
    n, pattern = 12 * N, mpc.g_pattern(N)
    st = _structure(24 * N, n, tuple(map(tuple, pattern.tolist())))
    rows, cols = st.normal_entries
    d = rng.uniform(0.5, 2.0, n)
    c = 0.3
    Gs = np.asarray(prob.G) * rng.uniform(0.5, 2.0, (24 * N, 1)) * d  # E G D
    w = 10.0 ** rng.uniform(-3, 3, 24 * N)
    gwg = (Gs.T * w) @ Gs
    P = np.asarray(prob.P, np.float64)
    Hs = c * d[:, None] * P * d[None, :] + gwg
    parts = NormalParts(
        d=jp.asarray(d, jp.float32), c=jp.asarray(c, jp.float32),
        p_diag=jp.asarray(np.diag(Hs - gwg), jp.float32),
        gwg=jp.asarray(gwg[rows, cols], jp.float32), one=jp.ones(()), rows=rows, cols=cols,
    )  # fmt: skip
    floor = 1e-6
    factor = mpc_kkt.RiccatiSolver(N).factor(_data(prob), parts, floor)
    b = rng.normal(size=n)
    y = np.asarray(factor.solve(jp.asarray(b, jp.float32)), np.float64)
    H = Hs + np.diag(floor * np.diag(Hs))
    assert np.abs(H @ y - b).max() / np.abs(b).max() <= _SOLVE_TOL
