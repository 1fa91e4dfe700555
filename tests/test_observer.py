"""The momentum disturbance observer (`control/observer.py`): its equation on synthetic motion, and
in simulation (MuJoCo C, the native engine: `tests/helpers.ENGINE`) against a known trunk wrench
(the bench) and against the oracle's u (the env).

The observer estimates every wrench on the A1 that its model does not explain. On the bare A1 at
rest that is, besides an applied wrench, the legs' weight that the torques tau = J^T f do not
carry (the feet push harder than the QP asked): `_legs_term` computes it from the data (for each
stance foot f_actual - f_commanded = J^-T qfrc_bias[leg], the static leg equation; qfrc_bias from
MuJoCo C's mj_forward on the state), and the tests
check the estimate against the applied wrench plus this term, and bound the term itself.
"""

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import ENGINE, FAST_COMPILE, STANDING_STILL

import dpc_mjx
from dpc_mjx import DpcError, sim
from dpc_mjx.control import balance, gait, observer
from dpc_mjx.control.closed_loop import init_loop, make_chunk
from dpc_mjx.control.controller import make_controller
from dpc_mjx.control.state import BodyState, read_state
from dpc_mjx.envs import DEFAULT_TASK
from dpc_mjx.physics import NativePhysics
from dpc_mjx.robots import build
from dpc_mjx.robots.bases.a1 import FOOT_RADIUS
from dpc_mjx.robots.standing import perturbed_home
from dpc_mjx.rotations import skew_np

_DT = 0.004  # s, the controller tick
_BATCH = 2
_TICKS = 125  # 0.5 s per compiled bench chunk
_SETTLE = 1.5  # s: 5/K = 0.25 s of the observer after the controller's own ~0.5 s start-up
_LAG_RTOL = 1e-4  # synthetic step response vs E (1 - (1 - K dt)^k), float32
_TUMBLE_TOL = 0.01  # torque-free tumbling: |r_tau| / max |omega x I_w omega|
# Bench, bare A1 standing, u = the estimate: estimate vs applied wrench + legs' term, per axis,
# after _SETTLE (measured at K = 20 rad/s: <= 0.07 N, 0.18 N·m for (0, 0, -30, 2, -3, 0);
# 0.8 N, 0.33 N·m for the 44 N 'general' wrench with 13 N horizontal force: 3 % of its norm).
_WRENCH_TOL_F = 1.2  # N, per axis
_WRENCH_TOL_TAU = 0.5  # N·m, per axis
# The legs' term at rest, the observer's model error on the bare A1 (measured |f| 11.7-11.9 N,
# mostly +10.5 N f_z, 9 % of the weight, and -5.2 N f_x; |tau| 1.3 N·m).
_LEGS_MAX_F = 15.0  # N, norm
_LEGS_MAX_TAU = 2.0  # N·m, norm
# Env, regular arm standing, no pushes: estimate's f_z vs the oracle's f_z + the legs' term over
# 0.4 s after 0.2 s (measured max 0.7 N, 0.1 N at the end; without the legs' term the gap is
# 10.2-10.5 N: the estimate's f_z is ~0 where the oracle's is -9.5 to -11.7 N).
_ENV_FZ_TOL = 1.2  # N
_ENV_SETTLE_STEPS, _ENV_STEPS = 10, 30  # env steps of 20 ms

# -- the equation, on synthetic motion ----------------------------------------------------------

_MODEL = balance.default_params(mass=12.0, inertia=(0.05, 0.2, 0.22))


@jax.jit
def _estimates(com_vel, rot, ang_vel, forces=None, config=observer.ObserverConfig()):
    """(T, 6) estimates over T ticks of (T, 3) com_vel, (T, 3, 3) rot, (T, 3) ang_vel, the feet
    at the COM; `forces` (T, 4, 3) N the ground forces the observer is told were commanded at the
    previous tick (None: none, a body in free flight); default gains."""
    zeros = jp.zeros((4, 3))
    forces = jp.zeros((com_vel.shape[0], 4, 3)) if forces is None else forces

    def body(i):
        return BodyState(
            jp.zeros(3), com_vel[i], rot[i], ang_vel[i], zeros, zeros, zeros, jp.zeros((4, 3, 3))
        )

    def tick(ob, i):
        ob = observer.update(config, _MODEL, ob, body(i), forces[i], _DT, 0.0)
        return ob, ob.estimate

    ob0 = observer.init(config, _MODEL, body(0))
    return jax.lax.scan(tick, ob0, jp.arange(com_vel.shape[0]))[1]


