"""Per-episode randomness of a DPC env: velocity commands, arm reference motions, end-effector
pushes, payloads and the weight added to a scene's objects; and the desired body path (the
command integrated from the start pose). Sampled per env from its own key; distributions are the
`EnvConfig` fields; a task's own draws (script timing, object placement) are its `draw_task`.

The schedule is a small Markov state (`Disturbances`) advanced once per env step (`advance`, at
50 Hz), and evaluated at any physics time t inside the step (`arm_targets`, `ee_forces`), so
motion and push onsets have the physics step's resolution (4 ms). Episodes may be of any length.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from flax import struct

from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.robots.layout import Layout

NEVER = 1e9  # s, "not scheduled" (finite on purpose: every array of the state stays finite)
GRAVITY = 9.81  # m/s², for payload weights


@struct.dataclass
class Disturbances:
    """The disturbance schedule of one env (n: arm servos, k: arms)."""

    command: jax.Array  # (3,) v_x, v_y (m/s, yaw frame), yaw rate (rad/s)
    command_switch: jax.Array  # () s, time of the pending command redraw (NEVER once done)
    ref_start: jax.Array  # (n,) arm servo targets when the current motion began (rad or m)
    ref_goal: jax.Array  # (n,) target of the current motion
    ref_t0: jax.Array  # () s, start of the current motion
    ref_next: jax.Array  # () s, when the next target is drawn
    push: jax.Array  # (k, 3) N, yaw frame, force of the current/next push of each arm
    push_on: jax.Array  # (k,) s, push start
    push_off: jax.Array  # (k,) s, push end
    payload: jax.Array  # (k,) kg held by each gripper
    object_load: jax.Array  # (n_obj,) kg, weight added to each free object of the scene
    ref_pose: jax.Array  # (3,) desired x, y (m, world) and heading (rad): the command integrated
    task: jax.Array  # (m,) the task's own draws (`DpcEnv.draw_task`; reaching: none)


@dataclasses.dataclass(frozen=True)
class DisturbanceSampler:
    """Static sampling parameters of one compiled variant (numpy; closed over in jit)."""

    config: EnvConfig
    home: np.ndarray  # (n,) arm servo targets of the home pose
    reach_low: np.ndarray  # (n,) lower bound of reaching targets
    reach_high: np.ndarray  # (n,)
    n_arms: int
    n_objects: int  # free objects of the scene (box, balls)
    start_pose: np.ndarray  # (3,) x, y (m, world), heading (rad) of the trunk at reset

    def init(self, key: jax.Array) -> Disturbances:
        """The schedule at t = 0: a command, a first arm target, a first push per arm."""
        cfg = self.config
        k_cmd, k_switch, k_ref, k_push, k_mass = jax.random.split(key, 5)
        zero = jp.zeros(())
        home = jp.asarray(self.home, jp.float32)
        d = Disturbances(
            command=self._command(k_cmd),
            command_switch=_uniform(k_switch, cfg.command_switch),  # s ~ U(command_switch)
            ref_start=home,
            ref_goal=home,
            ref_t0=zero,
            ref_next=zero,  # draw the first target at t = 0
            push=jp.zeros((self.n_arms, 3)),
            push_on=jp.full(self.n_arms, NEVER),
            push_off=jp.zeros(self.n_arms),  # the "previous push" ended at t = 0
            payload=_uniform(k_mass, cfg.payload_mass, (self.n_arms,)),  # kg ~ U(payload_mass)
            # kg ~ U(object_mass); a key of its own, so the draws above stay those of the envs
            # before objects had weights
            object_load=_uniform(jax.random.fold_in(key, 1), cfg.object_mass, (self.n_objects,)),
            ref_pose=jp.asarray(self.start_pose, jp.float32),
            task=jp.zeros(0),
        )
        d = self._new_target(d, zero, k_ref)
        return self._new_pushes(d, zero, k_push)

    def advance(self, d: Disturbances, t: jax.Array, key: jax.Array) -> Disturbances:
        """Redraw whatever is due at time t (s): command, arm target, pushes that have ended;
        then move the desired pose on by one env step (`policy_dt`) at the command."""
        k_cmd, k_ref, k_push = jax.random.split(key, 3)
        switch = t >= d.command_switch
        after = self.config.command_after
        new = self._command(k_cmd) if after is None else jp.asarray(after, jp.float32)
        d = d.replace(
            command=jp.where(switch, new, d.command),
            command_switch=jp.where(switch, NEVER, d.command_switch),
        )
        due = t >= d.ref_next
        d = jax.tree.map(lambda a, b: jp.where(due, a, b), self._new_target(d, t, k_ref), d)
        d = self._new_pushes(d, t, k_push)
        return d.replace(ref_pose=integrate_command(d.ref_pose, d.command, self.config.policy_dt))

    def arm_targets(self, d: Disturbances, t: jax.Array) -> jax.Array:
        """(n,) arm servo targets at time t: smooth step from `ref_start` to `ref_goal`."""
        x = jp.clip((t - d.ref_t0) / self.config.reach_move_time, 0.0, 1.0)
        return d.ref_start + (d.ref_goal - d.ref_start) * (3 * x**2 - 2 * x**3)

    def pushes(self, d: Disturbances, t: jax.Array, yaw: jax.Array) -> jax.Array:
        """(k, 3) N, world: the push force on each end effector at time t (0 between pushes).

        Pushes are drawn in the robot's yaw (heading) frame and turned with it: `yaw` (rad) is the
        trunk's current heading, so a push drawn along +x always pushes from behind."""
        active = (t >= d.push_on) & (t < d.push_off)
        c, s = jp.cos(yaw), jp.sin(yaw)
        x, y = d.push[:, 0], d.push[:, 1]
        world = jp.stack([c * x - s * y, s * x + c * y, d.push[:, 2]], axis=-1)
        return world * active[:, None]

    def payload_weights(self, d: Disturbances) -> jax.Array:
        """(k, 3) N, world: the payload's weight on each end effector."""
        return jp.zeros((self.n_arms, 3)).at[:, 2].set(-GRAVITY * d.payload)

    def ee_forces(self, d: Disturbances, t: jax.Array, yaw: jax.Array) -> jax.Array:
        """(k, 3) N, world: push + payload weight on each end effector at time t."""
        return self.pushes(d, t, yaw) + self.payload_weights(d)

    def object_forces(self, d: Disturbances) -> jax.Array:
        """(n_obj, 3) N, world: the added weight of each free object (at its COM)."""
        return jp.zeros((self.n_objects, 3)).at[:, 2].set(-GRAVITY * d.object_load)

    def _command(self, key: jax.Array) -> jax.Array:
        cfg = self.config
        lo = jp.array([cfg.command_vx[0], cfg.command_vy[0], cfg.command_yaw[0]])
        hi = jp.array([cfg.command_vx[1], cfg.command_vy[1], cfg.command_yaw[1]])
        return jax.random.uniform(key, (3,), minval=lo, maxval=hi)  # each ~ U(command_*)

    def _new_target(self, d: Disturbances, t: jax.Array, key: jax.Array) -> Disturbances:
        k_goal, k_period = jax.random.split(key)
        goal = jax.random.uniform(  # each joint ~ U(reach_low, reach_high)
            k_goal, self.home.shape, minval=self.reach_low, maxval=self.reach_high
        )
        return d.replace(
            ref_start=self.arm_targets(d, t),
            ref_goal=goal,
            ref_t0=t,
            ref_next=t + _uniform(k_period, self.config.reach_period),  # s ~ U(reach_period)
        )

    def _new_pushes(self, d: Disturbances, t: jax.Array, key: jax.Array) -> Disturbances:
        """For each arm whose push has ended, schedule the next one."""
        cfg, k = self.config, self.n_arms
        k_dir, k_mag, k_gap, k_dur = jax.random.split(key, 4)
        # direction ~ N(0, diag(w^2)) normalised, w = push_axis_weights (1, 1, 1: uniform sphere)
        direction = jax.random.normal(k_dir, (k, 3)) * jp.asarray(cfg.push_axis_weights)
        direction = direction / jp.maximum(jp.linalg.norm(direction, axis=1, keepdims=True), 1e-6)
        force = direction * _uniform(k_mag, cfg.push_force, (k, 1))  # |F| ~ U(push_force) N
        on = t + _uniform(k_gap, cfg.push_gap, (k,))  # s ~ U(push_gap) after the last push
        off = on + _uniform(k_dur, cfg.push_duration, (k,))  # s ~ U(push_duration)
        due = t >= d.push_off
        return d.replace(
            push=jp.where(due[:, None], force, d.push),
            push_on=jp.where(due, on, d.push_on),
            push_off=jp.where(due, off, d.push_off),
        )


