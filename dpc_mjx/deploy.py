"""The deployment loop: what a robot's computer runs at 250 Hz, from its measurements to the 12
leg torques, with the env's own controller and policy code (no second copy).

    robot = Deployment(controller="dpc")       # the shipped export, the arm it was trained on
    robot.reset(measurement)                   # standing still, feet on the ground
    while True:
        tau = robot.step(measurement)          # (12,) N·m, every 4 ms

One tick:

    1. leg and arm kinematics at the measured attitude and joint angles, by MuJoCo C
       (`mj_kinematics`, `mj_comPos` on the robot's own model, trunk origin at 0)
    2. the base state estimator (`control/estimator.py`): trunk position and velocity from the
       accelerometer and the stance legs (a robot measures neither)
    3. every `policy_dt` (50 Hz, the export's): the policy's u from the observation
       `[s_body, s_arm, p_arm, u_obs]` (`envs/observations.py`) - DPC only
    4. the low-level controller (`control/controller.py`, the env's instance): gait phase,
       Raibert footholds, the balance QP with u, swing PD, tau = J^T f

Steps 2-4 are one jitted call at batch 1. The controller is that of the export's arm in the
reaching env built with the export's options (`Deployment.env`; the env is only its vehicle).

What runs where, for an export on the arms' model wrench (`action_scaling.base` 'model', the
shipped ones): here the controller computes that wrench every tick in JAX (step 4,
`control/arm_estimate.py`: the arms' model from the robot's file, the measured arm joints, the
IMU and this tick's `arm_targets`, the balance QP's desired accelerations) and adds it to the
policy's u of the last policy step, as the env does. A robot that runs the policy with numpy
alone (`io/inference.py`, no JAX) computes the same wrench with `io/arm_dynamics.py` from the
export's `arm_model_<arm>.json` and the same inputs (docs/deployment.md).

I/O contract (`Measurement`; frames: world z up, trunk x forward, y left):

    quat         (4,)  trunk attitude, trunk -> world, (w, x, y, z) - the IMU's filter output
    gyro         (3,)  rad/s, trunk angular velocity, trunk frame
    accel        (3,)  m/s^2, specific force, trunk frame (at rest (0, 0, +9.81))
    leg_q        (12,) rad, leg joints in `robots.layout.Layout.leg_joints` order: FR, FL,
                       RR, RL legs, each hip, thigh, calf (the base file's signs and zeros)
    leg_qd       (12,) rad/s, same order
    arm_q        (n,)  rad (m for a finger), the arm's joints in the model's order
                       (`Deployment.arm_joints`)
    arm_qd       (n,)  rad/s (m/s)
    arm_targets  (k,)  the arm servos' current targets, same units (`Deployment.arm_actuators`)
    command      (3,)  v_x, v_y (m/s, heading frame), yaw rate (rad/s)
    contact      (4,)  foot contact flags (FR, FL, RR, RL; 1 in contact), or None: the gait's
                       planned stance (`estimator.stance_trust`)

Returned: (12,) leg torques, N·m, `leg_joints` order, clipped to the base's motors' limits (the
A1's 33.5 N·m; `Layout.torque_limits`). The arm's servos are driven by its own planner
(`arm_targets`), not by this loop.
"""

from __future__ import annotations

import dataclasses
import pathlib

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from flax import struct
from mujoco import mjx

from dpc_mjx import io
from dpc_mjx.control import estimator, gait
from dpc_mjx.control.controller import ControllerState
from dpc_mjx.control.state import read_state
from dpc_mjx.controllers import Controller
from dpc_mjx.envs.observations import observation
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.errors import DpcError
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.robots.spec_json import arm_argument
from dpc_mjx.robots.variants import arm_name

