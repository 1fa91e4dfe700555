"""The full env against the physical limit on a CPU: MuJoCo C's physics alone, in one run.

    .venv/bin/python experiments/bench_limit.py [--batches 64 256] [--threads 1 all] [--quick]
    taskset -c 0 .venv/bin/python experiments/bench_limit.py --one-core   # issue 26's one core

Per batch B and thread count (`--threads`: 1, a number, or `all`, every usable core), in
physics steps per second:

- physics only: `mujoco.batch.Batch(env.model, B, nthread).step()` on the reaching env's
  compiled model (`dpc_mjx.make("reaching", arm="regular", controller="mbc")`), from the
  states of the env's own reset (the same scene, the reset's controls held), a block of
  `--steps` calls of one step;
- the full env, native engine (`NativePhysics(threads=nthread)`) and MJX:
  `jax.jit(jax.vmap(env.step))` through the rollout core (`envs.rollout.make_chunk`, 10 env
  steps per call, MBC), a block of `--calls` calls from the same reset states, counted as env
  steps x `env.n_substeps`; the first call (compile + first run, in a process that compiled
  other batches before) is timed apart. MJX runs on XLA's own threads (as many as the
  process's cores, whatever `--threads` says), so it is measured once per batch, in the first
  thread count's group.

The blocks of a group run interleaved, `--rounds` rounds of one block each, so that every
ratio compares blocks timed seconds apart (this shared machine's speed drifts by 1.5x within
minutes). Rates are the best round's; "vs physics only" is the median over rounds of a row's
physics steps/s over the physics-only block of the same round, with the range of those
per-round ratios beside it.

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
from dpc_mjx.timing import Stopwatch, run_calls, timed

ONE_CORE_FLAG = "--xla_cpu_multi_thread_eigen=false"
CHUNK = 10  # env steps per jitted call
TASK, ARM = "reaching", "regular"
HEADER = (
    "| batch | threads | what | compile + first call (s) | env steps/s | physics steps/s "
    "| vs physics only (median of rounds) | per-round range |\n|---|---|---|---|---|---|---|---|"
)


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--batches", type=int, nargs="+", default=[64, 256])
    p.add_argument("--threads", nargs="+", default=["1", "all"], help="1, N or all (every core)")
    p.add_argument("--engines", nargs="+", default=["native", "mjx"], choices=["native", "mjx"])
    p.add_argument("--calls", type=int, default=20, help="env calls of 10 steps per round")
    p.add_argument("--steps", type=int, default=200, help="physics-only calls per round")
    p.add_argument("--rounds", type=int, default=10, help="rounds, each every row's block once")
    p.add_argument("--one-core", action="store_true", help="XLA single-threaded, one core")
    p.add_argument("--quick", action="store_true", help="batch 8, few repeats: a smoke run")
    args = p.parse_args(argv)
    if args.quick:
        args.batches, args.calls, args.steps, args.rounds = [8], 1, 5, 2
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


def physics_block(env, carry, nthread: int, steps: int):
    """f() -> seconds of `steps` calls of `mujoco.batch.Batch(env.model, B, nthread).step()`,
    each block from the env's reset states (`carry`) again."""
    d = jax.device_get(carry[0].pipeline_state)
    sims = Batch(env.model, len(d.qpos), nthread)
    fields = {k: sims.bind(k) for k in INPUTS}

    def block() -> float:
        for k, view in fields.items():
            view[...] = np.reshape(getattr(d, k), view.shape)
        with Stopwatch() as clock:
            for _ in range(steps):
                sims.step()
        return clock.seconds

    block()  # a warm-up, not timed
    return block


def env_block(env, carry, key, calls: int, nthread: int):
    """(compile + first call s, f() -> seconds of `calls` calls) of `jit(vmap(env.step))` in
    `CHUNK`-step chunks (`envs.rollout.make_chunk`, MBC: the action is ignored) from `carry`;
    the native engine on `nthread` threads. Each block starts from `carry` again, as each
    physics-only block does from the same reset states."""
    if env.config.engine == "native":
        env.physics = NativePhysics(env.model, threads=nthread)
    run = rollout.make_chunk(jax.vmap(env.step), rollout.zero_policy, CHUNK)
    _, first = timed(run, carry, key)

    def block() -> float:
        return run_calls(lambda c: run(c, key)[0], carry, calls)[0]

    return first, block


def interleaved(blocks: dict, rounds: int) -> dict[str, list[float]]:
    """{name: [seconds of each round]}: each round runs every block once, in turn, so that each
    row's time is taken beside the others' (this machine's speed drifts within minutes)."""
    times = {name: [] for name in blocks}
    for _ in range(rounds):
        for name, block in blocks.items():
            times[name].append(block())
    return times


def row(batch, nthread, what, base, compile_s=None, sps=None, n_substeps=1, ratios=None) -> str:
    """One table row; `sps` None: the physics-only row (`base` physics steps/s, best round);
    `ratios`: the per-round ratios to the physics-only block of the same round."""
    physics = base if sps is None else sps * n_substeps
    first = "-" if compile_s is None else f"{compile_s:.1f}"
    env_sps = "-" if sps is None else f"{sps:,.0f}"
    spread = "-" if ratios is None else f"{min(ratios):.2f}-{max(ratios):.2f}"
    median = 1.0 if ratios is None else float(np.median(ratios))
    return (
        f"| {batch} | {nthread} | {what} | {first} | {env_sps} | {physics:,.0f} "
        f"| {median:.2f} | {spread} |"
    )


def measure_group(args, batch: int, nthread: int, native, with_mjx: bool) -> None:
    """The rows of one batch and thread count: physics only, then each env, interleaved."""
    blocks = {"physics": physics_block(*native[:2], nthread, args.steps)}
    envs, compiles = {}, {}
    if "native" in args.engines:
        envs["env, native"] = native
    if with_mjx:  # XLA's threads, whatever nthread says
        envs["env, mjx (XLA's threads)"] = start("mjx", batch)
    for what, (env, carry, key) in envs.items():
        compiles[what], blocks[what] = env_block(env, carry, key, args.calls, nthread)
    times = interleaved(blocks, args.rounds)
    physics_steps, env_steps = batch * args.steps, batch * CHUNK * args.calls  # per block
    base = physics_steps / min(times["physics"])  # physics steps/s, best round
    print(row(batch, nthread, "mujoco.batch physics only", base), flush=True)
    for what, (env, _, _) in envs.items():
        sps = env_steps / min(times[what])  # env steps/s, best round
        ratios = [
            (env_steps * env.n_substeps / t) / (physics_steps / p)
            for t, p in zip(times[what], times["physics"], strict=True)
        ]
        print(row(batch, nthread, what, base, compiles[what], sps, env.n_substeps, ratios))


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
            measure_group(args, batch, nthread, native, "mjx" in args.engines and n == 0)
            sys.stdout.flush()  # the env rows of the group


if __name__ == "__main__":
    main()
