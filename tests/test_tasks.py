"""The object tasks (pushing, carrying, lifting) as DPC envs: every task with its default arm and
the paper's alternates resets and steps finitely, the scripts do what they say on the nominal
episode (the box moves, the weld grasps and releases the ball on the target table, the lifted
ball stays in the gripper), and unsuitable arms fail before anything is built (batch 2).

Compile time dominates (30-70 s per env on a busy 2-core CPU), so every env is compiled once
(module-scoped fixtures), mostly with XLA's backend optimisation off (`FAST_COMPILE`: about 40%
shorter compiles but ~10x slower steps; a test-only choice, not used for carrying's 450 steps).
The pushing, carrying and lifting envs with their default arms go through `wrap_for_training`
(and are traced once); `carrying_high` and the alternates through one jitted reset + two steps
each, and reaching with `longer` and `heavier` (the structure of `regular`, which test_envs.py
steps) through a jitted reset only (all marked slow, with tests/test_matrix.py: `make test-all`).
"""

import functools

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import ENGINE, FAST_COMPILE, CountTraces, recorded_compiles

import dpc_mjx
from dpc_mjx import DpcError
from dpc_mjx.envs import DEFAULT_TASK, base, registry, wrap_for_training
from dpc_mjx.envs.tasks import carrying, pushing, scripts
from dpc_mjx.robots import objects

_BATCH = 2
_DEFAULTS = {  # task -> default arm (each env class's DEFAULT_ARM)
    "pushing": "pusher",
    "carrying": "regular",
    "carrying_high": "longer",
    "lifting": "regular",
}
_WRAPPED = ("pushing", "carrying", "lifting")  # default arms, through the training wrappers
_STEPPED = [  # (task, arm) reset + two steps (reaching's regular, none, double: test_envs.py)
    ("carrying_high", "longer"),
    ("carrying", "double"),
    ("lifting", "heavier"),
]
_RESET_ONLY = [("reaching", "longer"), ("reaching", "heavier")]
# The scripts' mechanics are checked on each task's nominal episode: no pushes, no added
# weight, the script at its own pace, the box at its place, the command at its middle (the
# draws around it: tests/test_task_episodes.py).
_NOMINAL = {"push_force": (0.0, 0.0), "object_mass": (0.0, 0.0), "script_rate": (1.0, 1.0)}
_NOMINAL_TASK = {
    "pushing": {"command_vx": (0.2, 0.2), "box_jitter": (0.0, 0.0, 0.0)},
    "carrying": {},
    "lifting": {"command_vx": (0.3, 0.3), "lift_gain": (1.0, 1.0)},
}
_TASK_METRICS = {
    "pushing": {"box_dx", "box_turn", "box_target_dist"},
    "carrying": {"ball_target_dist", "ball_on_target", "grasped"},
    "carrying_high": {"ball_target_dist", "ball_on_target", "grasped"},
    "lifting": {"ball_gap"},
    "reaching": set(),
}
_BOX_MOVED = 0.02  # m, box displacement after 2 s of walking
# rad: a cube tilted about an edge past 45 deg falls over; below it, it may rock while pushed (the
# plate meets it at ~0.17 m, near the 0.2 m where a push against friction 0.5 would tip it)
_BOX_TIPPED = np.radians(45.0)
_BALL_IN_GRIPPER = 0.02  # m, lifted ball centre to grasp site
_BALL_PLACED = 0.03  # m, ball centre to its rest point on the target table, 1 s after release
_IK_CHECK_TOL = 2 * scripts.IK_TOL  # m, a waypoint's forward kinematics vs its target


def _keys(seed=0):
    return jax.random.split(jax.random.PRNGKey(seed), _BATCH)


def _finite(tree) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(x)))) for x in jax.tree.leaves(tree))


