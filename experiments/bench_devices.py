"""Evaluation's env steps/s on 1 vs N (forced host) devices, side by side in one run.

    python experiments/bench_devices.py [--devices 1 2] [--batches 8 64 256] [--calls 5]

Each (batch, device count) runs in its own subprocess (`XLA_FLAGS=
--xla_force_host_platform_device_count=N` must be set before JAX starts), one after the other so
they do not share the cores, the device counts of a batch back to back (a shared machine's load
changes over minutes). Per row: the steps of `rollout.run_episodes` (MBC on the reaching task,
`regular` arm): `rollout.start` (the batch reset and put on the devices), then `make_chunk`'s
jitted chunks of `--chunk` env steps, compiled ahead (timed apart), one warm-up call, then the
best of `--repeats` timings of `--calls` calls. On a CPU the forced devices share its cores.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import jax

from dpc_mjx.envs import rollout
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.timing import Stopwatch, run_calls, timed

_MARK = "ROW "  # a worker's result line


def worker(batch: int, chunk: int, calls: int, repeats: int) -> None:
    env = make(DEFAULT_TASK, arm="regular", controller="mbc")
    (carry, key), reset = timed(rollout.start, env, batch, seed=0)
    run_chunk = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, chunk)
    with Stopwatch() as compiling:
        compiled = run_chunk.lower(carry, key).compile()
    carry = jax.block_until_ready(compiled(carry, key)[0])  # warm-up

    def call(state):
        carry, key = state
        key, k = jax.random.split(key)
        return compiled(carry, k)[0], key

    best = float("inf")
    for _ in range(repeats):
        seconds, (carry, key) = run_calls(call, (carry, key), calls)
        best = min(best, seconds)
    row = {
        "devices": jax.device_count(),
        "batch": batch,
        "envs": carry[0].obs.shape[0],  # padded to a multiple of the devices
        "shards": len(carry[0].obs.sharding.device_set),
        "reset_s": reset,
        "compile_s": compiling.seconds,
        "sps": batch * chunk * calls / best,  # env steps of the episodes asked for
    }
    print(_MARK + json.dumps(row), flush=True)


def run(n_devices: int, batch: int, args) -> dict:
    env = dict(os.environ)
    flags = env.get("XLA_FLAGS", "")
    env["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n_devices}".strip()
    cmd = [sys.executable, __file__, "--worker", "--batches", str(batch)]
    cmd += ["--chunk", str(args.chunk), "--calls", str(args.calls), "--repeats", str(args.repeats)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode:
        sys.exit(f"the {n_devices}-device run failed:\n{out.stderr[-3000:]}")
    (line,) = [line for line in out.stdout.splitlines() if line.startswith(_MARK)]
    return json.loads(line[len(_MARK) :])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--devices", type=int, nargs="+", default=[1, 2])
    p.add_argument("--batches", type=int, nargs="+", default=[8, 64, 256])
    p.add_argument("--chunk", type=int, default=10, help="env steps per jitted call")
    p.add_argument("--calls", type=int, default=5, help="calls per timing")
    p.add_argument("--repeats", type=int, default=3, help="timings, the best one reported")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        worker(args.batches[0], args.chunk, args.calls, args.repeats)
        return
    clock = Stopwatch()
    print(f"{os.cpu_count()} CPUs; the load average (1 min) before each row\n")
    print("| batch | devices | envs per device | load | reset (s) | compile (s) | steps/s | vs 1 |")
    print("|---|---|---|---|---|---|---|---|", flush=True)
    for batch in args.batches:
        base = None
        for n in args.devices:
            load = os.getloadavg()[0]
            r = run(n, batch, args)
            base = base or r["sps"]  # the first device count's (1 by default)
            print(
                f"| {batch} | {r['devices']} | {r['envs'] // r['shards']} | {load:.1f} "
                f"| {r['reset_s']:.1f} | {r['compile_s']:.1f} | {r['sps']:,.0f} "
                f"| {r['sps'] / base:.2f} |",
                flush=True,
            )
    print(f"\n{clock.elapsed():.0f} s wall")


if __name__ == "__main__":
    main()
