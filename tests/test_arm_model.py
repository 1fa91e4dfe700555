"""The arms' rigid-body model (`control.arm_model`) against MuJoCo: the wrench the arms exert on
the base equals the measured mount wrench along free arm motion (no force on the arms but the
base's and gravity), in MuJoCo C and in MJX, on the paper's arm, two arms, the SO-100 and the
Z1; standing still it is the arms' gravity wrench; its joint torques are `mj_rne`'s; its servo
accelerations are MuJoCo's where no constraint acts on the arm; on a batch of arm parameters it
reads each model's numbers."""

import types

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import FAST_COMPILE
from mujoco import mjx

from dpc_mjx.control.arm_model import (
    BaseMotion,
    arm_model,
    exact_inputs,
    joint_torques,
    model_wrench,
    servo_motion,
    servo_qdd,
)
from dpc_mjx.control.state import gravity_u, oracle_u, state_index
from dpc_mjx.robots import ArmSpec, batch_arm_params, build, layout, with_leg_servos

ARMS = ("regular", "double", "so100", "z1")
# float32 model against float64 MuJoCo C, and float32 MJX: the wrench within this share of its
# scale (the largest |component| along the motion) plus an absolute floor
_WRENCH_RTOL = 2e-4
_WRENCH_ATOL = 2e-3  # N, N·m
_TORQUE_ATOL = 1e-4  # N·m: joint torques against mj_rne (float32, |tau| < 30 N·m)
_QDD_RTOL = 1e-4  # servo accelerations against MuJoCo's, of their scale
_STATES = 6  # states sampled along each motion
_STEPS_BETWEEN = 40  # physics steps (0.16 s) between samples


def _moving_robot(name: str, seed: int = 0):
    """(model, layout, data at states of free arm motion): the legs standing on servos, the arm
    servos driven to new random targets, the trunk rocking with it; no other force."""
    model = with_leg_servos(build(name))
    lay = layout(model)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    rng = np.random.default_rng(seed)
    lo, hi = model.actuator_ctrlrange[lay.arm_act].T
    home = data.ctrl[lay.arm_act].copy()
    states = []
    for _ in range(_STATES):
        data.ctrl[lay.arm_act] = np.clip(home + rng.uniform(-0.8, 0.8, home.size), lo, hi)
        for _ in range(_STEPS_BETWEEN):
            mujoco.mj_step(model, data)
        states.append((data.qpos.copy(), data.qvel.copy(), data.ctrl.copy()))
    return model, lay, states


def _forwarded(model, state):
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:], data.ctrl[:] = state
    mujoco.mj_forward(model, data)
    return data


def _inputs(model, lay, d):
    offset = jp.asarray(state_index(model, lay).com_offset, jp.float32)
    gravity = jp.asarray(model.opt.gravity, jp.float32)
    return exact_inputs(lay, offset, gravity, d)


def _native_data(model, state):
    """A jax-readable view of MuJoCo C's data after `mj_forward` (the fields the model reads)."""
    d = _forwarded(model, state)
    names = ("xmat", "xpos", "qpos", "qvel", "qacc", "site_xmat", "site_xpos", "sensordata")
    view = {k: jp.asarray(getattr(d, k), jp.float32) for k in names}
    return types.SimpleNamespace(**view | {"xmat": view["xmat"].reshape(-1, 3, 3)})


def _check_wrench(model, lay, datas):
    arm = arm_model(model, lay)
    got, want = [], []
    for d in datas:
        base, (q, qd, qdd) = _inputs(model, lay, d)
        got.append(model_wrench(arm, base, q, qd, qdd))
        want.append(oracle_u(lay, d, jp.asarray(d.xpos[lay.trunk]) + base.com))
    got, want = np.asarray(got), np.asarray(want)
    scale = np.abs(want).max()
    assert scale > 1.0  # the arms do load the base
    np.testing.assert_allclose(got, want, atol=_WRENCH_ATOL + _WRENCH_RTOL * scale)


@pytest.mark.parametrize("name", ARMS)
def test_the_model_wrench_is_the_measured_mount_wrench_in_mujoco_c(name):
    model, lay, states = _moving_robot(name)
    _check_wrench(model, lay, [_native_data(model, s) for s in states])


