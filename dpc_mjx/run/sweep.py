"""Jitted sweeps over a grid of arms: every controller at every (upper-arm length, gripper mass).

    dpc-mjx sweep --upper-arm 0.10:0.30:8 --gripper-mass 0.1:0.6:8 --episodes 16 --out runs/sweep
    table = dpc_mjx.sweep(upper_arm=(0.10, 0.30, 8), gripper_mass=(0.1, 0.6, 8), episodes=16)

The arm is the export's (the arm of its first encoder, a parametric `ArmSpec`: `regular` for
the shipped export); its upper-arm length (m) and gripper mass (kg) take every value of the grid
(`robots.arms.params.batch_arm_params`), so the whole grid is one batched `mjx.Model` and one
program: one compile for every controller (`envs.model_batch.ModelBatchEnv` in an
`envs.controller_batch.ControllerBatch`, MJX engine). DPC uses the export's
encoder of that arm at every grid point: the sweep asks how far one encoder carries.

Protocol (as `run.eval`): every grid point runs the same `episodes` episodes, reset from the
keys of `seed` (episode i from the i-th key, as `dpc-mjx eval --episodes E --seed S`), under
every controller, so differences between controllers are paired per grid point; each episode
runs `steps` env steps of 20 ms (default: the task's episode length) and ends at its first fall.
"""

from __future__ import annotations

import csv
import dataclasses
import pathlib
import time

import numpy as np

from dpc_mjx.controllers import Controller
from dpc_mjx.envs.controller_batch import ControllerBatch
from dpc_mjx.envs.model_batch import ModelBatchEnv
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.errors import DpcError
from dpc_mjx.io.shipped import SHIPPED, export_cells
from dpc_mjx.physics import AUTO
from dpc_mjx.robots.arms.params import batch_arm_params
from dpc_mjx.robots.variants import arm_name
from dpc_mjx.run.eval import CONTROLLERS, CellResult, cell_result
from dpc_mjx.run.plots import sweep_heatmaps
from dpc_mjx.run.report import write_episodes_csv
from dpc_mjx.stats import paired_diff_ci
from dpc_mjx.writer import is_writer

# One row per (grid point, controller) of the sweep's CSV; `*_minus_mbc` are paired differences
# with MBC on the same episodes (empty for MBC itself, or without MBC in the sweep).
COLUMNS = (
    *("upper_arm_m", "gripper_mass_kg", "controller", "episodes", "steps", "seed"),
    *("falls", "fall_rate", "fall_lo", "fall_hi", "mean_return", "return_lo", "return_hi"),
    *("roll_rms", "pitch_rms", "vx_rmse", "yaw_rate_rmse", "nan_resets"),
    *("return_minus_mbc", "return_minus_mbc_lo", "return_minus_mbc_hi"),
)


def grid_values(text: str | tuple) -> np.ndarray:
    """(count,) evenly spaced values from 'low:high:count' (or a tuple (low, high, count)),
    ends included; 'value' alone (or count 1) is the one value low."""
    parts = text.split(":") if isinstance(text, str) else list(text)
    try:
        if len(parts) not in (1, 3):
            raise ValueError
        low = float(parts[0])
        high, count = (low, 1) if len(parts) == 1 else (float(parts[1]), int(parts[2]))
    except ValueError as e:
        raise DpcError(
            f"A grid is 'low:high:count' (e.g. 0.10:0.30:8) or one value, got {text!r}."
        ) from e
    if count < 1 or not (np.isfinite(low) and np.isfinite(high)) or low <= 0 or high < low:
        raise DpcError(f"Grid {text!r} needs 0 < low <= high and count >= 1.")
    return np.linspace(low, high, count) if count > 1 else np.array([low])


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """Every cell of a sweep: `cells[controller]` holds one `CellResult` per grid point in
    row-major order (upper-arm length i, gripper mass j at i * len(gripper_mass) + j)."""

    upper_arm: np.ndarray  # (n,) m
    gripper_mass: np.ndarray  # (m,) kg
    cells: dict[str, list[CellResult]]
    seconds: dict[str, float]  # controller -> wall time of its whole grid, compile included

    def grid(self, controller: str, value: str = "fall_rate") -> np.ndarray:
        """(n, m) a cell figure over the grid: 'fall_rate', 'mean_return' or any
        `CellResult` field."""
        shape = (len(self.upper_arm), len(self.gripper_mass))
        return np.array([getattr(c, value) for c in self.cells[controller]]).reshape(shape)

    def minus_mbc(self, controller: str) -> np.ndarray:
        """(n, m, 3) the paired return difference `controller` - MBC per grid point (mean,
        95% low, high)."""
        shape = (len(self.upper_arm), len(self.gripper_mass), 3)
        pairs = zip(self.cells[controller], self.cells[Controller.MBC])
        diffs = [paired_diff_ci(a.per_episode["return"], b.per_episode["return"]) for a, b in pairs]
        return np.array(diffs).reshape(shape)

    def rows(self) -> list[dict]:
        """The sweep's table, one dict per (grid point, controller) with the keys `COLUMNS`."""
        points = [(u, g) for u in self.upper_arm for g in self.gripper_mass]
        out = []
        for name, cells in self.cells.items():
            diffs = self.minus_mbc(name).reshape(-1, 3) if self._paired(name) else None
            for k, ((u, g), c) in enumerate(zip(points, cells)):
                d = ("", "", "") if diffs is None else tuple(round(float(x), 3) for x in diffs[k])
                out.append(
                    dict(
                        zip(
                            COLUMNS,
                            (
                                *(round(float(u), 4), round(float(g), 4), name, c.episodes),
                                *(c.steps, c.seed, c.falls, c.fall_rate, *c.fall_ci),
                                *(c.mean_return, *c.return_ci, c.roll_rms, c.pitch_rms),
                                *(c.vx_rmse, c.yaw_rate_rmse, c.nan_resets, *d),
                            ),
                        )
                    )
                )
        return out

    def _paired(self, controller: str) -> bool:
        return controller != Controller.MBC and Controller.MBC in self.cells

    def write(self, out: str | pathlib.Path) -> dict[str, pathlib.Path]:
        """The table (sweep.csv), every episode (sweep_episodes.csv) and the heatmaps
        (`plots.sweep_heatmaps`) into the folder `out`; the paths by name."""
        out = pathlib.Path(out)
        out.mkdir(parents=True, exist_ok=True)
        with (out / "sweep.csv").open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS)
            w.writeheader()
            w.writerows(self.rows())
        every = [c for cells in self.cells.values() for c in cells]
        paths = {
            "table": out / "sweep.csv",
            "episodes": write_episodes_csv(out / "sweep_episodes.csv", every),
        }
        return paths | sweep_heatmaps(self, out)


