"""TensorBoard event files of a run (`dpc_mjx.run.tensorboard`) read back with TensorBoard's own
reader: the numbers of the CSVs, the run's hyperparameters, each row once after a resume; and in
a run of several processes only process 0 writes (`dpc_mjx.writer`).

The fast tests drive the writers with the rows the CSV writers get (no training); the slow one
starts two real processes (`jax.distributed` on localhost, CPU) that each run a tiny write path,
SAC on the toy env of tests/test_devices.py included, each given its own folder: process 1's
must stay empty.
"""

from __future__ import annotations

import argparse
import ast
import csv
import functools
import pathlib
import subprocess
import sys

import jax
import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.plugins.hparams import plugin_data_pb2

from dpc_mjx import devices, io
from dpc_mjx.adapter import checkpoint as adapter_checkpoint
from dpc_mjx.io.shipped import SHIPPED
from dpc_mjx.run import cli
from dpc_mjx.run.config import RunConfig, start_run
from dpc_mjx.run.eval import cell_result
from dpc_mjx.run.report import write_episodes_csv
from dpc_mjx.run.tensorboard import EVAL_SCALARS, METRICS, eval_tag, logdir_of, run_events
from dpc_mjx.sac import log as sac_log
from dpc_mjx.writer import barrier

HERE = pathlib.Path(__file__).resolve()
ROOT = HERE.parents[1]
CONFIG = RunConfig(arm="regular", eval_controllers=("mbc", "dpc"), seed=3)
# adapter.train's history (the keys adapter_log.csv is written from)
HISTORY = {"train_nll": [1.5, 0.75, 0.5], "val_nll": [1.6, 0.9, 0.8]}
REPORTS = [  # policy.regression's reports: the MBC samples, then one DAgger round
    {"samples": 100, "best_epoch": 4, "val_mse": 0.25, "r2": [0.9, 0.8, 0.7, 0.6, 0.5, 0.4]},
    {"samples": 150, "best_epoch": 5, "val_mse": 0.125, "r2": [0.95, 0.9, 0.8, 0.7, 0.6, 0.5]},
]


def _sac_rows() -> list[dict]:
    """sac_log.csv's rows of a 3-epoch run evaluated at epochs 0 (the start) and 2."""
    rows = [sac_log.empty_row() | {"epoch": 0, "env_steps": 0, "grad_steps": 0, "episodes": 0}]
    rows[0] |= {"eval_return": -4.0, "eval_fall_rate": 0.5}
    for epoch in (1, 2, 3):
        rows.append(
            sac_log.empty_row()
            | {"epoch": epoch, "env_steps": 256 * epoch, "grad_steps": 64 * epoch}
            | {"mean_return": 10.0 * epoch, "fall_rate": 0.5 / epoch, "critic_loss": 2.0 / epoch}
            | {"actor_loss": -epoch / 4, "alpha": 0.1 / epoch, "episodes": 8}
        )
    rows[2] |= {"eval_return": 12.5, "eval_fall_rate": 0.25, "eval_mbc_return": 3.0}
    return rows


def _cells() -> list:
    """Two evaluation cells from per-episode arrays as `rollout.run_episodes` returns them."""
    rng = np.random.default_rng(0)
    cells = []
    for controller, falls in (("mbc", [1, 0, 1, 0]), ("dpc", [0, 0, 0, 1])):
        r = {k: rng.uniform(0.1, 1.0, 4) for k in ("roll_sq", "pitch_sq", "vx_sq_err")}
        r |= {k: rng.uniform(0.1, 1.0, 4) for k in ("vy_sq_err", "yaw_rate_sq_err", "dist")}
        r |= {k: rng.uniform(0.1, 1.0, 4) for k in ("pos_sq_err", "ee_sq_err")}
        r |= {"return": rng.normal(50.0, 5.0, 4), "fell": np.array(falls, bool)}
        r |= {"length": np.array([5, 10, 7, 10]), "measured": np.array([5.0, 10, 7, 10])}
        r |= {"nan": np.zeros(4, bool)}
        cells.append(cell_result("regular", controller, r, 10, 1000, 0.1, ("dist",)))
    return cells


def _write_a_run(run: pathlib.Path, sac_rows=None) -> None:
    """The files of a tiny run, through the library's writers: the config, every stage's events,
    the adapter and SAC logs (SAC's from `sac_rows`, or a short toy SAC run), an export, the
    evaluation's per-episode CSV."""
    start_run(CONFIG, run, resume=False)
    events = run_events(CONFIG, run)
    events.adapter(HISTORY)
    events.regression(REPORTS)
    if sac_rows is None:
        from test_devices import SAC_TOY, ToyEnv  # noqa: PLC0415 (the slow test's worker only)

        from dpc_mjx.sac import SacConfig, train  # noqa: PLC0415

        config = SacConfig(**(SAC_TOY | {"num_timesteps": 1024}))  # 2 epochs
        result = train(ToyEnv(), config, run / "sac", progress=False, on_epoch=events.sac_row)
        sac_rows = result.history
    else:
        for row in sac_rows[1:]:
            events.sac_row(row)  # as `sac.train`'s on_epoch
    events.sac(sac_rows)
    art = _shipped()
    io.export(
        run / "export",
        adapter_config=art.adapter_config,
        policy=art.policy,
        decoder=art.decoder,
        encoders={"regular": art.encoder("regular")},
        arms={"regular": "regular"},
    )
    barrier("exported")
    cells = _cells()
    write_episodes_csv(run / "eval_episodes.csv", cells)
    events.eval(cells)


