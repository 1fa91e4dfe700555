"""The deployment loop (`dpc_mjx.deploy`) on a simulated robot (MuJoCo C as the plant): its
torques equal the env's controller's on the same states; with its state estimator and noisy
sensors it keeps the robot walking; bad input is refused."""

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from dpc_mjx.control import sensors
from dpc_mjx.deploy import Deployment, Measurement
from dpc_mjx.envs.observations import observation
from dpc_mjx.errors import DpcError

# The loop and the env's controller on the same states run the same code in float32 (on the
# loop's own view of the state the two agree bit for bit), but the loop computes kinematics at
# the trunk origin and shifts them: rounding differences of ~1e-8 m. The balance QP stops at
# its tolerance (2-4 warm-started iterations), so such a difference can change where it stops:
# a 1e-6 m/s change of the base velocity moves the torques by up to 0.6 N·m at some ticks
# (measured) and by ~1e-6 N·m at others. Hence bounds at the QP's tolerance; a wrong frame,
# sign or joint order gives errors of several N·m at every tick.
TORQUE_TOL_MEDIAN = 0.1  # N·m, the median tick (measured ~0.05)
TORQUE_TOL_MAX = 1.0  # N·m, every tick (the torques are tens of N·m)
COMMAND = np.array([0.3, 0.0, 0.0])  # m/s forward
ACCEL_STD = 0.05  # m/s^2, white noise of a MEMS accelerometer at 250 Hz (BMI088 class)


def measure(dep: Deployment, data: mujoco.MjData, errors: dict | None = None) -> Measurement:
    """What the robot's sensors read from the plant's `data` (after mj_forward): exact, or with
    `errors` (`sensor_errors`) added."""
    lay = dep.env.lay
    rot = data.xmat[lay.trunk].reshape(3, 3)
    accel = rot.T @ (data.qacc[0:3] - np.array([0.0, 0.0, -9.81]))  # specific force, trunk
    m = {
        "quat": data.qpos[3:7].copy(),
        "gyro": data.qvel[3:6].copy(),
        "accel": accel,
        "leg_q": data.qpos[lay.leg_qpos].copy(),
        "leg_qd": data.qvel[lay.leg_dof].copy(),
        "arm_q": data.qpos[lay.arm_qpos].copy(),
        "arm_qd": data.qvel[lay.arm_dof].copy(),
    }
    if errors is not None:
        rng, bias = errors["rng"], errors["bias"]
        tilt = bias["tilt"] + rng.normal(0, sensors.TILT[0], 2)  # rad, roll and pitch
        for axis, angle in zip(np.eye(3)[:2], tilt, strict=True):  # quat * q_x(roll) * q_y(pitch)
            turn = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
            mujoco.mju_mulQuat(m["quat"], m["quat"].copy(), turn)
        m["gyro"] += bias["gyro"] + rng.normal(0, sensors.GYRO[0], 3)
        m["accel"] += rng.normal(0, ACCEL_STD, 3)
        m["leg_q"] += rng.normal(0, sensors.LEG_Q[0], 12)
        m["leg_qd"] += rng.normal(0, sensors.LEG_QD[0], 12)
    targets = data.ctrl[lay.arm_act].copy()
    return Measurement(**m, arm_targets=targets, command=COMMAND)


def sensor_errors(seed: int) -> dict:
    """The sensor model of `control/sensors.py` at scale 1 (an episode's attitude and gyro
    biases, then white noise every tick), and accelerometer noise `ACCEL_STD`."""
    rng = np.random.default_rng(seed)
    bias = {
        name: rng.uniform(-1, 1, n) * spec[1]
        for name, n, spec in (("tilt", 2, sensors.TILT), ("gyro", 3, sensors.GYRO))
    }
    return {"rng": rng, "bias": bias}


def plant(dep: Deployment) -> mujoco.MjData:
    """The robot standing at its home pose, forwarded."""
    model = dep.env.model
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    return data


@pytest.fixture(scope="module")
def deployment():
    """DPC with the shipped export: the policy's path and the controller's (one compile; MBC
    and the observer differ only in `DpcEnv.controller_u`)."""
    return Deployment(controller="dpc")


