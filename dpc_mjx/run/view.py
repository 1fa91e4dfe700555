"""`dpc-mjx view`: MuJoCo's interactive viewer on a live env, a controller in real time.

One env (`engine='native'`: MuJoCo C steps it, `dpc_mjx/physics.py`) runs the chosen controller
(MBC, observer, DPC: the export's policy and the arm's encoder, or the oracle) with the arm's
reaching motion on, one jitted env step per `env.dt` (20 ms) of wall time, the rest of the 20 ms
slept (`run_loop`; a line warns when a step takes longer). The viewer
(`mujoco.viewer.launch_passive`) shows a copy of the env's data: after each step its qpos, qvel
and time go into an `MjData` of a copy of the model, forwarded for display (`LiveEnv.mirror`);
the viewer never steps physics itself. Its camera follows the trunk (`follow`), so a walking
robot stays in the picture (MuJoCo's default camera looks at the scene's centre, which a robot
walks out of).

Cost at batch 1 (CPU time per env step, the shipped DPC, XLA on one thread, measured on the
project's 2-core box at load average ~11): native 37 ms, most of it the host callback of each
of the 5 physics ticks (~3 ms each against 0.03 ms for `mj_step` itself); MJX 20 ms, after a
compile several times longer. Where the loop falls behind, `env={'engine': 'mjx'}` (`--env
engine=mjx`) may keep up.

Mouse perturbations are disturbances. In passive mode the viewer's `sync()` clears the
`xfrc_applied` of the `MjData` it shows and writes the perturbation there (double-click a body
to select it, Ctrl + right drag pulls it, Ctrl + left drag twists it: a spring to the mouse,
`mjv_applyPerturbForce`; world frame [f (N), tau (N·m)] at the body's COM, the convention of
`xfrc_applied`). Each step reads that (nbody, 6) array and adds it to the forces the env itself
applies (pushes, payload, object weights) before every physics tick of the step
(`pushed`, after the task's `task_physics`), held for the step's 20 ms. The controllers learn of
it as they would of any disturbance: the oracle through the arm's mount wrench, the observer
through the body's momentum, DPC through the arm's state. The env's own random pushes are off
unless asked for (`env={'push_force': (0, 30)}`): the mouse is the disturbance. A line says
when a pull begins and, when it is let go, how long it lasted, how hard it pulled and how far
it moved the body (`MousePulls`). `experiments/view_mouse.py` drives a real viewer with a
synthetic mouse on a virtual display (Xvfb) and checks that a pull moves the robot.

Keys (`KeyCommand`, the viewer's key_callback; keys the passive viewer does not use): Up/Down
forward velocity, Left/Right lateral velocity, Home/End yaw rate, Space the zero command, Delete
a new episode (so does a fall). The command is written into the env's disturbance state before
each step (`Disturbances.command`, its redraw disabled), within the ranges the env draws
commands from (`EnvConfig.command_*`, widened to include 0), where the policy was trained.

A viewer needs a display: without one (no DISPLAY or WAYLAND_DISPLAY on Linux) `view` refuses
before building anything; on macOS it must run under `mjpython` (MuJoCo's launcher: the viewer
owns the main thread there): `mjpython -m dpc_mjx.run.cli view ...`.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from brax.envs.base import State

from dpc_mjx.controllers import Controller
from dpc_mjx.envs.disturbances import NEVER
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.envs.rollout import Policy, zero_policy
from dpc_mjx.errors import DpcError
from dpc_mjx.io.shipped import SHIPPED, export_cells
from dpc_mjx.robots.variants import arm_name

# GLFW key codes (what the viewer's key_callback receives)
KEY_SPACE, KEY_DELETE, KEY_RIGHT, KEY_LEFT, KEY_DOWN, KEY_UP = 32, 261, 262, 263, 264, 265
KEY_HOME, KEY_END = 268, 269
# key -> (command component, change): v_x, v_y (m/s, yaw frame), yaw rate (rad/s)
KEY_STEPS = {
    KEY_UP: (0, 0.1),
    KEY_DOWN: (0, -0.1),
    KEY_LEFT: (1, 0.05),  # +y is the robot's left
    KEY_RIGHT: (1, -0.05),
    KEY_HOME: (2, 0.1),  # counter-clockwise: turn left
    KEY_END: (2, -0.1),
}
HELP = (
    "keys: Up/Down forward velocity +-0.1 m/s, Left/Right lateral +-0.05 m/s, Home/End yaw rate "
    "+-0.1 rad/s, Space stop, Delete new episode\n"
    "mouse: double-click a body to select it, then Ctrl + right drag pulls it, Ctrl + left drag "
    "twists it"
)
WARN_EVERY_S = 5.0  # s of wall time between two warnings that the loop is behind
# The camera that follows the trunk (`follow`): m from the trunk, degrees (negative: looking down),
# degrees of the viewing direction from +x (45: from behind the robot's right side)
FOLLOW_DISTANCE, FOLLOW_ELEVATION, FOLLOW_AZIMUTH = 2.0, -20.0, 45.0


def display_problem(platform: str, environ: Mapping[str, str], mjpython: bool) -> str | None:
    """Why no viewer window can open here (None: it can): Linux without DISPLAY or
    WAYLAND_DISPLAY, macOS outside `mjpython`."""
    if platform == "darwin" and not mjpython:
        return (
            "On macOS MuJoCo's viewer must run under mjpython (installed with mujoco): "
            "`mjpython -m dpc_mjx.run.cli view ...`."
        )
    screen = environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY")
    if platform.startswith("linux") and not screen:
        return (
            "dpc-mjx view opens a window, and this session has no display (neither DISPLAY nor "
            "WAYLAND_DISPLAY is set). Run it on a desktop (or with X forwarding: ssh -X); "
            "without a screen, `dpc-mjx render --out clip.mp4` writes a video instead."
        )
    return None


def require_display() -> None:
    """Raise `DpcError` saying what to do if no viewer window can open here."""
    mjpython = False
    if sys.platform == "darwin":  # mjpython sets the viewer's launcher; only it can open one
        import mujoco.viewer  # noqa: PLC0415 (GLFW, loaded only where a window can open)

        mjpython = getattr(mujoco.viewer, "_MJPYTHON", None) is not None
    problem = display_problem(sys.platform, os.environ, mjpython)
    if problem:
        raise DpcError(problem)


class KeyCommand:
    """The velocity command the keys set: call it with a GLFW key code (the viewer's
    key_callback, on the viewer's thread); `take()` on the loop's thread."""

    def __init__(self, low: np.ndarray, high: np.ndarray, log: Callable[[str], None] = print):
        self.low = np.asarray(low, np.float32)  # (3,) v_x, v_y (m/s), yaw rate (rad/s)
        self.high = np.asarray(high, np.float32)
        self.log = log
        self._command = np.zeros(3, np.float32)
        self._reset = False
        self._lock = threading.Lock()

    @classmethod
    def for_config(cls, config, log: Callable[[str], None] = print) -> KeyCommand:
        """Limits from an `EnvConfig`'s command ranges, widened to include 0."""
        ranges = np.array([config.command_vx, config.command_vy, config.command_yaw], np.float32)
        return cls(np.minimum(ranges[:, 0], 0.0), np.maximum(ranges[:, 1], 0.0), log)

    def __call__(self, key: int) -> None:
        with self._lock:
            if key == KEY_SPACE:
                self._command[:] = 0.0
            elif key == KEY_DELETE:
                self._reset = True
            elif key in KEY_STEPS:
                i, change = KEY_STEPS[key]
                value = np.float32(round(float(self._command[i]) + change, 3))
                self._command[i] = np.clip(value, self.low[i], self.high[i])
            else:
                return
            vx, vy, wz = self._command
        self.log(f"view: command v_x {vx:+.2f} m/s, v_y {vy:+.2f} m/s, yaw rate {wz:+.2f} rad/s")

    def take(self) -> tuple[np.ndarray, bool]:
        """(the command (3,), whether a new episode was asked for since the last take)."""
        with self._lock:
            reset, self._reset = self._reset, False
            return self._command.copy(), reset


@dataclasses.dataclass
class LoopStats:
    steps: int = 0
    late: int = 0  # steps that ended after their deadline
    max_lag: float = 0.0  # s, the most a step ended after its deadline


def run_loop(
    step: Callable[[np.ndarray, np.ndarray, bool], None],
    viewer,
    keys: KeyCommand,
    dt: float,
    n_steps: int | None = None,
    clock: Callable[[], float] = time.perf_counter,
    sleep: Callable[[float], None] = time.sleep,
    log: Callable[[str], None] = print,
) -> LoopStats:
    """Step in real time until the viewer closes (or `n_steps` steps): each step
    `step(command (3,), xfrc (nbody, 6), reset)` with the keys' command and the viewer's
    perturbation (`viewer.d.xfrc_applied`, written by its last `sync()`), then `viewer.sync()`,
    then sleep until the step's deadline (start + k dt, s of `clock`). A step that ends after
    its deadline starts the schedule afresh (no rushing to catch up) and, at most once every
    `WARN_EVERY_S`, logs a warning."""
    stats, last_warning = LoopStats(), -math.inf
    deadline = clock()
    while viewer.is_running() and (n_steps is None or stats.steps < n_steps):
        data = viewer.d  # None once the window has closed
        if data is None:
            break
        command, reset = keys.take()
        xfrc = np.array(data.xfrc_applied, np.float32)  # (nbody, 6) N, N·m, world
        step(command, xfrc, reset)
        viewer.sync()
        stats.steps += 1
        deadline += dt
        now = clock()
        if now <= deadline:
            sleep(deadline - now)
            continue
        stats.late += 1
        stats.max_lag = max(stats.max_lag, now - deadline)
        if now - last_warning >= WARN_EVERY_S:
            log(
                f"view: warning: behind real time, step {stats.steps} ended "
                f"{1e3 * (now - deadline):.1f} ms late (budget {1e3 * dt:.0f} ms per step); "
                "the robot moves slower than real time"
            )
            last_warning = now
        deadline = now
    return stats


def follow(cam: mujoco.MjvCamera, body: int) -> None:
    """Make the viewer's camera `cam` follow `body` (the trunk), so that a walking robot stays in
    view: MuJoCo's tracking camera, `FOLLOW_DISTANCE` m away, looking down `FOLLOW_ELEVATION`
    degrees, from behind the robot (facing +x) and to its right (`FOLLOW_AZIMUTH` degrees from
    +x); the mouse still turns and zooms it."""
    cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    cam.trackbodyid = body
    cam.distance = FOLLOW_DISTANCE
    cam.elevation = FOLLOW_ELEVATION
    cam.azimuth = FOLLOW_AZIMUTH


def pushed(env, xfrc: jax.Array):
    """A shallow copy of `env` whose physics ticks also apply `xfrc` (nbody, 6) world
    [f (N), tau (N·m)] at each body's COM, added to what the env and its task set."""
    out = copy.copy(env)
    task_physics = env.task_physics

    def with_push(d, t, dist):
        d = task_physics(d, t, dist)
        return d.replace(xfrc_applied=d.xfrc_applied + xfrc)

    out.task_physics = with_push
    return out


def make_live_step(env, policy: Policy):
    """Jitted (state, command (3,), xfrc (nbody, 6), key) -> state: one env step with `command`
    as the velocity command (redraws off), the policy's action and `xfrc` added (`pushed`)."""

    def step(state: State, command: jax.Array, xfrc: jax.Array, key: jax.Array) -> State:
        dist = state.info["dist"]
        never = jp.full_like(dist.command_switch, NEVER)
        dist = dist.replace(command=command.astype(dist.command.dtype), command_switch=never)
        state = state.replace(info={**state.info, "dist": dist})
        action = policy(state.obs[None], key)[0]
        return pushed(env, xfrc).step(state, action)

    return jax.jit(step)


class MousePulls:
    """Logs each mouse pull the viewer applies: the body when it begins; when it is let go, its
    duration (s of simulated time), its peak force (N) and torque (N·m), and how far the body's
    origin moved meanwhile (m, world). `update` is called before every step."""

    def __init__(self, model: mujoco.MjModel, log: Callable[[str], None] = print):
        self.model, self.log = model, log
        self.body: int | None = None  # the body pulled now (None: no pull)
        self._start, self._t0, self._force, self._torque = np.zeros(3), 0.0, 0.0, 0.0

    def update(self, data: mujoco.MjData, xfrc: np.ndarray) -> None:
        """`xfrc` (nbody, 6) world [f (N), tau (N·m)]: what the coming step applies; `data`:
        the state before it (after the last pulled step when a pull has just ended)."""
        strength = np.abs(xfrc).max(axis=1)  # (nbody,)
        if self.body is None and strength.max() > 0:
            self.body = int(strength.argmax())
            self._start, self._t0 = data.xpos[self.body].copy(), float(data.time)
            self._force = self._torque = 0.0
            self.log(f"view: mouse pull on body '{self.model.body(self.body).name}'")
        if self.body is None:
            return
        if strength[self.body] > 0:
            self._force = max(self._force, float(np.linalg.norm(xfrc[self.body, :3])))
            self._torque = max(self._torque, float(np.linalg.norm(xfrc[self.body, 3:])))
            return
        moved = float(np.linalg.norm(data.xpos[self.body] - self._start))
        self.log(
            f"view: pull on '{self.model.body(self.body).name}' let go after "
            f"{float(data.time) - self._t0:.2f} s, peak {self._force:.0f} N and "
            f"{self._torque:.1f} N·m; the body moved {moved:.2f} m"
        )
        self.body = None

    def forget(self) -> None:
        """A new episode: a pull in progress ends unreported (the body was moved by the reset)."""
        self.body = None


class LiveEnv:
    """One env stepped live (`make_live_step`), shown through `data`, an `MjData` of `model`
    (a copy of the env's model, so the viewer's settings never reach the physics)."""

    def __init__(self, env, policy: Policy = zero_policy, seed: int = 0, log=print):
        self.env, self.log = env, log
        self.model = env.model.__copy__()
        self.data = mujoco.MjData(self.model)
        self._reset_fn = jax.jit(env.reset)
        self._step_fn = make_live_step(env, policy)
        self._key = jax.random.PRNGKey(seed)
        self.pulls = MousePulls(self.model, log)
        self.episode = 0
        self.state = self.reset()

    def reset(self) -> State:
        self.state = self._reset_fn(jax.random.fold_in(self._key, self.episode))
        self.episode += 1
        self.pulls.forget()
        self.mirror()
        return self.state

    def step(self, command: np.ndarray, xfrc: np.ndarray, reset: bool = False) -> None:
        if reset:
            self.log(f"view: new episode {self.episode}")
            self.reset()
            return
        self.pulls.update(self.data, xfrc)
        self.state = self._step_fn(self.state, jp.asarray(command), jp.asarray(xfrc), self._key)
        self.mirror()
        if float(self.state.done):
            fell = "fell" if not float(self.state.info["nan_reset"]) else "became unstable"
            self.log(f"view: the robot {fell} at t = {self.data.time:.2f} s; new episode")
            self.reset()

    def mirror(self) -> None:
        """The env's state into `data` (qpos, qvel, time), forwarded for display and for the
        viewer's perturbation (it reads the bodies' poses)."""
        d = self.state.pipeline_state
        self.data.qpos[:] = np.asarray(d.qpos)
        self.data.qvel[:] = np.asarray(d.qvel)
        self.data.time = float(d.time)
        mujoco.mj_forward(self.model, self.data)


def view(
    controller: str = Controller.DPC,
    arm: str | None = None,
    task: str = DEFAULT_TASK,
    export: str | None = None,
    seconds: float | None = None,
    env: dict | None = None,
    seed: int = 0,
) -> LoopStats:
    """Open MuJoCo's viewer on `task` with `arm` (default: the export's arm) under `controller`
    ('mbc', 'observer', 'dpc': the export's policy, default the shipped one; 'oracle') in real
    time, until the window closes (or `seconds` of simulated time). The env runs under the
    export's env options (its policy frame and sensor model, as `dpc-mjx eval`), then `env` over
    them; its random pushes are off and its engine native unless `env` sets push_force or
    engine."""
    require_display()
    controller = Controller.parse(controller)
    art, (arm_spec,), options = export_cells(
        export or SHIPPED, [arm] if arm else None, [controller], task, env
    )
    defaults = {"push_force": (0.0, 0.0), "engine": "native"}  # the mouse is the disturbance
    options |= {k: v for k, v in defaults.items() if k not in (env or {})}
    options["controller"] = controller
    import mujoco.viewer  # noqa: PLC0415 (GLFW, loaded only once a display is known)

    with jax.default_device(jax.devices("cpu")[0]):  # one env: the host beats any accelerator
        live_env = make(task, arm=arm_spec, **options)
        policy = art.dpc_policy(arm_name(arm_spec)) if controller == Controller.DPC else zero_policy
        print(f"view: {controller} on {task}, arm {arm_name(arm_spec)}, compiling ...", flush=True)
        live = LiveEnv(live_env, policy, seed)
        live.step(np.zeros(3, np.float32), np.zeros((live.model.nbody, 6), np.float32))
        keys = KeyCommand.for_config(live_env.config)
        print(f"view: real time, {1e3 * live_env.dt:.0f} ms per step\n{HELP}", flush=True)
        n_steps = None if seconds is None else max(1, round(seconds / live_env.dt))
        with mujoco.viewer.launch_passive(live.model, live.data, key_callback=keys) as viewer:
            with viewer.lock():
                follow(viewer.cam, live_env.lay.trunk)
            stats = run_loop(live.step, viewer, keys, live_env.dt, n_steps)
    print(f"view: {stats.steps} steps, {stats.late} behind real time")
    return stats
