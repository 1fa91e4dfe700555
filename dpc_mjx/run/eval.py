"""Evaluation protocol: MBC, DPC and the oracle on the same episodes, with confidence intervals.

Protocol (docs/results.md states it with every table): for each (arm, controller) cell, `episodes`
envs of the task are reset from the same seeds (`seed`; so every controller meets the same
initial poses and the same disturbance schedules for as long as the episodes stay alike) and run
for `steps` env steps of 20 ms without auto-reset; an episode ends at its first fall (or NaN
reset) and its return is the sum of the paper's rewards (eq. 4) up to and including that step,
the fall penalty included. Reported per cell: fall rate with a 95% Wilson interval, mean return
with a 95% normal interval, RMS roll and pitch (rad), RMSE of forward and lateral speed (m/s) and
of the yaw rate (rad/s) over the steps before a fall, NaN resets, wall time; and the task's
measures (`TASK_HEADER`): RMS distance from the desired path (m) and the end effector's RMS
tracking error (m) over the same steps, and the task's success measures at each episode's end
(`DpcEnv.TASK_MEASURES`), each a mean with a 95% normal interval.

Controllers (`dpc_mjx.controllers.Controller`; plain strings work): 'mbc' (u = 0), 'observer'
(u = the momentum observer's estimate, no training, no force sensor), 'oracle' (u = the measured
arm-mount wrench) and 'dpc' (u from the trained policy acting on `[s_body, z]`, z from the arm's
own encoder).
"""

from __future__ import annotations

import collections
import dataclasses
import os
import pathlib
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from itertools import islice

import jax
import numpy as np

from dpc_mjx.controllers import Controller
from dpc_mjx.envs.controller_batch import ControllerBatch
from dpc_mjx.envs.registry import DEFAULT_TASK, get_config, make, resolve_arm
from dpc_mjx.envs.rollout import Policy, run_episodes, zero_policy
from dpc_mjx.errors import DpcError
from dpc_mjx.physics import AUTO, ENGINE_NAMES, resolve_engine
from dpc_mjx.robots.variants import Arm, arm_name
from dpc_mjx.run.report import write_episodes_csv
from dpc_mjx.stats import mcnemar_counts, mcnemar_p, mean_ci, paired_diff_ci, wilson_ci
from dpc_mjx.writer import is_writer

CONTROLLERS = tuple(Controller)  # mbc, observer, feedforward(_observer), dpc, oracle: tables' order
CHUNK = 50  # env steps per compiled chunk at most (`rollout.run_episodes`); more on a GPU


