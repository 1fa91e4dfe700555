"""The arms' model wrench with numpy alone (`dpc_mjx/io/arm_dynamics.py`, float64) against the
JAX model the env's controller runs (`control.arm_model.servo_motion`, float32), from the
arm-model file an export records (`io.export.arm_model_json`): the same wrench and joint
accelerations on random states of the paper's arm, two arms, the SO-100 and the Z1; standing
still and held by its servos, the arms' gravity wrench; the file's checks. Fast: no env, no MJX.
"""

import json

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import FAST_COMPILE

from dpc_mjx.control import arm_model as jax_model
from dpc_mjx.control.arm_model import BaseMotion, arm_model, joint_torques, servo_motion
from dpc_mjx.control.balance import GRAVITY
from dpc_mjx.control.state import gravity_u, state_index
from dpc_mjx.io import arm_dynamics
from dpc_mjx.io.export import arm_model_json
from dpc_mjx.robots import build, layout

ARMS = ("regular", "double", "so100", "z1")
# float32 JAX against float64 numpy: the wrench within this share of its scale (the largest
# |component| over the states), qdd within this share of its own scale (or 1 rad/s^2)
_RTOL = 1e-4
_STATES = 16


def _models(name: str):
    """(numpy ArmModel from the export's JSON, JAX ArmModel, compiled model, layout)."""
    model = build(name)
    lay = layout(model)
    data = json.loads(json.dumps(arm_model_json(name, name, "a1")))  # as a file holds it
    return arm_dynamics.arm_model_from_json(data), arm_model(model, lay), model, lay


def _states(arm: arm_dynamics.ArmModel, seed: int) -> dict[str, np.ndarray]:
    """Random (q, qd, targets, base motion) in and near the joints' ranges; some joints still
    (friction may hold them), some pushed past their range's end (held there)."""
    rng = np.random.default_rng(seed)
    n, b = arm.n, _STATES
    lo, hi = np.maximum(arm.q_min, arm.q_ref - 1.0), np.minimum(arm.q_max, arm.q_ref + 1.0)
    q = rng.uniform(lo, hi, (b, n))
    q[0] = np.where(np.isfinite(arm.q_min), arm.q_min, q[0])  # every joint at its lower end
    qd = rng.normal(0.0, 1.5, (b, n)) * (rng.random((b, n)) > 0.25)
    targets = q + rng.uniform(-0.6, 0.6, (b, n))
    quat = rng.normal(size=(b, 4)) * [3.0, 0.3, 0.3, 1.0]
    rot = np.array([arm_dynamics.quat_rot(x) for x in quat])
    base = [
        arm_dynamics.base_motion(r, rng.normal(0, 0.8, 3), rng.normal(0, 3.0, 6), r @ c)
        for r, c in zip(rot, rng.normal(0.0, 0.03, (b, 3)), strict=True)
    ]
    return {"q": q, "qd": qd, "targets": targets, "base": base}


@pytest.mark.parametrize("name", ARMS)
def test_the_numpy_servo_motion_is_the_jax_one(name):
    arm, jarm, _, _ = _models(name)
    x = _states(arm, seed=ARMS.index(name))
    motion = jax.jit(
        jax.vmap(lambda b, q, qd, t: servo_motion(jarm, b, q, qd, t)),
        compiler_options=FAST_COMPILE,
    )
    base = BaseMotion(*(jp.asarray(np.array(v), jp.float32) for v in zip(*x["base"], strict=True)))
    f32 = [jp.asarray(x[k], jp.float32) for k in ("q", "qd", "targets")]
    want_u, want_qdd = (np.asarray(v) for v in motion(base, *f32))
    got = [
        arm_dynamics.servo_motion(arm, b, q, qd, t)
        for b, q, qd, t in zip(x["base"], x["q"], x["qd"], x["targets"], strict=True)
    ]
    got_u, got_qdd = (np.array(v) for v in zip(*got, strict=True))
    scale = np.abs(want_u).max()
    assert scale > 5.0  # the arms do load the base
    err = np.abs(got_u - want_u).max() / scale
    assert err <= _RTOL, f"{name}: max |du| / max |u| = {err:.1e}"
    qdd_scale = max(np.abs(want_qdd).max(), 1.0)
    assert np.abs(got_qdd - want_qdd).max() / qdd_scale <= _RTOL
    assert (got_qdd[0] == 0.0).any()  # a joint at its range's end, pushed out of it, is held
    wrench = [arm_dynamics.model_wrench(arm, *v) for v in zip(x["base"], x["q"], x["qd"], got_qdd)]
    np.testing.assert_allclose(wrench, got_u, atol=1e-9 * scale)  # the full pass at those qdd


