"""dpc_mjx.control.mpc: the convex MPC's model, its condensed QP against OSQP, and the low level
'mpc' under the envs (stand and trot under MBC, abused envs stay finite).

The QPs are checked with test_qp's named tolerances (`check_against_reference`: objective gap,
violation, stationarity, complementarity against OSQP in float64, tight and polished) on
sampled problems and on the problems the controller itself built in a closed-loop run. The
default suite runs one stand-and-trot case (A1, `regular`, native, 16 envs x 10 s); `make
test-all` runs every named base with and without an arm, and a short MJX run.
"""

from __future__ import annotations

import types

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import fast_jit
from mujoco import mjx
from test_qp import check_against_reference, osqp_reference

from dpc_mjx import DpcError, make
from dpc_mjx.control import balance, gait, mpc
from dpc_mjx.control.controller import make_controller
from dpc_mjx.control.state import read_state
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.observations import PRIVILEGED
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.robots import build
from dpc_mjx.run.cli_tools import parse_sets
from dpc_mjx.run.config import RunConfig

CONFIG = mpc.MPCConfig()
PARAMS = balance.default_params()
N = CONFIG.steps
_ROLLOUT_TOL = 1e-4  # |gamma F + x_free - rollout| / max(1, |x|): float32, 10 steps
_SUPPORT_TOL = 0.03  # relative error of the summed f_z of a level standing plan to m g
SEED = 7  # chose nothing
CHECK = {  # tests/test_bases.py's check: MBC, no pushes, 0.3 m/s forward
    "controller": "mbc",
    "push_force": (0.0, 0.0),
    "command_vx": (0.3, 0.3),
    "command_vy": (0.0, 0.0),
    "command_yaw": (0.0, 0.0),
}


def sampled_problems(n: int, seed: int) -> list[mpc.MPCQP]:
    """n MPC QPs from `balance.sample_states` (A1-like stance, attitude and velocity errors), the
    trot's schedule from a random time, a random wrench sequence (|f| <= 50 N, |tau| <= 15 N·m per
    axis), the reference moving at the sampled desired velocity."""
    rng = np.random.default_rng(seed)
    states = balance.sample_states(rng, n)
    trot = gait.trot()

    def one(st, t, wrench):
        yaw = jp.arctan2(st["rot_des"][1, 0], st["rot_des"][0, 0])
        x0 = mpc.state_vector(st["com_pos"], st["com_vel"], st["rot"], st["ang_vel"], yaw)
        x_ref = mpc.reference(CONFIG, st["com_pos_des"], st["com_vel_des"], yaw, 0.3)
        stance = mpc.schedule(CONFIG, trot, t)
        hips = st["foot_pos"].at[:, 2].set(st["com_pos"][2])
        feet = mpc.levers(CONFIG, stance, st["foot_pos"], hips, st["com_vel_des"])
        return mpc.build_mpc_qp(PARAMS, CONFIG, x0, x_ref, feet, stance, wrench)

    t = jp.asarray(rng.uniform(0.0, 1.0, n), jp.float32)
    wrench = rng.uniform(-1.0, 1.0, (n, N, 6)) * np.array([50.0] * 3 + [15.0] * 3)
    return jax.jit(jax.vmap(one))(states, t, jp.asarray(wrench, jp.float32))


_solve_batch = jax.jit(jax.vmap(lambda prob: mpc.solve_mpc(CONFIG, prob)))


def _check_against_osqp(probs: mpc.MPCQP) -> dict[str, float]:
    _, res = _solve_batch(probs)
    problems = (probs.P, probs.q, probs.G, probs.h)
    return check_against_reference(res, problems, osqp_reference(*problems))


