"""Where one env step's time goes: each part of the reaching env's JAX work timed on its own.

    python experiments/profile_tick.py [--controllers mbc observer dpc] [--batch 64]
        [--engines mjx native] [--calls 20] [--repeats 3] [--compile] [--xla-dump DIR]

Each part runs as `jax.jit(jax.vmap(part))` on realistic states (a batch of `--batch` envs
after `--warmup` env steps of `dpc_mjx.envs.rollout`, the controller's own inputs computed from
them): the controller tick (`env.controller.step`) and inside it the state read, the sensor
errors, the gait schedule, the plan, the observer, the balance QP's build and solve, the swing
legs; the rest of a tick (sensor draw, the disturbance wrenches, the physics step under MJX and
under MuJoCo C); and once per env step the disturbance sampler, the observation, the reward, the
privileged values and the outcome (NaN guard, metrics), and the whole `env.step`. The base
state estimator (`control/estimator.py`) runs in `deploy` only, not in the env step: it is
timed apart.

Table: us per env (per tick for the parts that run each physics tick, per env step for the
others), and the share of one env step (`n_substeps` ticks): a part timed alone is not free of
the dispatch cost of a call (`dispatch`, an empty jitted call, is its floor) nor of the fusion
that its neighbours get in the whole step, so the shares need not sum to 100 %. Compile times
(`lower().compile()` of each part) are a column apart; `--compile` also times the first call
(compile included) of a 10-step `rollout.make_chunk` at the batch, and the compile of the
controller tick alone, of one env step and of the chunk. Times: `dpc_mjx.timing`, the best of
`--repeats` runs of `--calls` calls each.
"""

from __future__ import annotations

import argparse
import os

import jax
import jax.numpy as jp

import dpc_mjx
from dpc_mjx.control import estimator, gait, qp, sensors
from dpc_mjx.control.balance import G_PATTERN
from dpc_mjx.control.state import has_fallen, oracle_u, read_state
from dpc_mjx.envs import observations, outcome, rewards, rollout
from dpc_mjx.timing import Stopwatch, run_calls

CTRL_PARTS = ("plan", "observer", "QP build", "QP solve", "swing")


def _policy(controller: str):
    """Zero actions, or for 'dpc' uniform actions in [-0.5, 0.5] (a policy's u at work)."""
    if controller != "dpc":
        return rollout.zero_policy
    return lambda obs, key: jax.random.uniform(key, obs.shape[:-1] + (6,), minval=-0.5, maxval=0.5)


def _states(env, batch: int, warmup: int, controller: str):
    """(state, actions) of `batch` envs after `warmup` env steps."""
    carry, key = rollout.start(env, batch, seed=0)
    run = rollout.make_chunk(jax.vmap(env.step), _policy(controller), warmup)
    carry, _ = run(carry, key)
    actions = _policy(controller)(carry[0].obs, jax.random.PRNGKey(1))
    return jax.block_until_ready(carry[0]), actions


class Timer:
    """Compiles and times jit(vmap(fn)) calls; keeps the rows of the table."""

    def __init__(self, calls: int, repeats: int):
        self.calls, self.repeats, self.rows = calls, repeats, []

    def time(self, fn, *args, vmap=True) -> tuple[float, float]:
        """(compile s, s per call): best of the repeats."""
        jitted = jax.jit(jax.vmap(fn) if vmap else fn)
        with Stopwatch() as sw:
            compiled = jitted.lower(*args).compile()
        jax.block_until_ready(compiled(*args))
        best = min(
            run_calls(lambda _: compiled(*args), None, self.calls)[0] for _ in range(self.repeats)
        )
        return sw.seconds, best / self.calls

    def row(self, name: str, fn, *args, per_tick: bool, vmap=True):
        compile_s, seconds = self.time(fn, *args, vmap=vmap)
        self.rows.append((name, per_tick, seconds, compile_s))
        print(f"  {name}: {seconds * 1e6:.1f} us per call, compile {compile_s:.2f} s", flush=True)


def _inputs(env, state, actions):
    """The batched inputs of one tick, as the first tick of `env.step` sees them."""
    d, info = state.pipeline_state, state.info
    keys = jax.random.split(jax.random.PRNGKey(2), len(actions))

    def one(d, info, action, key):
        dist = env.sampler.advance(info["dist"], d.time, key)
        u_pol = env.policy_u(action)
        noise = sensors.draw(key, info["sensor_bias"], env.config.sensor_noise)
        u, *_ = env.controller_u(d, u_pol)  # (u, whether the estimate, the model are added)
        targets = env.arm_targets(dist, d.time, d)
        return dist, u_pol, noise, targets, u

    dist, u_pol, noise, targets, u = jax.jit(jax.vmap(one))(d, info, actions, keys)
    return d, info, dist, u_pol, noise, targets, u, keys


