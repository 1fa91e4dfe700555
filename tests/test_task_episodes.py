"""Every task draws its episode from the seed, and the measures Table I reads are right.

- the object tasks' episodes differ with the key (script pace, box place, object weights,
  commands) and repeat with the same key; reaching's draws are those of before (its episodes are
  pinned by tests/test_eval_regression.py);
- the desired path is the command integrated (a straight line, an arc, against closed forms);
- the end effector's tracking error is the forward kinematics' (MuJoCo C) to first order;
- an object's added weight reaches the arm as a known wrench (the measured mount force);
- a tally keeps a task measure as it was at the episode's end.

Envs run on the native engine (`engine='native'`): its programs compile in seconds.
"""

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from brax.envs.base import State
from helpers import FAST_COMPILE
from mujoco import mjx

import dpc_mjx
from dpc_mjx.envs import DEFAULT_TASK, base, outcome, rollout
from dpc_mjx.envs.disturbances import GRAVITY, integrate_command

_EPISODES = 4
_PATH_TOL = 0.01  # m, explicit Euler at 20 ms against the exact arc after 3 rad of turning
_FIRST_ORDER_TOL = 0.05  # relative: |J dq| vs the forward kinematics' displacement, |dq| 0.02 rad
_LOAD_TOL = 0.1  # relative: the mean change of the mount force vs the added weight m g
_LOAD = 0.5  # kg added to the lifted ball


@pytest.mark.parametrize(
    "task, arm, n_task",
    [("pushing", "pusher", 4), ("carrying", "regular", 1), ("lifting", "regular", 2)],
)
def test_object_tasks_draw_their_episodes_from_the_seed(task, arm, n_task):
    env = dpc_mjx.make(f"a1_arm/{task}", arm=arm, engine="native")
    reset = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)  # called once
    keys = jax.random.split(jax.random.PRNGKey(0), _EPISODES)
    s = jax.device_get(reset(keys))
    dist = s.info["dist"]
    assert dist.task.shape == (_EPISODES, n_task)
    assert dist.object_load.shape == (_EPISODES, len(env.props.objects))
    for draws in (dist.task[:, 0], dist.object_load[:, 0]):  # pace, the first object's weight
        assert len(np.unique(draws)) == _EPISODES  # 4 episodes, 4 different draws
    lo, hi = env.config.script_rate
    assert np.all((dist.task[:, 0] >= lo) & (dist.task[:, 0] <= hi))
    lo, hi = env.config.object_mass
    assert np.all((dist.object_load >= lo) & (dist.object_load <= hi))
    if task != "carrying":  # carrying stands still
        assert len(np.unique(dist.command[:, 0])) == _EPISODES
    if task == "pushing":  # the box's place and heading, in the initial state
        box = s.pipeline_state.qpos[:, env.props.box.qpos]
        np.testing.assert_allclose(box[:, 0] - pushing_home_x(env), dist.task[:, 1], atol=1e-6)
        assert len(np.unique(box[:, 1])) == _EPISODES
        assert np.all(np.abs(dist.task[:, 1:]) <= np.array(env.config.box_jitter))
    again = jax.device_get(reset(keys))
    np.testing.assert_array_equal(again.info["dist"].task, dist.task)  # same key, same episode
    np.testing.assert_array_equal(again.pipeline_state.qpos, s.pipeline_state.qpos)


def pushing_home_x(env) -> float:
    return float(env.model.key_qpos[0][env.props.box.qpos[0]])