@functools.cache
def _shipped():
    return io.load(SHIPPED)


def _scalars(logdir: pathlib.Path) -> tuple[EventAccumulator, dict]:
    acc = EventAccumulator(str(logdir))
    acc.Reload()
    tags = acc.Tags()["scalars"]
    return acc, {t: [(e.step, e.value) for e in acc.Scalars(t)] for t in tags}


def _csv(path: pathlib.Path) -> list[dict]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_the_events_hold_the_csvs_numbers_and_the_run_config(tmp_path):
    run, rows = tmp_path / "run", _sac_rows()
    _write_a_run(run, rows)
    # the CSVs the same rows make (adapter_log.csv, sac_log.csv)
    adapter_checkpoint._write_log(tmp_path / "adapter_log.csv", HISTORY)
    sac_log.rewrite(tmp_path, rows)
    acc, scalars = _scalars(run / "tensorboard")
    adapter_csv = _csv(tmp_path / "adapter_log.csv")
    for name in ("train_nll", "val_nll"):
        expected = [(int(r["epoch"]), float(r[name])) for r in adapter_csv]
        np.testing.assert_allclose(scalars[f"adapter/{name}"], expected)
    for name in ("mean_return", "fall_rate", "critic_loss", "actor_loss", "alpha", "eval_return"):
        csv_rows = [r for r in _csv(tmp_path / sac_log.LOG_FILE) if r[name] != "nan"]
        expected = [(int(r["env_steps"]), float(r[name])) for r in csv_rows]
        assert len(expected) == (2 if name == "eval_return" else 3)  # epochs 0 and 2 evaluated
        np.testing.assert_allclose(scalars[f"sac/{name}"], expected, rtol=1e-6)
    assert "sac/epoch" not in scalars and "sac/env_steps" not in scalars  # the step's columns
    np.testing.assert_allclose(scalars["regression/r2/u1"], [(0, 0.8), (1, 0.9)], rtol=1e-6)
    np.testing.assert_allclose(scalars["regression/val_mse"], [(0, 0.25), (1, 0.125)])
    for cell in _cells():
        for name in EVAL_SCALARS:
            (got,) = scalars[eval_tag("regular", cell.controller, name)]
            np.testing.assert_allclose(got, (0, getattr(cell, name)), rtol=1e-6)
        (dist,) = scalars[eval_tag("regular", cell.controller, "dist")]  # a task measure
        assert dist[1] == pytest.approx(cell.task["dist"][0], rel=1e-6)
    # the hyperparameters: the RunConfig flattened, the eval tags as metrics
    content = acc.PluginTagToContent("hparams")
    start = plugin_data_pb2.HParamsPluginData.FromString(content["_hparams_/session_start_info"])
    hparams = start.session_start_info.hparams
    assert hparams["sac.learning_rate"].number_value == pytest.approx(CONFIG.sac.learning_rate)
    assert hparams["seed"].number_value == 3 and hparams["arm"].string_value == "regular"
    assert hparams["sac.hidden"].string_value == str(list(CONFIG.sac.hidden))
    experiment = plugin_data_pb2.HParamsPluginData.FromString(content["_hparams_/experiment"])
    metrics = {m.name.tag for m in experiment.experiment.metric_infos}
    assert metrics == {eval_tag("regular", c, n) for c in ("mbc", "dpc") for n in METRICS}


def test_a_stage_written_again_replaces_its_events(tmp_path):
    """A resumed run: SAC's live rows after the restart, then its whole history; the adapter's
    history loaded again. Each row once, one file per stage."""
    rows = _sac_rows()
    events = run_events(CONFIG, tmp_path / "run", logdir=tmp_path / "tb")
    logdir = logdir_of(tmp_path / "run", tmp_path / "tb")
    assert logdir == tmp_path / "tb" / "run"
    events.adapter(HISTORY)
    for row in rows[1:3]:  # killed after epoch 2
        events.sac_row(row)
    events.close()
    events = run_events(CONFIG, tmp_path / "run", logdir=tmp_path / "tb")  # resumed
    events.adapter(HISTORY)
    events.sac_row(rows[3])
    events.sac(rows)
    _, scalars = _scalars(logdir)
    assert [s for s, _ in scalars["sac/mean_return"]] == [256, 512, 768]
    assert [s for s, _ in scalars["adapter/val_nll"]] == [1, 2, 3]
    suffixes = sorted(p.name.rsplit(".", 1)[1] for p in logdir.iterdir())
    assert suffixes == ["adapter", "config", "sac"]