def _controller_parts(t: Timer, env, d, cs, command, u, noise):
    """The controller tick's parts, each on the inputs the tick gives it."""
    ctl = env.controller
    t.row("  read_state", lambda d: read_state(ctl.idx, d), d, per_tick=True)
    s = jax.jit(jax.vmap(lambda d: read_state(ctl.idx, d)))(d)
    t.row("  sensors.measured", sensors.measured, s, noise, per_tick=True)
    t.row("  gait schedule", lambda t_: gait.contact_schedule(ctl.config.gait, t_), cs.t,
          per_tick=True)  # fmt: skip
    t.row("  plan (read_state, measured, gait, desired)", ctl.plan, cs, d, command, noise,
          per_tick=True)  # fmt: skip
    plan = jax.jit(jax.vmap(ctl.plan))(cs, d, command, noise)
    t.row("  observer update", ctl._observe, cs, plan.state, per_tick=True)
    observed = jax.jit(jax.vmap(ctl._observe))(cs, plan.state)
    u_qp = observed.estimate if u is None else u
    t.row("  balance QP build", ctl.balance_qp, plan, u_qp, per_tick=True)
    prob = jax.jit(jax.vmap(ctl.balance_qp))(plan, u_qp)

    def solve(prob, warm):
        return qp.solve(prob.P, prob.q, prob.G, prob.h, warm_start=warm, g_pattern=G_PATTERN)

    t.row("  balance QP solve (10 IP iterations)", solve, prob, cs.qp, per_tick=True)
    t.row("  swing legs (Raibert, trajectory, PD)", lambda p, cs: ctl.swing_legs(cs, p), plan, cs,
          per_tick=True)  # fmt: skip


def _tick_rest(t: Timer, env, d, info, dist, keys):
    """The tick's work outside the controller and the physics."""
    t.row(
        "sensor errors (draw)",
        lambda k, b: sensors.draw(k, b, env.config.sensor_noise),
        keys,
        info["sensor_bias"],
        per_tick=True,
    )

    def wrenches(d, dist):
        xfrc = env._ee_wrench(d, env.sampler.ee_forces(dist, d.time, env._yaw(d)))
        xfrc = xfrc.at[env._object_bodies, :3].add(env.sampler.object_forces(dist))
        return env.task_physics(d.replace(xfrc_applied=xfrc), d.time, dist).xfrc_applied

    t.row("disturbance wrenches (ee forces, pushes)", wrenches, d, dist, per_tick=True)
    t.row("arm targets", lambda d, dist: env.arm_targets(dist, d.time, d), d, dist, per_tick=True)


def _step_parts(t: Timer, env, d, info, dist, keys, noise):
    """The parts that run once per env step."""
    t.row(
        "disturbance sampler (advance)",
        lambda i, d, k: env.sampler.advance(i["dist"], d.time, k),
        info,
        d,
        keys,
        per_tick=False,
    )
    est = info["ctrl"].observer.estimate
    t.row(
        "observation (+ sensor errors)",
        lambda d, dist, noise, e: env._measured(
            observations.observation(env.lay, d, dist.command, e), noise
        ),
        d,
        dist,
        noise,
        est,
        per_tick=False,
    )
    true_obs = jax.jit(jax.vmap(lambda d, c, e: observations.observation(env.lay, d, c, e)))(
        d, dist.command, est
    )

    def reward(sb, command):
        vel = jp.stack([sb[5], sb[6], observations.world_yaw_rate(sb)])
        return rewards.total_reward(vel, command, sb[:2], jp.zeros(2))

    sb = true_obs[:, env.obs_layout.s_body]
    t.row("reward", reward, sb, dist.command, per_tick=False)
    t.row("privileged (oracle u, pushes)", env._privileged, d, dist, per_tick=False)
    t.row(
        "oracle u alone",
        lambda d: oracle_u(env.lay, d, env.com_pos(d)),
        d,
        per_tick=False,
    )
    t.row(
        "ee_sq_err (mjx.jac per arm)",
        lambda d, dist: outcome.ee_sq_err(env.mx, env.lay, d, env.arm_targets(dist, d.time, d)),
        d,
        dist,
        per_tick=False,
    )
    cs = info["ctrl"]

    def guard(d0, d, cs0, cs, obs, priv, sb, command):
        vel = jp.stack([sb[5], sb[6], observations.world_yaw_rate(sb)])
        r = rewards.total_reward(vel, command, sb[:2], jp.zeros(2))
        fall = has_fallen(d.qpos[2], sb[:2], env.controller.fall_height)
        bad = outcome.is_bad(d, obs, priv, cs, r["r_total"], env.config.explode_speed)
        metrics = outcome.zero_if_bad(outcome.step_metrics(r, vel - command, sb, fall, bad), bad)
        keep = lambda new, old: jp.where(bad, old, new)  # noqa: E731
        return jax.tree.map(keep, d, d0), jax.tree.map(keep, cs, cs0), metrics

    priv = jax.jit(jax.vmap(env._privileged))(d, dist)
    t.row(
        "outcome (NaN guard, metrics, reward)",
        guard,
        d,
        d,
        cs,
        cs,
        true_obs,
        priv,
        sb,
        dist.command,
        per_tick=False,
    )