class _Wrapped:
    """A default-arm env behind the training wrappers: jitted reset and step, three steps."""

    def __init__(self, task: str):
        # no arm: the task's default; its nominal episode
        self.env = dpc_mjx.make(f"a1_arm/{task}", engine=ENGINE, **_NOMINAL, **_NOMINAL_TASK[task])
        self.counted = CountTraces(self.env)
        wrapped = wrap_for_training(self.counted)
        options = None if task == "carrying" else FAST_COMPILE  # carrying runs 450 steps
        self.step = jax.jit(wrapped.step, compiler_options=options)
        reset = jax.jit(wrapped.reset, compiler_options=FAST_COMPILE)
        self.action = jp.zeros((_BATCH, self.env.action_size))
        self.states = [reset(_keys())]
        for _ in range(3):
            self.states.append(self.step(self.states[-1], self.action))

    def run_until(self, t: float):
        """Step on from the last state to physics time t (s); per-step metrics (steps, B)."""
        s, metrics = self.states[-1], []
        for _ in range(round((t - float(s.pipeline_state.time[0])) / self.env.dt)):
            s = self.step(s, self.action)
            metrics.append(s.metrics)
        self.states.append(s)
        return jax.device_get(jax.tree.map(lambda *m: jp.stack(m), *metrics))


@pytest.fixture(scope="module")
def wrapped():
    cache = {}

    def get(task):
        if task not in cache:
            cache[task] = _Wrapped(task)
        return cache[task]

    return get


def _check(task, env, states):
    lay = env.obs_layout
    n_arm = 2 * len(env.lay.arm_dof) + len(env.lay.arm_act)
    assert env.observation_size == lay.size == 11 + n_arm + 6  # [s_body, s_arm, p_arm, u_obs]
    for s in jax.device_get(states):
        assert s.obs.shape == (_BATCH, env.observation_size)
        assert set(s.metrics) >= set(base.METRICS) | _TASK_METRICS[task]
        assert set(s.metrics) == set(jax.device_get(states[0]).metrics)  # same keys every step
        assert _finite((s.obs, s.reward, s.done, s.metrics, s.info["privileged"]))
        assert _finite((s.pipeline_state.qpos, s.pipeline_state.qvel))
        if env.props.objects:
            assert s.info["objects"].shape == (_BATCH, len(env.props.objects), 3)
    assert np.all(jax.device_get(states[-1]).done == 0)


@pytest.mark.parametrize("task", _WRAPPED)
def test_default_arm_resets_and_steps_through_the_training_wrappers(wrapped, task):
    w = wrapped(task)
    assert w.env.model.nu == dpc_mjx.robots.build(_DEFAULTS[task]).nu  # the default arm
    _check(task, w.env, w.states)
    assert w.counted.traces == 1  # reset, then 3 steps of one jitted wrapped step


@pytest.mark.slow  # ~1 min of compile each on 2 cores; `make test-all`
@pytest.mark.parametrize("task, arm", _STEPPED, ids=[f"{t}-{a}" for t, a in _STEPPED])
def test_other_arms_reset_and_step(task, arm):
    env = dpc_mjx.make(f"a1_arm/{task}", arm=arm)
    vstep = jax.vmap(env.step)
    action = jp.zeros((_BATCH, env.action_size))

    @functools.partial(jax.jit, compiler_options=FAST_COMPILE)
    def reset_and_step(keys):
        s0 = jax.vmap(env.reset)(keys)
        return s0, jax.lax.scan(lambda s, _: (vstep(s, action), None), s0, None, length=2)[0]

    states = reset_and_step(_keys(1))
    _check(task, env, states)
    if arm == "double":
        assert len(env.props.balls) == len(env.props.welds) == 2


@pytest.mark.slow  # ~35 s of compile each; `make test-all`
@pytest.mark.parametrize("task, arm", _RESET_ONLY, ids=[f"{t}-{a}" for t, a in _RESET_ONLY])
def test_reaching_arms_reset(task, arm):
    env = dpc_mjx.make(f"a1_arm/{task}", arm=arm)
    reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)
    s = reset(_keys(2))
    _check(task, env, [s])