@dataclasses.dataclass(frozen=True)
class CellResult:
    """One (arm, controller) cell of the protocol."""

    arm: str
    controller: str
    episodes: int
    steps: int
    falls: int
    fall_ci: tuple[float, float]  # 95% Wilson interval of the fall rate
    mean_return: float
    return_ci: tuple[float, float]  # 95% normal interval of the mean return
    roll_rms: float  # rad, over the steps before a fall
    pitch_rms: float  # rad
    vx_rmse: float  # m/s, yaw frame, vs the command
    vy_rmse: float  # m/s
    yaw_rate_rmse: float  # rad/s
    nan_resets: int
    seconds: float  # wall time, compile included: the arm's batch of controllers' over their count
    seed: int = 0  # episode i is reset from the i-th key of `seed` (`rollout.start`)
    pos_rmse: float = 0.0  # m, trunk (x, y) vs the desired path (the command integrated)
    ee_rmse: float = 0.0  # m, end effector vs its servo targets (first order, `DpcEnv`)
    # the task's success measures at the episodes' end: name -> (mean, 95% CI low, high)
    task: dict = dataclasses.field(default_factory=dict)
    # per-episode arrays of `rollout.run_episodes` (episodes,), for `write_episodes_csv`
    per_episode: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)

    @property
    def fall_rate(self) -> float:
        return self.falls / self.episodes

    def summary(self) -> dict:
        """The cell's figures as JSON-able values (without the per-episode arrays)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if k != "per_episode"}


def evaluate_env(
    env,
    arm: str,
    controllers: list[str],
    episodes: int,
    steps: int,
    seed: int,
    policy: Policy | None,
    progress: bool = True,
    chunk: int = CHUNK,
) -> list[CellResult]:
    """The cells of `controllers` on a built env (its config's controller 'dpc'; `policy` for
    'dpc'), every controller's episodes in one batch through one compiled reset and one chunk
    (`envs.controller_batch`); each cell's `seconds` is the batch's wall time over k."""
    t0 = time.perf_counter()
    batch = ControllerBatch(env, controllers)
    k = len(batch.controllers)
    names = [c.value for c in batch.controllers]  # plain strings in tables and CSVs
    r = run_episodes(
        batch, k * episodes, steps, seed, policy or zero_policy, chunk, progress,
        f"{arm} {'/'.join(names)}", groups=k,
    )  # fmt: skip
    seconds = (time.perf_counter() - t0) / k
    measures = getattr(env, "TASK_MEASURES", ())
    group = lambda g: {key: v[g * episodes : (g + 1) * episodes] for key, v in r.items()}  # noqa: E731
    return [
        cell_result(arm, name, group(g), steps, seed, seconds, measures)
        for g, name in enumerate(names)
    ]


def cell_result(
    arm: str,
    controller: str,
    r: dict[str, np.ndarray],
    steps: int,
    seed: int,
    seconds: float,
    measures: tuple[str, ...] = (),
) -> CellResult:
    """A cell's figures from the per-episode arrays `r` of `rollout.run_episodes` (each
    (episodes,)), the task's success measures `measures` among them."""
    episodes = len(r["return"])
    falls = int(r["fell"].sum())
    mean, lo, hi = mean_ci(r["return"])
    measured = max(float(r["measured"].sum()), 1.0)

    def rms(key: str) -> float:
        return float(np.sqrt(r[key].sum() / measured))

    return CellResult(
        arm=arm,
        controller=controller,
        episodes=episodes,
        steps=steps,
        falls=falls,
        fall_ci=wilson_ci(falls, episodes),
        mean_return=mean,
        return_ci=(lo, hi),
        roll_rms=rms("roll_sq"),
        pitch_rms=rms("pitch_sq"),
        vx_rmse=rms("vx_sq_err"),
        vy_rmse=rms("vy_sq_err"),
        yaw_rate_rmse=rms("yaw_rate_sq_err"),
        nan_resets=int(r["nan"].sum()),
        seconds=seconds,
        seed=seed,
        pos_rmse=rms("pos_sq_err"),
        ee_rmse=rms("ee_sq_err"),
        task={k: mean_ci(r[k]) for k in measures},
        per_episode=r,
    )


def evaluate(
    arms: list[str | Arm],
    controllers: list[str],
    *,
    task: str = DEFAULT_TASK,
    episodes: int = 64,
    steps: int | None = None,
    seed: int = 0,
    dpc_policy_for: Callable[[str], Policy] | None = None,
    overrides: dict | None = None,
    on_result: Callable[[CellResult], None] | None = None,
    progress: bool = True,
    workers: int | None = None,
    chunk: int = CHUNK,
) -> list[CellResult]:
    """Every (arm, controller) cell of the protocol on `task`; an arm is a variant name or an arm
    (`robots.UrdfArm`, ...), its cells labelled `robots.arm_name(arm)`; `dpc_policy_for(name)`
    gives the DPC policy of an arm (its encoder + the shared actor), needed for 'dpc'; `steps`
    per episode default to the task's episode length (`EnvConfig.episode_length`). An arm's
    controllers run as one batch, one compiled program (`evaluate_env`), in chunks of at most
    `chunk` env steps; `workers` arms run at once, each in a thread of its own (default
    `cell_workers`), so one compiles while another runs; the results, and `on_result`'s calls,
    come in cell order and are those of one arm at a time."""
    controllers = Controller.parse_all(controllers)
    if Controller.DPC in controllers and dpc_policy_for is None:
        raise DpcError("Evaluating 'dpc' needs a trained policy: pass dpc_policy_for (or --run).")
    if episodes < 1 or (steps is not None and steps < 1):
        raise DpcError(f"episodes and steps must be >= 1, got {episodes} and {steps}.")
    for arm in arms:
        resolve_arm(arm)  # every arm checked (the A1 holds it up) before the first compile
    dpc = Controller.DPC in controllers
    policies = {arm_name(arm): dpc_policy_for(arm_name(arm)) for arm in arms} if dpc else {}

    def cells(arm: str | Arm) -> list[CellResult]:
        env = make(task, arm=arm, controller=Controller.DPC, **(overrides or {}))
        n_steps = env.config.episode_length if steps is None else steps
        policy = policies.get(arm_name(arm))
        return evaluate_env(
            env, arm_name(arm), controllers, episodes, n_steps, seed, policy, progress, chunk
        )

    jobs = iter(arms)
    results, n = [], workers or cell_workers(resolve_engine((overrides or {}).get("engine", AUTO)))
    with ThreadPoolExecutor(n) as pool:
        # a window of `workers` arms in flight, the oldest awaited first: a failed arm raises
        # once the arms in flight end, and no later arm starts
        flight = collections.deque(pool.submit(cells, arm) for arm in islice(jobs, n))
        while flight:
            for cell in flight.popleft().result():
                results.append(cell)
                if on_result is not None:
                    on_result(cell)
            flight.extend(pool.submit(cells, arm) for arm in islice(jobs, 1))
    return results


