"""Latency of the deployment loop (`dpc_mjx.deploy`) per 4 ms tick, on one CPU core.

    python experiments/bench_deploy.py [--ticks 2000] [--controller dpc]

Pins the process to one core and XLA to one thread (set before JAX starts), drives a simulated
robot (MuJoCo C, the plant, not timed) with the loop's torques for `--ticks` ticks after a
warm-up, and times `Deployment.step` per tick (the host-side kinematics and the jitted
estimator + policy + controller call, torques back as numpy), splitting the ticks where the
policy runs (every 5th) from the others. Prints median, p99 and max, and the compile time apart.
"""

from __future__ import annotations

import argparse
import os
import sys

os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false"
    " intra_op_parallelism_threads=1"
)

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
from test_deploy import measure, plant  # noqa: E402

from dpc_mjx.deploy import Deployment  # noqa: E402
from dpc_mjx.timing import Stopwatch  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--ticks", type=int, default=2000)
    p.add_argument("--controller", default="dpc", choices=["dpc", "mbc", "observer"])
    args = p.parse_args()
    dep = Deployment(controller=args.controller)
    model, data = dep.env.model, plant(dep)
    with Stopwatch() as compiling:
        dep.reset(measure(dep, data), xy=data.qpos[:2])
        for _ in range(dep.env.n_substeps):  # compiles the tick with and without the policy
            dep.step(measure(dep, data))
    times, policy_tick = [], []
    for tick in range(args.ticks):
        m = measure(dep, data)
        policy_tick.append(int(dep.state.tick) % dep.env.n_substeps == 0)
        with Stopwatch() as tick_time:  # torques come back as numpy: nothing to block on
            tau = dep.step(m)
        times.append(tick_time.seconds)
        data.ctrl[dep.env.lay.leg_act] = tau
        mujoco.mj_step(model, data)
        mujoco.mj_forward(model, data)
    us = np.array(times) * 1e6
    policy_tick = np.array(policy_tick)
    print(
        f"controller {args.controller}, 1 core, {args.ticks} ticks, compile + first 5 ticks "
        f"{compiling.seconds:.1f} s; trunk height at the end {data.qpos[2]:.3f} m\n"
    )
    print("| ticks | n | median (us) | p99 (us) | max (us) |\n|---|---|---|---|---|")
    groups = (
        ("all", np.ones_like(policy_tick, bool)),
        ("with the policy", policy_tick),
        ("without", ~policy_tick),
    )
    for name, sel in groups:
        if sel.any():
            x = us[sel]
            print(
                f"| {name} | {sel.sum()} | {np.median(x):.0f} | {np.percentile(x, 99):.0f} "
                f"| {x.max():.0f} |"
            )


if __name__ == "__main__":
    main()