def test_condensed_dynamics_match_a_step_by_step_rollout():
    """X = gamma F + x_free is the model x_{k+1} = A_k x_k + B_k f_k + D_k w_k + g_k rolled out."""
    rng = np.random.default_rng(1)
    feet = jp.asarray(rng.normal(size=(N, 4, 3)) * 0.2, jp.float32)
    contact = jp.asarray(rng.random((N, 4)) < 0.6)
    yaws, coms = jp.asarray(rng.uniform(-3, 3, N)), jp.asarray(rng.normal(size=(N, 3)))
    A, B, D, g = jax.vmap(lambda *a: mpc.step_model(PARAMS, CONFIG.dt, *a))(
        yaws, coms, feet, contact
    )
    x0 = jp.asarray(rng.normal(size=12), jp.float32)
    f = jp.asarray(rng.normal(size=(N, 12)) * 40.0, jp.float32)
    w = jp.asarray(rng.normal(size=(N, 6)) * 10.0, jp.float32)
    e = jp.einsum("kij,kj->ki", D, w) + g
    gamma, x_free = mpc.condense(A, B, e, x0)
    x, rollout = x0, []
    for k in range(N):
        x = A[k] @ x + B[k] @ f[k] + D[k] @ w[k] + g[k]
        rollout.append(x)
    condensed = np.asarray(gamma @ f.reshape(-1) + x_free).reshape(N, 12)
    rollout = np.asarray(jp.stack(rollout))
    err = np.abs(condensed - rollout).max() / max(1.0, np.abs(rollout).max())
    assert err <= _ROLLOUT_TOL, err
    # the zero-order hold is exact: v gains dt (f/m - g), p gains dt^2/2 of it, step 0
    acc = (f[0].reshape(4, 3) * contact[0][:, None]).sum(0) / PARAMS.mass + w[0, :3] / PARAMS.mass
    acc = acc - jp.array([0.0, 0.0, balance.GRAVITY])
    np.testing.assert_allclose(rollout[0, 9:], x0[9:] + CONFIG.dt * acc, rtol=1e-5, atol=1e-5)
    want_p = x0[3:6] + CONFIG.dt * x0[9:] + 0.5 * CONFIG.dt**2 * acc
    np.testing.assert_allclose(rollout[0, 3:6], want_p, rtol=1e-5, atol=1e-5)


def test_sampled_mpc_qps_match_osqp():
    probs = sampled_problems(48, seed=0)
    assert probs.P.shape == (48, 12 * N, 12 * N) and probs.G.shape == (48, 24 * N, 12 * N)
    G = np.asarray(probs.G)
    assert not G[:, ~mpc.g_pattern(N)].any()  # G lies in the pattern the solver is given
    _check_against_osqp(probs)


def test_the_controllers_own_mpc_qps_match_osqp():
    """The QPs the controller built along a closed-loop trot with the `regular` arm (A1, MBC,
    native, 2 envs x 0.6 s, every 4th env step), u the arm's measured wrench held."""
    env = make("reaching", arm="regular", engine="native", low_level="mpc", **CHECK)
    ctl = env.controller
    step, state = (
        jax.jit(jax.vmap(env.step)),
        jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(SEED), 2)),
    )

    def problem(cs, d):
        p = ctl.plan(cs, d, jp.array([0.3, 0.0, 0.0]))
        u = env._oracle(d)
        desired = (p.pos_des, p.vel_des, p.yaw_des, p.yaw_rate_des)
        feet = ctl._contact_points(p.state)
        wrench = jp.tile(u, (N, 1))
        return mpc.controller_qp(CONFIG, ctl.config.balance, ctl.config.gait, cs.t, p.state,
                                 feet, desired, wrench)  # fmt: skip

    probs = []
    for i in range(30):
        state = step(state, jp.zeros((2, 6)))
        if i % 4 == 3:
            probs.append(jax.jit(jax.vmap(problem))(state.info["ctrl"], state.pipeline_state))
    assert not np.asarray(state.done).any()
    _check_against_osqp(jax.tree.map(lambda *a: jp.concatenate(a), *probs))


def test_a_level_standing_plan_holds_the_weight_and_swing_feet_carry_nothing():
    model = build("none")
    ctl = make_controller(model, low_level="mpc")
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    s = read_state(ctl.idx, mjx.put_data(model, data))
    feet = s.foot_pos.at[:, 2].set(0.0)
    params, cfg = ctl.config.balance, ctl.config.mpc
    level = jp.concatenate([jp.zeros(3), s.com_pos, jp.zeros(6)])
    x_ref = jp.tile(level, (N, 1))
    for t, n_stance in ((0.0, 4), (0.05, 2)):
        stance = mpc.schedule(cfg, gait.trot() if n_stance == 2 else gait.stand(), jp.asarray(t))
        prob = mpc.build_mpc_qp(params, cfg, level, x_ref, jp.tile(feet, (N, 1, 1)), stance,
                                jp.zeros((N, 6)))  # fmt: skip
        forces, res = jax.jit(lambda p: mpc.solve_mpc(cfg, p))(prob)
        assert bool(res.converged)
        weight = float(params.mass) * balance.GRAVITY
        support = float(forces[0, :, 2].sum())
        assert abs(support / weight - 1.0) <= _SUPPORT_TOL, (n_stance, support, weight)
        swing = ~np.asarray(stance)
        assert swing.any() == (n_stance == 2)
        assert np.all(np.asarray(forces)[swing] == 0.0)  # exactly: masked, and boxed at 0


