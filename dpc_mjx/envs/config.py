"""Environment configuration: one frozen dataclass, validated before anything is compiled.

Every task has its own default (`dpc_mjx.envs.tasks.reaching.default_config()`); override fields
by keyword (`dpc_mjx.make("reaching", arm="regular", controller="mbc")`) or with
`config.replace(...)`. Ranges are `(low, high)` tuples of a uniform distribution, `# ~ U(low, high)`
in the field comments; a range with low == high is a constant.

The fields fall into parts, each readable and replaceable as a whole under the same field names:
`config.sensors` (`SensorConfig`: the sensor model), `config.disturbances` (`DisturbanceConfig`:
initial pose, pushes, payload, object weights) and `config.motion` (`MotionConfig`: the velocity
command and the arm's motion: what the robot is asked to do); the rest (controller, rates, action
bounds, reward, termination) is the env's own. Every field keeps its flat name everywhere: a `make`
keyword, a `--set env.NAME` / `--env NAME` key, the export sidecar's `env_config` key, and
`config.NAME`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from dpc_mjx.control.arm_estimate import BASE_ACC_SOURCES, QDD_SOURCES, ArmEstimateConfig
from dpc_mjx.control.mpc import LOW_LEVELS
from dpc_mjx.control.observer import ObserverConfig
from dpc_mjx.controllers import Controller
from dpc_mjx.envs.checks import (
    check_axes,
    check_bool,
    check_choice,
    check_int,
    check_number,
    check_number_or_pair,
    check_positive,
    check_range,
    per_axis,
)
from dpc_mjx.errors import DpcError
from dpc_mjx.physics import ENGINE_CHOICES

U_AHEAD = ("held", "model", "replay", "pushes", "push_ends")  # `EnvConfig.u_ahead`
CONTROLLERS = tuple(Controller)  # and 'policy', the old name of 'dpc' (`controllers.ALIASES`)
U_FRAMES = ("yaw", "world")
# what DPC's policy u is added to (`EnvConfig.u_base`)
U_BASES = ("zero", "observer", "gravity", "model")
GAITS = ("trot", "stand")


@dataclasses.dataclass(frozen=True)
class SensorConfig:
    """The sensor model (`EnvConfig.sensor_noise`, `sensor_delay`)."""

    sensor_noise: float
    sensor_delay: int


@dataclasses.dataclass(frozen=True)
class DisturbanceConfig:
    """What pushes the robot off its plan, drawn per episode (`EnvConfig`'s comments)."""

    joint_noise: float
    push_force: tuple[float, float]
    push_duration: tuple[float, float]
    push_axis_weights: tuple[float, float, float]
    push_gap: tuple[float, float]
    payload_mass: tuple[float, float]
    object_mass: tuple[float, float]


@dataclasses.dataclass(frozen=True)
class MotionConfig:
    """What the robot is asked to do: its velocity command and its arm's motion."""

    command_vx: tuple[float, float]
    command_vy: tuple[float, float]
    command_yaw: tuple[float, float]
    command_switch: tuple[float, float]
    command_after: tuple[float, float, float] | None
    reach_fraction: float
    reach_period: tuple[float, float]
    reach_move_time: float
    script_rate: tuple[float, float]


PARTS = {"sensors": SensorConfig, "disturbances": DisturbanceConfig, "motion": MotionConfig}


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """What one DPC environment does; units and distributions in the comments."""

    # Low-level controller and rates.
    # `dpc_mjx.controllers.Controller` (a plain string works; 'policy' is read as 'dpc'):
    # 'dpc': u = scaled action; 'mbc': u = 0; 'oracle': measured; 'observer': u = the momentum
    # observer's estimate (`control/observer.py`)
    controller: Controller = Controller.DPC
    gait: str = "trot"  # 'trot' or 'stand'
    policy_dt: float = 0.02  # s, one env step (50 Hz); a multiple of the physics step (0.004 s)
    episode_length: int = 1000  # env steps per episode (20 s) for `wrap_for_training`
    # The low level under every controller: 'qp' (the one-tick balance QP, `control/balance.py`)
    # or 'mpc' (the convex MPC over a horizon, the QP tracking its plan: `control/mpc.py`)
    low_level: str = "qp"
    # With low_level 'mpc', the arms' wrench over its horizon: 'held' (the present u) or 'model'
    # (the present u plus the arms' model wrench's change along their servo targets ahead, for
    # the controllers that add the model wrench: `arm_estimate.planned_change`; not privileged)
    # or 'replay' (the present u plus the measured wrench's change along a recording of the
    # same episode, for every controller: privileged, the bound; `envs/ahead.py`) or 'pushes'
    # (the present u plus the change of the pushes at the grippers, from their schedule:
    # privileged, what of the bound the pushes' timing is) or 'push_ends' (the same for the
    # pushes under way only: when they end, not when the next begins)
    u_ahead: str = "held"
    # Physics engine (`dpc_mjx/physics.py`): 'mjx' (JAX, on the device), 'native' (MuJoCo C on
    # the same model, on the host: the faster path on a CPU, and sim-to-sim) or 'auto' (native
    # on one CPU device, MJX on an accelerator: `physics.resolve_engine`); a built env's
    # `config.engine` is the one it resolved to
    engine: str = "auto"
    # The quadruped: a name of `robots.bases.file.NAMED_BASES` ('a1', 'go1', 'go2', 'b1', 'b1-z1')
    # or the path of its .urdf, MJCF .xml (or .json) file, read when the env is built
    # (`robots.bases.model`).
    # `make` / `get_config` scale the pushes, payloads and u's bounds below by the base's weight
    # (`envs.registry.WEIGHT_SCALED`); the numbers written here are the A1's.
    base: str = "a1"

    # Action a in [-1, 1]^6 -> u = [f_a, tau_a] = [max_force * a[:3], max_torque * a[3:]]
    # (per axis x, y, z of `u_frame`; about the base's COM). A number applies to all three axes.
    # The defaults bound the oracle's u on the reaching task with margin (its std there: f 2.6,
    # 2.6, 19 N around a mean f_z of -10 N; tau 3.8, 4.0, 0.44 N·m), so exploration does not
    # throw the robot around with forces no arm exerts. The oracle's own u is not clipped. With
    # u_base 'model', `make` / `get_config` bound the residual to small loads instead
    # (`envs.registry.RESIDUAL_BOUNDS`: 6 N, 3 N·m on the A1).
    #
    # The frame of the policy's u: 'yaw' (heading-aligned, z up; turned to the world frame, the
    # controller's, at every tick), or 'world' (the exports written before this option existed). The
    # policy observes nothing of the heading (s_body and u_obs are yaw-frame), so only a yaw-frame u
    # can follow the arm's moments as the robot turns (docs/results-estimator.md, ablation).
    u_frame: str = "yaw"
    # What the policy's u is added to ('dpc' only): 'zero' (the paper: u = the policy's u),
    # 'observer' (u = the disturbance observer's estimate of each tick, world frame, + the
    # policy's u: the policy is a learned residual of the classical estimate, trained on
    # u_oracle - u_obs, `policy.regression`), or 'gravity' (u = the arms' weight and its torque
    # about the base's COM, from the arm file's masses at the arm's pose of each tick
    # (`DpcEnv.arm_gravity`), + the policy's u, trained on u_oracle - u_gravity: the learned part
    # is the arm's motion, its weight comes from its file), or 'model' (shipped; u = the model
    # wrench of the arms each tick, their inverse dynamics from measured states (`arm_estimate`),
    # + the policy's u, trained on what the model cannot know: the pushes and the payload)
    u_base: str = "zero"
    max_force: float | tuple[float, float, float] = (15.0, 15.0, 60.0)  # N
    max_torque: float | tuple[float, float, float] = (12.0, 12.0, 3.0)  # N·m

    # Reward (paper eqs. 2-4, fixed weights in `rewards`) and termination.
    fall_penalty: float = -1000.0  # added on the step that falls (see `reaching.py` for why)
    explode_speed: float = 500.0  # m/s or rad/s: |qvel| above this is an exploded state (reset)

    # Sensors (`control/sensors.py`): measurement errors of the IMU, the velocity estimate and
    # the joint encoders, as a multiple of the documented robot values there (0: exact
    # sensors), the same for every controller, in what the controller, the observer and the
    # policy read; and the delay from measurement to torque, in 4 ms ticks.
    sensor_noise: float = 1.0
    sensor_delay: int = 1

    # The disturbance observer (`control/observer.py`; the 'observer' controller's u and the
    # policy's u_obs): its gain K (rad/s, the estimate's bandwidth: a lag of 1/K, the
    # measurement noise passed in proportion to K), one for every axis or (force, torque), and
    # whether it is aligned to the sensor_delay above (True: the known wrench uses the forces
    # that acted over the tick just past, commanded 1 + sensor_delay ticks before; False: those
    # of the previous tick).
    observer_gain: float | tuple[float, float] = 40.0
    observer_aligned: bool = False

    # The arms' model wrench (`control/arm_estimate.py`; the 'feedforward' controllers' u and
    # DPC's with u_base 'model'): the arms' joint accelerations from their servo targets
    # ('servo': the arm's own dynamics under its servo law) or from the encoders' velocity
    # difference ('difference'); the trunk's accelerations the balance QP asks for ('desired':
    # the arms as a composite rigid body with the base) or measured ('measured': accelerometer,
    # gyro difference); the time constant (s) of the differences' low-pass.
    arm_qdd: str = "servo"
    arm_base_acc: str = "desired"
    arm_filter_s: float = 0.02

    # Initial state: home pose, leg joints offset ~ U(-joint_noise, joint_noise) rad.
    joint_noise: float = 0.05

    # Velocity command [v_x, v_y (m/s, yaw frame), yaw rate (rad/s)] per episode, each ~ U,
    # redrawn once at t ~ U(command_switch) s (set both to a time past the episode to disable).
    command_vx: tuple[float, float] = (0.0, 0.5)
    command_vy: tuple[float, float] = (-0.2, 0.2)
    command_yaw: tuple[float, float] = (-0.5, 0.5)
    command_switch: tuple[float, float] = (5.0, 15.0)
    # The command after the switch: None redraws it from the ranges above; a fixed
    # (v_x, v_y, yaw rate) scripts a change instead (e.g. a turn mid-episode, `lifting.py`).
    command_after: tuple[float, float, float] | None = None

    # Arm reference motion: a new target every ~ U(reach_period) s, each joint ~ U(home -
    # f (home - low), home + f (high - home)) with f = reach_fraction and [low, high] its
    # model.jnt_range (unlimited joints: home +- pi); the servo targets move there along a smooth
    # step 3x^2 - 2x^3 lasting `reach_move_time` s.
    reach_fraction: float = 0.5
    reach_period: tuple[float, float] = (1.5, 3.0)
    reach_move_time: float = 1.0

    # Sudden forces on each end effector: piecewise constant, drawn in the yaw (heading) frame,
    # applied at the `ee` site; magnitude ~ U(push_force) N, direction below, lasting
    # ~ U(push_duration) s, the next one starting ~ U(push_gap) s after the last one ends.
    push_force: tuple[float, float] = (0.0, 30.0)  # reaching: 60 N vertical, see reaching.py
    push_duration: tuple[float, float] = (0.2, 1.0)
    # Push direction: a (3,) standard normal vector scaled per yaw-frame axis (x, y, z) by these
    # weights, then normalised: (1, 1, 1) is uniform on the sphere, (1, 0, 1) keeps pushes in the
    # sagittal plane (no lateral component).
    push_axis_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    push_gap: tuple[float, float] = (0.5, 2.0)

    # Payload held by each gripper for the whole episode, mass ~ U(payload_mass) kg, modelled as a
    # constant downward force m g at the `ee` site (the model's masses are not changed).
    payload_mass: tuple[float, float] = (0.0, 0.3)

    # Object tasks (scenes with a box or balls; reaching has none, and ignores both):
    # weight added to each free object for the episode, mass ~ U(object_mass) kg, a constant
    # downward force m g at the object's COM (its inertia is not changed), so a held ball loads
    # the arm and a box presses harder on the floor;
    object_mass: tuple[float, float] = (0.0, 0.0)
    # the pace of the scripted arm motion: its time runs ~ U(script_rate) times as fast.
    script_rate: tuple[float, float] = (1.0, 1.0)

    def __post_init__(self) -> None:
        # one name per controller: a string or an alias becomes its member ('policy' -> DPC);
        # an unknown name is left for `validate` to report
        if not isinstance(self.controller, Controller):
            try:
                object.__setattr__(self, "controller", Controller.parse(self.controller))
            except DpcError:
                pass

    @property
    def sensors(self) -> SensorConfig:
        return self._part(SensorConfig)

    @property
    def disturbances(self) -> DisturbanceConfig:
        return self._part(DisturbanceConfig)

    @property
    def motion(self) -> MotionConfig:
        return self._part(MotionConfig)

    def _part(self, part: type) -> Any:
        return part(**{f.name: getattr(self, f.name) for f in dataclasses.fields(part)})

    @property
    def u_scale(self) -> tuple[float, ...]:
        """(6,) N, N, N, N·m, N·m, N·m: u = u_scale * a for an action a in [-1, 1]^6."""
        return per_axis(self.max_force) + per_axis(self.max_torque)

    def observer_config(self) -> ObserverConfig:
        """The disturbance observer these fields configure (gains; delay if aligned)."""
        gain = self.observer_gain  # rad/s, one or (force, torque)
        k_force, k_torque = gain if isinstance(gain, tuple) else (gain, gain)
        delay = self.sensor_delay if self.observer_aligned else 0  # ticks
        return ObserverConfig(k_force=k_force, k_torque=k_torque, delay=delay)

    def arm_estimate_config(self) -> ArmEstimateConfig:
        """How the arms' model wrench reads its accelerations (`arm_qdd`, `arm_base_acc`,
        `arm_filter_s`)."""
        return ArmEstimateConfig(
            qdd=self.arm_qdd, base_acc=self.arm_base_acc, filter_s=self.arm_filter_s
        )

    @property
    def adds_observer_estimate(self) -> bool:
        """Whether the controller adds the observer's estimate to the given u (the observer
        controllers, DPC with `u_base` 'observer': `Controller.adds`)."""
        return self.controller.adds(self.u_base)[0]

    def replace(self, **overrides: Any) -> EnvConfig:
        """A validated copy with `overrides` by field name, or a whole part by its name
        (`sensors=SensorConfig(0.0, 0)`, or a dict of some of its fields); unknown names raise
        `DpcError` listing the fields."""
        overrides = _flat(overrides)
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise DpcError(
                f"Unknown config option(s) {unknown} for {type(self).__name__}; "
                f"known options: {sorted(names)}."
            )
        overrides = {k: tuple(v) if isinstance(v, list) else v for k, v in overrides.items()}
        out = dataclasses.replace(self, **overrides)
        out.validate()
        return out

    def substeps(self, timestep: float) -> int:
        """Physics steps of `timestep` s per env step (`policy_dt`); `DpcError` unless whole."""
        n_sub = round(self.policy_dt / timestep)
        if n_sub < 1 or abs(n_sub * timestep - self.policy_dt) > 1e-9:
            raise DpcError(
                f"policy_dt={self.policy_dt} s must be a whole multiple of the physics step "
                f"{timestep} s (e.g. {5 * timestep:g} s for 50 Hz)."
            )
        return n_sub

    def _validate_u_ahead(self) -> None:
        check_choice("u_ahead", self.u_ahead, U_AHEAD)
        if self.u_ahead != "held" and self.low_level != "mpc":
            raise DpcError(
                f"u_ahead={self.u_ahead!r} plans the arms' wrench over the MPC's horizon: it "
                "needs low_level='mpc' (or u_ahead='held')."
            )

    def validate(self) -> None:
        """Raise `DpcError` naming the first invalid field and what it must be."""
        Controller.parse(self.controller)
        check_choice("gait", self.gait, GAITS)
        check_choice("engine", self.engine, ENGINE_CHOICES)
        check_choice("low_level", self.low_level, LOW_LEVELS)
        self._validate_u_ahead()
        _policy_u(self.u_frame, self.u_base)
        if not isinstance(self.base, str) or not self.base:
            raise DpcError(
                f"base={self.base!r}: give a base's name (a1, go1, go2, b1, b1-z1) or the path "
                "of its .urdf, MJCF .xml or .json file."
            )
        check_number("sensor_noise", self.sensor_noise, 0.0, 10.0)
        check_int("sensor_delay", self.sensor_delay, 0, 10)
        check_number_or_pair("observer_gain", self.observer_gain, 1.0, 200.0)
        check_bool("observer_aligned", self.observer_aligned)
        check_choice("arm_qdd", self.arm_qdd, QDD_SOURCES)
        check_choice("arm_base_acc", self.arm_base_acc, BASE_ACC_SOURCES)
        check_number("arm_filter_s", self.arm_filter_s, 0.0, 1.0)
        for name in ("max_force", "max_torque"):
            check_axes(name, getattr(self, name))
        for name in ("policy_dt", "explode_speed", "reach_move_time"):
            check_positive(name, getattr(self, name))
        check_int("episode_length", self.episode_length, 1)
        check_number("fall_penalty", self.fall_penalty)
        check_number("joint_noise", self.joint_noise, low=0.0)
        check_number("reach_fraction", self.reach_fraction, low=0.0, high=1.0)
        for name in ("command_vx", "command_vy", "command_yaw"):
            check_range(name, getattr(self, name))
        if self.command_after is not None:
            if not (isinstance(self.command_after, tuple) and len(self.command_after) == 3):
                raise DpcError(
                    "command_after must be None or a (v_x, v_y, yaw rate) tuple, "
                    f"got {self.command_after!r}."
                )
            for v in self.command_after:
                check_number("command_after", v)
        for name in ("command_switch", "push_force", "push_gap", "payload_mass", "object_mass"):
            check_range(name, getattr(self, name), low=0.0)
        for name in ("reach_period", "push_duration", "script_rate"):
            check_range(name, getattr(self, name), low=1e-3)
        w = self.push_axis_weights
        if not (isinstance(w, tuple) and len(w) == 3):
            raise DpcError(f"push_axis_weights must be an (x, y, z) tuple, got {w!r}.")
        for v in w:
            check_number("push_axis_weights", v, low=0.0)
        if not any(v > 0 for v in w):
            raise DpcError("push_axis_weights must have at least one weight > 0.")


def _flat(overrides: dict) -> dict:
    """`overrides` with each part (`PARTS`; an instance, or a dict of some of its fields) spread
    into its fields; a field named twice raises `DpcError`."""
    out = {k: v for k, v in overrides.items() if k not in PARTS}
    for key in overrides.keys() & PARTS.keys():
        value = overrides[key]
        fields = dataclasses.asdict(value) if isinstance(value, PARTS[key]) else value
        own = {f.name for f in dataclasses.fields(PARTS[key])}
        if not isinstance(fields, dict) or not set(fields) <= own:
            raise DpcError(
                f"{key} takes a {PARTS[key].__name__} or a dict of some of {sorted(own)}, got "
                f"{value!r}."
            )
        twice = sorted(fields.keys() & out.keys())
        if twice:
            raise DpcError(f"{twice} given both alone and in {key}; give each once.")
        out.update(fields)
    return out


def _policy_u(u_frame: Any, u_base: Any) -> None:
    """`DpcError` unless the frame and base of the policy's u are known and fit together."""
    check_choice("u_frame", u_frame, U_FRAMES)
    check_choice("u_base", u_base, U_BASES)
    if u_base == "observer" and u_frame != "yaw":
        raise DpcError(
            "u_base='observer' adds the policy's u to u_obs, a yaw-frame estimate: set "
            "u_frame='yaw' (the default) with it."
        )
