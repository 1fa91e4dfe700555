"""TensorBoard event files of a run (`dpc-mjx train`, `train-adapter`; `tensorboard --logdir
RUN`): the numbers of the run's CSVs and JSON records, and its hyperparameters. The CSVs stay.

    tags                                       step                  the same numbers as
    adapter/train_nll, adapter/val_nll         epoch (1, 2, ...)     adapter/adapter_log.csv
    regression/r2/u0 .. u5, regression/val_mse round (0: the MBC      sac/warm_start.json
                                               samples, then DAgger)
    sac/<column>: mean_return, fall_rate,      env steps             sac/sac_log.csv
      critic_loss, actor_loss, alpha,
      eval_return, eval_fall_rate, ...
    eval/<arm>/<controller>/fall_rate,         0                     eval.md, eval_episodes.csv
      mean_return, roll_rms, ..., <task measure>
    HPARAMS tab: the RunConfig, flattened (`sac.learning_rate`), the eval tags its metrics

Every stage writes its own event file (`events.out.tfevents.*.<stage>`), and writing a stage
again replaces its file, so a resumed run holds each row once, as its CSVs do. SAC's rows go in
as its epochs end (`sac_row`: a run can be watched live), and SAC's whole history is written
again when it ends (`sac`: with the starting policy's epoch 0 and a resumed run's earlier epochs).
Values that are not finite (the evaluation's columns on other epochs) are left out.

Only process 0 of a run writes (`writer.is_writer`). tensorboardX (a dependency of brax, and
ours) is imported when the first file is opened, not by `import dpc_mjx`.
"""

from __future__ import annotations

import json
import math
import pathlib

from dpc_mjx.errors import DpcError
from dpc_mjx.writer import is_writer

FOLDER = "tensorboard"  # the default logdir, in the run folder
EVENTS = "events.out.tfevents."  # tensorboardX's file names: EVENTS<time>.<host><suffix>
SAC_STEP = "env_steps"  # the x axis of SAC's scalars
EVAL_SCALARS = ("fall_rate", "mean_return", "roll_rms", "pitch_rms", "vx_rmse", "vy_rmse")
EVAL_SCALARS += ("yaw_rate_rmse", "pos_rmse", "ee_rmse")
METRICS = ("fall_rate", "mean_return")  # the HPARAMS tab's columns, per arm and controller


def logdir_of(run_dir: str | pathlib.Path, logdir: str | pathlib.Path | None = None):
    """Where a run's events go: `run_dir/tensorboard`, or `logdir/<run folder's name>` (one
    TensorBoard run per run folder, so several runs can share one `--logdir`)."""
    run_dir = pathlib.Path(run_dir)
    if logdir is None:
        return run_dir / FOLDER
    return pathlib.Path(logdir) / run_dir.resolve().name


def run_events(config, run_dir: str | pathlib.Path, logdir=None) -> RunEvents:
    """The `RunEvents` of a run (a `RunConfig`) in `logdir_of(run_dir, logdir)`, with its
    hyperparameters written."""
    events = RunEvents(logdir_of(run_dir, logdir))
    events.config(config)
    return events


def eval_tag(arm: str, controller: str, name: str) -> str:
    return f"eval/{arm}/{controller}/{name}"


def flat_hparams(config: dict, prefix: str = "") -> dict:
    """A nested config (`RunConfig.to_json()`) as TensorBoard's hyperparameters: dotted names,
    numbers, strings and booleans (a list as its JSON text; None left out)."""
    out = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out |= flat_hparams(value, f"{name}.")
        elif isinstance(value, (list, tuple)):
            out[name] = json.dumps(value)
        elif value is not None:
            out[name] = value
    return out