def test_a_constant_wrench_is_estimated_with_a_first_order_lag():
    """p_k = p_0 + k (F_known + E) dt exactly -> r_k = E (1 - (1 - K dt)^k), k ticks after init."""
    n = 100
    ext = np.array([5.0, -3.0, 20.0, 1.0, -2.0, 0.5])  # N, N·m
    f_known = np.array([0.0, 0.0, -balance.GRAVITY * float(_MODEL.mass)])  # weight only
    t = np.arange(n)[:, None] * _DT  # the first tick reads init's state
    com_vel = (f_known + ext[:3]) / float(_MODEL.mass) * t
    ang_vel = np.linalg.solve(np.asarray(_MODEL.inertia), ext[3:]) * t  # rot = I: I_w = I_B
    r = np.asarray(_estimates(com_vel, np.tile(np.eye(3), (n, 1, 1)), ang_vel))
    k = np.asarray(observer.ObserverConfig().gains())
    expected = ext * (1.0 - (1.0 - k * _DT) ** np.arange(n)[:, None])
    np.testing.assert_allclose(r, expected, rtol=_LAG_RTOL, atol=_LAG_RTOL * np.abs(ext).max())
    one_lag = round(1.0 / (k[0] * _DT))  # ticks in one time constant 1/K: 1 - 1/e of the step
    assert np.all(np.abs(r[one_lag] / ext - (1 - np.exp(-1))) < 0.03), r[one_lag] / ext


def test_an_aligned_observer_integrates_the_forces_that_acted():
    """Ground forces commanded at tick j act over [t_{j+D}, t_{j+D+1}] (D = 2 ticks of delay):
    the observer aligned to D (`delay=D`) estimates a constant external wrench with the same
    first-order lag as with no delay; the one that integrates the previous tick's forces is off
    by the forces' change over D ticks, filtered."""
    n, delay = 150, 2
    mass = float(_MODEL.mass)
    ext = np.array([5.0, -3.0, 20.0, 0.0, 0.0, 0.0])  # N; no torque (the feet at the COM)
    t = np.arange(n) * _DT
    f_z = mass * balance.GRAVITY / 4 * (1.0 + 0.3 * np.sin(2 * np.pi * t / 0.3))  # N per foot
    commanded = np.zeros((n, 4, 3))
    commanded[:, :, 2] = f_z[:, None]  # commanded at tick j
    acting = np.concatenate([np.zeros((delay, 4, 3)), commanded[:-delay]])  # over [t_j, t_j+1]
    weight = np.array([0.0, 0.0, -balance.GRAVITY * mass])
    dv = (acting.sum(axis=1) + weight + ext[:3]) / mass * _DT  # (n, 3) m/s per tick
    com_vel = np.concatenate([np.zeros((1, 3)), np.cumsum(dv, axis=0)[:-1]])  # v at t_k
    told = np.concatenate([np.zeros((1, 4, 3)), commanded[:-1]])  # tick k: commanded at k - 1
    rot, ang_vel = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
    aligned = observer.ObserverConfig(delay=delay)
    r = np.asarray(_estimates(com_vel, rot, ang_vel, told, aligned))
    k = np.asarray(aligned.gains())
    expected = ext * (1.0 - (1.0 - k * _DT) ** np.arange(n)[:, None])
    np.testing.assert_allclose(r, expected, rtol=_LAG_RTOL, atol=_LAG_RTOL * np.abs(ext).max())
    unaligned = np.asarray(_estimates(com_vel, rot, ang_vel, told))
    assert np.abs(unaligned - expected)[n // 2 :, 2].max() > 1.0  # N: what alignment removes


def test_torque_free_tumbling_needs_no_gyroscopic_term():
    """L = R I_B R^T omega is conserved without torque, so r stays 0 while omega x I_w omega
    (which F_known must not contain) is large. Euler's equations in the body frame,
    I_B dw/dt = -w x I_B w and dR/dt = R [w]x, by RK4 in 0.1 ms steps."""
    inertia = np.asarray(_MODEL.inertia, float)
    w0 = np.array([3.0, 1.0, -2.0])  # rad/s, body frame, not about a principal axis

    def deriv(x):  # x = (R (9), w_body (3))
        rot, w = x[:9].reshape(3, 3), x[9:]
        dw = np.linalg.solve(inertia, -np.cross(w, inertia @ w))
        return np.concatenate([(rot @ skew_np(w)).ravel(), dw])

    x, h, rots, omegas = np.concatenate([np.eye(3).ravel(), w0]), 1e-4, [], []
    for i in range(100 * 40):
        if i % 40 == 0:  # every 4 ms
            rots.append(x[:9].reshape(3, 3))
            omegas.append(rots[-1] @ x[9:])  # world frame
        k1 = deriv(x)
        k2 = deriv(x + h / 2 * k1)
        k3 = deriv(x + h / 2 * k2)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + deriv(x + h * k3))
    rots, omegas = np.array(rots), np.array(omegas)
    com_vel = np.array([0.0, 0.0, -balance.GRAVITY]) * np.arange(len(rots))[:, None] * _DT
    r = np.asarray(_estimates(com_vel, rots, omegas))
    gyro = np.cross(omegas, np.einsum("tij,jk,tlk,tl->ti", rots, inertia, rots, omegas))
    assert np.abs(r[:, 3:]).max() < _TUMBLE_TOL * np.linalg.norm(gyro, axis=1).max()
    assert np.abs(r[:, :3]).max() < 1e-3  # N: free fall is explained by the weight