# the oracle needs a force sensor no robot has
CONTROLLERS = (
    Controller.DPC,
    Controller.MBC,
    Controller.OBSERVER,
    Controller.FEEDFORWARD,
    Controller.FEEDFORWARD_OBSERVER,
)
# mjx.Data fields MuJoCo C computes from the measured attitude and joints (trunk origin at 0)
KINEMATICS = ("xpos", "xmat", "xipos", "site_xpos", "site_xmat", "subtree_com", "cdof")


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One tick of what the robot measures; units, frames and order in the module docstring."""

    quat: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    leg_q: np.ndarray
    leg_qd: np.ndarray
    arm_q: np.ndarray
    arm_qd: np.ndarray
    arm_targets: np.ndarray
    command: np.ndarray
    contact: np.ndarray | None = None


@struct.dataclass
class LoopState:
    """What the loop carries from tick to tick."""

    ctrl: ControllerState
    est: estimator.EstimatorState
    u_policy: jax.Array  # (6,) the policy's last u, N and N·m, in `u_frame`
    tick: jax.Array  # () ticks since reset


class Deployment:
    """The whole controller for one robot; `reset` once, then `step` every tick."""

    def __init__(
        self,
        export: str | pathlib.Path | None = None,
        arm: str | None = None,
        controller: str = Controller.DPC,
        estimator_config: estimator.EstimatorConfig | None = None,
    ):
        controller = Controller.parse(controller)
        if controller not in CONTROLLERS:
            raise DpcError(
                f"controller={controller.value!r} cannot run on a robot; choose one of "
                f"{[c.value for c in CONTROLLERS]} (the oracle reads a mount force sensor)."
            )
        artefacts = io.load(export or SHIPPED)
        arm = arm or next(iter(artefacts.meta["encoders"]))
        robot_arm = artefacts.arm_spec(arm) if arm in artefacts.encoders else arm_argument(arm)
        overrides = {**env_overrides(artefacts), "sensor_noise": 0.0, "sensor_delay": 0}
        self.env = make(DEFAULT_TASK, arm=robot_arm, controller=controller, **overrides)
        self.controller_name = controller
        dpc = controller == Controller.DPC
        self.policy = artefacts.dpc_policy(arm_name(robot_arm)) if dpc else None
        self.estimator_config = estimator_config or estimator.EstimatorConfig()
        model, lay = self.env.model, self.env.lay
        self.arm_joints = tuple(model.joint(model.dof_jntid[i]).name for i in lay.arm_dof)
        self.arm_actuators = tuple(model.actuator(i).name for i in lay.arm_act)
        self._data = mujoco.MjData(model)
        self._template = mjx.make_data(self.env.mx)
        self._shapes = {k: getattr(self._template, k).shape for k in KINEMATICS}
        self._tick = jax.jit(self._tick_fn, static_argnames=("policy_step", "truth"))
        self._reset = jax.jit(self._reset_fn)
        self.state: LoopState | None = None

    # host side -----------------------------------------------------------------------------

    def _inputs(self, m: Measurement) -> dict:
        """The jitted tick's array inputs: qpos, qvel with the base at 0 (nq,), (nv,), the
        kinematics at that pose (`KINEMATICS`), ctrl with the arm targets, the measurements."""
        model, lay = self.env.model, self.env.lay
        quat = np.asarray(m.quat, float)
        qpos = np.zeros(model.nq)
        qpos[3:7] = quat / np.linalg.norm(quat)
        qpos[lay.leg_qpos], qpos[lay.arm_qpos] = m.leg_q, m.arm_q
        qvel = np.zeros(model.nv)
        qvel[3:6] = m.gyro
        qvel[lay.leg_dof], qvel[lay.arm_dof] = m.leg_qd, m.arm_qd
        d = self._data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        ctrl = np.zeros(model.nu)
        ctrl[lay.arm_act] = m.arm_targets
        contact = -np.ones(4) if m.contact is None else np.asarray(m.contact, float)
        arrays = {
            "qpos": qpos,
            "qvel": qvel,
            "ctrl": ctrl,
            "accel": np.asarray(m.accel),
            "command": np.asarray(m.command),
            "arm_targets": np.asarray(m.arm_targets),
            "contact": contact,
            **{k: np.reshape(getattr(d, k), self._shapes[k]) for k in KINEMATICS},
        }
        return {k: np.asarray(v, np.float32) for k, v in arrays.items()}

    def reset(self, m: Measurement, xy: tuple[float, float] = (0.0, 0.0)) -> None:
        """Start the loop: the robot standing still with its feet on the ground at `m`, its
        trunk at `xy` (m, world; the estimator's origin). Checks the measurement's sizes (`step`
        does not, to stay fast). The first `step`s compile the tick (~15 s, once per object)."""
        self._check(m)
        self.state = self._reset(self._inputs(m), jp.asarray(xy, jp.float32))

    def step(
        self,
        m: Measurement,
        base_position: np.ndarray | None = None,
        base_velocity: np.ndarray | None = None,
    ) -> np.ndarray:
        """One 4 ms tick: (12,) leg torques, N·m. `base_position`, `base_velocity` (3,) world
        (m, m/s; motion capture, or a simulation's truth) replace the estimator's output."""
        if self.state is None:
            raise DpcError("Deployment.step before reset: call reset(measurement) first.")
        if (base_position is None) != (base_velocity is None):
            raise DpcError("Give both base_position and base_velocity, or neither (estimated).")
        x = self._inputs(m)
        truth = base_position is not None
        if truth:
            x["truth"] = np.concatenate([base_position, base_velocity]).astype(np.float32)
        policy_step = self.policy is not None and int(self.state.tick) % self.env.n_substeps == 0
        self.state, tau = self._tick(self.state, x, policy_step=policy_step, truth=truth)
        return np.asarray(tau)

    def _check(self, m: Measurement) -> None:
        n_arm, n_act = len(self.arm_joints), len(self.arm_actuators)
        sizes = {"quat": 4, "gyro": 3, "accel": 3, "leg_q": 12, "leg_qd": 12, "arm_q": n_arm}
        sizes |= {"arm_qd": n_arm, "arm_targets": n_act, "command": 3}
        if m.contact is not None:
            sizes["contact"] = 4
        for name, size in sizes.items():
            shape = np.shape(getattr(m, name))
            if shape != (size,):
                raise DpcError(
                    f"Measurement.{name} must have shape ({size},), got {shape} (units, frames "
                    "and order: dpc_mjx.deploy's docstring)."
                )

    # jitted side ---------------------------------------------------------------------------

    def _data_at_origin(self, x: dict) -> mjx.Data:
        kin = {k: x[k] for k in KINEMATICS}
        adr = self.env.lay.sensor_adr["accelerometer"]  # read by the arms' model wrench
        sensors = self._template.sensordata.at[adr : adr + 3].set(x["accel"])
        return self._template.replace(
            qpos=x["qpos"], qvel=x["qvel"], ctrl=x["ctrl"], sensordata=sensors, **kin
        )

    @staticmethod
    def _moved(d: mjx.Data, p: jax.Array, v: jax.Array) -> mjx.Data:
        """`d` with the trunk origin at p (3,) m and moving at v (3,) m/s, world."""
        return d.replace(
            qpos=d.qpos.at[0:3].set(p),
            qvel=d.qvel.at[0:3].set(v),
            xpos=d.xpos + p,
            xipos=d.xipos + p,
            site_xpos=d.site_xpos + p,
            subtree_com=d.subtree_com + p,
        )

    def _reset_fn(self, x: dict, xy: jax.Array) -> LoopState:
        d0 = self._data_at_origin(x)
        s0 = read_state(self.env.controller.idx, d0)
        est = estimator.init(s0.foot_pos, self.env.lay.foot_radius, xy)
        d = self._moved(d0, est.position, est.velocity)
        return LoopState(
            ctrl=self.env.controller.init(d), est=est, u_policy=jp.zeros(6), tick=jp.zeros((), int)
        )

    def _tick_fn(self, ls: LoopState, x: dict, policy_step: bool, truth: bool):
        env, ctl = self.env, self.env.controller
        d0 = self._data_at_origin(x)
        s0 = read_state(ctl.idx, d0)  # feet from the trunk origin, base velocity 0
        ecfg, g = self.estimator_config, ctl.config.gait
        planned = estimator.stance_trust(ecfg, gait.phase(g, ls.ctrl.t), g.duty)
        trust = jp.where(x["contact"] >= 0, x["contact"], planned)
        est = estimator.update(
            ecfg,
            ls.est,
            s0.rot,
            x["accel"],
            s0.foot_pos,
            s0.foot_vel,
            trust,
            ctl.dt,
            env.lay.foot_radius,
        )
        p, v = (x["truth"][:3], x["truth"][3:]) if truth else (est.position, est.velocity)
        d = self._moved(d0, p, v)
        u_policy = ls.u_policy
        if policy_step:  # the policy acts at its rate, as in `DpcEnv.step`
            obs = observation(env.lay, d, x["command"], ls.ctrl.observer.estimate)
            u_policy = env.policy_u(self.policy(obs[None], jax.random.PRNGKey(0))[0])
        u, add, model = env.controller_u(d, u_policy)
        cs, ctrl = ctl.step(
            ls.ctrl, d, x["command"], u, x["arm_targets"], add_estimate=add, add_model=model
        )
        new = LoopState(ctrl=cs, est=est, u_policy=u_policy, tick=ls.tick + 1)
        return new, ctrl[env.lay.leg_act]


__all__ = ["CONTROLLERS", "Deployment", "LoopState", "Measurement"]
