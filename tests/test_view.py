"""`dpc-mjx view` (`dpc_mjx/run/view.py`) without a window: the real-time loop driven by a fake
viewer that pushes a body and presses a key, on a tiny fake env (no env compile); the display
check; the key map. The real env under the loop's step, and MuJoCo's real viewer pulled by a
synthetic mouse on a virtual display, are the slow tests at the end."""

import contextlib
import shutil
import subprocess
import sys
import types
from pathlib import Path

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from brax.envs.base import State
from flax import struct

from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.errors import DpcError
from dpc_mjx.robots import build
from dpc_mjx.run import view
from dpc_mjx.run.cli import main
from dpc_mjx.run.render import gl_context

NBODY = 3  # world, trunk, arm link of the fake model
PUSH = np.zeros((NBODY, 6), np.float32)
PUSH[2] = [5.0, -3.0, 0.0, 0.0, 0.0, 0.5]  # N, N·m, world: the mouse pulling the arm link
OWN = np.zeros((NBODY, 6), np.float32)
OWN[2, 2] = -1.0  # N: the env's own force (a payload's weight) on the arm link
DT = 0.02
_FAKE_XML = """<mujoco><worldbody>
  <body name="trunk"><freejoint/><geom size=".1"/>
    <body name="link" pos=".2 0 0"><joint axis="0 1 0"/><geom size=".05"/></body>
  </body></worldbody></mujoco>"""


@struct.dataclass
class FakeData:
    qpos: jax.Array
    qvel: jax.Array
    time: jax.Array
    xfrc_applied: jax.Array  # what the physics tick was handed


@struct.dataclass
class FakeDist:
    command: jax.Array
    command_switch: jax.Array


class FakeEnv:
    """The DpcEnv surface the live loop uses: the forces its physics tick gets are those the
    env sets (OWN) then `task_physics`; the trunk moves at the command's v_x."""

    dt = DT

    def __init__(self):
        self.model = mujoco.MjModel.from_xml_string(_FAKE_XML)

    def task_physics(self, d, t, dist):
        del t, dist
        return d

    def reset(self, rng):
        del rng
        m = self.model
        d = FakeData(
            jp.asarray(m.qpos0, jp.float32), jp.zeros(m.nv), jp.zeros(()), jp.zeros((NBODY, 6))
        )
        info = {"dist": FakeDist(jp.array([0.3, 0.0, 0.0]), jp.zeros(())), "nan_reset": 0.0}
        return State(d, jp.zeros(4), jp.zeros(()), jp.zeros(()), {}, info)

    def step(self, state, action):
        del action
        d, dist = state.pipeline_state, state.info["dist"]
        d = self.task_physics(d.replace(xfrc_applied=jp.asarray(OWN)), d.time, dist)
        d = d.replace(time=d.time + DT, qpos=d.qpos.at[0].add(DT * dist.command[0]))
        return state.replace(pipeline_state=d)


class FakeClock:
    """Wall time that moves only when slept or when a step costs `cost` s."""

    def __init__(self):
        self.t, self.sleeps = 100.0, []

    def __call__(self):
        return self.t

    def sleep(self, s):
        assert s >= 0
        self.sleeps.append(s)
        self.t += s


class FakeViewer:
    """Shows `data`; like the passive viewer, each `sync()` clears data.xfrc_applied and writes
    the mouse's perturbation there. From the 2nd sync on the user pulls the arm link (PUSH);
    before the 3rd step they press Up (the viewer thread's key_callback)."""

    def __init__(self, data, keys):
        self.d, self.keys, self.syncs = data, keys, 0

    def is_running(self):
        return True

    def sync(self):
        self.syncs += 1
        self.d.xfrc_applied[:] = PUSH if self.syncs >= 2 else 0.0
        if self.syncs == 2:
            self.keys(view.KEY_UP)


def _keys(log=None):
    return view.KeyCommand([0.0, -0.2, -0.5], [0.5, 0.2, 0.5], log=log or (lambda s: None))