@pytest.mark.parametrize("name", ARMS)
def test_standing_still_held_by_its_servos_it_is_the_arms_gravity_wrench(name):
    """At the home pose, still, the trunk still and tilted: with the servo targets that hold
    the arms against gravity (T = q + h / kp) they do not move, and the wrench is their weight
    and its moment, as `state.gravity_u` gives it."""
    arm, jarm, model, lay = _models(name)
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    d.qpos[3:7] = [np.cos(0.2), 0.1, np.sin(0.2), 0.3]
    d.qpos[3:7] /= np.linalg.norm(d.qpos[3:7])
    mujoco.mj_kinematics(model, d)
    rot = d.xmat[lay.trunk].reshape(3, 3)
    com = rot @ state_index(model, lay).com_offset
    base = arm_dynamics.base_motion(rot, np.zeros(3), np.zeros(6), com)  # lin_acc = +g
    q, still = d.qpos[lay.arm_qpos], np.zeros(arm.n)
    jbase = BaseMotion(*(jp.asarray(v, jp.float32) for v in base))
    h = np.asarray(
        joint_torques(jarm, jbase, *(jp.asarray(v, jp.float32) for v in (q, still, still)))
    )
    wrench, qdd = arm_dynamics.servo_motion(arm, base, q, still, q + h / arm.kp)
    gravity = np.array([0.0, 0.0, -GRAVITY])
    masses = model.body_mass[lay.arm_bodies]
    want = np.asarray(gravity_u(masses, gravity, d.xipos[lay.arm_bodies], d.xpos[lay.trunk] + com))
    np.testing.assert_allclose(qdd, 0.0, atol=1e-3)
    np.testing.assert_allclose(wrench, want, atol=1e-3 * np.abs(want).max())
    np.testing.assert_allclose(
        arm_dynamics.model_wrench(arm, base, q, still, still), want, atol=1e-6 * np.abs(want).max()
    )


def test_the_constants_are_the_controllers():
    assert arm_dynamics.GRAVITY == GRAVITY
    assert arm_dynamics.STICK_SPEED == jax_model._STICK_SPEED


def test_the_file_holds_the_env_controllers_numbers_exactly():
    """The file's numbers are the float32 ArmModel's, unbounded ones null; the tick's inputs take
    an IMU's quaternion and trunk-frame gyro in place of the rotation and the world rate."""
    data = arm_model_json("z1", "z1", "a1")
    arm, jarm, _, _ = _models("z1")
    for field in (*arm_dynamics.SHAPES, *arm_dynamics.BOUNDS):
        np.testing.assert_array_equal(getattr(arm, field), np.asarray(getattr(jarm, field)))
    assert json.dumps(data, allow_nan=False)  # JSON-safe
    data["limit"][0] = None
    assert arm_dynamics.arm_model_from_json(data).limit[0] == np.inf
    data["q_min"][0] = None
    assert arm_dynamics.arm_model_from_json(data).q_min[0] == -np.inf
    rot = arm_dynamics.quat_rot([0.9, 0.1, -0.2, 0.3])
    x = {"q": arm.q_ref, "qd": np.ones(arm.n), "targets": arm.q_ref, "desired": np.ones(6)}
    x |= {"com": np.zeros(3)}
    a = arm_dynamics.tick_wrench(arm, x | {"rot": rot, "ang_vel": rot @ [0.1, 0.2, 0.3]})
    b = arm_dynamics.tick_wrench(arm, x | {"quat": [0.9, 0.1, -0.2, 0.3], "gyro": [0.1, 0.2, 0.3]})
    np.testing.assert_allclose(a, b, atol=1e-12)


def _broken(edit):
    data = arm_model_json("regular", "regular", "a1")
    edit(data)
    return data


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(format="other"), "is not a 'dpc_mjx arm model' file"),
        (lambda d: d.update(format_version=2), "format_version 2"),
        (lambda d: d.pop("kp"), "lacks or mangles a field"),
        (lambda d: d["mass"].pop(), r"fields \['mass'\] have the wrong shapes"),
        (lambda d: d["parent"].__setitem__(1, 3), "tree"),
        (lambda d: d["qadr"].__setitem__(1, 2), "each joint once"),
        (lambda d: d["pos"][0].__setitem__(0, None), "lacks or mangles|not finite"),
    ],
)
def test_a_broken_file_is_refused(edit, message):
    with pytest.raises(ValueError, match=message):
        arm_dynamics.arm_model_from_json(_broken(edit), "arm model")