def test_gains_must_be_below_the_tick_rate():
    observer.ObserverConfig(k_force=(10.0, 20.0, 30.0)).validate(_DT)
    for bad in (dict(k_force=0.0), dict(k_torque=300.0), dict(k_force=(1.0, 2.0))):
        with pytest.raises(DpcError, match="rad/s"):
            observer.ObserverConfig(**bad).validate(_DT)
    for delay in (-1, 11, 1.0):
        with pytest.raises(DpcError, match="sensor_delay"):
            observer.ObserverConfig(delay=delay).validate(_DT)


# -- the bench: bare A1 standing, u = the estimate ----------------------------------------------


def _reader(idx):
    """jit(vmap(read_state)) for a batch of data."""
    return jax.jit(jax.vmap(lambda d: read_state(idx, d)))


def _bias_in_c(model, data) -> np.ndarray:
    """(B, nv) qfrc_bias (N, N·m: gravity, Coriolis) of each env's qpos, qvel, from MuJoCo C's
    mj_forward (the native engine does not hand qfrc_bias back; the env reads none of it)."""
    one = mujoco.MjData(model)
    out = []
    for qpos, qvel in zip(np.asarray(data.qpos), np.asarray(data.qvel), strict=True):
        one.qpos[:], one.qvel[:] = qpos, qvel
        mujoco.mj_forward(model, one)
        out.append(one.qfrc_bias.copy())
    return np.stack(out)


def _legs_term(read, idx, data, stance, qfrc_bias) -> np.ndarray:
    """(B, 6) [N, N·m] about the A1 COM: the stance legs' weight not carried by tau = J^T f;
    `qfrc_bias` (B, nv) from `_bias_in_c`."""
    s = jax.device_get(read(data))
    bias = np.asarray(qfrc_bias)[:, idx.leg_dof]  # (B, 4, 3) N·m on the leg joints
    jac_t = np.swapaxes(np.asarray(s.foot_jac), -1, -2)  # (B, 4, joints, xyz)
    df = np.linalg.solve(jac_t, bias[..., None])[..., 0] * np.asarray(stance)[..., None]
    lever = np.asarray(s.foot_pos) - np.asarray(s.com_pos)[:, None]
    lever[..., 2] -= FOOT_RADIUS
    return np.concatenate([df.sum(1), np.cross(lever, df).sum(1)], axis=-1)


