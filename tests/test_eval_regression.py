"""Evaluation stays what it was: short evaluations against two recordings.

`tests/data/eval_regression.json`, recorded at commit 84660d8 (before the architecture refactor,
the sensor model and the yaw-frame policy): its MBC episodes are replayed with exact sensors and
no delay (`sensor_noise=0, sensor_delay=0`), the envs as they were then: the sensor model,
switched off, must change nothing (checked bit for bit for MBC and the oracle when the sensor
model was added; one controller is enough to keep it so). Its DPC rows belonged to the export
shipped then, which is gone.

`tests/data/eval_regression_shipped.json`, recorded when the present export was shipped (see its
`recorded` key): all four controllers on the shipped export with its env options (sensors on),
each controller an env of its own then (its own compiled reset and chunk); today's evaluation
runs the four in one batch, one program (`envs.controller_batch`), which must give the same
episodes. Both were recorded in MJX, which these tests ask for by name (a CPU's default is
native MuJoCo C).

Seed 4242 chose nothing. The episodes are short (100 env steps, 2 s), so that a change of
arithmetic shows as a small drift of the continuous metrics rather than as other episodes. On one
machine and one jax the evaluation is deterministic, but XLA:CPU compiles the float32 QP and
physics for the host's instruction set (vector width, FMA), and another jax fuses them
differently: the tolerances below are the measured spread across both, times about three
(docs/decisions.md, "Reproducibility across CPUs"). Falls, episode lengths, measured steps and
NaN resets stay exact on every CPU and jax. Both files name the jax they were recorded with.
Re-record the second file (only after a deliberate change of the shipped export) with
`python tests/test_eval_regression.py --record`.
"""

import csv
import json
import pathlib
import sys

import jax
import numpy as np
import pytest
from helpers import lowered_programs

from dpc_mjx import DpcError
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.run.eval import evaluate
from dpc_mjx.run.pipeline import SHIPPED, evaluate_export
from dpc_mjx.run.report import EPISODE_COLUMNS

DATA = pathlib.Path(__file__).parent / "data"
EXACT = DATA / "eval_regression.json"
SHIPPED_RECORDING = DATA / "eval_regression_shipped.json"
SEED, EPISODES, STEPS = 4242, 4, 100
# Measured on one commit (2026-12-01) against the AVX-512 machine's recording: this AMD EPYC (AVX2,
# FMA, no AVX-512), and the same with XLA_FLAGS=--xla_cpu_max_isa=AVX; and jax 0.10.2 against the
# 0.9.2 recording (`make test-latest`). Worst over the four controllers and four episodes:
# returns within 5.7e-4 (relative), every squared-error sum within 2.9e-2 of the largest recorded
# value of that metric in the cell (a sum of small squares over 100 steps amplifies a rounding
# difference; relative to a single small sum it reached 7e-2). Compiled with XLA's older fusion
# emitters, as the suite is (dpc_mjx/xla_flags.py; 2026-12-03): DPC's episodes within 7.6 % of these
# tolerances, the exact keys exact. MuJoCo 4.0.1 (mujoco-mjx 3.17.0) on this EPYC, 2026-12-05:
# returns within 2.7e-4, sums within 1.2e-2, the exact keys exact: the same figures, bit for bit,
# as MuJoCo 3.17.0 (`python experiments/mujoco_spread.py` in each venv).
RTOL_RETURN = 2e-3
SUM_TOL = 0.1  # of the largest recorded value of the metric in the cell
EXACT_KEYS = ("fell", "length", "measured", "nan")
# The env options of the 84660d8 recording: the reaching task then, with exact sensors
EXACT_SENSORS = {"sensor_noise": 0.0, "sensor_delay": 0}
MJX = {"engine": "mjx"}  # the recordings' physics (a CPU's default is native MuJoCo C)


def _recording(path: pathlib.Path) -> dict:
    recording = json.loads(path.read_text())
    assert (recording["seed"], recording["episodes"], recording["steps"]) == (SEED, EPISODES, STEPS)
    return recording["per_episode"]