def test_the_loop_feeds_the_mouse_push_and_the_keys_to_the_env():
    live = view.LiveEnv(FakeEnv(), log=lambda s: None)
    keys, clock = _keys(), FakeClock()
    viewer = FakeViewer(live.data, keys)
    seen = []

    def step(command, xfrc, reset):
        seen.append((command, xfrc.copy()))
        live.step(command, xfrc, reset)
        clock.t += 0.005  # the step costs 5 ms of its 20

    stats = view.run_loop(step, viewer, keys, DT, n_steps=4, clock=clock, sleep=clock.sleep)
    assert stats.steps == 4 and stats.late == 0
    # steps 1-2 saw no push; from step 3 on, the push of the sync before and the Up key
    np.testing.assert_array_equal(seen[1][1], 0.0)
    np.testing.assert_array_equal(seen[2][1], PUSH)
    np.testing.assert_array_equal(seen[1][0], [0.0, 0.0, 0.0])  # the env's own 0.3 is replaced
    np.testing.assert_allclose(seen[2][0], [0.1, 0.0, 0.0])
    state = live.state
    # what the env's physics got: its own force plus the mouse's
    np.testing.assert_allclose(state.pipeline_state.xfrc_applied, OWN + PUSH)
    np.testing.assert_allclose(state.info["dist"].command, [0.1, 0.0, 0.0])
    assert float(state.info["dist"].command_switch) >= view.NEVER  # no redraw of the command
    np.testing.assert_allclose(live.data.qpos[0], 2 * DT * 0.1, rtol=1e-5)  # mirrored, moved
    assert viewer.syncs == 4
    np.testing.assert_allclose(clock.sleeps, [0.015] * 4, atol=1e-9)  # real time: 4 x 20 ms


def test_a_pull_is_reported_when_it_begins_and_when_it_is_let_go():
    lines = []
    live = view.LiveEnv(FakeEnv(), log=lines.append)
    command, none = np.array([0.5, 0.0, 0.0], np.float32), np.zeros_like(PUSH)
    for xfrc in (none, PUSH, PUSH, PUSH, none, none):
        live.step(command, xfrc)
    # 3 steps of 20 ms pulled; the link rode on the trunk, moving at v_x 0.5 m/s: 0.03 m
    assert lines == [
        "view: mouse pull on body 'link'",
        "view: pull on 'link' let go after 0.06 s, peak 6 N and 0.5 N·m; the body moved 0.03 m",
    ]
    live.step(command, PUSH)
    live.reset()  # a new episode ends a pull unreported
    live.step(command, none)
    assert len(lines) == 3 and lines[2] == "view: mouse pull on body 'link'"


def test_the_loop_warns_when_it_falls_behind_and_does_not_rush():
    keys, clock, lines = _keys(), FakeClock(), []
    viewer = FakeViewer(types.SimpleNamespace(xfrc_applied=np.zeros((NBODY, 6))), keys)
    costs = iter([0.005, 0.030, 0.030, 0.005, 0.005])

    def step(command, xfrc, reset):
        clock.t += next(costs)

    stats = view.run_loop(step, viewer, keys, DT, 5, clock, clock.sleep, lines.append)
    assert (stats.steps, stats.late) == (5, 2)
    assert stats.max_lag == pytest.approx(0.010)
    assert len(lines) == 1 and "behind real time" in lines[0]  # once per WARN_EVERY_S
    # after a late step the schedule starts afresh: the next fast steps sleep their 15 ms
    np.testing.assert_allclose(clock.sleeps, [0.015, 0.015, 0.015], atol=1e-9)


def test_the_loop_stops_when_the_window_closes():
    keys = _keys()
    viewer = types.SimpleNamespace(is_running=lambda: False, d=None, sync=lambda: None)
    stats = view.run_loop(lambda *a: pytest.fail("stepped"), viewer, keys, DT)
    assert stats.steps == 0


def test_keys_change_the_command_within_the_trained_ranges():
    lines = []
    keys = _keys(lines.append)
    for key in [view.KEY_UP] * 7 + [view.KEY_LEFT, view.KEY_END, view.KEY_END]:
        keys(key)
    command, reset = keys.take()
    np.testing.assert_allclose(command, [0.5, 0.05, -0.2])  # v_x held at its high 0.5
    assert not reset and "v_x +0.50" in lines[-1]
    keys(ord("A"))  # not a command key: nothing changes, nothing printed
    assert len(lines) == 10
    keys(view.KEY_DOWN)
    keys(view.KEY_DELETE)
    command, reset = keys.take()
    np.testing.assert_allclose(command, [0.4, 0.05, -0.2])
    assert reset and not keys.take()[1]  # a new episode, asked for once
    keys(view.KEY_SPACE)
    np.testing.assert_array_equal(keys.take()[0], 0.0)
    for _ in range(3):
        keys(view.KEY_DOWN)
    assert keys.take()[0][0] == 0.0  # the low of v_x, 0