@pytest.fixture(scope="module")
def bench():
    """`settle(wrench)` -> (estimate, applied wrench about the A1 COM, legs' term), (B, 6) each,
    after _SETTLE s; one compiled chunk."""
    model = build("none")
    controller = make_controller(model, gait_=gait.stand())
    mx = sim.put_model(model)
    qpos = perturbed_home(model, _BATCH, seed=0)
    data = sim.batched_data(mx, qpos, np.tile(model.key_ctrl[0], (_BATCH, 1)))
    ls0 = init_loop(controller, data)
    chunk = make_chunk(mx, controller, _TICKS, kind="observer", physics=NativePhysics(model))
    idx = controller.idx
    read = _reader(idx)

    def settle(wrench):
        ls, w = ls0, jp.tile(jp.asarray(wrench, jp.float32), (_BATCH, 1))
        for _ in range(round(_SETTLE / (_TICKS * _DT))):
            ls = chunk(ls, jp.zeros((_BATCH, 3)), w, jp.zeros((_BATCH, 6)))
        ls = jax.device_get(ls)
        d = ls.data
        com = read(d).com_pos  # (B, 3) A1 COM; the wrench acts at the trunk COM, d.xipos
        lever = np.asarray(d.xipos[:, idx.trunk] - com)
        wrench = np.broadcast_to(wrench, (_BATCH, 6))
        known = np.concatenate([wrench[:, :3], wrench[:, 3:] + np.cross(lever, wrench[:, :3])], 1)
        assert np.all(np.isfinite(ls.ctrl.observer.estimate)) and not np.any(ls.metrics.fallen)
        return (
            np.asarray(ls.ctrl.observer.estimate),
            known,
            _legs_term(read, idx, d, ls.ctrl.stance, _bias_in_c(model, d)),
        )

    return settle


@pytest.mark.parametrize(
    "wrench",
    [(0.0, 0.0, -30.0, 2.0, -3.0, 0.0), (10.0, -8.0, -40.0, -3.0, 4.0, 1.5)],
    ids=["vertical", "general"],
)
def test_observer_recovers_a_constant_trunk_wrench(bench, wrench):
    estimate, known, legs = bench(np.array(wrench))
    err = estimate - known - legs
    assert np.all(np.abs(err[:, :3]) < _WRENCH_TOL_F), err
    assert np.all(np.abs(err[:, 3:]) < _WRENCH_TOL_TAU), err


def test_without_a_wrench_the_estimate_is_the_legs_model_error(bench):
    estimate, known, legs = bench(np.zeros(6))
    assert not known.any()
    err = estimate - legs
    assert np.all(np.abs(err[:, :3]) < _WRENCH_TOL_F), err
    assert np.all(np.abs(err[:, 3:]) < _WRENCH_TOL_TAU), err
    assert np.all(np.linalg.norm(estimate[:, :3], axis=1) < _LEGS_MAX_F), estimate
    assert np.all(np.linalg.norm(estimate[:, 3:], axis=1) < _LEGS_MAX_TAU), estimate


# -- the env: regular arm, u = the estimate, vs the oracle's u ---------------------------------


def test_env_observer_follows_the_oracles_vertical_force():
    """Standing, no pushes, exact sensors: the estimate's f_z is the oracle's (the arm's mount
    force) plus the legs' term, to _ENV_FZ_TOL; the env steps finitely and ignores the action."""
    env = dpc_mjx.make(
        DEFAULT_TASK,
        arm="regular",
        controller="observer",
        engine=ENGINE,
        **STANDING_STILL,
    )
    reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)
    step = jax.jit(jax.vmap(env.step), compiler_options=FAST_COMPILE)
    idx = env.controller.idx
    read = _reader(idx)
    state = reset(jax.random.split(jax.random.PRNGKey(0), _BATCH))
    zeros, ones = jp.zeros((_BATCH, env.action_size)), jp.ones((_BATCH, env.action_size))
    ignored = jax.device_get(step(state, ones).pipeline_state.qpos)
    gaps = []
    for i in range(_ENV_STEPS):
        state = step(state, zeros)
        if i == 0:  # the action is ignored
            np.testing.assert_array_equal(ignored, np.asarray(state.pipeline_state.qpos))
        s = jax.device_get(state)
        assert np.all(np.isfinite(s.info["ctrl"].observer.estimate)) and not np.any(s.done)
        if i >= _ENV_SETTLE_STEPS:
            bias = _bias_in_c(env.model, s.pipeline_state)
            legs = _legs_term(read, idx, s.pipeline_state, s.info["ctrl"].stance, bias)
            u_oracle = s.info["privileged"][:, :6]
            gaps.append(s.info["ctrl"].observer.estimate[:, 2] - u_oracle[:, 2] - legs[:, 2])
    assert np.abs(gaps).max() < _ENV_FZ_TOL, np.round(gaps, 2)