def _assert_as_recorded(cells, recording: dict) -> None:
    assert [c.controller for c in cells] == list(recording)
    for cell in cells:
        for key, recorded in recording[cell.controller].items():
            got, expected = np.asarray(cell.per_episode[key], float), np.asarray(recorded, float)
            msg = f"{cell.controller} {key}"
            if key in EXACT_KEYS:
                np.testing.assert_array_equal(got, expected, err_msg=msg)
            elif key == "return":
                np.testing.assert_allclose(got, expected, rtol=RTOL_RETURN, err_msg=msg)
            else:
                atol = SUM_TOL * max(float(np.max(np.abs(expected))), 1e-6)
                np.testing.assert_allclose(got, expected, rtol=0, atol=atol, err_msg=msg)


def _evaluate_shipped(csv_path=None, controllers=None):
    return evaluate_export(
        SHIPPED,
        arms=["regular"],
        controllers=controllers or ["mbc", "observer", "dpc", "oracle"],
        episodes=EPISODES,
        steps=STEPS,
        seed=SEED,
        csv=csv_path,
        env=MJX,
    )


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    path = tmp_path_factory.mktemp("eval") / "episodes.csv"
    recording = _recording(SHIPPED_RECORDING)  # mbc, observer, dpc, oracle
    with lowered_programs() as programs:
        cells = _evaluate_shipped(path, list(recording))
    return cells, recording, path, programs


def test_shipped_export_evaluates_as_recorded(evaluated):
    cells, recording, _, _ = evaluated
    _assert_as_recorded(cells, recording)


def test_four_controllers_compile_one_reset_and_one_chunk(evaluated):
    *_, programs = evaluated
    assert programs.count("jit(reset_batch)") == 1, programs
    assert programs.count("jit(chunk_steps)") == 1, programs


@pytest.mark.slow  # a third evaluation's compile (~2 min on 2 cores); `make test-all`
def test_exact_sensors_evaluate_as_the_envs_before_the_sensor_model():
    recording = {"mbc": _recording(EXACT)["mbc"]}  # one controller shows the envs unchanged
    cells = evaluate(
        ["regular"],
        list(recording),
        episodes=EPISODES,
        steps=STEPS,
        seed=SEED,
        overrides=EXACT_SENSORS | MJX,
        progress=False,
    )
    _assert_as_recorded(cells, recording)


def test_eval_writes_one_csv_row_per_episode(evaluated):
    cells, _, path, _ = evaluated
    with path.open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == EPISODE_COLUMNS
    assert len(rows) == EPISODES * len(cells)
    for cell in cells:
        mine = [r for r in rows if r["controller"] == cell.controller]
        assert [int(r["episode"]) for r in mine] == list(range(EPISODES))
        assert all(int(r["seed"]) == SEED for r in mine)
        np.testing.assert_allclose(
            [float(r["return"]) for r in mine], cell.per_episode["return"], rtol=1e-6
        )
        falls = [r["fall_step"] for r in mine if r["fell"] == "1"]
        assert len(falls) == cell.falls and all(int(s) <= STEPS for s in falls)
        measured = np.maximum(cell.per_episode["measured"], 1.0)
        roll = np.sqrt(cell.per_episode["roll_sq"] / measured)
        np.testing.assert_allclose([float(r["roll_rms"]) for r in mine], roll, rtol=1e-6)


@pytest.mark.parametrize("episodes, steps", [(0, 100), (4, 0)])
def test_run_episodes_rejects_an_empty_run_before_building_anything(episodes, steps):
    with pytest.raises(DpcError, match="episodes, steps and chunk >= 1"):
        run_episodes(None, episodes, steps)  # fails before the env is touched


if __name__ == "__main__" and sys.argv[1:] == ["--record"]:
    import datetime
    import subprocess

    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    cells = _evaluate_shipped()
    SHIPPED_RECORDING.write_text(
        json.dumps(
            {
                "recorded": f"{datetime.date.today()}, on top of {commit}",
                "command": "python tests/test_eval_regression.py --record",
                "jax": jax.__version__,
                "seed": SEED,
                "episodes": EPISODES,
                "steps": STEPS,
                "per_episode": {
                    c.controller: {
                        k: np.asarray(v, float).tolist() for k, v in sorted(c.per_episode.items())
                    }
                    for c in cells
                },
            },
            indent=1,
        )
        + "\n"
    )
    print(f"recorded {SHIPPED_RECORDING}")