def test_pushing_moves_the_box_forward(wrapped):
    w = wrapped("pushing")
    m = w.run_until(2.0)  # walking at 0.2 m/s; the plate meets the box after about 1.5 s
    assert np.all(m["box_dx"][-1] > _BOX_MOVED), m["box_dx"][-1]
    assert np.all(m["box_target_dist"][-1] < 0.8 - _BOX_MOVED)  # closer to the target point
    quat = jax.device_get(w.states[-1].pipeline_state.qpos)[:, w.env.props.box.qpos[3:]]
    tilt = np.arccos(np.clip(1 - 2 * (quat[:, 1] ** 2 + quat[:, 2] ** 2), -1, 1))  # (B,) rad
    assert np.all(tilt < _BOX_TIPPED), np.degrees(tilt)  # pushed along, not tipped over
    assert not m["fall"].any() and not m["nan_resets"].any()


def test_carrying_grasps_carries_and_releases_the_ball(wrapped):
    w = wrapped("carrying")
    env = w.env
    m = w.run_until(env.t_lift)  # reach, descend, close: the weld must be on by now
    d = jax.device_get(w.states[-1].pipeline_state)
    assert np.all(d.eq_active[:, env.props.welds])
    assert np.all(m["grasped"][-1] == 1) and not m["grasped"][0].any()
    gaps = np.linalg.norm(
        d.site_xpos[:, env.props.grasp_sites] - d.site_xpos[:, env.props.ball_sites], axis=-1
    )
    assert np.all(gaps < 0.01)
    m = w.run_until(env.t_release + 1.0)  # lift, swing, lower, release, land
    d = jax.device_get(w.states[-1].pipeline_state)
    assert not np.any(d.eq_active[:, env.props.welds])
    assert np.all(m["ball_on_target"][-1] == 1), m["ball_target_dist"][-1]
    # The released ball keeps rolling ~1 cm/s (`objects.BALL_FRICTION`'s rolling term is too low).
    assert np.all(m["ball_target_dist"][-1] < _BALL_PLACED)
    assert not m["fall"].any() and not m["nan_resets"].any()


def test_lifted_ball_stays_in_the_gripper_while_walking(wrapped):
    w = wrapped("lifting")
    m = w.run_until(3.0)  # up (1 s), hold, down (1 s) while walking at 0.3 m/s
    assert np.max(m["ball_gap"]) < _BALL_IN_GRIPPER
    s = jax.device_get(w.states[-1])
    assert np.all(s.pipeline_state.qpos[:, 0] > 0.6)  # walked
    assert not m["fall"].any() and not m["nan_resets"].any()


def test_carrying_waypoints_put_the_gripper_at_the_ball():
    """The IK against MuJoCo C forward kinematics: at the grasp waypoint, the grasp site is at the
    ball (the robot standing level at its start); the script is smooth and starts at home."""
    env = dpc_mjx.make("a1_arm/carrying", arm="double")
    data = scripts.standing_data(env.model, env.config.robot_x)
    grasp = np.asarray(env.script.targets(jp.float32(env.t_close)))
    data.qpos[env.lay.arm_qpos] = grasp
    mujoco.mj_kinematics(env.model, data)
    balls = env.model.key_qpos[0][np.array([b.qpos[:3] for b in env.props.balls])]
    sites = data.site_xpos[env.props.grasp_sites]
    assert np.linalg.norm(sites - balls, axis=1).max() < _IK_CHECK_TOL
    home = env.model.key_ctrl[0][env.lay.arm_act]
    np.testing.assert_allclose(env.script.targets(jp.float32(0.0)), home, atol=1e-6)
    t = np.arange(0.0, env.script.end + 1.0, 0.004, dtype=np.float32)
    targets = np.asarray(jax.vmap(env.script.targets)(t))
    assert np.max(np.abs(np.diff(targets, axis=0))) < 0.02  # rad per 4 ms: no jumps
    np.testing.assert_allclose(targets[-1], home, atol=1e-6)  # back home at the end


