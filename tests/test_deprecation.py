"""Modules that moved (`dpc_mjx.deprecation`): the old import paths of `dpc_mjx.robots`' modules
answer with the module at its new path, warning once; the package's public names stay where
users import them."""

import importlib.util
import json
import pathlib
import subprocess
import sys

import dpc_mjx.robots

ROBOTS = pathlib.Path(dpc_mjx.robots.__file__).parent

# The public names of `dpc_mjx.robots` before its modules moved into `bases/` and `arms/`.
_PUBLIC_BEFORE = (
    "VARIANTS ArmFamily ArmSpec Layout Mount RobotSpec UrdfArm arm_argument arm_name "
    "batch_arm_params build build_spec home_ctrl layout mount_wrench perturbed_home prop_layout "
    "read_arm_description resolve robot_spec with_leg_servos"
).split()

# In a fresh process: every old path imported twice, three ways; the warnings of each round.
_IMPORT_EVERY_OLD_PATH = """
import json, sys, warnings
import dpc_mjx.robots as robots
rounds = []
for _ in range(2):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        same = {}
        for old, new in robots.MOVED.items():
            exec(f"import {old} as module", globals())
            tail = old.rsplit(".", 1)[1]
            exec(f"from dpc_mjx.robots import {tail} as by_from", globals())
            same[old] = module is sys.modules[new] is by_from and module.__spec__.name == new
    rounds.append({"same": same, "warnings": [
        (str(w.message), w.category.__name__, w.filename) for w in caught]})
print(json.dumps(rounds))
"""


def test_every_old_module_path_imports_the_moved_module_warning_once():
    done = subprocess.run(
        [sys.executable, "-c", _IMPORT_EVERY_OLD_PATH],
        capture_output=True,
        text=True,
        check=True,
    )
    first, second = json.loads(done.stdout)
    assert all(first["same"].values()), first["same"]
    assert len(first["warnings"]) == len(dpc_mjx.robots.MOVED)
    for (old, new), (message, category, filename) in zip(
        dpc_mjx.robots.MOVED.items(), first["warnings"], strict=True
    ):
        assert category == "DeprecationWarning"
        assert message.startswith(f"{old} moved to {new};") and "dpc_mjx 0.3" in message
        assert filename == "<string>"  # the importing line, not the import machinery
    assert all(second["same"].values()) and second["warnings"] == []  # once per process


def test_old_paths_lead_to_modules_that_exist_and_the_public_names_stay():
    for old, new in dpc_mjx.robots.MOVED.items():
        assert importlib.util.find_spec(new) is not None, f"{old} -> {new}: no such module"
        assert not (ROBOTS / (old.rsplit(".", 1)[1] + ".py")).exists(), f"{old}: a file is left"
    missing = [n for n in _PUBLIC_BEFORE if not hasattr(dpc_mjx.robots, n)]
    assert not missing and set(_PUBLIC_BEFORE) <= set(dpc_mjx.robots.__all__)