def test_low_level_is_an_env_option_with_a_clear_error():
    assert EnvConfig().low_level == "qp"
    assert EnvConfig().replace(low_level="mpc").low_level == "mpc"
    with pytest.raises(
        DpcError, match=r"low_level='lqr' is not valid; choose one of \['qp', 'mpc'\]"
    ):
        EnvConfig().replace(low_level="lqr")
    with pytest.raises(
        DpcError, match="low_level='MPC' is not a low-level controller; choose 'qp'"
    ):
        make_controller(build("none"), low_level="MPC")
    assert make_controller(build("none")).config.mpc is None  # 'qp', today's, by default
    run = RunConfig().replace(**parse_sets(["env.low_level=mpc"]))  # --set env.low_level=mpc
    assert run.env_overrides == {"low_level": "mpc"}
    with pytest.raises(DpcError, match="low_level"):
        RunConfig().replace(**parse_sets(["env.low_level=mcp"]))


def _trot(base: str, arm: str, engine: str, gait_: str, envs: int, seconds: float) -> dict:
    kw = CHECK | ({"gait": "stand", "command_vx": (0.0, 0.0)} if gait_ == "stand" else {})
    env = make("reaching", arm=arm, base=base, engine=engine, low_level="mpc", **kw)
    assert env.controller.config.mpc is not None
    return run_episodes(env, envs, round(seconds / env.config.policy_dt), seed=SEED)


def _assert_no_falls(ep: dict, what: str) -> None:
    assert np.sum(ep["fell"]) == 0, f"{what}: {int(np.sum(ep['fell']))} falls"
    assert np.sum(ep["nan"]) == 0, f"{what}: {int(np.sum(ep['nan']))} NaN resets"


def test_mbc_on_the_mpc_trots_on_the_a1_with_an_arm():
    _assert_no_falls(_trot("a1", "regular", "native", "trot", envs=16, seconds=10.0), "a1")


@pytest.mark.slow
@pytest.mark.parametrize("gait_", ["stand", "trot"])
@pytest.mark.parametrize("arm", ["none", "regular"])
@pytest.mark.parametrize("base", ["a1", "go1", "go2", "b1"])
def test_mbc_on_the_mpc_stands_and_trots_on_every_named_base(base, arm, gait_):
    what = f"{base}/{arm}/{gait_}"
    _assert_no_falls(_trot(base, arm, "native", gait_, envs=16, seconds=10.0), what)


@pytest.mark.slow
def test_mbc_on_the_mpc_trots_under_mjx():
    _assert_no_falls(_trot("a1", "regular", "mjx", "trot", envs=4, seconds=1.0), "a1/mjx")


@pytest.mark.parametrize("low_level", ["qp", "mpc"])
def test_an_abused_env_gives_nothing_non_finite(low_level, monkeypatch):
    """Pushes of 3 kN on the gripper and NaN or huge actions under DPC: every output finite (the
    NaN guard resets what breaks, `envs/outcome.py`)."""
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: 4 envs, 20 steps
    env = make(
        "reaching", arm="regular", engine="native", low_level=low_level, controller="dpc",
        push_force=(3000.0, 3000.0), push_gap=(0.0, 0.05), push_duration=(0.05, 0.2),
    )  # fmt: skip
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(SEED), 4))
    step = jax.jit(jax.vmap(env.step))
    rng = np.random.default_rng(SEED)
    push = 0.0  # N, the largest push seen
    for i in range(20):
        action = rng.normal(size=(4, 6)) * 1e3
        action[i % 4] = np.nan
        state = step(state, jp.asarray(action, jp.float32))
        d = state.pipeline_state
        leaves = jax.tree.leaves(state.replace(pipeline_state=None)) + [d.qpos, d.qvel, d.ctrl]
        bad = [
            a for a in leaves if jp.issubdtype(a.dtype, jp.floating) and not jp.isfinite(a).all()
        ]
        assert not bad, f"step {i}: non-finite outputs"
        ee_force = np.asarray(state.info["privileged"])[:, PRIVILEGED["ee_force"]]
        push = max(push, float(np.linalg.norm(ee_force, axis=1).max()))
    assert push >= 2900.0, push  # the pushes did reach the envs


