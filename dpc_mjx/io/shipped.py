"""What describes an export beyond its networks: where the shipped ones are, the env options it
imposes on a use, and the cells an evaluation of it covers.

    SHIPPED, SHIPPED_PAPER                 the exports in the package (docs/results.md)
    shipped_for(base)                      the shipped export trained on a base (SHIPPED_BASES)
    env_overrides(artefacts, task)         the env options it was trained with, for a use on `task`
    engine_of(artefacts)                   the engine it records, where this device runs it
    export_cells(export_dir, arms, ...)    its artefacts, the arms to evaluate, the env options
"""

from __future__ import annotations

import pathlib

from dpc_mjx.controllers import Controller
from dpc_mjx.envs.registry import DEFAULT_TASK, resolve_arm, task_name
from dpc_mjx.errors import DpcError
from dpc_mjx.io.load import Artefacts, load
from dpc_mjx.physics import AUTO, ENGINE_CHOICES, resolve_engine
from dpc_mjx.robots.spec_json import arm_argument
from dpc_mjx.robots.variants import arm_name
from dpc_mjx.serialization import tuples

SHIPPED = pathlib.Path(__file__).parents[1] / "artefacts" / "regular"  # the trained run's export
# the paper's recipe (`RECIPES["paper"]`: SAC from a random actor, no oracle label for the actor)
SHIPPED_PAPER = SHIPPED.with_name("regular-paper")
# The default recipe on other bases (`dpc-mjx train --base go2`; `--base b1 --arm z1`, native
# engine): docs/results-transfer.md, "Other bases: the reaching task"
SHIPPED_BASES = {"a1": SHIPPED, "go2": SHIPPED.with_name("go2"), "b1": SHIPPED.with_name("b1")}
# The env options that belong to the policy rather than the task (they follow an export to any
# task: the frame and base of its u, the observer a base 'observer' adds to, the sensor model),
# with the values of exports written before they existed
_POLICY_ENV_BEFORE = {
    "u_frame": "world",
    "u_base": "zero",
    "observer_gain": 20.0,
    "observer_aligned": False,
    "sensor_noise": 0.0,
    "sensor_delay": 0,
}
# env options an export's env_config never imposes (the engine: a default, `engine_of`)
_CHOSEN_PER_USE = ("controller", "engine")


def shipped_for(base: str | None) -> pathlib.Path:
    """The shipped export trained on `base` (a named base; None: the A1's). A base without one
    gets the A1's, which `export_cells` refuses for DPC, naming the fix."""
    return SHIPPED_BASES.get(base or "a1", SHIPPED)


def env_overrides(artefacts: Artefacts, task: str | None = None) -> dict:
    """The env options an export was trained with (its sidecar's env_config), to evaluate and
    transfer under the same disturbances; the controller and the engine are chosen per use. On
    another `task` than the export's, only what belongs to the policy carries over (the frame
    and base of its u, the observer, the sensor model: `_POLICY_ENV_BEFORE`'s keys; the task
    brings its own disturbances). An export written before `EnvConfig.u_frame` and the
    sensor model existed acted in the world frame and was trained with exact sensors."""
    saved = {**_POLICY_ENV_BEFORE, **(artefacts.meta.get("env_config") or {})}
    saved = tuples({k: v for k, v in saved.items() if k not in _CHOSEN_PER_USE})
    trained_on = artefacts.meta.get("extra", {}).get("task", DEFAULT_TASK)
    if task is not None and task_name(task) != task_name(trained_on):
        return {k: saved[k] for k in _POLICY_ENV_BEFORE}
    return saved


def engine_of(artefacts: Artefacts) -> str:
    """The engine to evaluate an export with unless told: the one its sidecar records where this
    device runs it (native MuJoCo C only where JAX runs on one CPU: `physics.resolve_engine`),
    else 'auto' (an export written before the engine was recorded, or native on a GPU)."""
    recorded = (artefacts.meta.get("env_config") or {}).get("engine", AUTO)
    if recorded == "native" and resolve_engine(AUTO) != "native":
        return AUTO
    return recorded if recorded in ENGINE_CHOICES else AUTO


def export_cells(
    export_dir: str | pathlib.Path,
    arms: list[str] | None,
    controllers,
    task: str,
    env: dict | None = None,
) -> tuple[Artefacts, list, dict]:
    """What evaluating an export needs: its artefacts, the arms (`evaluate_export`'s rules; an
    arm the A1 cannot hold up or an encoder missing for 'dpc' fails here, before any compile)
    and the env options (the export's, its engine where this device runs it (`engine_of`), then
    `env` over them)."""
    artefacts = load(export_dir)
    arms = [
        artefacts.arm_spec(arm) if arm in artefacts.encoders else arm_argument(arm)
        for arm in (arms or list(artefacts.meta["encoders"])[:1])
    ]
    for arm in arms:
        resolve_arm(arm)  # the A1 holds it up (`control.static_balance`), before any compile
    options = {**env_overrides(artefacts, task), "engine": engine_of(artefacts), **(env or {})}
    if Controller.DPC in Controller.parse_all(controllers):  # 'policy' too; unknown names fail
        for arm in arms:
            artefacts.encoder(arm_name(arm))
        trained_on = (artefacts.meta.get("env_config") or {}).get("base", "a1")
        if options.get("base", trained_on) != trained_on:
            raise DpcError(
                f"The export {export_dir} was trained on the base {trained_on!r}; its encoders "
                f"learned that base's dynamics, not {options['base']!r}'s. Evaluate it on "
                f"{trained_on!r} (drop --base), train on that base (dpc-mjx train --base), or "
                "give its policy a new encoder trained on that base (experiments/carry_over.py; "
                "the A1's policy carries to a Go1 so, docs/results-transfer.md)."
            )
    return artefacts, arms, options
