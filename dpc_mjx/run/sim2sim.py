"""Sim-to-sim: an export's controllers in MJX and in native MuJoCo C, on the same episodes.

The check before trusting an MJX-trained policy: run it on the same MJCF in MuJoCo C, whose
contact handling and solver differ from MJX's, and see whether it still works. Each (arm,
controller) cell of the evaluation protocol (`dpc_mjx.run.eval`) runs under both engines
(`EnvConfig.engine`, `dpc_mjx/physics.py`) from the same seed: the same initial poses,
commands, arm targets, pushes and sensor errors (drawn from the keys, not from the physics), and
the same controller and policy code. Reported: the protocol's figures per engine side by side,
and per controller the paired difference native - MJX over the same episodes (return, falls,
and the episodes that fell under one engine only).
"""

from __future__ import annotations

import dataclasses
import pathlib

from dpc_mjx.envs.registry import DEFAULT_TASK
from dpc_mjx.errors import DpcError
from dpc_mjx.io.shipped import SHIPPED, export_cells
from dpc_mjx.physics import ENGINES
from dpc_mjx.run.eval import (
    CONTROLLERS,
    PAIRED_HEADER,
    CellResult,
    evaluate,
    paired_row,
    paired_rows,
)
from dpc_mjx.run.report import write_episodes_csv
from dpc_mjx.writer import is_writer

HEADER = (
    "| arm | controller | engine | fall rate [95% CI] | mean return [95% CI] | roll RMS (rad) "
    "| pitch RMS (rad) | v_x RMSE (m/s) | v_y RMSE (m/s) | yaw-rate RMSE (rad/s) | NaN resets "
    "| wall (s) |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def row(engine: str, c: CellResult) -> str:
    """A markdown row under `HEADER`."""
    return (
        f"| {c.arm} | {c.controller} | {engine} | {c.fall_rate:.2f} [{c.fall_ci[0]:.2f}, "
        f"{c.fall_ci[1]:.2f}] | {c.mean_return:.1f} [{c.return_ci[0]:.1f}, "
        f"{c.return_ci[1]:.1f}] | {c.roll_rms:.3f} | {c.pitch_rms:.3f} | {c.vx_rmse:.3f} "
        f"| {c.vy_rmse:.3f} | {c.yaw_rate_rmse:.3f} | {c.nan_resets} | {c.seconds:.0f} |"
    )


def engine_rows(cells: dict[str, list[CellResult]]) -> list[str]:
    """Paired rows (`PAIRED_HEADER`): per engine, DPC (or the observer) against the others
    (`eval.paired_rows`: does the ranking carry over?), then per (arm, controller) native minus
    MJX on the same episodes."""
    rows = []
    for engine, engine_cells in cells.items():
        labelled = [dataclasses.replace(c, arm=f"{c.arm} ({engine})") for c in engine_cells]
        rows += paired_rows(labelled)
    for mjx_cell, native_cell in zip(cells["mjx"], cells["native"], strict=True):
        rows.append(
            paired_row(
                f"{mjx_cell.arm} {mjx_cell.controller}: native - mjx",
                (native_cell.per_episode["fell"], native_cell.per_episode["return"]),
                (mjx_cell.per_episode["fell"], mjx_cell.per_episode["return"]),
            )
        )
    return rows


def sim2sim(
    export_dir: str | pathlib.Path = SHIPPED,
    *,
    arms: list[str] | None = None,
    controllers: list[str] = CONTROLLERS,
    task: str = DEFAULT_TASK,
    episodes: int = 64,
    steps: int | None = None,
    seed: int = 1000,
    env: dict | None = None,
    out: str | pathlib.Path | None = None,
    csv: str | pathlib.Path | None = None,
    progress: bool = True,
) -> dict[str, list[CellResult]]:
    """Every (arm, controller) cell of `dpc_mjx.run.eval`'s protocol under each engine
    (`ENGINES`), arms and env options as for `pipeline.evaluate_export`; prints the side-by-side
    table and the native - MJX paired rows (and writes them to `out`, and one row per episode
    with its engine to `csv`). Returns {engine: cells}."""
    if env and "engine" in env:
        raise DpcError("sim2sim runs both engines itself; drop engine= from the env options.")
    artefacts, arm_list, overrides = export_cells(export_dir, arms, controllers, task, env)
    print(HEADER, flush=True)
    cells = {}
    for engine in ENGINES:
        cells[engine] = evaluate(
            arm_list,
            list(controllers),
            task=task,
            episodes=episodes,
            steps=steps,
            seed=seed,
            dpc_policy_for=artefacts.dpc_policy,
            overrides={**overrides, "engine": engine},
            on_result=lambda c, e=engine: print(row(e, c), flush=True),
            progress=progress,
        )
    paired = engine_rows(cells)
    print("\n" + "\n".join([PAIRED_HEADER, *paired]), flush=True)
    if out is not None and is_writer():
        table = [
            row(e, c) for pair in zip(cells["mjx"], cells["native"]) for e, c in zip(ENGINES, pair)
        ]
        lines = [HEADER, *table, "", PAIRED_HEADER, *paired]
        pathlib.Path(out).write_text("\n".join(lines) + "\n")
    if csv is not None:
        engines = [e for e, engine_cells in cells.items() for _ in engine_cells]
        path = write_episodes_csv(csv, [c for e in cells.values() for c in e], engines)
        print(f"per-episode rows: {path}", flush=True)
    return cells
