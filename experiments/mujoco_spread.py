"""How far the installed MuJoCo moves what the tests hold to recordings and to MuJoCo C.

    python experiments/mujoco_spread.py [--out episodes.json]   # in each venv: .venv, .venv-mujoco3

Prints the mujoco and mujoco-mjx versions, then:
- MJX against MuJoCo C (`tests/test_mjx.py::test_mjx_agrees_with_mujoco_c`): the `regular` robot
  on leg servos, 100 steps from the perturbed home pose of seed 1 in both; the gap of the trunk
  height (m) and of its quaternion, against the tests' named tolerances;
- the shipped export's evaluation against its recording (`tests/test_eval_regression.py`: seed
  4242, 4 episodes of 100 env steps, the four controllers, MJX): the worst relative difference of
  the returns, the worst squared-error-sum difference as a fraction of the cell's largest recorded
  value of that metric, each against the tests' tolerance, and whether falls, lengths, measured
  steps and NaN resets are exact; `--out` writes the episodes' figures (JSON), to compare two
  MuJoCo releases with each other.
Compiles as the tests do (a few minutes on 2 cores; the first part is seconds).
"""

from __future__ import annotations

import json
import pathlib
import sys
from importlib.metadata import version

import mujoco
import numpy as np

from dpc_mjx import sim
from dpc_mjx.robots import build
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.run.pipeline import SHIPPED, evaluate_export

TESTS = pathlib.Path(__file__).resolve().parents[1] / "tests"
sys.path.insert(0, str(TESTS))
import test_eval_regression as regression  # noqa: E402 (the tests' tolerances and settings)
import test_mjx  # noqa: E402


def mjx_against_c() -> None:
    model = with_leg_servos(build("regular"))
    qpos, ctrl = perturbed_home(model, 1, seed=1)[0], home_ctrl(model)
    data = mujoco.MjData(model)
    data.qpos[:], data.ctrl[:] = qpos, ctrl
    steps = 2 * test_mjx._CHUNK
    for _ in range(steps):
        mujoco.mj_step(model, data)
    dx = sim.make_rollout(sim.put_model(model), steps)(
        sim.batched_data(sim.put_model(model), qpos[None], ctrl[None])
    )
    height = abs(float(dx.qpos[0, 2]) - data.qpos[2])
    quat = float(np.max(np.abs(np.asarray(dx.qpos[0, 3:7]) - data.qpos[3:7])))
    print(
        f"MJX vs MuJoCo C after {steps} steps: trunk height {height:.2e} m "
        f"(tolerance {test_mjx._MJX_C_HEIGHT_TOL:g}), quaternion {quat:.2e} "
        f"(tolerance {test_mjx._MJX_C_QUAT_TOL:g})"
    )


def eval_against_recording(out: str | None) -> None:
    recording = regression._recording(regression.SHIPPED_RECORDING)
    cells = evaluate_export(
        SHIPPED,
        arms=["regular"],
        controllers=list(recording),
        episodes=regression.EPISODES,
        steps=regression.STEPS,
        seed=regression.SEED,
        env=regression.MJX,
    )
    if out:
        figures = {
            c.controller: {k: np.asarray(v).tolist() for k, v in c.per_episode.items()}
            for c in cells
        }
        pathlib.Path(out).write_text(json.dumps(figures, indent=1, sort_keys=True))
    ret, sums, exact = 0.0, 0.0, True
    for cell in cells:
        for key, recorded in recording[cell.controller].items():
            got, want = np.asarray(cell.per_episode[key], float), np.asarray(recorded, float)
            if key in regression.EXACT_KEYS:
                exact &= bool(np.array_equal(got, want))
            elif key == "return":
                ret = max(ret, float(np.max(np.abs(got - want) / np.abs(want))))
            else:
                scale = max(float(np.max(np.abs(want))), 1e-6)
                sums = max(sums, float(np.max(np.abs(got - want))) / scale)
    print(
        f"shipped export vs its recording: returns {ret:.1e} (relative; tolerance "
        f"{regression.RTOL_RETURN:g}), squared-error sums {sums:.1e} (of the cell's largest; "
        f"tolerance {regression.SUM_TOL:g}), falls/lengths/measured/NaN "
        f"{'exact' if exact else 'NOT exact'}"
    )


if __name__ == "__main__":
    print(f"mujoco {version('mujoco')}, mujoco-mjx {version('mujoco-mjx')}")
    mjx_against_c()
    eval_against_recording(sys.argv[2] if sys.argv[1:2] == ["--out"] else None)
