"""`dpc-mjx sweep`: every controller over a grid of arms, the grid as one batched model."""

import csv

import jax
import numpy as np
import pytest
from helpers import fast_jit

from dpc_mjx.envs.registry import make
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.errors import DpcError
from dpc_mjx.run import cli
from dpc_mjx.run.pipeline import SHIPPED, export_cells
from dpc_mjx.run.sweep import grid_values, sweep
from dpc_mjx.stats import paired_diff_ci

# 2 x 2 arms: the shipped export's `regular` (0.14 m, 0.1 kg), `longer` (0.28 m), `heavier`
# (0.5 kg) and both changed at once
GRID = ("--upper-arm", "0.14:0.28:2", "--gripper-mass", "0.1:0.5:2")
EPISODES, STEPS, SEED = 2, 10, 3
CONTROLLERS = ("mbc", "dpc")
# Per-episode return of a grid point vs the same arm compiled as its own variant, after STEPS
# steps: the batched model leaves body_invweight0/dof_invweight0 (constraint regularisation
# scales) at the base arm's values (`robots.params`). Measured (FAST_COMPILE, jax 0.9.2): the
# grid point within 1.0e-4 of `longer`, `regular` 2.0e-3 away from it.
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
    args = ["--controllers", *CONTROLLERS, "--episodes", str(EPISODES), "--steps", str(STEPS)]
    assert cli.main(["sweep", *GRID, *args, "--seed", str(SEED), "--out", str(out)]) == 0
    return out


def _rows(path):
    with path.open() as f:
        return list(csv.DictReader(f))


def test_the_sweep_writes_its_table_episodes_and_heatmaps(swept):
    rows = _rows(swept / "sweep.csv")
    points = {(float(r["upper_arm_m"]), float(r["gripper_mass_kg"])) for r in rows}
    assert points == {(0.14, 0.1), (0.14, 0.5), (0.28, 0.1), (0.28, 0.5)}
    assert sorted(r["controller"] for r in rows) == ["dpc"] * 4 + ["mbc"] * 4
    episodes = _rows(swept / "sweep_episodes.csv")
    assert len(episodes) == 2 * 4 * EPISODES
    for row in rows:  # the table's paired difference is that of its episodes
        mine = [e for e in episodes if e["arm"].startswith(f"L={float(row['upper_arm_m']):.3f}")]
        mine = [e for e in mine if f"m={float(row['gripper_mass_kg']):.3f}" in e["arm"]]
        ret = {c: [float(e["return"]) for e in mine if e["controller"] == c] for c in CONTROLLERS}
        assert float(row["mean_return"]) == pytest.approx(np.mean(ret[row["controller"]]), 1e-5)
        if row["controller"] == "dpc":
            diff = paired_diff_ci(np.array(ret["dpc"]), np.array(ret["mbc"]))[0]
            assert float(row["return_minus_mbc"]) == pytest.approx(diff, abs=1e-3)
        else:
            assert row["return_minus_mbc"] == ""
    for name in ("fall_rate", "return", "dpc_minus_mbc"):
        with (swept / f"sweep_{name}.png").open("rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow  # a third MJX env compile (~2 min); the batched model's physics: test_mjx
def test_a_grid_point_steps_as_the_arm_compiled_alone(swept):
    """Grid point (0.28 m, 0.1 kg) is the variant `longer`: its MBC episodes match `longer`'s own
    env on the same seed, and differ from `regular`'s by more than the tolerance."""
    _, _, overrides = export_cells(SHIPPED, None, ["mbc"], "a1_arm/reaching")
    env = make("a1_arm/reaching", arm="longer", controller="mbc", **overrides)
    ref = run_episodes(env, EPISODES, STEPS, seed=SEED)["return"]
    episodes = [e for e in _rows(swept / "sweep_episodes.csv") if e["controller"] == "mbc"]
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