def ee_wrench(nbody: int, ee_sites, ee_bodies, d, forces: jax.Array) -> jax.Array:
    """(nbody, 6) xfrc_applied: each (3,) force of `forces` (k, 3) at its end-effector site
    `ee_sites` (k,), on the body `ee_bodies` (k,) that holds it.

    xfrc_applied acts at the body COM (world frame, force then torque), so the force is moved to
    the site with the torque (site - COM) x F."""
    xfrc = jp.zeros((nbody, 6))
    if not len(ee_sites):
        return xfrc
    lever = d.site_xpos[ee_sites] - d.xipos[ee_bodies]
    wrench = jp.concatenate([forces, jp.cross(lever, forces)], axis=1)
    return xfrc.at[ee_bodies].add(wrench)


def integrate_command(pose: jax.Array, command: jax.Array, dt: float) -> jax.Array:
    """(3,) the desired pose [x, y (m, world), heading (rad)] after `dt` s at `command` (3,)
    [v_x, v_y (m/s, yaw frame), yaw rate (rad/s)] (explicit Euler: the velocity turned by the
    heading at the start of the step)."""
    c, s = jp.cos(pose[2]), jp.sin(pose[2])
    vx, vy, wz = command
    return pose + dt * jp.array([c * vx - s * vy, s * vx + c * vy, wz])


def make_sampler(
    config: EnvConfig, model: mujoco.MjModel, lay: Layout, n_objects: int = 0
) -> DisturbanceSampler:
    """Sampling bounds from the model: reaching targets within the arm joints' ranges; the
    desired path starts at the home key's trunk position, heading 0 (the key is level and
    faces +x)."""
    home = np.asarray(model.key_ctrl[0][lay.arm_act], np.float32)
    joints = model.actuator_trnid[lay.arm_act, 0]
    limited = model.jnt_limited[joints].astype(bool)
    lo = np.where(limited, model.jnt_range[joints, 0], home - np.pi)  # unlimited: +-pi rad
    hi = np.where(limited, model.jnt_range[joints, 1], home + np.pi)
    f = config.reach_fraction
    reach_low = np.clip(home - f * (home - lo), lo, hi).astype(np.float32)
    reach_high = np.clip(home + f * (hi - home), lo, hi).astype(np.float32)
    start = np.array([*model.key_qpos[0][:2], 0.0], np.float32)
    return DisturbanceSampler(config, home, reach_low, reach_high, len(lay.arms), n_objects, start)


def _uniform(key: jax.Array, bounds: tuple[float, float], shape: tuple = ()) -> jax.Array:
    return jax.random.uniform(key, shape, minval=bounds[0], maxval=bounds[1])