@pytest.mark.parametrize("name", ARMS)
def test_the_model_wrench_is_the_measured_mount_wrench_in_mjx(name):
    model, lay, states = _moving_robot(name, seed=1)
    mx = mjx.put_model(model)
    batch = jax.tree.map(lambda *x: jp.stack(x), *[mjx.make_data(mx) for _ in states])
    batch = batch.replace(
        qpos=jp.asarray(np.array([s[0] for s in states])),
        qvel=jp.asarray(np.array([s[1] for s in states])),
        ctrl=jp.asarray(np.array([s[2] for s in states])),
    )
    forward = jax.jit(jax.vmap(mjx.forward, in_axes=(None, 0)), compiler_options=FAST_COMPILE)
    out = forward(mx, batch)
    _check_wrench(model, lay, [jax.tree.map(lambda x, i=i: x[i], out) for i in range(len(states))])


@pytest.mark.parametrize("name", ARMS)
def test_standing_still_it_is_the_arms_gravity_wrench(name):
    model = build(name)
    lay = layout(model)
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    mujoco.mj_kinematics(model, d)
    rot = jp.asarray(d.xmat[lay.trunk].reshape(3, 3), jp.float32)
    com_offset = jp.asarray(state_index(model, lay).com_offset, jp.float32)
    gravity = jp.asarray(model.opt.gravity, jp.float32)
    still = BaseMotion(
        rot=rot, ang_vel=jp.zeros(3), ang_acc=jp.zeros(3), lin_acc=-gravity, com=rot @ com_offset
    )
    n = len(lay.arm_dof)
    u = model_wrench(arm_model(model, lay), still, d.qpos[lay.arm_qpos], jp.zeros(n), jp.zeros(n))
    masses = jp.asarray(model.body_mass[lay.arm_bodies], jp.float32)
    com = jp.asarray(d.xpos[lay.trunk]) + still.com
    want = gravity_u(masses, gravity, jp.asarray(d.xipos[lay.arm_bodies]), com)
    np.testing.assert_allclose(u, want, atol=_WRENCH_ATOL)


@pytest.mark.parametrize("name", ARMS)
def test_joint_torques_are_mj_rne_and_servo_accelerations_mujocos(name):
    model, lay, states = _moving_robot(name, seed=2)
    arm = arm_model(model, lay)
    free = 0
    for state in states:
        d = _forwarded(model, state)
        base, (q, qd, qdd) = _inputs(model, lay, _native_data(model, state))
        rne = np.zeros(model.nv)
        mujoco.mj_rne(model, d, 1, rne)  # M qacc + bias, no armature
        np.testing.assert_allclose(
            joint_torques(arm, base, q, qd, qdd), rne[lay.arm_dof], atol=_TORQUE_ATOL
        )
        # the wrench of the servo accelerations, from their linear part (one forward pass), is
        # the full model's at those accelerations
        wrench, servo = servo_motion(arm, base, q, qd, jp.asarray(d.ctrl[lay.arm_act]))
        np.testing.assert_allclose(
            wrench, model_wrench(arm, base, q, qd, servo), atol=_WRENCH_ATOL, rtol=_WRENCH_RTOL
        )
        if not np.any(d.qfrc_constraint[lay.arm_dof]):  # no limit or friction acts on the arm
            free += 1
            got = servo_qdd(arm, base, q, qd, jp.asarray(d.ctrl[lay.arm_act], jp.float32))
            want = d.qacc[lay.arm_dof]
            np.testing.assert_allclose(got, want, atol=_QDD_RTOL * np.abs(want).max() + 1e-3)
    assert free > 0 or name == "z1"  # z1's joints have dry friction: a constraint always acts


def test_on_a_batch_of_arm_parameters_it_reads_each_models_numbers():
    """`ArmModel.on` of one model of `batch_arm_params`' batch is the model compiled with those
    parameters (what `envs.model_batch` hands the controller)."""
    model = build("regular")
    lay = layout(model)
    mx = mjx.put_model(model)
    lengths, grippers = np.array([0.14, 0.22]), np.array([0.1, 0.4])
    batch, axes = batch_arm_params(mx, model, upper_arm_length=lengths, gripper_mass=grippers)
    arm = arm_model(model, lay)
    for i, (length, gripper) in enumerate(zip(lengths, grippers, strict=True)):
        pick = lambda ax, x, i=i: x if ax is None else x[i]  # noqa: E731
        one = arm.on(jax.tree.map(pick, axes, batch, is_leaf=lambda v: v is None))
        other = build(ArmSpec(upper_arm_length=float(length), gripper_mass=float(gripper)))
        want = arm_model(other, layout(other))
        for field in ("pos", "mass", "com", "inertia"):
            np.testing.assert_allclose(getattr(one, field), getattr(want, field), atol=1e-6)
