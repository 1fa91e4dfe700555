"""`dpc-mjx sweep`: every controller over a grid of arms, the grid as one batched model.

The sweep itself runs once, DPC only (one MJX compile of the batched model, the export's policy
on every grid point); the table's paired columns and the heatmaps of two controllers are checked
on a `SweepResult` of synthetic episodes, which needs no compile."""

import csv

import jax
import numpy as np
import pytest
from helpers import fast_jit

from dpc_mjx.envs.registry import make
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.errors import DpcError
from dpc_mjx.robots.variants import arm_name
from dpc_mjx.run import cli
from dpc_mjx.run.eval import cell_result
from dpc_mjx.run.pipeline import SHIPPED, export_cells
from dpc_mjx.run.sweep import SweepResult, grid_values, sweep
from dpc_mjx.stats import paired_diff_ci

# 2 x 2 arms: the shipped export's `regular` (0.14 m, 0.1 kg), `longer` (0.28 m), `heavier`
# (0.5 kg) and both changed at once
GRID = ("--upper-arm", "0.14:0.28:2", "--gripper-mass", "0.1:0.5:2")
POINTS = {(0.14, 0.1), (0.14, 0.5), (0.28, 0.1), (0.28, 0.5)}
EPISODES, STEPS, SEED = 2, 10, 3
CONTROLLER = "dpc"
# Per-episode return of a grid point vs the same arm compiled as its own variant, after STEPS
# steps: the batched model leaves body_invweight0/dof_invweight0 (constraint regularisation
# scales) at the base arm's values (`robots.arms.params`). Measured on MBC's episodes (FAST_COMPILE,
# jax 0.9.2): the grid point within 1.0e-4 of `longer`, `regular` 2.0e-3 away from it; DPC's
# episodes (the test since 2026-12-02) pass the same tolerance.
RETURN_RTOL = 5e-4


@pytest.fixture(scope="module", autouse=True)
def _fast_compile():
    """Compile-bound (10 steps of each program): every program of this module, the sweep's and
    its reference's alike, compiled with FAST_COMPILE."""
    with pytest.MonkeyPatch.context() as m:
        m.setattr(jax, "jit", fast_jit)
        yield


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    args = ["--controllers", CONTROLLER, "--episodes", str(EPISODES), "--steps", str(STEPS)]
    assert cli.main(["sweep", *GRID, *args, "--seed", str(SEED), "--out", str(out)]) == 0
    return out


def _rows(path):
    with path.open() as f:
        return list(csv.DictReader(f))


def _point(row):
    return float(row["upper_arm_m"]), float(row["gripper_mass_kg"])


def _episodes_of(episodes, row, controller):
    """The returns of the episodes of a table row's grid point and `controller`."""
    arm = f"L={float(row['upper_arm_m']):.3f} m, m={float(row['gripper_mass_kg']):.3f} kg"
    return [
        float(e["return"]) for e in episodes if e["arm"] == arm and e["controller"] == controller
    ]