def test_the_desired_path_is_the_command_integrated():
    dt, pose = 0.02, jp.zeros(3)
    for _ in range(50):  # 1 s straight ahead at 0.3 m/s, then 1 s sideways at 0.2 m/s
        pose = integrate_command(pose, jp.array([0.3, 0.0, 0.0]), dt)
    for _ in range(50):
        pose = integrate_command(pose, jp.array([0.0, 0.2, 0.0]), dt)
    np.testing.assert_allclose(pose, [0.3, 0.2, 0.0], atol=1e-6)
    pose, v, w = jp.zeros(3), 0.3, 0.3  # an arc of radius v / w = 1 m for 10 s (3 rad)
    for _ in range(500):
        pose = integrate_command(pose, jp.array([v, 0.0, w]), dt)
    theta, r = 3.0, v / w
    exact = [r * np.sin(theta), r * (1 - np.cos(theta)), theta]
    np.testing.assert_allclose(pose, exact, atol=_PATH_TOL)


@pytest.mark.parametrize("arm", ["regular", "double"])
def test_the_end_effector_error_is_the_forward_kinematics_to_first_order(arm):
    env = dpc_mjx.make(DEFAULT_TASK, arm=arm, engine="native")
    model, lay = env.model, env.lay
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    rng = np.random.default_rng(0)
    dq = rng.choice([-0.02, 0.02], len(lay.arm_act))  # rad (m for a finger: no ee motion)
    qadr = model.jnt_qposadr[model.actuator_trnid[lay.arm_act, 0]]  # each servo's joint
    targets = data.qpos[qadr] + dq
    targets_f32 = jp.asarray(targets, jp.float32)
    got = float(outcome.ee_sq_err(env.mx, lay, mjx.put_data(model, data), targets_f32))
    moved = mujoco.MjData(model)
    moved.qpos[:] = data.qpos
    moved.qpos[qadr] = targets
    mujoco.mj_kinematics(model, moved)
    shift = moved.site_xpos[env.ee_sites] - data.site_xpos[env.ee_sites]  # (k, 3) m
    want = float(np.mean(np.sum(shift**2, axis=1)))
    assert want > 1e-5  # the motion is not lost in the tolerance
    assert got == pytest.approx(want, rel=_FIRST_ORDER_TOL)


def test_an_objects_added_weight_loads_the_arm_by_m_g():
    """The lifted ball (welded in the gripper) weighs `_LOAD` kg more: the arm's mount force on
    the trunk (the oracle's u, measured) changes by m g downward, on average over 0.5 s."""
    mounts = []
    for load in (0.0, _LOAD):
        env = dpc_mjx.make(
            "a1_arm/lifting",
            controller="oracle",
            engine="native",
            object_mass=(load, load),
            push_force=(0.0, 0.0),
        )
        keys = jax.random.split(jax.random.PRNGKey(3), 2)
        s = jax.jit(jax.vmap(env.reset), compiler_options=FAST_COMPILE)(keys)
        action = jp.zeros((2, env.action_size))

        def run(s, _, env=env, action=action):
            s = jax.vmap(env.step)(s, action)
            return s, s.info["privileged"][:, 2]  # u_oracle f_z, N, world

        steps = jax.jit(
            lambda s, run=run: jax.lax.scan(run, s, None, length=25), compiler_options=FAST_COMPILE
        )
        _, f_z = steps(s)
        mounts.append(np.asarray(f_z))
    change = float(np.mean(mounts[1] - mounts[0]))
    assert change == pytest.approx(-_LOAD * GRAVITY, rel=_LOAD_TOL)


def test_a_tally_keeps_the_task_measures_of_the_episodes_end():
    def state(done: float, value: float) -> State:
        metrics = {k: jp.zeros(1) for k in base.METRICS} | {"box_dx": jp.full(1, value)}
        return State(None, jp.zeros((1, 2)), jp.zeros(1), jp.full(1, done), metrics, {})

    tally = rollout.Tally.zeros(1, ("box_dx",))
    for done, value in ((0.0, 0.1), (1.0, 0.2), (0.0, 0.9)):  # ends at the 2nd step
        tally = tally.add(state(done, value))
    assert float(tally.final["box_dx"][0]) == pytest.approx(0.2)
    assert float(tally.length[0]) == 2