def test_key_limits_come_from_the_env_config_and_include_zero():
    config = types.SimpleNamespace(
        command_vx=(0.2, 0.5), command_vy=(-0.2, 0.2), command_yaw=(0.1, 0.4)
    )
    keys = view.KeyCommand.for_config(config)
    np.testing.assert_allclose(keys.low, [0.0, -0.2, 0.0])
    np.testing.assert_allclose(keys.high, [0.5, 0.2, 0.4])


def test_pushed_adds_the_force_after_the_task_and_leaves_the_env_alone():
    env = FakeEnv()
    env.task_physics = lambda d, t, dist: d.replace(qvel=d.qvel + 1.0)  # a task's own hook
    d = FakeData(np.zeros(7), np.zeros(7), np.zeros(()), OWN)  # numpy: no JAX op to compile
    out = view.pushed(env, PUSH).task_physics(d, 0.0, None)
    np.testing.assert_allclose(out.xfrc_applied, OWN + PUSH)
    np.testing.assert_allclose(out.qvel, 1.0)  # the task's hook ran too
    np.testing.assert_allclose(env.task_physics(d, 0.0, None).xfrc_applied, OWN)


@pytest.mark.parametrize(
    ("platform", "environ", "mjpython", "problem"),
    [
        ("linux", {}, False, "DISPLAY"),
        ("linux", {"DISPLAY": ""}, False, "DISPLAY"),
        ("linux", {"DISPLAY": ":0"}, False, None),
        ("linux", {"WAYLAND_DISPLAY": "wayland-0"}, False, None),
        ("darwin", {}, False, "mjpython"),
        ("darwin", {}, True, None),
        ("win32", {}, False, None),
    ],
)
def test_display_problem(platform, environ, mjpython, problem):
    found = view.display_problem(platform, environ, mjpython)
    assert found is None if problem is None else problem in found