def cell_workers(engine: str) -> int:
    """Cells evaluated at once by default: 2 for the native engine where JAX runs on the CPU of
    one process with two or more cores (a cell's XLA compile, which holds one core, overlaps
    another cell's run: docs/benchmarks-cpu.md, "Evaluation cells two at a time"), else 1 (MJX,
    whose cells compile longer and in more memory, measured 4.2 GB for a train's two at once
    against 3.0 GB one at a time; an accelerator; several processes, whose collectives must meet
    in the same order)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    on_cpu = jax.default_backend() == "cpu" and jax.process_count() == 1
    return 2 if engine == "native" and on_cpu and (cores or 1) >= 2 else 1


TABLE_HEADER = (
    "| arm | controller | fall rate [95% CI] | mean return [95% CI] | roll RMS (rad) "
    "| pitch RMS (rad) | v_x RMSE (m/s) | yaw-rate RMSE (rad/s) | NaN resets | wall (s) |\n"
    "|---|---|---|---|---|---|---|---|---|---|"
)


def table_row(c: CellResult) -> str:
    """A markdown row under `TABLE_HEADER`."""
    return (
        f"| {c.arm} | {c.controller} | {c.fall_rate:.2f} [{c.fall_ci[0]:.2f}, {c.fall_ci[1]:.2f}]"
        f" | {c.mean_return:.1f} [{c.return_ci[0]:.1f}, {c.return_ci[1]:.1f}]"
        f" | {c.roll_rms:.3f} | {c.pitch_rms:.3f} | {c.vx_rmse:.3f} | {c.yaw_rate_rmse:.3f}"
        f" | {c.nan_resets} | {c.seconds:.0f} |"
    )


TASK_HEADER = (
    "| arm | controller | path RMSE (m) | end-effector RMSE (m) | task measures at the end "
    "[95% CI] |\n|---|---|---|---|---|"
)


def task_row(c: CellResult) -> str:
    """A markdown row under `TASK_HEADER`."""
    measures = "; ".join(f"{k} {m:.3f} [{lo:.3f}, {hi:.3f}]" for k, (m, lo, hi) in c.task.items())
    return f"| {c.arm} | {c.controller} | {c.pos_rmse:.3f} | {c.ee_rmse:.4f} | {measures or '-'} |"


PAIRED_HEADER = (
    "| comparison (same episodes) | return difference [95% CI] | fall-rate difference [95% CI] "
    "| only the first fell | only the second fell | McNemar p |\n|---|---|---|---|---|---|"
)


def paired_row(label: str, first: tuple, second: tuple) -> str:
    """One row under `PAIRED_HEADER`: `first` minus `second`, each (fell, return) per episode
    (episodes,) on the same episodes: the return difference and the fall-rate difference (the
    mean of the per-episode differences of the fall indicators) with paired 95% intervals, the
    discordant falls and the exact McNemar p."""
    (fell_a, ret_a), (fell_b, ret_b) = first, second
    diff, lo, hi = paired_diff_ci(np.asarray(ret_a), np.asarray(ret_b))
    f_diff, f_lo, f_hi = paired_diff_ci(np.asarray(fell_a, float), np.asarray(fell_b, float))
    only_a, only_b = mcnemar_counts(np.asarray(fell_a) > 0, np.asarray(fell_b) > 0)
    return (
        f"| {label} | {diff:+.1f} [{lo:+.1f}, {hi:+.1f}] | {f_diff:+.3f} [{f_lo:+.3f}, "
        f"{f_hi:+.3f}] | {only_a} | {only_b} | {mcnemar_p(only_a, only_b):.2g} |"
    )


def paired_rows(cells: list[CellResult]) -> list[str]:
    """Markdown rows under `PAIRED_HEADER`: per arm, DPC (or else the observer) against each
    other controller evaluated on the same episodes, and the share of the MBC-to-oracle gap in
    falls each estimate closes ((MBC falls - its falls) / (MBC falls - oracle falls))."""
    rows = []
    for arm in dict.fromkeys(c.arm for c in cells):
        mine = {c.controller: c for c in cells if c.arm == arm}
        first = next((k for k in (Controller.DPC, Controller.OBSERVER) if k in mine), None)
        if first is None:
            continue
        a = mine[first]
        for name, b in mine.items():
            if name == first:
                continue
            rows.append(
                paired_row(
                    f"{arm}: {first} - {name}",
                    (a.per_episode["fell"], a.per_episode["return"]),
                    (b.per_episode["fell"], b.per_episode["return"]),
                )
            )
        mbc, oracle = mine.get(Controller.MBC), mine.get(Controller.ORACLE)
        if mbc is not None and oracle is not None and mbc.falls > oracle.falls:
            gap = mbc.falls - oracle.falls
            for name in (c for c in Controller if c not in (Controller.MBC, Controller.ORACLE)):
                if name in mine:
                    share = (mbc.falls - mine[name].falls) / gap
                    rows.append(
                        f"| {arm}: {name} closes {share:.0%} of the MBC-to-oracle gap "
                        "in falls | | | | | |"
                    )
    return rows


def evaluate_table(arms, controllers, *, out=None, csv=None, **kwargs) -> list[CellResult]:
    """`evaluate`, printing the table row by row, writing it to `out` (markdown) and every
    episode to `csv` (`write_episodes_csv`). A line above the table names the engine, the
    episodes per cell and their seed."""
    engine = resolve_engine((kwargs.get("overrides") or {}).get("engine", AUTO))
    task, overrides = kwargs.get("task", DEFAULT_TASK), kwargs.get("overrides") or {}
    steps = kwargs.get("steps") or get_config(task, **overrides).episode_length
    size = f"{kwargs.get('episodes', 64)} episodes of {steps} env steps per cell"
    preface = [f"physics: {ENGINE_NAMES[engine]} (engine={engine!r}); {size}, "
               f"seed {kwargs.get('seed', 0)}", ""]  # fmt: skip
    print("\n".join([*preface, TABLE_HEADER]), flush=True)

    def show(cell: CellResult) -> None:
        print(table_row(cell), flush=True)

    cells = evaluate(arms, controllers, on_result=show, **kwargs)
    paired = paired_rows(cells)
    tasks = [TASK_HEADER, *map(task_row, cells)]
    print("\n" + "\n".join(tasks), flush=True)
    if paired:
        print("\n" + "\n".join([PAIRED_HEADER, *paired]), flush=True)
    if out is not None and is_writer():
        lines = [*preface, TABLE_HEADER, *map(table_row, cells), "", *tasks]
        lines += ["", PAIRED_HEADER, *paired] if paired else []
        pathlib.Path(out).write_text("\n".join(lines) + "\n")
    if csv is not None:
        print(f"per-episode rows: {write_episodes_csv(csv, cells)}", flush=True)
    return cells