def sweep(
    export: str | pathlib.Path | None = None,
    *,
    upper_arm: str | tuple = (0.10, 0.30, 8),
    gripper_mass: str | tuple = (0.1, 0.6, 8),
    controllers: list[str] | tuple[str, ...] = CONTROLLERS,
    task: str = DEFAULT_TASK,
    episodes: int = 16,
    steps: int | None = None,
    seed: int = 1000,
    env: dict | None = None,
    out: str | pathlib.Path | None = None,
    progress: bool = True,
) -> SweepResult:
    """Every controller at every point of the grid `upper_arm` x `gripper_mass` (each
    'low:high:count' or (low, high, count); m and kg) for the export `export` (default: the
    shipped one), each grid point `episodes` episodes of `steps` env steps from `seed`, env
    options `env` over the export's. Writes the table, episodes and heatmaps into `out` if
    given, prints the table's summary, returns the `SweepResult`."""
    uppers, masses = grid_values(upper_arm), grid_values(gripper_mass)
    controllers = [c.value for c in Controller.parse_all(controllers)]  # plain names, labels
    if episodes < 1 or (steps is not None and steps < 1):
        raise DpcError(f"episodes and steps must be >= 1, got {episodes} and {steps}.")
    artefacts, (arm,), overrides = export_cells(export or SHIPPED, None, controllers, task, env)
    if overrides.get("engine", AUTO) not in (AUTO, "mjx"):
        raise DpcError("A sweep runs one batched MJX model; drop engine=native from --env.")
    overrides = {**overrides, "engine": "mjx"}  # on a CPU too (the default there is native)
    ua, gm = (a.ravel() for a in np.meshgrid(uppers, masses, indexing="ij"))  # (G,) row-major
    points = len(ua)
    k, t0 = len(controllers), time.perf_counter()
    base = make(task, arm=arm, controller=Controller.DPC, **overrides)
    mx, in_axes = (
        batch_arm_params(  # env (c * G + g) * E + i: controller c, grid point g, episode i
            base.mx,
            base.model,
            upper_arm_length=np.tile(np.repeat(ua, episodes), k),
            gripper_mass=np.tile(np.repeat(gm, episodes), k),
        )
    )
    n_steps = base.config.episode_length if steps is None else steps
    dpc = Controller.DPC in controllers
    kw = {"policy": artefacts.dpc_policy(arm_name(arm))} if dpc else {}
    r = run_episodes(  # every controller at every grid point: one batch, one program
        ControllerBatch(ModelBatchEnv(base, mx, in_axes), controllers),
        k * points * episodes,
        n_steps,
        seed=seed,
        progress=progress,
        desc=f"sweep {'/'.join(controllers)} ({points} arms)",
        groups=k * points,
        **kw,
    )
    wall = (time.perf_counter() - t0) / k  # each controller's share of the batch's wall time
    seconds = dict.fromkeys(controllers, wall)
    per_cell = {key: v.reshape(k, points, episodes) for key, v in r.items()}
    cells = {
        name: [
            cell_result(
                f"L={ua[g]:.3f} m, m={gm[g]:.3f} kg",
                name,
                {key: v[c, g] for key, v in per_cell.items()},
                n_steps,
                seed,
                wall / points,
                base.TASK_MEASURES,
            )
            for g in range(points)
        ]
        for c, name in enumerate(controllers)
    }
    result = SweepResult(uppers, masses, cells, seconds)
    _print_summary(result)
    if out is not None and is_writer():
        for name, path in result.write(out).items():
            print(f"{name}: {path}")
    return result


def _print_summary(result: SweepResult) -> None:
    """Per controller: the grid's mean fall rate and return, the best and worst grid point."""
    print("| controller | mean fall rate | mean return | worst grid point (falls) | wall (s) |")
    print("|---|---|---|---|---|")
    for name, cells in result.cells.items():
        worst = max(cells, key=lambda c: c.fall_rate)
        fr = np.mean([c.fall_rate for c in cells])
        ret = np.mean([c.mean_return for c in cells])
        print(
            f"| {name} | {fr:.2f} | {ret:.1f} | {worst.arm} ({worst.fall_rate:.2f}) "
            f"| {result.seconds[name]:.0f} |"
        )
