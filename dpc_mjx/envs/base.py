"""`DpcEnv`: one env of a quadruped (any base) and its arms behind the brax `Env` API, unbatched
and pure.

One env step (50 Hz) = redraw due disturbances, then `n_substeps` x [controller tick -> physics
step] at the physics rate (250 Hz), with u chosen by `config.controller`. The physics step is
`mjx.step`, or MuJoCo C's `mj_step` on the same model with `config.engine = 'native'` (by
default native on a CPU, MJX on an accelerator: `dpc_mjx/physics.py`); everything else is the
same code under both engines.

u by controller (`dpc_mjx.controllers`): 'mbc' 0; 'observer' the momentum observer's estimate;
'oracle' the measured arm-mount wrench; 'dpc' u_scale * clip(action, -1, 1) (`EnvConfig.u_scale`)
in the yaw frame (`u_frame`), with `u_base='observer'` added to the observer's estimate, with
'gravity' to the arms' gravity wrench (`arm_gravity`). The action is ignored by all but 'dpc'.
`info['controller']`, where present, picks it per env.

State (brax `State`):
    pipeline_state  mjx.Data
    obs             (obs_size,) [s_body, s_arm, p_arm, u_obs], slices in `env.obs_layout`
    reward          () paper eq. 4 (+ `fall_penalty` on the falling step; 0 on a NaN reset)
    done            () 1.0 on a fall or a non-finite/exploded state
    metrics         per-step terms (`envs.outcome.METRICS`); wrappers add keys: we never drop any
    info            'rng' (2,) key; 'ctrl' ControllerState; 'dist' Disturbances;
                    'sensor_bias' SensorNoise, this episode's sensor biases; 'ctrl_queue'
                    (sensor_delay, nu) ctrl computed but not yet applied (`control/sensors.py`);
                    'privileged' (10,) [u_oracle, payload, ee_force] (`observations.PRIVILEGED`);
                    'nan_reset' () 1.0 when this step was non-finite or exploded;
                    'controller' () int32 `Controller.index`, only in a batch of mixed
                    controllers (`envs.controller_batch`), else `config.controller`;
                    'objects' (n_obj, 3) m, world positions of the scene's free objects (box,
                    balls; `objects.prop_layout` order), only in scenes that have some;
                    'u_replay', 'u_ticks' only with `u_ahead='replay'` (`envs/ahead.py`)

Tasks customise the env through hooks, never by rewriting `step`:

    build_model(arm)        the compiled scene (objects: the task's `scene_spec(arm)`)
    check_arm(robot)        raise `DpcError` for an arm the task cannot use (before any compile)
    draw_task(key)          (m,) this episode's own task draws (script pace, object placement),
                            kept in `Disturbances.task`
    place_objects(qpos, dist) the initial qpos with the scene's objects placed (pushing: the box)
    arm_targets(dist, t, d) (n_act,) arm servo targets at physics time t: the reference motion
                            p_arm (reaching: the sampler's random targets; tasks: scripts)
    task_physics(d, t, dist) edits the data before each physics step (carrying: grasp welds)
    task_metrics(d, dist)   extra per-step metrics (scalars, the same keys at reset and step):
                            the task's success measures (`TASK_MEASURES` says how each is read)

Fall: trunk height < 0.15 m (the A1's; scaled with a base's standing height) or |roll| or
|pitch| > 1 rad (`control.state.has_fallen`). A non-finite or exploded step (|qvel| >
`explode_speed`) keeps the previous physics and controller state, returns obs = 0 and reward = 0
with done = 1 and is counted in `metrics['nan_resets']`; the auto-reset wrapper
(`wrappers.wrap_for_training`) then resets that env alone.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from brax.envs.base import Env, State
from mujoco import mjx

from dpc_mjx import sim
from dpc_mjx.control import gait, sensors
from dpc_mjx.control.controller import make_controller
from dpc_mjx.control.state import gravity_u, has_fallen, oracle_u
from dpc_mjx.controllers import Controller
from dpc_mjx.envs import ahead as ahead_lib
from dpc_mjx.envs import observations, outcome, rewards
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.disturbances import Disturbances, ee_wrench, make_sampler
from dpc_mjx.envs.outcome import METRICS
from dpc_mjx.physics import make_physics, resolve_engine
from dpc_mjx.robots import build
from dpc_mjx.robots.layout import layout
from dpc_mjx.robots.objects import prop_layout
from dpc_mjx.robots.variants import Arm, RobotSpec, on_base, resolve
from dpc_mjx.rotations import wrench_to_world, yaw_of

ACTION_SIZE = 6  # u = [f_a (3), tau_a (3)]
_GAITS = {"trot": gait.trot, "stand": gait.stand}


class DpcEnv(Env):
    """Base + arm(s) + low-level controller; `reset(rng)` / `step(state, action)` on one env."""

    def __init__(self, config: EnvConfig, arm: str | Arm | RobotSpec = "regular"):
        config.validate()
        self.config = config
        arm = getattr(self, "DEFAULT_ARM", "regular") if arm is None else arm  # a task's default
        self.model = self.build_model(on_base(resolve(arm), config.base))
        # 'auto' -> the engine that runs (`physics.resolve_engine`), so config.engine names it
        self.config = config = config.replace(engine=resolve_engine(config.engine, self.model))
        self.n_substeps = config.substeps(float(self.model.opt.timestep))
        self.lay = layout(self.model)
        self.mx = sim.put_model(self.model)
        self.physics = make_physics(config.engine, self.model, self.mx)
        self.controller = make_controller(
            self.model,
            gait_=_GAITS[config.gait](),
            observer=config.observer_config(),
            arm_estimate=config.arm_estimate_config(),
            low_level=config.low_level,
        )
        self.arm_model = self.controller.arm  # the arms' rigid-body model (None: no arm)
        # on for the controllers that add it, and under u_base 'model' (its policy's u is the
        # model wrench plus what the policy learned)
        self.use_arm_model(config.controller.adds(config.u_base)[1] or config.u_base == "model")
        self.props = prop_layout(self.model)
        self.sampler = make_sampler(config, self.model, self.lay, len(self.props.objects))
        self.obs_layout = observations.ObsLayout.of(self.lay)
        self._object_bodies = np.array([o.body for o in self.props.objects], int)
        self.ee_sites = np.array([a.ee_site for a in self.lay.arms], int)
        self._ee_bodies = self.model.site_bodyid[self.ee_sites]
        self._u_scale = jp.array(config.u_scale)  # (6,) N, N·m per unit of action
        self._arm_masses = jp.asarray(self.model.body_mass[self.lay.arm_bodies], jp.float32)  # kg

    def use_arm_model(self, on: bool) -> None:
        """Whether the controller computes the arms' model wrench every tick (`arm_estimate`;
        off, `ControllerState.arm` stays at its reset): it slows the env step by about a fifth
        (docs/benchmarks.md, "The arms' model wrench"), so only the envs that read it compute
        it (`__init__`; `ControllerBatch` turns it on for a batch with a controller that adds
        it)."""
        arm = self.arm_model if on else None
        self.controller = dataclasses.replace(self.controller, arm=arm)

    # task hooks -----------------------------------------------------------------------------

    # How `dpc_mjx.run.eval` reads each `task_metrics` key: its value at the episode's end
    # (its last step, or the fall), averaged over episodes. Tasks name theirs.
    TASK_MEASURES: tuple[str, ...] = ()

    def build_model(self, arm: str | Arm | RobotSpec) -> mujoco.MjModel:
        """The compiled scene; tasks with objects override this (add bodies with MjSpec)."""
        return build(arm)

    @classmethod
    def check_arm(cls, robot: RobotSpec) -> None:
        """Raise `DpcError` if the task cannot use `robot`'s arms; called by `make` before
        anything is built. Every arm (or none) can reach random targets."""

    def arm_targets(self, dist: Disturbances, t: jax.Array, d: mjx.Data) -> jax.Array:
        """(n_act,) arm servo targets (rad, m for a finger) at physics time t (s): p_arm.

        Reaching: the sampler's random targets. `d` is the physics state of this tick (at reset:
        the initial state, forwarded with the home targets)."""
        del d
        return self.sampler.arm_targets(dist, t)

    def draw_task(self, key: jax.Array) -> jax.Array:
        """(m,) the episode's own draws of the task (script pace, object placement), from the
        config's ranges; stored in `Disturbances.task`. Reaching: none."""
        del key
        return jp.zeros(0)

    def place_objects(self, qpos: jax.Array, dist: Disturbances) -> jax.Array:
        """(nq,) the initial qpos (home key, leg noise) with the scene's objects placed for this
        episode (`dist.task`). Default: as in the home key."""
        del dist
        return qpos

    def task_physics(self, d: mjx.Data, t: jax.Array, dist: Disturbances) -> mjx.Data:
        """The data handed to the physics step at physics time t (s), after the controller set
        `ctrl` and `xfrc_applied`: tasks switch grasp welds here. Pure, jit-safe."""
        del t, dist
        return d

    def task_metrics(self, d: mjx.Data, dist: Disturbances) -> dict[str, jax.Array]:
        """Per-step task metrics (scalars) merged into `state.metrics`, from the data after the
        step (at reset: the initial data). Keys must not depend on the data."""
        del d, dist
        return {}

    # brax Env API ---------------------------------------------------------------------------

    @property
    def observation_size(self) -> int:
        return self.obs_layout.size

    @property
    def action_size(self) -> int:
        return ACTION_SIZE

    @property
    def backend(self) -> str:
        return "mjx"

    @property
    def dt(self) -> float:
        """s per env step."""
        return self.config.policy_dt

    def reset(self, rng: jax.Array) -> State:
        if self._sensing:
            rng, k_pose, k_dist, k_bias = jax.random.split(rng, 4)
        else:  # exact sensors: the key stream of the envs before the sensor model
            rng, k_pose, k_dist = jax.random.split(rng, 3)
        model, lay, cfg = self.model, self.lay, self.config
        qpos = jp.asarray(model.key_qpos[0], jp.float32)
        noise = jax.random.uniform(  # leg joints ~ U(-joint_noise, joint_noise) rad
            k_pose, (len(lay.leg_qpos),), minval=-cfg.joint_noise, maxval=cfg.joint_noise
        )
        qpos = qpos.at[lay.leg_qpos].add(noise)
        dist = self.sampler.init(k_dist)
        dist = dist.replace(task=self.draw_task(jax.random.fold_in(k_dist, 2)))  # own stream
        qpos = self.place_objects(qpos, dist)
        ctrl = jp.asarray(model.key_ctrl[0], jp.float32)
        d = mjx.make_data(self.mx).replace(qpos=qpos, ctrl=ctrl)
        d = self.physics.forward(d)
        d = d.replace(ctrl=ctrl.at[lay.arm_act].set(self.arm_targets(dist, jp.zeros(()), d)))
        n_arm = len(lay.arm_dof)
        if self._sensing:
            bias = sensors.draw_bias(k_bias, n_arm, cfg.sensor_noise)
        else:
            bias = sensors.zeros(n_arm)
        info = {
            "rng": rng,
            "ctrl": self.controller.init(d),
            "dist": dist,
            "privileged": self._privileged(d, dist),
            "nan_reset": jp.zeros(()),
            "sensor_bias": bias,
            "ctrl_queue": jp.tile(d.ctrl, (cfg.sensor_delay, 1)),  # (delay, nu) not yet applied
            **self._objects(d),
        }
        info |= ahead_lib.replay_info(cfg, self.n_substeps)  # 'replay': its recordings
        metrics = {k: jp.zeros(()) for k in METRICS} | self.task_metrics(d, dist)
        obs = observations.observation(lay, d, dist.command, info["ctrl"].observer.estimate)
        obs = self._measured(obs, bias)
        return State(d, obs, jp.zeros(()), jp.zeros(()), metrics, info)

    def step(self, state: State, action: jax.Array) -> State:
        d0, info = state.pipeline_state, state.info
        if self._sensing:
            rng, key, k_sense = jax.random.split(info["rng"], 3)
            tick_keys = jax.random.split(k_sense, self.n_substeps)
        else:  # exact sensors: the key stream of the envs before the sensor model
            rng, key = jax.random.split(info["rng"])
            tick_keys = None
        dist = self.sampler.advance(info["dist"], d0.time, key)
        command = dist.command
        d, cs, queue, noise, u_ticks = self._ticks(d0, info, dist, self.policy_u(action), tick_keys)

        true_obs = observations.observation(self.lay, d, command, cs.observer.estimate)
        obs = self._measured(true_obs, noise)  # what the policy reads
        sb = true_obs[self.obs_layout.s_body]  # the reward, the fall test and metrics: true
        vel = jp.stack([sb[5], sb[6], observations.world_yaw_rate(sb)])
        r = rewards.total_reward(vel, command, sb[:2], jp.zeros(2))  # desired roll = pitch = 0
        fall = has_fallen(d.qpos[2], sb[:2], self.controller.fall_height)
        privileged = self._privileged(d, dist)
        bad = outcome.is_bad(d, obs, privileged, cs, r["r_total"], self.config.explode_speed)
        fall = fall & ~bad
        new_metrics = outcome.step_metrics(r, vel - command, sb, fall, bad) | {
            "pos_sq_err": jp.sum((d.qpos[:2] - dist.ref_pose[:2]) ** 2),
            "ee_sq_err": outcome.ee_sq_err(self.mx, self.lay, d, self.arm_targets(dist, d.time, d)),
            **self.task_metrics(d, dist),
        }
        new_metrics = outcome.zero_if_bad(new_metrics, bad)
        reward = r["r_total"] + jp.where(fall, self.config.fall_penalty, 0.0)
        # the NaN guard: a bad step keeps the previous physics and controller state
        keep = lambda new, old: jp.where(bad, old, new)  # noqa: E731
        d = jax.tree.map(keep, d, d0)
        cs = jax.tree.map(keep, cs, info["ctrl"])
        info = {
            **info,
            "rng": rng,
            "ctrl": cs,
            "ctrl_queue": keep(queue, info["ctrl_queue"]),
            "dist": dist,
            "privileged": jp.where(bad, 0.0, privileged),
            "nan_reset": bad.astype(jp.float32),
            **self._objects(d),
            **({} if u_ticks is None else {"u_ticks": u_ticks}),  # (n_substeps, 6) 'replay'
        }
        return state.replace(
            pipeline_state=d,
            obs=jp.where(bad, 0.0, obs),
            reward=jp.where(bad, 0.0, reward),
            done=(fall | bad).astype(jp.float32),
            metrics={**state.metrics, **new_metrics},
            info=info,
        )

    def _ticks(self, d0: mjx.Data, info: dict, dist: Disturbances, u_policy, tick_keys):
        """`n_substeps` x [controller tick -> physics step] from `d0` (one `lax.scan`; u of each
        tick by `controller_u`): (data, controller state, ctrl queue, the last tick's sensor
        errors). `tick_keys` (n_substeps, 2) draw the sensor errors (None: exact sensors); the
        ticks' index i, the same in the whole batch, times the MPC's re-solves (`tick`)."""
        bias, scale = info["sensor_bias"], self.config.sensor_noise
        command = dist.command

        def substep(carry, xs):
            (d, cs, queue, _), (i, tick_key) = carry, xs
            noise = None if tick_key is None else sensors.draw(tick_key, bias, scale)
            u, add, model = self.controller_u(d, u_policy, info.get("controller"))
            targets = self.arm_targets(dist, d.time, d)
            ahead, change = ahead_lib.horizon(self, info, dist, d)  # `EnvConfig.u_ahead`
            # (6,) the tick's mount wrench, a replay's recording ('replay' only: a hot path)
            measured = self._oracle(d) if self.config.u_ahead == "replay" else None
            cs, ctrl = self.controller.step(
                cs, d, command, u, targets, noise, add, model, ahead, i, u_change=change
            )
            if self.config.sensor_delay:  # ctrl acts `sensor_delay` ticks after its measurement
                ctrl, queue = queue[0], jp.concatenate([queue[1:], ctrl[None]])
            forces = self.sampler.ee_forces(dist, d.time, self._yaw(d))
            xfrc = ee_wrench(self.model.nbody, self.ee_sites, self._ee_bodies, d, forces)
            xfrc = xfrc.at[self._object_bodies, :3].add(self.sampler.object_forces(dist))
            d = self.task_physics(d.replace(ctrl=ctrl, xfrc_applied=xfrc), d.time, dist)
            d = self.physics.step(d)
            return (d, cs, queue, bias if noise is None else noise), measured

        carry = (d0, info["ctrl"], info["ctrl_queue"], bias)
        xs = (jp.arange(self.n_substeps), tick_keys)
        (d, cs, queue, noise), u_ticks = jax.lax.scan(substep, carry, xs, length=self.n_substeps)
        return d, cs, queue, noise, u_ticks

    # the disturbance u -----------------------------------------------------------------------

    def policy_u(self, action: jax.Array) -> jax.Array:
        """(6,) the policy's u in `config.u_frame` (N, N·m) for an action (6,) (clipped to
        [-1, 1], times `EnvConfig.u_scale`)."""
        return self._u_scale * jp.clip(action, -1.0, 1.0)

    def controller_u(self, d, u_policy: jax.Array, controller: jax.Array | None = None):
        """(u, add_estimate, add_model) of this tick for the controller: u (6,) in the world
        frame, about the base's COM (None: the observer's own estimate of the tick), whether the
        controller adds the observer's estimate to u and whether it adds the arms' model wrench
        (`LowLevelController.step`). By `config.controller`, or, given `controller`, a traced ()
        int32 `Controller.index` (each env of a batch its own: `envs.controller_batch`).
        `u_policy` from `policy_u` (used by 'dpc' only)."""
        zero = jp.zeros(ACTION_SIZE)
        u_of = {Controller.DPC: self._dpc_u(d, u_policy), Controller.ORACLE: self._oracle(d)}
        if controller is not None:
            u = jp.stack([u_of.get(c, zero) for c in Controller])[controller]  # (6,) its row
            adds = jp.array([c.adds(self.config.u_base) for c in Controller])  # (n_c, 2) bool
            return u, adds[controller, 0], adds[controller, 1]
        c = self.config.controller
        if c == Controller.OBSERVER:
            return None, False, False  # the controller's own observer estimate of this tick
        return u_of.get(c, zero), *c.adds(self.config.u_base)

    def _dpc_u(self, d, u_policy: jax.Array) -> jax.Array:
        """(6,) the policy's u in the world frame (turned from the yaw frame, `u_frame`), plus
        the arms' gravity wrench with `u_base` 'gravity' (the observer's estimate and the arms'
        model wrench are added by the controller: `controller_u`)."""
        if self.config.u_frame == "yaw":  # the policy's u turns with the heading
            u_policy = wrench_to_world(u_policy, self._yaw(d))
        if self.config.u_base == "gravity":
            return u_policy + self.arm_gravity(d)
        return u_policy

    def arm_gravity(self, d) -> jax.Array:
        """(6,) world frame: the arms' weight and its torque about the base's COM at this tick's
        pose, from the arm file's masses (`control.state.gravity_u`; `u_base` 'gravity')."""
        gravity = jp.asarray(self.model.opt.gravity, jp.float32)  # (3,) m/s^2, world
        return gravity_u(self._arm_masses, gravity, d.xipos[self.lay.arm_bodies], self.com_pos(d))

    def _oracle(self, d) -> jax.Array:
        """(6,) the measured arm-mount wrench about the base's COM (world frame)."""
        return oracle_u(self.lay, d, self.com_pos(d))

    # helpers --------------------------------------------------------------------------------

    @property
    def _sensing(self) -> bool:
        """Whether sensors have errors (`EnvConfig.sensor_noise` > 0): draws keys for them."""
        return self.config.sensor_noise > 0

    def _measured(self, obs: jax.Array, noise: sensors.SensorNoise) -> jax.Array:
        """The true observation `obs` as measured: s_body and s_arm with the errors `noise` of
        the last tick (`control/sensors.py`); u_obs is the observer's, from measured states."""
        if not self._sensing:
            return obs
        lay = self.obs_layout
        s_body, s_arm = sensors.observe(obs[lay.s_body], obs[lay.s_arm], noise)
        return obs.at[lay.s_body].set(s_body).at[lay.s_arm].set(s_arm)

    def _objects(self, d) -> dict[str, jax.Array]:
        """{'objects': (n_obj, 3) m, world} for scenes with free objects, else {}."""
        return {"objects": d.xpos[self._object_bodies]} if self._object_bodies.size else {}

    def _yaw(self, d) -> jax.Array:
        """() rad, the trunk's heading."""
        return yaw_of(d.xmat[self.controller.idx.trunk])

    def com_pos(self, d) -> jax.Array:
        """(3,) m, world: the base (trunk + legs) COM, as the controller sees it."""
        idx = self.controller.idx
        offset = jp.asarray(idx.com_offset, jp.float32)
        return d.xpos[idx.trunk] + d.xmat[idx.trunk] @ offset

    def _privileged(self, d, dist) -> jax.Array:
        """(10,) [u_oracle (6), payload (1), ee push force (3)], see `observations.PRIVILEGED`."""
        u = self._oracle(d)
        push = self.sampler.pushes(dist, d.time, self._yaw(d)).sum(axis=0)
        return jp.concatenate([u, dist.payload.sum()[None], push])