def test_torques_equal_the_env_controller(deployment):
    """0.4 s of walking in MuJoCo C driven by the loop (the true base state given, as motion
    capture would): at every tick the env's controller (and, for DPC, the env's policy at its
    rate), from the loop's controller state before the tick and on `mjx.put_data` of the same
    physics state, asks for the same torques."""
    dep = deployment
    env, ctl = dep.env, dep.env.controller
    model, data = env.model, plant(dep)
    policy = dep.policy

    @jax.jit
    def reference(cs, u_policy, d, tick):
        if policy is not None:
            obs = observation(env.lay, d, jp.asarray(COMMAND), cs.observer.estimate)
            new_u = env.policy_u(policy(obs[None], jax.random.PRNGKey(0))[0])
            u_policy = jp.where(tick % env.n_substeps == 0, new_u, u_policy)
        u, add, model = env.controller_u(d, u_policy)
        cs, ctrl = ctl.step(cs, d, jp.asarray(COMMAND), u, add_estimate=add, add_model=model)
        return cs, u_policy, ctrl[env.lay.leg_act]

    dep.reset(measure(dep, data), xy=data.qpos[:2])
    errors = []  # per tick, N·m
    for tick in range(100):
        before = dep.state  # the recorded controller state: both start each tick from it
        m = measure(dep, data)
        tau = dep.step(m, base_position=data.qpos[:3], base_velocity=data.qvel[:3])
        d = mjx.put_data(model, data)
        _, _, tau_ref = reference(before.ctrl, before.u_policy, d, tick)
        errors.append(float(np.max(np.abs(tau - np.asarray(tau_ref)))))
        data.ctrl[env.lay.leg_act] = tau
        mujoco.mj_step(model, data)
        mujoco.mj_forward(model, data)
    print(f"torque differences: median {np.median(errors):.1e}, max {max(errors):.2f} N·m")
    assert np.median(errors) < TORQUE_TOL_MEDIAN
    assert max(errors) < TORQUE_TOL_MAX
    assert data.qpos[2] > 0.2  # still standing
    assert np.any(np.asarray(dep.state.u_policy) != 0)  # the policy acted


def test_estimator_keeps_the_robot_walking_with_noisy_sensors(deployment):
    """2 s in MuJoCo C on the loop's own estimate (no base state given) with the sensor model
    (attitude and gyro bias and noise, encoder and accelerometer noise) and its one-tick delay
    from measurement to torque: the robot walks at the command and the estimate tracks the true
    velocity and height."""
    dep = deployment
    model, data = dep.env.model, plant(dep)
    errors = sensor_errors(seed=0)
    dep.reset(measure(dep, data, errors), xy=data.qpos[:2])
    vel_err, height_err, speed = [], [], []
    tau = data.ctrl[dep.env.lay.leg_act].copy()
    for tick in range(500):
        data.ctrl[dep.env.lay.leg_act] = tau  # the torques of the previous tick's measurement
        tau = dep.step(measure(dep, data, errors))
        if tick >= 125:  # after 0.5 s
            est = dep.state.est
            vel_err.append(np.asarray(est.velocity) - data.qvel[:3])
            height_err.append(float(est.position[2]) - data.qpos[2])
            speed.append(data.qvel[0])
        mujoco.mj_step(model, data)
        mujoco.mj_forward(model, data)
        assert data.qpos[2] > 0.15, f"fell at tick {tick}"
    vel_rmse = np.sqrt(np.mean(np.square(vel_err), axis=0))
    print(f"velocity RMSE {vel_rmse} m/s, height error {np.abs(height_err).max():.3f} m")
    assert np.all(vel_rmse < 0.1)
    assert np.max(np.abs(height_err)) < 0.03
    assert abs(np.mean(speed) - COMMAND[0]) < 0.1


def test_bad_input_is_refused(deployment):
    dep = Deployment.__new__(Deployment)  # no model needed for the controller check
    with pytest.raises(DpcError, match="oracle reads a mount force sensor"):
        Deployment.__init__(dep, controller="oracle")
    data = plant(deployment)
    m = measure(deployment, data)
    bad = Measurement(**{**m.__dict__, "leg_q": m.leg_q[:6]})
    with pytest.raises(DpcError, match=r"Measurement.leg_q must have shape \(12,\)"):
        deployment.reset(bad)
    with pytest.raises(DpcError, match=r"Measurement.contact must have shape \(4,\)"):
        deployment.reset(Measurement(**{**m.__dict__, "contact": np.ones(2)}))
    deployment.reset(m)
    with pytest.raises(DpcError, match="both base_position and base_velocity"):
        deployment.step(m, base_position=data.qpos[:3])
    fresh = Deployment(controller="mbc")
    with pytest.raises(DpcError, match="before reset"):
        fresh.step(m)