def test_view_refuses_without_a_display_before_building_anything(monkeypatch, capsys):
    if not view.sys.platform.startswith("linux"):
        pytest.skip("the no-display check of Linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)

    def built(*args, **kwargs):
        pytest.fail("built something before the display check")

    monkeypatch.setattr(view, "export_cells", built)
    monkeypatch.setattr(view, "make", built)
    with pytest.raises(DpcError, match="no display.*dpc-mjx render"):
        view.view(controller="mbc")
    assert main(["view", "--controller", "mbc"]) == 2
    assert "neither DISPLAY nor WAYLAND_DISPLAY" in capsys.readouterr().err


class Built(Exception):
    pass


@pytest.mark.parametrize(
    ("env", "engine", "push_force"),
    [(None, "native", (0.0, 0.0)), ({"engine": "mjx", "push_force": (0, 30)}, "mjx", (0, 30))],
)
def test_view_builds_the_export_arm_natively_without_random_pushes(
    monkeypatch, env, engine, push_force
):
    made = {}

    def fake_make(task, arm, **options):
        made.update(task=task, arm=arm, **options)
        raise Built

    monkeypatch.setattr(view, "require_display", lambda: None)
    monkeypatch.setattr(view, "make", fake_make)
    with pytest.raises(Built):
        view.view(controller="oracle", env=env)
    assert (made["task"], made["arm"]) == (DEFAULT_TASK, "regular")  # the shipped export's arm
    assert (made["engine"], made["controller"]) == (engine, "oracle")
    assert tuple(made["push_force"]) == push_force
    assert made["sensor_delay"] == 1  # the export's own env options, as dpc-mjx eval


@pytest.mark.slow
def test_a_mouse_push_moves_the_real_env():
    """The native reaching env under MBC: a 150 N lateral pull on the trunk for 0.2 s moves it
    sideways, and the keys' command is the env's."""
    env = make(DEFAULT_TASK, arm="regular", controller="mbc", engine="native", push_force=(0, 0))
    live = view.LiveEnv(env, log=lambda s: None)
    trunk = env.model.body("trunk").id
    xfrc = np.zeros((env.model.nbody, 6), np.float32)
    xfrc[trunk, 1] = 150.0  # N, world +y
    command = np.array([0.2, 0.0, 0.0], np.float32)
    start = live.data.qpos[1]
    for _ in range(10):
        live.step(command, xfrc)
    pulled = live.data.qpos[1] - start
    live.reset()
    start = live.data.qpos[1]
    for _ in range(10):
        live.step(command, np.zeros_like(xfrc))
    assert pulled > 0.02 and pulled > 3 * abs(live.data.qpos[1] - start)
    np.testing.assert_allclose(live.state.info["dist"].command, command)


def _body_at_the_centre(model, data, cam, size=48) -> int:
    """The body whose geom the pixel at the centre of `cam`'s picture shows (-1: none), from
    MuJoCo's segmentation rendering (each geom drawn in a colour that encodes its index in the
    scene), headless."""
    ctx = gl_context(size, size)
    ctx.make_current()
    try:
        scene = mujoco.MjvScene(model, maxgeom=2000)
        con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        viewport = mujoco.MjrRect(0, 0, size, size)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, con)
        opt, perturb = mujoco.MjvOption(), mujoco.MjvPerturb()
        mujoco.mjv_updateScene(model, data, opt, perturb, cam, mujoco.mjtCatBit.mjCAT_ALL, scene)
        scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = 1
        scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = 1
        rgb = np.zeros((size, size, 3), np.uint8)
        mujoco.mjr_render(viewport, scene, con)
        mujoco.mjr_readPixels(rgb, None, viewport, con)
        con.free()
    finally:
        ctx.free()
    r, g, b = (int(c) for c in rgb[size // 2, size // 2])
    index = r + 256 * g + 65536 * b - 1  # -1: the background
    if index < 0 or scene.geoms[index].objtype != mujoco.mjtObj.mjOBJ_GEOM:
        return -1
    return int(model.geom_bodyid[scene.geoms[index].objid])


@pytest.mark.parametrize("walked", [0.0, 5.0])
def test_the_camera_follows_the_robot_where_it_walks(walked):
    """`follow` keeps the robot at the centre of the viewer's picture, also after it walked 5 m
    (MuJoCo's default free camera looks at the scene's centre: the floor, by then)."""
    model = build("regular")
    data = mujoco.MjData(model)
    data.qpos[:] = model.key_qpos[0]
    data.qpos[0] += walked  # m along +x
    mujoco.mj_forward(model, data)
    trunk = model.body("trunk").id
    cam = mujoco.MjvCamera()
    view.follow(cam, trunk)
    body = _body_at_the_centre(model, data, cam)
    assert body >= 0 and model.body_rootid[body] == model.body_rootid[trunk], body
    if walked:  # the check can fail: without `follow` the centre shows no part of the robot
        free = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(model, free)
        body = _body_at_the_centre(model, data, free)
        assert body < 0 or model.body_rootid[body] != model.body_rootid[trunk]


class FakeWindow:
    """`launch_passive`'s handle, for `view` end to end: a window open for the steps asked,
    the user pressing Up once and pulling nothing."""

    def __init__(self, model, data, key_callback):
        self.m, self.d, self.key_callback, self.syncs = model, data, key_callback, 0
        self.cam = mujoco.MjvCamera()

    def lock(self):
        return contextlib.nullcontext()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def is_running(self):
        return True

    def sync(self):
        self.syncs += 1
        self.d.xfrc_applied[:] = 0.0
        if self.syncs == 2:
            self.key_callback(view.KEY_UP)


@pytest.mark.slow
def test_view_runs_the_shipped_dpc_live(monkeypatch):
    """`view` as `dpc-mjx view` runs it, the window faked: the shipped export's policy on the
    native engine, the keys' command reaching the env."""
    import mujoco.viewer  # noqa: PLC0415 (GLFW, as in view)

    windows = []
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(view, "require_display", lambda: None)  # any platform
    monkeypatch.setattr(
        mujoco.viewer,
        "launch_passive",
        lambda m, d, key_callback: windows.append(FakeWindow(m, d, key_callback)) or windows[-1],
    )
    stats = view.view(controller="dpc", seconds=0.2)
    assert stats.steps == 10 and windows[0].syncs == 10
    cam = windows[0].cam  # following the trunk
    assert cam.type == mujoco.mjtCamera.mjCAMERA_TRACKING
    assert cam.trackbodyid == windows[0].m.body("trunk").id
    assert windows[0].m.nbody > 10  # the A1 with its arm


@pytest.mark.slow
@pytest.mark.skipif(
    not all(shutil.which(tool) for tool in ("Xvfb", "xdotool")),
    reason="needs the X tools Xvfb and xdotool (apt-get install xvfb xdotool)",
)
def test_a_mouse_pull_in_the_real_viewer_moves_the_robot():
    """MuJoCo's own passive viewer on a virtual display, a synthetic double-click on the trunk and
    a Ctrl + right drag (experiments/view_mouse.py): the pull reaches the env and moves it."""
    root = Path(__file__).resolve().parents[1]
    script = root / "experiments" / "view_mouse.py"
    run = [sys.executable, str(script), "--controller", "mbc", "--display", ":96"]
    out = subprocess.run(run, check=False, cwd=root, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout[-4000:]
    assert "| trunk |" in out.stdout
