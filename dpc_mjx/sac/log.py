"""The CSV log of a SAC run (`sac_log.csv` in its run folder): one row per epoch.

Ours (brax's SAC reports metrics through a `progress_fn` instead). A row holds the counters, the
returns and falls of the episodes that ended in the epoch, the mean losses, the epoch's env
steps/s and gradient steps/s, and on evaluation epochs the deterministic evaluation and its
episodes with u = 0 (MBC); `LOG_COLUMNS` lists them. The same rows are the `history` of a
`TrainResult` and of a checkpoint, which is why a resumed run rewrites the file from the
checkpoint's rows (`rewrite`) before appending.
"""

from __future__ import annotations

import csv
import pathlib

from dpc_mjx.sac.config import SacConfig
from dpc_mjx.sac.trainer import Carry

LOG_FILE = "sac_log.csv"

LOG_COLUMNS = (
    *("epoch", "env_steps", "grad_steps", "episodes", "mean_return", "fall_rate", "nan_resets"),
    *("mean_length", "critic_loss", "actor_loss", "alpha", "env_steps_per_s", "grad_steps_per_s"),
    *("epoch_seconds", "wall_seconds"),
    # the deterministic evaluation (on evaluation epochs), and its episodes with u = 0 (MBC)
    *("eval_return", "eval_fall_rate", "eval_mbc_return", "eval_mbc_fall_rate"),
)


def empty_row() -> dict:
    return dict.fromkeys(LOG_COLUMNS, float("nan"))


def epoch_row(carry: Carry, m: dict, seconds: float, grads: int, config: SacConfig, wall: float):
    """One CSV row: counters, returns and falls of the episodes that ended in the epoch, mean
    losses, and the epoch's env steps/s and gradient steps/s (env and learning together)."""
    episodes = float(m["episodes"])
    steps = config.env_steps_per_epoch

    def per_episode(key):
        return float(m[key]) / episodes if episodes else float("nan")

    return empty_row() | {
        "epoch": int(carry.epoch),
        "env_steps": int(carry.training.env_steps),
        "grad_steps": int(carry.training.grad_steps),
        "episodes": int(episodes),
        "mean_return": per_episode("return_sum"),
        "fall_rate": per_episode("falls"),
        "nan_resets": int(m["nan_resets"]),
        "mean_length": per_episode("length_sum"),
        "critic_loss": float(m["critic_loss"]),
        "actor_loss": float(m["actor_loss"]),
        "alpha": float(m["alpha"]),
        "env_steps_per_s": steps / seconds,
        "grad_steps_per_s": grads / seconds,
        "epoch_seconds": seconds,
        "wall_seconds": wall,
    }


def append(run_dir: pathlib.Path, row: dict) -> None:
    """Append `row` to the run's log (with the header if the file is new)."""
    path = run_dir / LOG_FILE
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)


def rewrite(run_dir: pathlib.Path, history: list[dict]) -> None:
    """The log holds exactly the checkpoint's epochs (a kill may have left a row after the last
    checkpoint)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / LOG_FILE).unlink(missing_ok=True)
    for row in history:
        append(run_dir, row)


__all__ = ["LOG_COLUMNS", "LOG_FILE", "append", "empty_row", "epoch_row", "rewrite"]