def test_the_sweep_writes_its_table_episodes_and_heatmaps(swept):
    rows = _rows(swept / "sweep.csv")
    assert {_point(r) for r in rows} == POINTS
    assert [r["controller"] for r in rows] == [CONTROLLER] * 4
    episodes = _rows(swept / "sweep_episodes.csv")
    assert len(episodes) == 4 * EPISODES
    for row in rows:
        returns = _episodes_of(episodes, row, CONTROLLER)
        assert len(returns) == EPISODES and np.all(np.isfinite(returns))
        assert float(row["mean_return"]) == pytest.approx(np.mean(returns), 1e-5)
        assert row["return_minus_mbc"] == ""  # no MBC in this sweep: nothing to pair with
    for name in ("fall_rate", "return"):
        with (swept / f"sweep_{name}.png").open("rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    assert not (swept / "sweep_dpc_minus_mbc.png").exists()


def _synthetic_cells(controller, returns, fell):
    """One cell per grid point from per-episode returns (points, episodes) and falls."""
    zeros = np.zeros(returns.shape[1])
    sums = ("roll_sq", "pitch_sq", "vx_sq_err", "vy_sq_err", "yaw_rate_sq_err", "pos_sq_err")
    cells = []
    for g, (ret, f) in enumerate(zip(returns, fell)):
        r = {"return": ret, "fell": f, "nan": zeros, "length": zeros + STEPS, "measured": zeros + 1}
        r |= {k: zeros + 0.01 * (g + 1) for k in (*sums, "ee_sq_err")}
        cells.append(cell_result(f"point {g}", controller, r, STEPS, SEED, 0.0))
    return cells


def test_the_table_pairs_every_controller_with_mbc_episode_by_episode(tmp_path):
    rng = np.random.default_rng(0)
    mbc = rng.normal(50.0, 5.0, (4, 6))
    dpc = mbc + rng.normal(3.0, 1.0, mbc.shape)  # the same episodes, better on each
    fell = rng.random(mbc.shape) < 0.3
    result = SweepResult(
        upper_arm=np.array([0.14, 0.28]),
        gripper_mass=np.array([0.1, 0.5]),
        cells={
            "mbc": _synthetic_cells("mbc", mbc, fell),
            "dpc": _synthetic_cells("dpc", dpc, fell),
        },
        seconds={"mbc": 1.0, "dpc": 1.0},
    )
    paths = result.write(tmp_path)
    rows = _rows(paths["table"])
    # row-major: upper-arm length, then gripper mass
    assert [(_point(r), r["controller"]) for r in rows] == [
        (p, c) for c in ("mbc", "dpc") for p in sorted(POINTS)
    ]
    for g, row in enumerate(rows[4:]):
        mean, lo, hi = paired_diff_ci(dpc[g], mbc[g])
        assert [float(row[k]) for k in ("return_minus_mbc", "return_minus_mbc_lo",
                                        "return_minus_mbc_hi")] == pytest.approx(
            [mean, lo, hi], abs=1e-3
        )  # fmt: skip
        assert float(row["fall_rate"]) == pytest.approx(fell[g].mean())
        assert lo > 0  # the interval of a consistent +3 gain excludes 0
    assert all(r["return_minus_mbc"] == "" for r in rows[:4])
    assert len(_rows(paths["episodes"])) == 2 * mbc.size
    for key in ("fall_rate", "return", "dpc_minus_mbc"):
        with paths[f"heatmap {key}"].open("rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow  # a second MJX env compile (~2 min); the batched model's physics: test_mjx
def test_a_grid_point_steps_as_the_arm_compiled_alone(swept):
    """Grid point (0.28 m, 0.1 kg) is the variant `longer`: its episodes (the export's policy and
    encoder, as the sweep runs them) match `longer`'s own env on the same seed, and differ from
    `regular`'s by more than the tolerance."""
    artefacts, (export_arm,), overrides = export_cells(SHIPPED, None, [CONTROLLER], "reaching")
    env = make("reaching", arm="longer", controller=CONTROLLER, **overrides)
    policy = artefacts.dpc_policy(arm_name(export_arm))
    ref = run_episodes(env, EPISODES, STEPS, seed=SEED, policy=policy)["return"]
    episodes = _rows(swept / "sweep_episodes.csv")
    grid = {
        arm: np.array([float(e["return"]) for e in episodes if e["arm"] == arm])
        for arm in ("L=0.280 m, m=0.100 kg", "L=0.140 m, m=0.100 kg")
    }
    np.testing.assert_allclose(grid["L=0.280 m, m=0.100 kg"], ref, rtol=RETURN_RTOL)
    assert np.max(np.abs(grid["L=0.140 m, m=0.100 kg"] - ref) / np.abs(ref)) > RETURN_RTOL


def test_bad_grids_and_engines_fail_before_compiling():
    assert grid_values("0.1:0.3:3") == pytest.approx([0.1, 0.2, 0.3])
    assert grid_values("0.2") == pytest.approx([0.2])
    for bad in ("0.3:0.1:4", "0.1:0.3", "a:b:c", "0:0.3:2", "0.1:0.3:0"):
        with pytest.raises(DpcError, match="low"):
            grid_values(bad)
    with pytest.raises(DpcError, match="MJX"):
        sweep(upper_arm="0.1:0.2:2", env={"engine": "native"}, progress=False)
    with pytest.raises(DpcError, match="Unknown controller"):
        sweep(controllers=["mpc"], progress=False)