_TRACK_TOL = 1e-4  # m/s^2: float32, one 6-vector of sums


def test_between_solves_the_qp_tracks_the_plans_predicted_state():
    """`tracked_acceleration`: on the state the plan predicts it is the plan's own acceleration
    (its forces' and wrench's, no feedback); off it by dz in height, eq. 9's feedback adds
    -Kp_z dz, and by dv in vertical velocity -Kd_z dv (the balance QP's gains)."""
    rng = np.random.default_rng(SEED)
    states = jp.asarray(rng.normal(0.0, 0.05, (N + 1, 12)), jp.float32).at[:, 5].add(0.26)
    plan = mpc.MPCPlan.zeros(CONFIG).replace(
        forces=jp.asarray(rng.uniform(0.0, 40.0, (N, 4, 3)), jp.float32), states=states
    )
    feet = jp.asarray(
        [[0.18, -0.13, 0.0], [0.18, 0.13, 0.0], [-0.18, -0.13, 0.0], [-0.18, 0.13, 0.0]]
    )
    t = 1.5 * CONFIG.dt  # halfway through step 1
    x = states[1] + 0.5 * (states[2] - states[1])  # what the plan predicts at t

    def tracked(dz=0.0, dv=0.0):
        s = types.SimpleNamespace(
            com_pos=x[3:6].at[2].add(dz), com_vel=x[9:12].at[2].add(dv),
            rot=mpc.euler_matrix(x[0:3]), ang_vel=x[6:9],
        )  # fmt: skip
        return np.asarray(mpc.tracked_acceleration(CONFIG, PARAMS, plan, t, s, feet))

    on = tracked()
    M, _ = balance.wrench_matrix(PARAMS, x[3:6], mpc.euler_matrix(x[0:3]), feet, jp.ones(4, bool))
    planned = np.asarray(M @ plan.forces[1].reshape(-1)) - [0, 0, balance.GRAVITY, 0, 0, 0]
    np.testing.assert_allclose(on, planned, atol=_TRACK_TOL)
    kp, kd = np.asarray(PARAMS.kp), np.asarray(PARAMS.kd)
    np.testing.assert_allclose(tracked(dz=0.01)[2] - on[2], -kp[2] * 0.01, atol=_TRACK_TOL)
    np.testing.assert_allclose(tracked(dv=0.1)[2] - on[2], -kd[2] * 0.1, atol=_TRACK_TOL)


_PLAN_TOL = 1.0  # N: a closed-loop plan's forces against its problem solved to convergence


def test_the_closed_loops_plans_are_at_the_optimum():
    """MBC on the MPC trotting with the `regular` arm under pushes (native, exact sensors, 4 envs
    x 36 env steps): every fourth step's plan (solved at the step's first tick) has the forces of
    its problem solved to convergence (rebuilt from the state before the step, 60 iterations),
    within 1 N. Warm-started from the plan before it, 10 iterations left them up to 160 N off."""
    env = make(
        "reaching", arm="regular", engine="native", low_level="mpc", controller="mbc",
        sensor_noise=0.0, push_force=(30.0, 60.0),
    )  # fmt: skip
    ctl = env.controller
    converged = ctl.config.mpc.replace(iterations=60)

    def optimum(cs, d, command):  # (N, 4, 3) N: MBC's wrench is 0 over the horizon
        p = ctl.plan(cs, d, command)
        desired = (p.pos_des, p.vel_des, p.yaw_des, p.yaw_rate_des)
        wrench = jp.zeros((N, 6))
        prob = mpc.controller_qp(converged, ctl.config.balance, ctl.config.gait, cs.t, p.state,
                                 ctl._contact_points(p.state), desired, wrench)  # fmt: skip
        return mpc.solve_mpc(converged, prob)[0]

    step, optimum = jax.jit(jax.vmap(env.step)), jax.jit(jax.vmap(optimum))
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(SEED), 4))
    worst = 0.0
    for i in range(36):
        new = step(state, jp.zeros((4, 6)))
        if i % 4 == 3:
            want = optimum(state.info["ctrl"], state.pipeline_state, new.info["dist"].command)
            worst = max(worst, float(np.abs(new.info["ctrl"].mpc.forces - want).max()))
        state = new
    assert not np.asarray(state.done).any()
    assert worst <= _PLAN_TOL, worst