class RunEvents:
    """The event files of one run in `logdir` (created); does nothing outside process 0, nor
    without a `logdir` (`NO_EVENTS`)."""

    def __init__(self, logdir: str | pathlib.Path | None):
        self.logdir = None if logdir is None else pathlib.Path(logdir)
        self.enabled = logdir is not None and is_writer()
        self._live = None  # the SAC writer of `sac_row`

    def config(self, config) -> None:
        """The run's hyperparameters (a `RunConfig`; HPARAMS tab) and its JSON (TEXT tab), with
        the evaluation's tags as the metrics."""
        if not self.enabled:
            return
        from tensorboardX.summary import hparams  # noqa: PLC0415 (tensorboardX: lazily)

        # the metrics' names (their values are the eval stage's scalars)
        names = [eval_tag(config.arm, c, n) for c in config.eval_controllers for n in METRICS]
        with self._open("config") as w:
            for summary in hparams(flat_hparams(config.to_json()), dict.fromkeys(names)):
                w.file_writer.add_summary(summary)
            text = json.dumps(config.to_json(), indent=2)
            w.add_text("config", "    " + text.replace("\n", "\n    "), 0)

    def adapter(self, history: dict) -> None:
        """The adapter's per-epoch train and held-out NLL (`adapter.train`'s history)."""
        rows = zip(history["train_nll"], history["val_nll"], strict=True)
        points = [(i + 1, {"train_nll": t, "val_nll": v}) for i, (t, v) in enumerate(rows)]
        self._write("adapter", points)

    def regression(self, reports: list[dict]) -> None:
        """The actor regressed on the oracle's u, one report per round (`regress_actor`'s)."""
        points = []
        for round_, report in enumerate(reports):
            r2 = {f"r2/u{i}": v for i, v in enumerate(report["r2"]) if v is not None}
            points.append((round_, r2 | {"val_mse": report["val_mse"]}))
        self._write("regression", points)

    def sac_row(self, row: dict) -> None:
        """One epoch of SAC (a `sac.log` row) as it ends (`sac.train`'s `on_epoch`)."""
        if not self.enabled:
            return
        if self._live is None:
            self._live = self._open("sac", replace=False)
        _add(self._live, "sac", int(row[SAC_STEP]), _sac_scalars(row))
        self._live.flush()

    def sac(self, history: list[dict]) -> None:
        """SAC's whole history (`TrainResult.history`, the rows of sac_log.csv)."""
        self._close_live()
        self._write("sac", [(int(row[SAC_STEP]), _sac_scalars(row)) for row in history])

    def eval(self, cells) -> None:
        """The evaluation's cells (`run.eval.CellResult`): fall rate, mean return, tracking
        errors and the task's success measures, per arm and controller."""
        points = {}
        for c in cells:
            values = {n: getattr(c, n) for n in EVAL_SCALARS}
            values |= {name: mean for name, (mean, *_) in c.task.items()}
            points |= {eval_tag(c.arm, c.controller, n): v for n, v in values.items()}
        self._write("eval", [(0, points)], prefix="")

    def close(self) -> None:
        self._close_live()

    def _write(self, stage: str, points: list[tuple[int, dict]], prefix: str | None = None):
        """`points` [(step, {name: value})] into the stage's file (replacing it), each name
        after `prefix/` (default: the stage's name)."""
        if not self.enabled:
            return
        with self._open(stage) as w:
            for step, values in points:
                _add(w, stage if prefix is None else prefix, step, values)

    def _open(self, stage: str, replace: bool = True):
        """A tensorboardX writer of the stage's file (after deleting its files, `replace`)."""
        try:
            from tensorboardX import SummaryWriter  # noqa: PLC0415 (tensorboardX: lazily)
        except ImportError as e:
            raise DpcError(
                "TensorBoard event files need tensorboardX: `pip install tensorboardX` (brax "
                "installs it; `make install` does)."
            ) from e
        self.logdir.mkdir(parents=True, exist_ok=True)
        if replace:
            for old in self.logdir.glob(f"{EVENTS}*.{stage}"):
                old.unlink()
        return SummaryWriter(str(self.logdir), filename_suffix=f".{stage}")

    def _close_live(self) -> None:
        if self._live is not None:
            self._live.close()
            self._live = None


NO_EVENTS = RunEvents(None)  # writes nothing


def _sac_scalars(row: dict) -> dict:
    """A `sac.log` row's columns but the step's (and the epoch, a counter)."""
    return {k: v for k, v in row.items() if k not in (SAC_STEP, "epoch")}


def _add(writer, prefix: str, step: int, values: dict) -> None:
    for name, value in values.items():
        if value is not None and math.isfinite(float(value)):
            writer.add_scalar(f"{prefix}/{name}" if prefix else name, float(value), step)


__all__ = [
    "FOLDER",
    "NO_EVENTS",
    "RunEvents",
    "eval_tag",
    "flat_hparams",
    "logdir_of",
    "run_events",
]
