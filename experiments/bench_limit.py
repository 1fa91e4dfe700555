"""The full env against the physical limit on a CPU: MuJoCo C's physics alone, in one run.

    .venv/bin/python experiments/bench_limit.py [--batches 64 256] [--threads 1 all] [--quick]
    taskset -c 0 .venv/bin/python experiments/bench_limit.py --one-core   # issue 26's one core

Per batch B and thread count (`--threads`: 1, a number, or `all`, every usable core), in
physics steps per second:

- physics only: `mujoco.batch.Batch(env.model, B, nthread).step()` on the reaching env's
  compiled model (`dpc_mjx.make("reaching", arm="regular", controller="mbc")`), from the
  states of the env's own reset (the same scene, the reset's controls held), `--steps` calls
  of one step per repeat, each repeat from those states;
- the full env, native engine (`NativePhysics(threads=nthread)`) and MJX:
  `jax.jit(jax.vmap(env.step))` through the rollout core (`envs.rollout.make_chunk`, 10 env
  steps per call, MBC), counted as env steps x `env.n_substeps`; the first call (compile +
  first run, in a process that compiled other batches before) is timed apart. MJX runs on
  XLA's own threads (as many as the process's cores, whatever `--threads` says), so it is
  measured once per batch, in the first thread count's group.

"vs physics only" is a row's physics steps/s over the physics-only row of its group.

One core (issue 26's "what must hold"): `taskset -c 0 ... --one-core`. `--one-core` adds
`--xla_cpu_multi_thread_eigen=false` to XLA_FLAGS (Eigen's kernels single-threaded) and
restarts the script pinned to its first usable core (`os.sched_setaffinity`: the whole process,
so `taskset` is then optional), before jax starts. jaxlib 0.9.2 sizes XLA:CPU's intra-op thread
pool from the process's CPU affinity, so the pin is what makes XLA one-threaded; the often
quoted `intra_op_parallelism_threads=1` is not an XLA flag (jaxlib 0.9.2 ignores it without a
leading `--` and aborts on `--intra_op_parallelism_threads=1`).
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import numpy as np
from mujoco.batch import Batch

import dpc_mjx
from dpc_mjx.envs import rollout
from dpc_mjx.physics import INPUTS, NativePhysics
from dpc_mjx.timing import Stopwatch, time_calls

ONE_CORE_FLAG = "--xla_cpu_multi_thread_eigen=false"
CHUNK = 10  # env steps per jitted call
TASK, ARM = "reaching", "regular"
HEADER = (
    "| batch | threads | what | compile + first call (s) | env steps/s | physics steps/s "
    "| vs physics only |\n|---|---|---|---|---|---|---|"
)


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--batches", type=int, nargs="+", default=[64, 256])
    p.add_argument("--threads", nargs="+", default=["1", "all"], help="1, N or all (every core)")
    p.add_argument("--engines", nargs="+", default=["native", "mjx"], choices=["native", "mjx"])
    p.add_argument("--calls", type=int, default=5, help="timed env calls of 10 steps per row")
    p.add_argument("--steps", type=int, default=200, help="physics-only calls per repeat")
    p.add_argument("--reps", type=int, default=10, help="physics-only repeats")
    p.add_argument("--one-core", action="store_true", help="XLA single-threaded, one core")
    p.add_argument("--quick", action="store_true", help="batch 8, few repeats: a smoke run")
    args = p.parse_args(argv)
    if args.quick:
        args.batches, args.calls, args.steps, args.reps = [8], 1, 5, 2
    return args


def one_core() -> None:
    """Restart this script with XLA single-threaded on one core, unless it already is: jax
    reads XLA_FLAGS and sizes its threads when its backend starts, which `import jax` does not
    do (`import dpc_mjx` set its own flag, where its jaxlib needs one, and is kept)."""
    cores = os.sched_getaffinity(0)
    flags = os.environ.get("XLA_FLAGS", "")
    if len(cores) == 1 and ONE_CORE_FLAG in flags.split():
        return
    os.sched_setaffinity(0, {min(cores)})  # kept across exec: the new process, every thread
    os.environ["XLA_FLAGS"] = f"{flags} {ONE_CORE_FLAG}".strip()
    os.execv(sys.executable, [sys.executable, *sys.argv])


def thread_counts(names: list[str]) -> list[int]:
    """`--threads` as numbers (`all`: the process's usable cores), in order, without repeats."""
    cores = len(os.sched_getaffinity(0))
    counts = [cores if t == "all" else int(t) for t in names]
    return list(dict.fromkeys(counts))


def start(engine: str, batch: int) -> tuple:
    """(env, carry, key): the reaching env (MBC) under `engine`, its batch reset from seed 0."""
    env = dpc_mjx.make(TASK, arm=ARM, controller="mbc", engine=engine)
    carry, key = rollout.start(env, batch, seed=0)
    return env, carry, key


def physics_rate(env, carry, nthread: int, steps: int, reps: int) -> float:
    """Physics steps/s of `mujoco.batch.Batch(env.model, B, nthread).step()` from the env's
    reset states (`carry`), `steps` calls per repeat, each repeat from those states again."""
    d = jax.device_get(carry[0].pipeline_state)
    batch = len(d.qpos)
    sims = Batch(env.model, batch, nthread)
    fields = {k: sims.bind(k) for k in INPUTS}
    seconds = 0.0
    for rep in range(reps + 1):  # repeat 0: a warm-up, not timed
        for k, view in fields.items():
            view[...] = np.reshape(getattr(d, k), view.shape)
        with Stopwatch() as clock:
            for _ in range(steps):
                sims.step()
        seconds += clock.seconds if rep else 0.0
    return batch * steps * reps / seconds


def env_rate(env, carry, key, calls: int, nthread: int) -> dict:
    """{'compile': s, 'sps': env steps/s} of `jit(vmap(env.step))` in `CHUNK`-step chunks
    (`envs.rollout.make_chunk`, MBC: the action is ignored) from `carry`; the native engine
    on `nthread` threads."""
    if env.config.engine == "native":
        env.physics = NativePhysics(env.model, threads=nthread)
    run = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, CHUNK)
    first, per_call, _ = time_calls(lambda c: run(c, key)[0], carry, calls)
    return {"compile": first, "sps": len(carry[1].ret) * CHUNK / per_call}