def test_only_process_0_writes(tmp_path, monkeypatch):
    """Process 1 of a run (faked) writes nothing; the same calls in process 0 write the run."""
    monkeypatch.setattr(jax, "process_index", lambda: 1)
    _write_a_run(tmp_path / "p1", _sac_rows())
    assert not (tmp_path / "p1").exists()
    monkeypatch.undo()
    _write_a_run(tmp_path / "p0", _sac_rows())
    written = {p.relative_to(tmp_path / "p0").parts[0] for p in (tmp_path / "p0").rglob("*")}
    assert written == {"config.json", "tensorboard", "export", "eval_episodes.csv"}


def test_tensorboardx_is_imported_only_inside_functions():
    """`import dpc_mjx` (which loads only its own top modules, tests/test_xla_flags.py) and its
    run layer load no tensorboardX: no module imports it at module level."""
    inside = []
    for path in (ROOT / "dpc_mjx").rglob("*.py"):
        if "tensorboardX" not in (text := path.read_text()):
            continue
        tree = ast.parse(text)
        functions = (f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef))
        in_function = {id(n) for f in functions for n in ast.walk(f)}
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [getattr(node, "module", None) or ""] + [a.name for a in node.names]
                if any(n.split(".")[0] == "tensorboardX" for n in names):
                    assert id(node) in in_function, f"{path}: tensorboardX imported at import"
                    inside.append(path.name)
    assert inside and set(inside) == {"tensorboard.py"}


@pytest.mark.slow  # a whole `dpc-mjx train`, tiny budget (25 min on 2 busy cores: MJX compiles)
def test_dpc_mjx_train_writes_events_that_tensorboard_reads(tmp_path):
    from test_readme_snippets import TINY_SAC  # noqa: PLC0415 (slow test only)

    run, logdir = tmp_path / "run", tmp_path / "tb"
    sets = [f"sac.{k}={v}" for k, v in TINY_SAC.items()]  # 3 epochs, no SAC evaluations
    sets += ["eval_steps=10", 'eval_controllers=["mbc","dpc"]', "adapter.epochs=5"]
    argv = ["train", "--run", str(run), "--device", "cpu", "--samples", "3200", "--episodes", "2"]
    assert cli.main([*argv, "--logdir", str(logdir), "--set", *sets]) == 0
    acc, scalars = _scalars(logdir / "run")
    adapter_csv = _csv(run / "adapter" / adapter_checkpoint.LOG)
    expected = [(int(r["epoch"]), float(r["val_nll"])) for r in adapter_csv]
    np.testing.assert_allclose(scalars["adapter/val_nll"], expected, rtol=1e-6)
    sac_csv = _csv(run / "sac" / sac_log.LOG_FILE)
    expected = [(int(r["env_steps"]), float(r["critic_loss"])) for r in sac_csv]
    assert [s for s, _ in expected] == [256, 512, 768]
    np.testing.assert_allclose(scalars["sac/critic_loss"], expected, rtol=1e-6)
    assert len(scalars["regression/r2/u0"]) == 1
    for c in ("mbc", "dpc"):
        (fall_rate,) = scalars[eval_tag("regular", c, "fall_rate")]
        assert 0.0 <= fall_rate[1] <= 1.0
    assert "_hparams_/session_start_info" in acc.PluginTagToContent("hparams")
    assert not (run / "tensorboard").exists()  # --logdir: the events went there


@pytest.mark.slow  # two processes, each compiling the toy SAC (6 min on 2 busy cores)
def test_two_processes_write_one_set_of_files(tmp_path):
    from test_devices import _free_port, _subprocess_env  # noqa: PLC0415 (slow test only)

    address = f"127.0.0.1:{_free_port()}"
    procs = [
        subprocess.Popen(
            [sys.executable, str(HERE), f"--run={tmp_path / f'p{i}'}", f"--coordinator={address}"]
            + [f"--process-id={i}"],
            env=_subprocess_env(),
            cwd=ROOT,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    errors = [p.communicate(timeout=900)[1] for p in procs]
    assert all(p.returncode == 0 for p in procs), "\n".join(e[-3000:] for e in errors)
    assert not (tmp_path / "p1").exists()  # process 1 wrote nothing
    run = tmp_path / "p0"
    log = _csv(run / "sac" / sac_log.LOG_FILE)
    assert [int(r["epoch"]) for r in log] == [0, 1, 2]
    _, scalars = _scalars(run / "tensorboard")
    assert [s for s, _ in scalars["sac/eval_return"]] == [0, 512, 1024]
    assert (run / "export" / "dpc.json").is_file() and (run / "config.json").is_file()


def _worker(argv: list[str]) -> None:
    """One process of the slow test: join the run, write the tiny run into `--run`."""
    p = argparse.ArgumentParser()
    p.add_argument("--run", required=True)
    p.add_argument("--coordinator", required=True)
    p.add_argument("--process-id", type=int, required=True)
    args = p.parse_args(argv)
    devices.initialize(args.coordinator, 2, args.process_id)
    _write_a_run(pathlib.Path(args.run))


if __name__ == "__main__":
    _worker(sys.argv[1:])
