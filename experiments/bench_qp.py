"""Benchmark the balance-QP solver against OSQP (Python, one problem at a time), qpax and jaxopt.

All solvers get the same balance QPs (12 forces, 24 rows) built from random realistic states
(`dpc_mjx.control.balance.sample_states`). Speed: jit(vmap(solve)) per batch size, compile time
apart, median wall time of several calls (block_until_ready). Accuracy: relative objective gap
|J - J*| / max(1, |J*|) and constraint violation max(Gx - h, 0) / max(1, |h|_inf) against OSQP in
float64 with eps 1e-9 and polishing, on the first problems of the batch.

Rows "ours" run `jax.vmap(qp.solve)` (the batch-minor kernel) with a dense G; "ours, G pattern"
passes `g_pattern=balance.G_PATTERN`, as the controller does (40 of G's 288 entries can be
nonzero); the "default vmap layout" row runs the same code vmapped the default way
(`qp._solve_reference`); `--previous` adds a row for a single-file version of the solver (the
revisions up to 84660d8, before `control/qp.py` became the package `control/qp/`), e.g.
`git show 84660d8:dpc_mjx/control/qp.py > /tmp/qp_prev.py`. `--one-core` pins the process (JAX's
threads included) to one CPU core, so that ours and OSQP each get one core.

    .venv/bin/python experiments/bench_qp.py           # full (~3 min on 2 cores)
    .venv/bin/python experiments/bench_qp.py --quick   # smoke run (~40 s)
    .venv/bin/python experiments/bench_qp.py --one-core --previous /tmp/qp_prev.py
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import os
import sys
from collections.abc import Callable

if "--one-core" in sys.argv:  # before JAX (and its thread pool) starts; the flag is in main()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # Linux only

import jax
import jax.numpy as jp
import numpy as np
import osqp
import qpax
import scipy.sparse as sp
from jaxopt import BoxOSQP

from dpc_mjx.control import balance, qp
from dpc_mjx.timing import Stopwatch, timed


def build_problems(n: int, seed: int) -> tuple[np.ndarray, ...]:
    """(P, q, G, h) float32 arrays of n balance QPs."""
    states = balance.sample_states(np.random.default_rng(seed), n)
    params = balance.default_params()
    prob = jax.jit(jax.vmap(lambda s: balance.build_balance_qp(params, **s)))(states)
    return tuple(np.asarray(a) for a in (prob.P, prob.q, prob.G, prob.h))


def osqp_solve(P, q, G, h, **settings) -> tuple[np.ndarray, float, float]:
    """One problem with OSQP from Python: x, setup time (incl. CSC conversion), solve time (s)."""
    with Stopwatch() as setup:
        solver = osqp.OSQP()
        solver.setup(
            sp.csc_matrix(np.triu(P)),
            q,
            sp.csc_matrix(G),
            np.full(h.shape, -np.inf),
            h,
            verbose=False,
            **settings,
        )
    with Stopwatch() as solve:
        res = solver.solve(raise_error=False)
    return res.x, setup.seconds, solve.seconds


def reference(P, q, G, h) -> np.ndarray:
    """J* of each problem: OSQP in float64, eps 1e-9, polished."""
    j = []
    for i in range(len(q)):
        x, _, _ = osqp_solve(
            *(a[i].astype(np.float64) for a in (P, q, G, h)),
            eps_abs=1e-9,
            eps_rel=1e-9,
            polishing=True,
            max_iter=200_000,
        )
        j.append(objective(P[i : i + 1], q[i : i + 1], x[None])[0])
    return np.array(j)


def objective(P, q, x) -> np.ndarray:
    P, q, x = (np.asarray(a, np.float64) for a in (P, q, x))
    return 0.5 * np.einsum("bi,bij,bj->b", x, P, x) + np.einsum("bi,bi->b", q, x)


def accuracy(problems: tuple[np.ndarray, ...], x, j_star) -> dict[str, float]:
    """Objective gap and violation of solutions x of the first len(j_star) problems."""
    k = len(j_star)
    P, q, G, h, x = (np.asarray(a[:k], np.float64) for a in (*problems, x))
    gap = np.abs(objective(P, q, x) - j_star) / np.maximum(1.0, np.abs(j_star))
    viol = np.maximum(np.einsum("bij,bj->bi", G, x) - h, 0.0).max(1) / np.maximum(
        1.0, np.abs(h).max(1)
    )
    return {
        "gap_med": float(np.median(gap)),
        "gap_max": float(gap.max()),
        "viol_max": float(viol.max()),
        "n": k,
    }


def time_batched(fn: Callable, args: tuple, repeats: int, budget_s: float):
    """Compile time (s), median call time (s), output of jit(vmap(fn)) on args.

    The compile time is that of the first call minus one timed call. Fewer repeats are made when
    they would take longer than budget_s.
    """
    f = jax.jit(jax.vmap(fn))
    out, first = timed(f, *args)
    times = []
    while len(times) < repeats and (not times or sum(times) + times[0] <= budget_s):
        times.append(timed(f, *args)[1])
    return max(first - times[0], 0.0), float(np.median(times)), out


def qpax_fn():
    def solve(P, q, G, h):
        empty_a, empty_b = jp.zeros((0, P.shape[0]), P.dtype), jp.zeros((0,), P.dtype)
        return qpax.solve_qp(P, q, empty_a, empty_b, G, h)[0]  # defaults: 30 iterations, tol 1e-5

    return solve


def boxosqp_fn():
    solver = BoxOSQP(tol=1e-3)

    def solve(P, q, G, h):
        sol = solver.run(params_obj=(P, q), params_eq=G, params_ineq=(jp.full_like(h, -jp.inf), h))
        return sol.params.primal[0]

    return solve


QPAX, BOX = "qpax (30 it, tol 1e-5)", "jaxopt BoxOSQP (tol 1e-3)"
OURS, OURS8 = "ours (qp.solve, 10 it)", "ours, 8 it"
SPARSE = "ours, G pattern (g_pattern=balance.G_PATTERN, 10 it)"
REF = "ours, default vmap layout (qp._solve_reference)"  # same code, batch on the leading axis
PREV = "previous qp.py (--previous)"


def load_solve(path: str) -> Callable:
    """`solve` of a qp.py loaded from path (another version of the solver)."""
    spec = importlib.util.spec_from_file_location("qp_previous", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return lambda *a: module.solve(*a).x


@dataclasses.dataclass
class Bench:
    """The problems, their reference J*, the options and the collected results."""

    problems: tuple[np.ndarray, ...]  # (P, q, G, h), float32
    j_star: np.ndarray  # reference objective of the first len(j_star) problems
    repeats: int
    budget_s: float  # per timed configuration
    rows: list = dataclasses.field(default_factory=list)  # (name, batch, compile s, us/problem)
    acc: dict = dataclasses.field(default_factory=dict)  # name -> accuracy figures
    per_batch: dict = dataclasses.field(default_factory=dict)  # (name, batch) -> us/problem
    osqp_us: float = float("nan")


def run_osqp(bench: Bench, n_osqp: int) -> None:
    """OSQP from Python one problem at a time, default settings (eps 1e-3, no polishing)."""
    xs, t_setup, t_solve = [], [], []
    for i in range(n_osqp):
        x, ts, tv = osqp_solve(*(a[i].astype(np.float64) for a in bench.problems))
        xs.append(x)
        t_setup.append(ts)
        t_solve.append(tv)
    bench.osqp_us = 1e6 * (np.median(t_setup) + np.median(t_solve))
    bench.rows.append(("OSQP (Python, setup+solve)", 1, None, bench.osqp_us))
    bench.rows.append(("OSQP (Python, solve only)", 1, None, 1e6 * np.median(t_solve)))
    bench.acc["OSQP default (eps 1e-3)"] = accuracy(
        bench.problems, np.array(xs), bench.j_star[:n_osqp]
    )


def run_batched(bench: Bench, name: str, fn: Callable, batches) -> None:
    """Time jit(vmap(fn)) at each batch size (skipping those over the time budget)."""
    us = None
    for b in batches:
        if us is not None and us * 1e-6 * b * 2 > bench.budget_s:  # compile + one call
            bench.rows.append((f"{name} (skipped: ~{us * 1e-6 * b:.0f} s per call)", b, None, None))
            continue
        batch = tuple(jp.asarray(a[:b]) for a in bench.problems)
        compile_s, call_s, out = time_batched(fn, batch, bench.repeats, bench.budget_s)
        us = 1e6 * call_s / b
        bench.rows.append((name, b, compile_s, us))
        bench.per_batch[name, b] = us
        x = out.x if isinstance(out, qp.QPResult) else out
        k = min(b, len(bench.j_star))
        if name not in bench.acc or k > bench.acc[name]["n"]:
            bench.acc[name] = accuracy(bench.problems, np.asarray(x)[:k], bench.j_star[:k])


def print_tables(bench: Bench) -> None:
    rows, acc, per_batch, osqp_us = bench.rows, bench.acc, bench.per_batch, bench.osqp_us
    print(
        f"\nBalance QPs (n=12, m=24), float32 JAX on {jax.devices()[0].device_kind}, "
        f"{len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else '-'} of "
        f"{os.cpu_count()} CPU threads, "
        f"load avg {os.getloadavg()[0]:.1f}\n"
    )
    print("| solver | batch | compile (s) | us/problem | solves/s | OSQP-py (setup+solve) / this |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, b, compile_s, us in rows:
        if us is None:
            print(f"| {name} | {b} | - | - | - | - |")
            continue
        c = "-" if compile_s is None else f"{compile_s:.1f}"
        print(f"| {name} | {b} | {c} | {us:.2f} | {1e6 / us:,.0f} | {osqp_us / us:.1f}x |")

    others = (REF, PREV, QPAX, BOX)
    print(
        "\n| speed-up at batch | of | vs OSQP-py (setup+solve) | vs default vmap layout "
        "| vs previous qp.py | vs qpax | vs BoxOSQP |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|")
    for b in sorted({b for (name, b) in per_batch if name in (OURS, SPARSE)}):
        for mine, label in ((OURS, "ours, dense G"), (SPARSE, "ours, G pattern")):
            if (mine, b) not in per_batch:
                continue
            ours = per_batch[mine, b]
            cells = [f"{osqp_us / ours:.1f}x"] + [
                f"{per_batch[o, b] / ours:.1f}x" if (o, b) in per_batch else "-" for o in others
            ]
            print(f"| {b} | {label} | {' | '.join(cells)} |")

    print("\nAccuracy vs OSQP float64 (eps 1e-9, polished) on the first n problems of the batch\n")
    print("| solver | n | gap median | gap max | max violation |")
    print("|---|---:|---:|---:|---:|")
    for name, a in acc.items():
        print(
            f"| {name} | {a['n']} | {a['gap_med']:.1e} | {a['gap_max']:.1e} | {a['viol_max']:.1e} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small batches, few repeats")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--previous", help="path of another qp.py to benchmark as one more row")
    parser.add_argument("--one-core", action="store_true", help="pin the process to one core")
    args = parser.parse_args()

    ours_batches = (1, 256, 1024) if args.quick else (1, 256, 1024, 4096)
    base_batches = (64, 256) if args.quick else (256, 1024, 4096)
    n_osqp, n_ref = (100, 128) if args.quick else (400, 512)

    problems = build_problems(max(ours_batches + base_batches), args.seed)
    bench = Bench(
        problems,
        reference(*(a[:n_ref] for a in problems)),
        repeats=3 if args.quick else 5,
        budget_s=10.0 if args.quick else 30.0,
    )
    run_osqp(bench, n_osqp)
    solvers = {
        OURS: (qp.solve, ours_batches),
        SPARSE: (lambda *a: qp.solve(*a, g_pattern=balance.G_PATTERN), ours_batches),
        OURS8: (lambda *a: qp.solve(*a, settings=qp.QPSettings(iterations=8)), ours_batches[-1:]),
        REF: (qp._solve_reference, base_batches),
        **({PREV: (load_solve(args.previous), base_batches)} if args.previous else {}),
        QPAX: (qpax_fn(), base_batches),
        BOX: (boxosqp_fn(), base_batches),
    }
    for name, (fn, batches) in solvers.items():
        run_batched(bench, name, fn, batches)
    print_tables(bench)


if __name__ == "__main__":
    main()
