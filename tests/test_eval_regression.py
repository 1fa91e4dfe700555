"""Evaluation stays what it was: a short evaluation of the shipped export against a recording.

The recording (`tests/data/eval_regression.json`) was made at commit 84660d8, the last commit
before the architecture refactor, with the evaluation code of that commit
(`dpc_mjx.pipeline.evaluate_export` there, per-episode arrays of `envs.episodes.run_episodes`).
Seed 4242 chose nothing. The episodes are short (100 env steps, 2 s), so that a change of arithmetic
shows as a small drift of the continuous metrics rather than as other episodes; on one machine
the evaluation is deterministic and the match is exact.
"""

import csv
import json
import pathlib

import numpy as np
import pytest

from dpc_mjx import DpcError
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.run.eval import EPISODE_COLUMNS
from dpc_mjx.run.pipeline import SHIPPED, evaluate_export

RECORDING = pathlib.Path(__file__).parent / "data" / "eval_regression.json"
SEED, EPISODES, STEPS = 4242, 4, 100
# Relative tolerance of returns and error sums: exact on the recording machine; another CPU's
# XLA code may round differently, and 2 s of walking grows a 1e-7 difference to ~1e-5.
RTOL = 1e-4
ATOL = 1e-6  # for sums that are ~0 (an episode without error)


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    path = tmp_path_factory.mktemp("eval") / "episodes.csv"
    recording = json.loads(RECORDING.read_text())
    assert (recording["seed"], recording["episodes"], recording["steps"]) == (SEED, EPISODES, STEPS)
    per_episode = recording["per_episode"]
    cells = evaluate_export(
        SHIPPED,
        controllers=list(per_episode),
        episodes=EPISODES,
        steps=STEPS,
        seed=SEED,
        csv=path,
    )
    return cells, per_episode, path


def test_shipped_export_evaluates_as_recorded(evaluated):
    cells, recording, _ = evaluated
    assert [c.controller for c in cells] == list(recording)
    for cell in cells:
        for key, expected in recording[cell.controller].items():
            got = np.asarray(cell.per_episode[key], float)
            np.testing.assert_allclose(
                got, expected, rtol=RTOL, atol=ATOL, err_msg=f"{cell.controller} {key}"
            )


def test_eval_writes_one_csv_row_per_episode(evaluated):
    cells, _, path = evaluated
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
