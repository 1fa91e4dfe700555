"""Reports from evaluations: the per-episode CSVs read back, controllers paired on the same
episodes, and the markdown cells of the tables (`experiments/table_one.py`, `paired_csv.py`,
`transfer_curve.py`).

A per-episode CSV (`dpc-mjx eval --csv`, `write_episodes_csv`) has one row per episode and
controller, columns `EPISODE_COLUMNS` then the task's measures: rows with the same
(arm, seed, episode) are the same episode (initial pose, disturbances) under each controller, so
two controllers' rows pair. Intervals are 95% (`dpc_mjx.stats`).
"""

from __future__ import annotations

import csv
import pathlib

import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.stats import mcnemar_counts, mcnemar_p, mean_ci, paired_diff_ci
from dpc_mjx.writer import is_writer

# the columns a report reads (a subset of `EPISODE_COLUMNS`)
KEY_COLUMNS = ("arm", "controller", "seed", "episode", "fell", "return")
# columns that are not numbers (`fall_step` is empty when the episode did not fall)
TEXT_COLUMNS = ("engine", "arm", "controller", "fall_step")


# per-episode CSV columns; a task's measures (`DpcEnv.TASK_MEASURES`) follow them
EPISODE_COLUMNS = (
    *("arm", "controller", "seed", "episode", "fell", "fall_step", "nan_reset", "length"),
    *("return", "roll_rms", "pitch_rms", "vx_rmse", "vy_rmse", "yaw_rate_rmse"),
    *("pos_rmse", "ee_rmse"),
)


def episode_rows(c) -> list[dict]:
    """One row per episode of a cell `c` (a `run.eval.CellResult`; `EPISODE_COLUMNS`): `episode`
    i was reset from the i-th key of `seed`, so rows with the same (seed, episode) are the same
    episode under every controller (pair them); `fall_step` is the env step (1-based) of the
    fall, empty if none; RMS errors (rad, m/s, rad/s, m) over the steps before the episode's
    end; then the task's measures at the episode's end."""
    r = c.per_episode
    measured = np.maximum(r["measured"], 1.0)

    def rms(key: str, i: int) -> float:
        return float(np.sqrt(r[key][i] / measured[i]))

    return [
        {
            "arm": c.arm,
            "controller": c.controller,
            "seed": c.seed,
            "episode": i,
            "fell": int(r["fell"][i]),
            "fall_step": int(r["length"][i]) if r["fell"][i] else "",
            "nan_reset": int(r["nan"][i]),
            "length": int(r["length"][i]),
            "return": float(r["return"][i]),
            "roll_rms": rms("roll_sq", i),
            "pitch_rms": rms("pitch_sq", i),
            "vx_rmse": rms("vx_sq_err", i),
            "vy_rmse": rms("vy_sq_err", i),
            "yaw_rate_rmse": rms("yaw_rate_sq_err", i),
            "pos_rmse": rms("pos_sq_err", i),
            "ee_rmse": rms("ee_sq_err", i),
            **{k: float(r[k][i]) for k in c.task},
        }
        for i in range(len(r["return"]))
    ]


def write_episodes_csv(
    path: str | pathlib.Path, cells: list, engines: list[str] | None = None
) -> pathlib.Path:
    """Every episode of `cells` (`run.eval.CellResult`s) as a CSV row (`episode_rows`), to
    re-analyse, pair or bootstrap a table without re-running it; with `engines` (one per cell),
    an `engine` column first. Written by process 0 only (`writer.is_writer`)."""
    path = pathlib.Path(path)
    if not is_writer():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    measures = dict.fromkeys(k for c in cells for k in c.task)
    columns = ["engine"] * (engines is not None) + [*EPISODE_COLUMNS, *measures]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns, restval="")
        w.writeheader()
        for i, c in enumerate(cells):
            label = {} if engines is None else {"engine": engines[i]}
            w.writerows({**label, **row} for row in episode_rows(c))
    return path


def read_episodes(path: str | pathlib.Path, controller: str | None = None) -> list[dict[str, str]]:
    """The rows of a per-episode CSV as {column: text}, in file order; only `controller`'s if
    given."""
    path = pathlib.Path(path)
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        missing = [k for k in KEY_COLUMNS if k not in (reader.fieldnames or ())]
        if missing:
            raise DpcError(
                f"{path} lacks the columns {missing}: give a per-episode CSV of "
                "`dpc-mjx eval --csv` (run.report.write_episodes_csv)."
            )
        return [r for r in reader if controller is None or r["controller"] == controller]


