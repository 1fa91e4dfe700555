"""The robots without the example-robot-data wheel: every named variant builds from the URDFs
shipped in dpc_mjx/descriptions/ and is the same model as built from the wheel (MuJoCo C, fast)."""

import importlib.metadata
import json
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from dpc_mjx import DpcError, assets
from dpc_mjx.robots import VARIANTS, build

_SAME_MODEL_ATOL = 1e-9  # same URDF bytes: every compiled field and stepped state agrees to this
_STEPS = 50  # mj_step calls (0.2 s) from the home keyframe, legs unpowered: the robot sinks onto
# its feet, so foot contacts and the arms' servos act

needs_wheel = pytest.mark.skipif(
    not assets.wheel_installed(), reason="the optional example-robot-data wheel is not installed"
)
_installed = assets.wheel_installed() and importlib.metadata.version(assets.WHEEL)
needs_copied_wheel = pytest.mark.skipif(  # a later release may change its URDFs
    _installed != assets.WHEEL_VERSION,
    reason=f"the shipped URDFs are copies of example-robot-data {assets.WHEEL_VERSION}",
)


def _model_fields(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    """Every size (nbody, nq, ...) and array of the compiled model (masses, inertias, poses,
    geoms, joints, actuators, sensors, keyframes, names) and every scalar of its options."""
    fields = {
        name: np.asarray(value)
        for name in dir(model)
        if not name.startswith("_") and isinstance(value := getattr(model, name), (int, np.ndarray))
    }
    for name in dir(model.opt):
        value = getattr(model.opt, name)
        if not name.startswith("_") and isinstance(value, (int, float, np.ndarray)):
            fields[f"opt.{name}"] = np.asarray(value)
    return fields


def _stepped_qpos(model: mujoco.MjModel) -> np.ndarray:
    """(nq,) qpos after `_STEPS` steps from the home keyframe."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    for _ in range(_STEPS):
        mujoco.mj_step(model, data)
    return data.qpos.copy()


@needs_copied_wheel
@pytest.mark.parametrize("name", sorted(assets.URDFS))
def test_shipped_urdfs_are_the_wheels_files(name):
    shipped = assets.urdf_path(name)
    wheel = assets.wheel_urdf(assets.URDFS[name][1])
    assert shipped.read_bytes() == wheel.read_bytes(), f"{shipped} differs from {wheel}"


@needs_copied_wheel
@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_variant_from_shipped_files_is_the_model_from_the_wheel(name, monkeypatch):
    shipped = build(name)
    read = []

    def from_wheel(urdf: str):
        read.append(urdf)
        return assets.wheel_urdf(assets.URDFS[urdf][1])

    monkeypatch.setattr(assets, "urdf_path", from_wheel)
    wheel = build(name)
    assert "a1" in read  # the patched loader was used: this model came from the wheel's files

    ours, theirs = _model_fields(shipped), _model_fields(wheel)
    assert ours.keys() == theirs.keys()
    for field, value in ours.items():
        if value.dtype.kind in "fiub":
            np.testing.assert_allclose(value, theirs[field], atol=_SAME_MODEL_ATOL, err_msg=field)
        else:
            np.testing.assert_array_equal(value, theirs[field], err_msg=field)
    np.testing.assert_allclose(_stepped_qpos(shipped), _stepped_qpos(wheel), atol=_SAME_MODEL_ATOL)


@needs_wheel
def test_a_file_the_wheel_lacks_names_its_robots():
    with pytest.raises(DpcError, match="has no robots/a2_description.*a1_description"):
        assets.wheel_urdf("a2_description/urdf/a2.urdf")


# A Python process that cannot see the wheel: its distribution is not found, and opening any file
# under its share/example-robot-data/ folder fails. It builds and steps every variant, prints each
# one's stepped qpos and the error a URDF of the wheel gives.
_WITHOUT_WHEEL = """
import importlib.metadata, json, sys

_distribution = importlib.metadata.distribution
def _hidden(name):
    if name.lower().replace("_", "-") == "example-robot-data":
        raise importlib.metadata.PackageNotFoundError(name)
    return _distribution(name)
importlib.metadata.distribution = _hidden
sys.modules["example_robot_data"] = None  # its Python module, where a version ships one

def _no_wheel_files(event, args):
    if event == "open" and "example-robot-data" in str(args[0]):
        raise PermissionError(f"read from the hidden wheel: {args[0]}")
sys.addaudithook(_no_wheel_files)

import mujoco
from dpc_mjx import DpcError, assets
from dpc_mjx.robots import VARIANTS, build

out = {"installed": assets.wheel_installed(), "qpos": {}}
for name in VARIANTS:
    model = build(name)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    for _ in range(STEPS):
        mujoco.mj_step(model, data)
    out["qpos"][name] = data.qpos.tolist()
try:
    assets.wheel_urdf("so_arm_description/urdf/so101.urdf")
except DpcError as e:
    out["error"] = str(e)
print(json.dumps(out))
"""


def test_every_variant_builds_and_steps_without_the_wheel():
    script = _WITHOUT_WHEEL.replace("STEPS", str(_STEPS))
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=False
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["installed"] is False
    assert sorted(out["qpos"]) == sorted(VARIANTS)
    for name, qpos in out["qpos"].items():
        reference = _stepped_qpos(build(name))  # this process: the same code, wheel or not
        np.testing.assert_allclose(qpos, reference, atol=_SAME_MODEL_ATOL, err_msg=name)
    assert "pip install 'dpc_mjx[urdf]'" in out["error"]
    assert "own .urdf or MJCF .xml file" in out["error"]
