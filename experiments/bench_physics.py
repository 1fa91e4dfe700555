"""Physics throughput: native MuJoCo C vs MJX jit(vmap(step)) for A1 variants, in one run.

    python experiments/bench_physics.py [--quick] [--sweep]

Robots stand on leg PD servos (dpc_mjx.robots.standing), so both engines simulate the same
contact-rich steady state. Native: a Python loop over mj_step (one core) and mujoco.rollout with
1 and 2 threads. MJX: 50 steps scanned per jitted call, compile time reported apart.
`--sweep` also times MJX solver settings on the `regular` variant and checks each still stands.
"""

from __future__ import annotations

import argparse

import jax
import mujoco
import numpy as np
from mujoco import rollout

import dpc_mjx  # noqa: F401  (silences mjx's warp import message)
from dpc_mjx import sim
from dpc_mjx.robots import build
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.timing import Stopwatch, time_calls

CHUNK = 50


def native_loop(model, seconds=1.0):
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    data.ctrl[:] = home_ctrl(model)
    n = 0
    clock = Stopwatch()
    while clock.elapsed() < seconds:
        for _ in range(500):
            mujoco.mj_step(model, data)
        n += 500
    return n / clock.elapsed()


def native_rollout(model, nthread, nbatch=32, nstep=500):
    datas = [mujoco.MjData(model) for _ in range(nthread)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.zeros((nbatch, mujoco.mj_stateSize(model, spec)))
    for i, q in enumerate(perturbed_home(model, nbatch)):
        d = mujoco.MjData(model)
        d.qpos[:] = q
        mujoco.mj_getState(model, d, state[i], spec)
    ctrl = np.tile(home_ctrl(model), (nbatch, nstep, 1))
    rollout.rollout(model, datas, state, ctrl)  # warm-up (thread pool, allocation)
    with Stopwatch() as clock:
        out, _ = rollout.rollout(model, datas, state, ctrl)
    rate = nbatch * nstep / clock.seconds
    return rate, out


def mjx_rate(model, batch, calls):
    mx = sim.put_model(model)
    data = sim.batched_data(mx, perturbed_home(model, batch), np.tile(home_ctrl(model), (batch, 1)))
    run = sim.make_rollout(mx, CHUNK)
    compile_s, per_call, data = time_calls(run, data, calls)
    return batch * CHUNK / per_call, compile_s, np.asarray(data.qpos[:, 2])


def physics_table(variants, batches, calls):
    print(
        "| variant | engine | batch/threads | compile (s) | env-steps/s "
        "| ratio to native 1 thread | ratio to native 2 threads |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in variants:
        model = with_leg_servos(build(name))
        loop = native_loop(model)
        base, _ = native_rollout(model, 1)
        two, _ = native_rollout(model, 2)
        rows = [
            ("MuJoCo C, Python mj_step loop", "1", "-", loop),
            ("MuJoCo C, rollout", "1 thread", "-", base),
            ("MuJoCo C, rollout", "2 threads", "-", two),
        ]
        for engine, size, comp, rate in rows:
            print(
                f"| {name} | {engine} | {size} | {comp} | {rate:,.0f} "
                f"| {rate / base:.2f} | {rate / two:.2f} |",
                flush=True,
            )
        for b in batches:
            rate, comp, _ = mjx_rate(model, b, calls)
            print(
                f"| {name} | MJX jit(vmap) | {b} | {comp:.1f} | {rate:,.0f} "
                f"| {rate / base:.2f} | {rate / two:.2f} |",
                flush=True,
            )


SWEEP = {  # name -> (solver, iterations, ls_iterations, timestep)
    "Newton 4/8, dt 4 ms (default)": (mujoco.mjtSolver.mjSOL_NEWTON, 4, 8, 0.004),
    "Newton 1/4, dt 4 ms": (mujoco.mjtSolver.mjSOL_NEWTON, 1, 4, 0.004),
    "Newton 2/4, dt 4 ms": (mujoco.mjtSolver.mjSOL_NEWTON, 2, 4, 0.004),
    "CG 4/8, dt 4 ms": (mujoco.mjtSolver.mjSOL_CG, 4, 8, 0.004),
    "Newton 100/50 (MuJoCo default), dt 4 ms": (mujoco.mjtSolver.mjSOL_NEWTON, 100, 50, 0.004),
    "Newton 4/8, dt 2 ms": (mujoco.mjtSolver.mjSOL_NEWTON, 4, 8, 0.002),
}


def sweep_table(batch, calls):
    print(
        f"\n| MJX options (regular, batch {batch}) | compile (s) | env-steps/s | sim s per wall s "
        "| min trunk height after 2 s (m) |"
    )
    print("|---|---|---|---|---|")
    for label, (solver, iters, ls, dt) in SWEEP.items():
        model = with_leg_servos(build("regular"))
        model.opt.solver, model.opt.iterations, model.opt.ls_iterations = solver, iters, ls
        model.opt.timestep = dt
        n_calls = max(calls, round(2.0 / dt / CHUNK) - 1)
        rate, comp, z = mjx_rate(model, batch, n_calls)
        print(
            f"| {label} | {comp:.1f} | {rate:,.0f} | {rate * dt:,.0f} | {z.min():.3f} |", flush=True
        )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="batches 1 and 16 only, regular only")
    parser.add_argument("--sweep", action="store_true", help="also sweep MJX solver options")
    parser.add_argument(
        "--batches", type=int, nargs="+", help="MJX batches (default 1 16 128 1024)"
    )
    parser.add_argument("--variants", nargs="+", help="default: none regular double")
    args = parser.parse_args()
    print(f"jax {jax.__version__}, mujoco {mujoco.__version__}, devices {jax.devices()}")
    if args.quick:
        physics_table(args.variants or ["regular"], args.batches or [1, 16], calls=4)
    else:
        physics_table(
            args.variants or ["none", "regular", "double"], args.batches or [1, 16, 128, 1024], 6
        )
    if args.sweep:
        sweep_table(128, calls=6)


if __name__ == "__main__":
    main()