def _estimator(t: Timer, d, batch: int):
    """The base state estimator's update (deploy only), on zero-ish inputs of the batch."""
    cfg = estimator.EstimatorConfig()
    foot = jp.tile(jp.array([[0.2, 0.1, -0.26]] * 4), (batch, 1, 1))
    est = jax.vmap(lambda f: estimator.init(f, 0.02))(foot)  # the A1's feet (m)
    rot = jp.tile(jp.eye(3), (batch, 1, 1))
    t.row(
        "[deploy only] state estimator update",
        lambda e, r, f: estimator.update(cfg, e, r, jp.array([0, 0, 9.81]), f, 0 * f, jp.ones(4),
                                         0.004, 0.02),
        est,
        rot,
        foot,
        per_tick=True,
    )  # fmt: skip
    del d


def profile(controller: str, args) -> None:
    print(f"\n## reaching, arm regular, controller {controller}, batch {args.batch}\n", flush=True)
    env = dpc_mjx.make("reaching", arm="regular", controller=controller)
    t = Timer(args.calls, args.repeats)
    state, actions = _states(env, args.batch, args.warmup, controller)
    d, info, dist, u_pol, noise, targets, u, keys = _inputs(env, state, actions)
    cs, command = info["ctrl"], dist.command
    t.row("dispatch (empty jitted call)", lambda x: x + 1.0, d.time, per_tick=False)
    for engine in args.engines:
        e = env if engine == env.config.engine else dpc_mjx.make(
            "reaching", arm="regular", controller=controller, engine=engine
        )  # fmt: skip
        t.row(f"env.step ({engine})", e.step, state, actions, per_tick=False)
        t.row(f"physics step ({engine})", e.physics.step, d, per_tick=True)

    # u (B, 6) of the controller, or None (the observer's own estimate): an empty pytree
    t.row("controller tick (controller.step)", env.controller.step, cs, d, command, u, targets,
          noise, per_tick=True)  # fmt: skip
    _controller_parts(t, env, d, cs, command, u, noise)
    t.row("controller_u (u of the tick)", env.controller_u, d, u_pol, per_tick=True)
    _tick_rest(t, env, d, info, dist, keys)
    _step_parts(t, env, d, info, dist, keys, noise)
    _estimator(t, d, args.batch)
    _table(t.rows, env.n_substeps, args.batch, f"env.step ({args.engines[0]})")
    if args.compile:
        _compiles(env, state, actions, cs, d, command, u, targets, noise, args)


def _table(rows, n_sub: int, batch: int, step_name: str) -> None:
    step = next(s for name, _, s, _ in rows if name == step_name)
    print(f"\nshare: of one `{step_name}` ({n_sub} ticks); us per env = us per call / {batch}\n")
    print("| part | runs | us per env | share of the step | compile s |")
    print("|---|---|---:|---:|---:|")
    for name, per_tick, seconds, compile_s in rows:
        share = seconds * (n_sub if per_tick else 1) / step
        runs = "tick" if per_tick else "step"
        print(
            f"| {name} | {runs} | {seconds / batch * 1e6:.2f} | {100 * share:.1f} % "
            f"| {compile_s:.2f} |"
        )


def _compiles(env, state, actions, cs, d, command, u, targets, noise, args) -> None:
    """Compile of the controller tick alone, one env step, and a 10-step chunk's first call."""
    tick = jax.jit(jax.vmap(env.controller.step))
    tick_args = (cs, d, command, u, targets, noise)
    with Stopwatch() as lower:
        lowered = tick.lower(*tick_args)
    with Stopwatch() as comp:
        lowered.compile()
    print(
        f"\ncontroller tick alone: trace+lower {lower.seconds:.2f} s, compile {comp.seconds:.2f} s"
    )
    step = jax.jit(jax.vmap(env.step))
    with Stopwatch() as lower:
        lowered = step.lower(state, actions)
    with Stopwatch() as comp:
        lowered.compile()
    print(f"env.step alone: trace+lower {lower.seconds:.2f} s, compile {comp.seconds:.2f} s")
    carry, key = rollout.start(env, args.batch, seed=0)
    run = rollout.make_chunk(jax.vmap(env.step), _policy(env.config.controller), 10)
    with Stopwatch() as first:
        jax.block_until_ready(run(carry, key))
    print(f"10-step chunk, batch {args.batch}: compile + first call {first.seconds:.2f} s")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--controllers", nargs="+", default=["mbc", "observer", "dpc"])
    p.add_argument("--engines", nargs="+", default=["mjx", "native"])
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--warmup", type=int, default=5, help="env steps before the states are taken")
    p.add_argument("--calls", type=int, default=20)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--compile", action="store_true", help="also the compile times")
    p.add_argument("--xla-dump", help="dump XLA's optimised HLO of every program to this folder")
    args = p.parse_args()
    if args.xla_dump:
        os.environ["XLA_FLAGS"] = (
            os.environ.get("XLA_FLAGS", "")
            + f" --xla_dump_to={args.xla_dump} --xla_dump_hlo_as_text"
        )
    print(f"jax {jax.__version__}, {jax.default_backend()}, load {os.getloadavg()}")
    for controller in args.controllers:
        profile(controller, args)


if __name__ == "__main__":
    main()
