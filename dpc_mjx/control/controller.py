"""The low-level controller (paper §III-D): gait schedule, balance QP for stance feet with the
disturbance terms u = [f_a, tau_a], Cartesian PD for swing feet, tau = J^T f, arm joint servos.

Unbatched and pure: `LowLevelController.init(data)` and `.step(state, data, command, u)` act on one
env's `mjx.Data`; vmap at the call site. Controllers differ only in u:

- `mbc`: u = 0 (the paper's model-based baseline, after Di Carlo et al. 2018);
- `oracle`: u = the measured arm-mount wrench (privileged upper bound, `state.oracle_u`);
- `observer`: u = the momentum observer's estimate (`observer.py`; no training, no force sensor):
  pass u = None to `LowLevelController.step`;
- `feedforward`: u = the arms' model wrench (`arm_estimate.py`, from the arms' files and the
  measured states): pass u = 0 and `add_model=True`; `feedforward_observer` adds the observer's
  estimate of what the model leaves (`add_estimate=True` too);
- anything else (the DPC policy): pass its u.

The balance QP's model is the bare base (trunk + legs, mass and inertia at the home pose): the
arm is exactly the disturbance it does not model. Every controller carries the observer and the
arms' model wrench in its state (`ControllerState.observer`, `.arm`, updated each tick from the
data and the previous tick's commanded forces); only the controllers above feed them back.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
from flax import struct

from dpc_mjx.control import arm_estimate as arm_estimate_lib
from dpc_mjx.control import balance, gait, qp, sensors, swing
from dpc_mjx.control import mpc as mpc_lib
from dpc_mjx.control import observer as observer_lib
from dpc_mjx.control.arm_model import ArmModel, arm_model
from dpc_mjx.control.base_scaling import base_scale, scaled_config
from dpc_mjx.control.state import (
    BodyState,
    StateIndex,
    legs_weight_wrench,
    read_state,
    state_index,
)
from dpc_mjx.robots.layout import Layout, layout
from dpc_mjx.rotations import rot_z, yaw_of


@struct.dataclass
class ControllerConfig:
    """Tunable numbers of the low-level controller (arrays or floats; no structure)."""

    balance: balance.BalanceParams
    gait: gait.Gait
    body_height: float = 0.26  # m, desired COM height
    swing_height: float = 0.08  # m, apex of a swing above the straight line
    swing_kp: jax.Array = struct.field(default_factory=lambda: jp.array([500.0, 500.0, 500.0]))
    swing_kd: jax.Array = struct.field(default_factory=lambda: jp.array([15.0, 15.0, 15.0]))
    raibert_k: float = 0.03  # s, velocity feedback of the foothold
    max_pos_error: float = 0.05  # m, clamp of the horizontal COM tracking error
    torque_limit: float = 33.5  # N·m, A1 joint torque limit
    observer: observer_lib.ObserverConfig = struct.field(
        default_factory=observer_lib.ObserverConfig
    )  # gains of the disturbance observer (rad/s)
    arm_estimate: arm_estimate_lib.ArmEstimateConfig = struct.field(
        default_factory=arm_estimate_lib.ArmEstimateConfig
    )  # how the arms' model wrench reads its accelerations
    mpc: mpc_lib.MPCConfig | None = None  # the low level: None the balance QP, else the MPC's


@struct.dataclass
class ControllerState:
    t: jax.Array  # () s since init
    pos_des: jax.Array  # (3,) desired COM position (x, y integrated from the command)
    yaw_des: jax.Array  # () rad
    swing_start: jax.Array  # (4, 3) foot positions at the last lift-off
    stance: jax.Array  # (4,) bool, stance at the previous tick
    qp: qp.QPResult  # warm start for the next balance QP
    forces: jax.Array  # (4, 3) last ground reaction forces asked of the stance feet, N
    observer: observer_lib.ObserverState  # the disturbance observer, updated every tick
    arm: arm_estimate_lib.ArmEstimate  # the arms' model wrench, updated every tick
    mpc: mpc_lib.MPCPlan | None = None  # the MPC's plan (low level 'mpc'; None: 'qp')


@struct.dataclass
class Plan:
    """What one tick decided before solving: state, schedule and desired body motion."""

    state: BodyState
    stance: jax.Array  # (4,) bool
    progress: jax.Array  # (4,) swing progress in [0, 1]
    pos_des: jax.Array  # (3,) m, desired COM position
    vel_des: jax.Array  # (3,) m/s, world
    yaw_des: jax.Array  # () rad
    yaw_rate_des: jax.Array  # () rad/s


@dataclasses.dataclass(frozen=True)
class LowLevelController:
    """Static parts (indices, dt) plus the config; `init`/`step` are pure JAX."""

    idx: StateIndex
    lay: Layout
    dt: float  # s, the control period (= physics step)
    config: ControllerConfig
    arm_home: jax.Array  # (n_arm_act,) servo targets of the home pose
    fall_height: float  # m: the base's trunk below this has fallen (`state.has_fallen`)
    arm: ArmModel | None  # the arms' rigid-body model (None: no arm)

    def init(self, d) -> ControllerState:
        s = read_state(self.idx, d)
        return ControllerState(
            t=jp.zeros(()),
            pos_des=s.com_pos.at[2].set(self.config.body_height),
            yaw_des=yaw_of(s.rot),
            swing_start=s.foot_pos,
            stance=jp.ones(4, bool),
            qp=qp.QPResult.zeros(balance.N_VARS, balance.N_ROWS),  # the first tick starts cold
            forces=jp.zeros((4, 3)),
            observer=observer_lib.init(self.config.observer, self.config.balance, s),
            arm=arm_estimate_lib.init(s, d.qvel[self.lay.arm_dof]),
            mpc=None if self.config.mpc is None else mpc_lib.MPCPlan.zeros(self.config.mpc),
        )

    def _arm_wrench(
        self, cs: ControllerState, d, p: Plan, targets: jax.Array, noise
    ) -> arm_estimate_lib.ArmEstimate:
        """The arms' model wrench of this tick from the measured state (`arm_estimate`)."""
        if self.arm is None:
            return cs.arm
        s = p.state
        measured = arm_estimate_lib.read_sensors(self.lay, d, noise)
        lever = self._com_lever(s)
        state = (s.com_pos, s.com_vel, s.rot, s.ang_vel)
        desired = balance.desired_acceleration(self.config.balance, state, _desired_state(p))
        config = self.config.arm_estimate
        return arm_estimate_lib.update(
            config, self.arm, cs.arm, s, measured, targets, lever, desired, self.dt
        )

    def _observe(
        self, cs: ControllerState, s: BodyState, also_known: jax.Array
    ) -> observer_lib.ObserverState:
        cfg = self.config
        return observer_lib.update(
            cfg.observer,
            cfg.balance,
            cs.observer,
            s,
            cs.forces,
            self.dt,
            self.lay.foot_radius,
            also_known,
        )

    def plan(
        self, cs: ControllerState, d, command: jax.Array, noise: sensors.SensorNoise | None = None
    ) -> Plan:
        """Read the state (with the measurement errors `noise`, `control/sensors.py`; None:
        exact), the gait schedule and the desired body motion of this tick."""
        cfg = self.config
        s = read_state(self.idx, d)
        if noise is not None:
            s = sensors.measured(s, noise)
        stance, progress = gait.contact_schedule(cfg.gait, cs.t)
        # Desired body motion: integrate the command, keep the tracking error bounded.
        yaw_des = cs.yaw_des + command[2] * self.dt
        vel_des = rot_z(yaw_des) @ jp.array([command[0], command[1], 0.0])
        pos_des = cs.pos_des + vel_des * self.dt
        err = jp.clip(pos_des[:2] - s.com_pos[:2], -cfg.max_pos_error, cfg.max_pos_error)
        pos_des = pos_des.at[:2].set(s.com_pos[:2] + err).at[2].set(cfg.body_height)
        return Plan(s, stance, progress, pos_des, vel_des, yaw_des, command[2])

    def balance_qp(self, p: Plan, u: jax.Array, qdd_des=None) -> balance.BalanceQP:
        """The stance-force QP of this tick (eqs. 5-10) with the disturbance u = [f_a, tau_a],
        asking for eq. 9's acceleration or `qdd_des` (6,) (the MPC's, `_mpc`)."""
        s = p.state
        return balance.build_balance_qp(
            self.config.balance,
            s.com_pos,
            s.com_vel,
            s.rot,
            s.ang_vel,
            *_desired_state(p),
            self._contact_points(s),
            p.stance,
            u[:3],
            u[3:],
            qdd_des,
        )

    def _contact_points(self, s: BodyState) -> jax.Array:
        """(4, 3) m, world: where the feet's forces act, on the ground below each foot's centre."""
        return s.foot_pos.at[:, 2].add(-self.lay.foot_radius)

    def _mpc(self, cs: ControllerState, p: Plan, u, ahead: tuple, tick):
        """(the MPC's plan, the QP's target acceleration (6,)) of this tick (`mpc.update`):
        re-solved where tick % `MPCConfig.every` == 0 (`tick` None: where the plan is that many
        ticks old or not valid), for the wrench w_k = u + change[k], k = 0 .. N-1: `ahead` is
        (targets_ahead, add_model, u_change), the change `u_change` where given, else along
        `targets_ahead` (`_planned_change`; none: u held), computed only to re-solve."""
        targets_ahead, add_model, u_change = ahead
        cfg, plan = self.config.mpc, cs.mpc
        if tick is None:
            replan = (cs.t - plan.t0 >= (cfg.every - 0.5) * self.dt) | ~plan.qp.valid
        else:
            replan = tick % cfg.every == 0

        def wrench() -> jax.Array:  # (N, 6) w_0 .. w_{N-1}
            change = u_change
            if change is None:
                change = self._planned_change(p, targets_ahead, add_model)
            return jp.tile(u, (cfg.steps, 1)) if change is None else u + change

        desired = (p.pos_des, p.vel_des, p.yaw_des, p.yaw_rate_des)
        feet = self._contact_points(p.state)
        return mpc_lib.update(
            cfg, self.config.balance, self.config.gait, plan, cs.t, p.state, feet, desired,
            wrench, replan,
        )  # fmt: skip

    def _planned_change(self, p: Plan, targets_ahead, add_model):
        """(N, 6) `arm_estimate.planned_change` along `targets_ahead` where `add_model` (a bool,
        or a traced () bool per env), else 0; None without targets, arms or the model."""
        if targets_ahead is None or self.arm is None or add_model is False:
            return None
        lever, dt = self._com_lever(p.state), self.config.mpc.dt
        change = arm_estimate_lib.planned_change(self.arm, p.state, lever, targets_ahead, dt)
        return jp.where(add_model, change, 0.0)

    def _com_lever(self, s: BodyState) -> jax.Array:
        """(3,) m, world: the base's COM minus the trunk's origin, at the measured attitude."""
        return s.rot @ jp.asarray(self.idx.com_offset, jp.float32)

    def swing_legs(self, cs: ControllerState, p: Plan) -> tuple[jax.Array, jax.Array]:
        """The swing feet of this tick: (4, 3) m, world, each foot's position at its last
        lift-off (recorded as it lifts off), and (4, 3) N, world, the PD force that tracks a
        trajectory from there to its Raibert foothold (stance feet: ignored by `step`)."""
        cfg, s = self.config, p.state
        lift_off = cs.stance & ~p.stance
        swing_start = jp.where(lift_off[:, None], s.foot_pos, cs.swing_start)
        target = swing.raibert_foothold(
            s.hip_pos,
            s.com_vel,
            p.vel_des,
            p.yaw_rate_des,
            s.com_pos,
            cfg.gait.stance_time,
            cfg.raibert_k,
            self.lay.foot_radius,  # m: the foothold's z, the foot sphere's centre on the ground
        )
        p_des, v_des = swing.swing_trajectory(
            swing_start, target, p.progress, cfg.gait.swing_time, cfg.swing_height
        )
        f_swing = swing.swing_force(
            p_des, v_des, s.foot_pos, s.foot_vel, cfg.swing_kp, cfg.swing_kd
        )
        return swing_start, f_swing

    def step(
        self,
        cs: ControllerState,
        d,
        command: jax.Array,
        u: jax.Array | None,
        arm_targets: jax.Array | None = None,
        noise: sensors.SensorNoise | None = None,
        add_estimate: bool | jax.Array = False,
        add_model: bool | jax.Array = False,
        targets_ahead: jax.Array | None = None,
        tick: int | jax.Array | None = None,
        u_change: jax.Array | None = None,
    ) -> tuple[ControllerState, jax.Array]:
        """One control tick. `command` (3,): forward and lateral velocity (m/s, yaw frame) and yaw
        rate (rad/s); `u` (6,): [f_a (N), tau_a (N·m)], world frame, about the COM, or None for
        the disturbance observer's estimate of this tick (the `observer` controller), or with
        `add_estimate` a residual added to that estimate (DPC on the observer,
        `EnvConfig.u_base`; a traced () bool where each env of a batch has its own controller,
        `envs.controller_batch`); `add_model` adds the arms' model wrench of this tick
        (`arm_estimate`; the `feedforward` controllers, DPC on the model), and with
        `add_estimate` too the observer estimates what the model leaves (the model wrench is
        then among its known wrenches); `noise` the measurement errors of this tick
        (`control/sensors.py`; None: exact sensors). With the MPC as the low level
        (`ControllerConfig.mpc`): `targets_ahead` (N + 2, n) the arms' servo targets over its
        horizon (`arm_estimate.planned_change`): with `add_model` it plans against u plus the
        model wrench's change along them (None: u held), or against u plus `u_change` (N, 6)
        given (a replay's, `envs/ahead.py`; privileged);
        `tick` () int, this tick's index in a sequence the whole batch shares (an env step's
        ticks), which times the re-solves as a cond that runs one branch (None: the plan's age
        times them, per env: under vmap both branches run at every tick; `_mpc`).
        Returns the new state and ctrl (nu,): leg torques and arm servo targets."""
        cfg = self.config
        p = self.plan(cs, d, command, noise)
        s, stance = p.state, p.stance
        targets = self.arm_home if arm_targets is None else arm_targets
        arm = self._arm_wrench(cs, d, p, targets, noise)
        # with the model and the observer both (`feedforward_observer`), the observer estimates
        # what the model leaves: the model wrench and the legs' weight at the feet (its bias on
        # a bare base, `state.legs_weight_wrench`) among its known wrenches
        known = 0.0
        both = add_model is not False and add_estimate is not False  # may be, at trace time
        if self.arm is not None and both:  # without the arms' model no controller adds it
            legs = legs_weight_wrench(self.idx, d, s, cs.stance, self.lay.foot_radius)
            known = jp.where(add_model & jp.asarray(add_estimate), arm.wrench + legs, 0.0)
        observed = self._observe(cs, s, known)  # this tick's data, the previous tick's forces
        if u is None:
            u = observed.estimate
        elif add_estimate is not False:  # True, or a traced () bool (selects per env)
            u = jp.where(add_estimate, observed.estimate + u, u)
        if add_model is not False:
            u = jp.where(add_model, u + arm.wrench, u)
        plan, qdd = cs.mpc, None
        if self.config.mpc is not None:
            ahead = (targets_ahead, add_model, u_change)
            plan, qdd = self._mpc(cs, p, u, ahead, tick)
        prob = self.balance_qp(p, u, qdd)
        res = qp.solve(
            prob.P, prob.q, prob.G, prob.h, warm_start=cs.qp, g_pattern=balance.G_PATTERN
        )
        forces = res.x.reshape(4, 3) * stance[:, None]  # N, world, swing feet exactly 0

        swing_start, f_swing = self.swing_legs(cs, p)

        # Stance legs push the ground with -f (so the ground pushes back with f); swing legs
        # apply the PD force: tau = J^T f per leg.
        f_leg = jp.where(stance[:, None], -forces, f_swing)  # (4, 3)
        tau = jp.einsum("fcj,fc->fj", s.foot_jac, f_leg).reshape(-1)
        tau = jp.clip(tau, -cfg.torque_limit, cfg.torque_limit)

        ctrl = jp.zeros(d.ctrl.shape).at[self.lay.leg_act].set(tau)
        if self.lay.arms:
            ctrl = ctrl.at[self.lay.arm_act].set(targets)
        new = ControllerState(
            t=cs.t + self.dt, pos_des=p.pos_des, yaw_des=p.yaw_des, swing_start=swing_start,
            stance=stance, qp=res, forces=forces, observer=observed, arm=arm, mpc=plan,
        )  # fmt: skip
        return new, ctrl