def row(batch, nthread, what, base, compile_s=None, sps=None, n_substeps=1) -> str:
    """One table row; `sps` None: the physics-only row (`base` physics steps/s)."""
    physics = base if sps is None else sps * n_substeps
    first = "-" if compile_s is None else f"{compile_s:.1f}"
    env_sps = "-" if sps is None else f"{sps:,.0f}"
    return (
        f"| {batch} | {nthread} | {what} | {first} | {env_sps} | {physics:,.0f} "
        f"| {physics / base:.2f} |"
    )


def main(argv: list[str] | None = None) -> None:
    args = parse(argv)
    if args.one_core:
        one_core()
    cores = len(os.sched_getaffinity(0))
    print(
        f"{TASK} {ARM} MBC, {cores} usable core(s), XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}"
        f", jax {jax.__version__}, args: {' '.join(sys.argv[1:]) or '-'}\n"
    )
    print(HEADER, flush=True)
    for batch in args.batches:
        native = start("native", batch)
        for n, nthread in enumerate(thread_counts(args.threads)):
            base = physics_rate(*native[:2], nthread, args.steps, args.reps)
            print(row(batch, nthread, "mujoco.batch physics only", base), flush=True)
            if "native" in args.engines:
                r = env_rate(*native, args.calls, nthread)
                what = "env, native"
                print(row(batch, nthread, what, base, r["compile"], r["sps"], native[0].n_substeps))
            if "mjx" in args.engines and n == 0:  # XLA's threads, whatever nthread says
                env = start("mjx", batch)
                r = env_rate(*env, args.calls, nthread)
                what = "env, mjx (XLA's threads)"
                print(row(batch, nthread, what, base, r["compile"], r["sps"], env[0].n_substeps))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