def test_pushing_pose_meets_the_box_below_its_top():
    env = dpc_mjx.make("a1_arm/pushing")
    data = scripts.standing_data(env.model)
    data.qpos[env.lay.arm_qpos] = env.pose
    mujoco.mj_kinematics(env.model, data)
    ee = data.site_xpos[env.lay.arms[0].ee_site]
    np.testing.assert_allclose(
        ee, [pushing.PUSH_REACH, 0.0, pushing.PUSH_HEIGHT], atol=_IK_CHECK_TOL
    )
    assert pushing.PUSH_HEIGHT < 2 * pushing.BOX_HALF[2]


def test_unsuitable_arms_fail_before_anything_is_built(monkeypatch):
    def no_build(*_):
        pytest.fail("the scene was built before the arm was checked")

    monkeypatch.setattr(objects, "robot_scene", no_build)  # every object task's scene starts here
    monkeypatch.setattr(base, "build", no_build)
    with recorded_compiles() as compiles:
        for task, arm, match in (
            ("carrying", "pusher", "gripper arm"),
            ("carrying_high", "pusher", "gripper arm"),
            ("lifting", "pusher", "gripper arm"),
            ("carrying", "none", "needs an arm"),
            ("pushing", "none", "needs an arm"),
            ("lifting", "so100", "URDF arm"),
            ("pushing", "regularr", "known variants"),
        ):
            with pytest.raises(DpcError, match=match):
                dpc_mjx.make(f"a1_arm/{task}", arm=arm)
        with pytest.raises(DpcError, match="grasp_threshold"):
            dpc_mjx.make("a1_arm/carrying", grasp_threshold=0.0)
        with pytest.raises(DpcError, match="command_after"):
            dpc_mjx.make("a1_arm/lifting", command_after=(0.3, 0.0))
        for task, option, value in (  # each episode's draws: ranges that cannot be
            ("pushing", "box_jitter", (0.2, 0.0, 0.0)),  # the plate would miss the box
            ("pushing", "box_jitter", (0.05, 0.03)),
            ("lifting", "lift_gain", (0.5, 2.0)),
            ("carrying", "object_mass", (-0.5, 0.5)),
            ("carrying", "script_rate", (0.0, 1.0)),
        ):
            with pytest.raises(DpcError, match=option):
                dpc_mjx.make(f"a1_arm/{task}", **{option: value})
    assert compiles == []


def test_registry_names_and_configs():
    assert registry.known_tasks() == [
        "carrying",
        "carrying_high",
        "lifting",
        "pushing",
        DEFAULT_TASK,
    ]
    for task, arm in {**_DEFAULTS, "reaching": "regular"}.items():
        assert registry.default_arm(task) == arm
    cfg = registry.get_config("carrying_high", grasp_threshold=0.02)
    assert isinstance(cfg, carrying.CarryingConfig) and cfg.grasp_threshold == 0.02
    assert registry.get_config("pushing").push_force == pushing.PUSHES


def test_the_controller_models_the_bare_a1_on_every_scene():
    """The controller's model (A1 mass, COM offset, inertia) is the robot's own tree without its
    arms, whatever the scene holds: a task's box, balls and tables are not part of the robot
    (before this was fixed, pushing's 1 kg box added 1 kg and moved the COM 4.8 cm forward)."""
    bare = dpc_mjx.make(DEFAULT_TASK, arm="none").controller.idx
    for task, arm in (*_DEFAULTS.items(), ("carrying", "double")):
        idx = dpc_mjx.make(f"a1_arm/{task}", arm=arm).controller.idx
        assert idx.base_mass == pytest.approx(bare.base_mass, rel=1e-9), task
        np.testing.assert_allclose(idx.com_offset, bare.com_offset, atol=1e-9, err_msg=task)
        np.testing.assert_allclose(idx.base_inertia, bare.base_inertia, atol=1e-9, err_msg=task)
