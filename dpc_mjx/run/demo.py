"""The demo (`make demo`, `dpc-mjx demo`): a small DPC run end to end on the default arm, then an
MBC / observer / feedforward / DPC line; and `run_variants` (`dpc-mjx variants`): every arm
variant built and stood in MJX, with a table of DOF, masses and MJX steps/s."""

from __future__ import annotations

import dataclasses
import datetime
import pathlib
import time

import numpy as np

from dpc_mjx import sim
from dpc_mjx.control.base_scaling import model_scale
from dpc_mjx.control.state import has_fallen
from dpc_mjx.controllers import Controller
from dpc_mjx.physics import AUTO, resolve_engine
from dpc_mjx.robots import VARIANTS, build, resolve
from dpc_mjx.robots.layout import layout
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.rotations import roll_pitch_yaw
from dpc_mjx.run.bench import time_calls
from dpc_mjx.run.config import RECIPES, RunConfig
from dpc_mjx.run.pipeline import train_and_evaluate


@dataclasses.dataclass(frozen=True)
class DemoRow:
    variant: str
    arm_dof: int
    arm_mass: float  # kg, every arm body
    total_mass: float  # kg
    compile_s: float
    steps_per_s: float  # MJX env-steps/s after compilation
    stood: int  # envs that did not fall (`control.state.has_fallen`)


def stand_variant(name: str, batch: int = 16, seconds: float = 1.0, chunk: int = 50) -> DemoRow:
    """Stand `batch` perturbed copies of variant `name` on leg servos in MJX for `seconds`."""
    model = with_leg_servos(build(name))
    lay = layout(model)
    mx = sim.put_model(model)
    data = sim.batched_data(mx, perturbed_home(model, batch), np.tile(home_ctrl(model), (batch, 1)))
    rollout = sim.make_rollout(mx, chunk)
    n_calls = max(1, round(seconds / model.opt.timestep / chunk) - 1)
    compile_s, call_s, data = time_calls(rollout, data, n_calls)
    arm_bodies = np.concatenate([a.bodies for a in lay.arms]) if lay.arms else np.zeros(0, int)
    rpy = roll_pitch_yaw(data.qpos[:, 3:7])
    fallen = has_fallen(data.qpos[:, 2], rpy[:, :2], model_scale(model).fall_height)
    return DemoRow(
        variant=name,
        arm_dof=int(lay.arm_dof.size),
        arm_mass=float(model.body_mass[arm_bodies].sum()),
        total_mass=float(model.body_mass.sum()),
        compile_s=compile_s,
        steps_per_s=batch * chunk / call_s,
        stood=int((~np.asarray(fallen)).sum()),
    )


def format_table(rows: list[DemoRow], batch: int) -> str:
    lines = [
        "| variant | arm DOF | arm mass (kg) | total mass (kg) | compile (s) "
        f"| MJX env-steps/s (batch {batch}) | standing after 1 s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.variant} | {r.arm_dof} | {r.arm_mass:.3f} | {r.total_mass:.3f} | "
            f"{r.compile_s:.1f} | {r.steps_per_s:,.0f} | {r.stood}/{batch} |"
        )
    return "\n".join(lines)


def run_variants(variants=tuple(VARIANTS), batch: int = 16, seconds: float = 1.0) -> list[DemoRow]:
    for name in variants:
        resolve(name)  # fail on a bad name before compiling anything
    rows = []
    for i, name in enumerate(variants, 1):
        print(
            f"[{i}/{len(variants)}] {name}: building, compiling and standing {batch} envs "
            f"for {seconds:g} s in MJX ...",
            flush=True,
        )
        rows.append(stand_variant(name, batch=batch, seconds=seconds))
    print(format_table(rows, batch), flush=True)
    return rows


# The shipped run's recipe (`RECIPES["default"]`: random-motion data, the adapter, the actor
# regressed on what the arms' model cannot know on [s_body, z], added to the model wrench, no
# SAC stage) on a budget that runs in a few minutes on a 2-core CPU: a fifth of the shipped
# run's samples and a sixteenth of its evaluation (docs/results.md), beside MBC, the observer
# and the feedforward. `quick` is a smoke run of the same stages.
DEMO = RECIPES["default"] | {
    "samples": 20_000,
    "adapter.epochs": 20,
    "eval_episodes": 16,
    "eval_steps": 500,
    "eval_controllers": (
        Controller.MBC,
        Controller.OBSERVER,
        Controller.FEEDFORWARD,
        Controller.DPC,
    ),
}
QUICK = DEMO | {
    "samples": 4096,
    "adapter.epochs": 5,
    "eval_episodes": 8,
    "eval_steps": 100,
}


def run_demo(quick: bool = False, run_dir: str | None = None, engine: str | None = None) -> dict:
    """Data, adapter, policy, export and evaluation of the regular arm on the reaching task with
    a small budget, on `engine` (default: the env's, `physics.resolve_engine`: native MuJoCo C
    on a CPU, MJX on an accelerator); prints the stages, the evaluation table and one MBC /
    observer / DPC line."""
    engine = resolve_engine(engine or AUTO)
    config = RunConfig().replace(**(QUICK if quick else DEMO), **{"env.engine": engine})
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    run = pathlib.Path(run_dir or f"runs/demo-{stamp}")
    print(
        f"demo: a small DPC run of the {config.arm} arm on {config.task} into {run} "
        f"(physics: {engine})",
        flush=True,
    )
    t0 = time.perf_counter()
    summary = train_and_evaluate(config, run)
    cells = {c["controller"]: c for c in summary["eval"]}
    shown = [cells[c] for c in DEMO["eval_controllers"]]
    n, seconds = shown[0]["episodes"], shown[0]["steps"] * 0.02
    falls = " / ".join(f"{c['falls'] / n:.2f}" for c in shown)
    returns = " / ".join(f"{c['mean_return']:.1f}" for c in shown)
    print(
        f"\nMBC / observer / feedforward / DPC ({config.arm}, {n} episodes of {seconds:g} s): "
        f"fall rate {falls}, mean return {returns} "
        f"(demo budget, {engine} engine; the shipped run is in docs/results.md). "
        f"Wall time {time.perf_counter() - t0:.0f} s.",
        flush=True,
    )
    return summary