def read_cells(path: str | pathlib.Path) -> dict[str, dict[str, np.ndarray]]:
    """{controller: {column: (episodes,) float array}} of a per-episode CSV of one arm, episodes
    in order (the same episodes under every controller); text columns (`TEXT_COLUMNS`) left out."""
    by: dict[str, list[dict]] = {}
    for row in read_episodes(path):
        by.setdefault(row["controller"], []).append(row)
    out = {}
    for controller, rows in by.items():
        rows.sort(key=lambda r: int(r["episode"]))
        out[controller] = {
            k: np.array([float(r[k]) for r in rows]) for k in rows[0] if k not in TEXT_COLUMNS
        }
    return out


def read_controller(
    spec: str, columns: tuple[str, ...] = ("fell", "return")
) -> dict[tuple[str, str, str], tuple[float, ...]]:
    """{(arm, seed, episode): (fell, return)} of one controller in one CSV, `spec` =
    `PATH:CONTROLLER` (e.g. `runs/eval/x.csv:dpc`); other numeric `columns` (a task's measure,
    e.g. ("ball_on_target",)) give their values in that order."""
    path, sep, controller = spec.rpartition(":")
    if not sep:
        raise DpcError(f"Give CSV:CONTROLLER, got {spec!r} (e.g. runs/eval/x.csv:dpc).")
    rows = read_episodes(path, controller)
    if not rows:
        raise DpcError(f"{path} has no rows of controller {controller!r}.")
    missing = [c for c in columns if c not in rows[0]]
    if missing:
        raise DpcError(f"{path} has no column {missing}; its columns are {sorted(rows[0])}.")
    return {(r["arm"], r["seed"], r["episode"]): tuple(float(r[c]) for c in columns) for r in rows}


def pair(first: dict, second: dict, names: tuple[str, str] = ("first", "second")) -> tuple:
    """Two controllers' episodes (`read_controller`) on the same episodes, for
    `run.eval.paired_row`: ((fell, return), (fell, return)), or the columns read, each
    (episodes,), episodes in the order of their sorted keys; `names` label the error when the
    episodes differ."""
    if set(first) != set(second):
        raise DpcError(
            f"{names[0]} and {names[1]} hold different episodes; pair the same ones (same --seed "
            "and --episodes)."
        )
    keys = sorted(first)
    width = len(first[keys[0]]) if keys else 0
    a, b = ([np.array([x[k][i] for k in keys]) for i in range(width)] for x in (first, second))
    return tuple(a), tuple(b)


def ci_text(values: np.ndarray, fmt: str = ".3f") -> str:
    """`mean [low, high]`: the mean of `values` (episodes,) and its 95% interval."""
    m, lo, hi = mean_ci(values)
    return f"{m:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"


def paired_text(a: np.ndarray, b: np.ndarray, fmt: str = "+.3f") -> str:
    """`diff [low, high]`: the mean of a - b over the same episodes (each (episodes,)) and its
    paired 95% interval."""
    d, lo, hi = paired_diff_ci(a, b)
    return f"{d:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"


def versus_baseline(cell, base, full_return: float | None = None) -> tuple[str, str, str]:
    """Markdown cells comparing an evaluated cell (`run.eval.CellResult`) with `base` (e.g. MBC)
    on the same episodes: (return - base's, paired [95% CI]; exact McNemar p of the falls with
    the discordant counts `(only cell's vs only base's)`; the share of a reference's gain over
    the base, (R - R_base) / (R_full - R_base), with `full_return` = R_full). Empty strings for
    the base itself, and for the share without a reference or when it equals the base."""
    if cell is base:
        return "", "", ""
    diff, lo, hi = paired_diff_ci(cell.per_episode["return"], base.per_episode["return"])
    only_c, only_b = mcnemar_counts(cell.per_episode["fell"], base.per_episode["fell"])
    share = ""
    if full_return is not None and full_return != base.mean_return:
        share = f"{(cell.mean_return - base.mean_return) / (full_return - base.mean_return):.0%}"
    paired = f"{diff:+.1f} [{lo:+.1f}, {hi:+.1f}]"
    return paired, f"{mcnemar_p(only_c, only_b):.2g} ({only_c} vs {only_b})", share