def _desired_state(p: Plan) -> tuple[jax.Array, ...]:
    """(COM position (3,) m, COM velocity (3,) m/s, trunk rotation (3, 3), angular velocity
    (3,) rad/s) the plan asks for, world frame: the balance QP's targets (eq. 9)."""
    return p.pos_des, p.vel_des, rot_z(p.yaw_des), jp.array([0.0, 0.0, p.yaw_rate_des])


def make_controller(
    model: mujoco.MjModel,
    config: ControllerConfig | None = None,
    gait_: gait.Gait | None = None,
    observer: observer_lib.ObserverConfig | None = None,
    arm_estimate: arm_estimate_lib.ArmEstimateConfig | None = None,
    low_level: str = "qp",
) -> LowLevelController:
    """A controller for a compiled variant. The balance model is the bare base (see module doc);
    the default config is the A1's scaled to the base (`control.base_scaling`); `observer` and
    `arm_estimate`, if given, replace the config's (gains, delay; the arms' accelerations);
    `low_level` 'qp' (the balance QP alone) or 'mpc' (the MPC's defaults, `control/mpc.py`,
    R scaled to the base's mass as the QP's; a config that has an MPC keeps it)."""
    lay = layout(model)
    idx = state_index(model, lay)
    scale = base_scale(idx)
    if config is None:
        a1_config = ControllerConfig(balance=balance.default_params(), gait=gait_ or gait.trot())
        config = scaled_config(a1_config, scale, lay, idx)
    if observer is not None:
        config = config.replace(observer=observer)
    if arm_estimate is not None:
        config = config.replace(arm_estimate=arm_estimate)
    if mpc_lib.low_level(low_level) == "mpc" and config.mpc is None:
        config = config.replace(mpc=mpc_lib.MPCConfig(R=mpc_lib.MPCConfig.R / scale.mass**2))
    config.observer.validate(float(model.opt.timestep))
    config.arm_estimate.validate()
    arm_home = jp.asarray(model.key_ctrl[0][lay.arm_act], jp.float32)
    return LowLevelController(
        idx=idx,
        lay=lay,
        dt=float(model.opt.timestep),
        config=config,
        arm_home=arm_home,
        fall_height=scale.fall_height,
        arm=arm_model(model, lay) if lay.arms else None,
    )


__all__ = [
    "BodyState",
    "ControllerConfig",
    "ControllerState",
    "LowLevelController",
    "make_controller",
]
