"""The object tasks on any quadruped base: the scene moves with the arm's mount.

`scripts.mount_offset` is (dx, dz) m, the first arm's mount standing on the base minus on the A1;
pushing and carrying add it to their objects and heights, lifting needs none (its ball and raise
are relative to the gripper). Checked: on the A1 the offset is exactly (0, 0) and every scene is
the one the module constants build (the A1's scenes must not move); on go2 and b1 each object
task builds with its default arm, its objects moved by the mount's offset, measured here on the
compiled models, and its IK waypoints the A1's; a few steps of pushing on go2 stay finite.
"""

import functools

import jax
import mujoco
import numpy as np
import pytest
from helpers import fast_jit, model_bytes

from dpc_mjx import make
from dpc_mjx.envs import registry
from dpc_mjx.envs.rollout import run_episodes
from dpc_mjx.envs.tasks import carrying, pushing, scripts
from dpc_mjx.robots import objects
from dpc_mjx.robots.layout import layout
from dpc_mjx.robots.variants import on_base, resolve

OBJECT_TASKS = ("pushing", "carrying", "carrying_high", "lifting")
_EXACT = 1e-12  # m: positions computed the same way from the same numbers
# rad between a waypoint's joint angles on another base and on the A1: go2's mount sits 0.2 mm
# off the trunk's centre line (the scene moves in x and z only), and the IK's soft approach axis
# lets carrying's waypoints settle up to ~0.01 rad apart for it; b1's agree to 1e-6.
_SAME_IK_TOL = 0.02


def _a1_reference(task: str, arm: str) -> mujoco.MjSpec:
    """The A1's scene as the module constants build it, without the mount's offset."""
    robot = resolve(arm)
    spec = objects.robot_scene(robot, registry.task_name(task))
    if task == "pushing":
        return objects.add_box(
            spec, pushing.BOX_POS, pushing.BOX_HALF, pushing.BOX_MASS, pushing.BOX_FRICTION
        )
    height = carrying.TABLE_HEIGHT_HIGH if task == "carrying_high" else carrying.TABLE_HEIGHT
    carrying.add_tables_and_balls(spec, height, n_balls=len(robot.arms))
    for i, arm_ in enumerate(robot.arms):
        offset = objects.grasp_offset(arm_, robot.name, task)
        objects.add_grasp(spec, f"ball{i}", i, offset, active=False)
    return spec


@pytest.mark.parametrize(
    "task, arm",
    [("pushing", "pusher"), ("pushing", "regular"), ("carrying", "regular"),
     ("carrying", "double"), ("carrying_high", "longer")],
)  # fmt: skip
def test_the_a1s_scenes_are_the_module_constants_exactly(task, arm):
    assert scripts.mount_offset(resolve(arm)) == (0.0, 0.0)
    reference = _a1_reference(task, arm)
    assert registry.scene_spec(task, arm).to_xml() == reference.to_xml()
    assert model_bytes(registry.build_scene(task, arm)) == model_bytes(reference.compile())


def test_the_a1_stands_at_the_stand_height_exactly():
    model = registry.build_scene("lifting")
    assert scripts.stand_height(model) == scripts.STAND_HEIGHT
    assert scripts.standing_data(model).qpos[2] == scripts.STAND_HEIGHT


@functools.cache
def _a1_env(task: str):
    return make(task, engine="native")


def _mount(env, key: bool = False) -> np.ndarray:
    """(3,) m, world: the first arm's mount site, standing (`standing_data`) or in the home key."""
    model = env.model
    data = scripts.standing_data(model)
    if key:
        mujoco.mj_resetDataKeyframe(model, data, 0)
        mujoco.mj_kinematics(model, data)
    return data.site_xpos[layout(model).arms[0].mount_site].copy()


def _ball_keys(env) -> np.ndarray:
    """(k, 3) m, world: the balls' centres in the home key."""
    return np.array([env.model.key_qpos[0][b.qpos[:3]] for b in env.props.balls])


@pytest.mark.parametrize("base", ["go2", "b1"])
@pytest.mark.parametrize("task", OBJECT_TASKS)
def test_object_task_scene_moves_with_the_arms_mount(task, base):
    env, a1 = make(task, base=base, engine="native"), _a1_env(task)
    dx, dz = scripts.mount_offset(on_base(resolve(env.DEFAULT_ARM), base))
    moved = _mount(env) - _mount(a1)  # measured on the two scenes
    assert (dx, dz) == pytest.approx((moved[0], moved[2]), abs=_EXACT)
    assert dz > 0.0  # both stand higher than the A1
    shift = np.array([dx, 0.0, dz])
    if task == "pushing":
        box, box_a1 = env.props.box, a1.props.box
        assert env.offset == (dx, dz)
        half, half_a1 = env.model.geom_size[box.geom], a1.model.geom_size[box_a1.geom]
        grown = [dz / 2, 0.0, dz / 2]  # dz taller and dz deeper
        np.testing.assert_allclose(half, half_a1 + grown, atol=_EXACT)
        at, at_a1 = env.model.key_qpos[0][box.qpos[:3]], a1.model.key_qpos[0][box_a1.qpos[:3]]
        near, near_a1 = at[0] - half[0], at_a1[0] - half_a1[0]  # the face the plate meets
        assert near == pytest.approx(near_a1 + dx, abs=_EXACT)
        np.testing.assert_allclose(at[2], at_a1[2] + dz / 2, atol=_EXACT)  # on the floor
    elif task.startswith("carrying"):
        tops = env.props.table_tops
        np.testing.assert_allclose(tops, a1.props.table_tops + shift, atol=_EXACT)
        np.testing.assert_allclose(_ball_keys(env), _ball_keys(a1) + shift, atol=_EXACT)
    else:  # lifting: the ball in the gripper, where the A1's is relative to the mount
        np.testing.assert_allclose(
            _ball_keys(env) - _mount(env, key=True), _ball_keys(a1) - _mount(a1, key=True),
            atol=1e-6,
        )  # fmt: skip
    # the IK solved every waypoint (else `make` raised), and as on the A1
    np.testing.assert_allclose(env.script.q0, a1.script.q0, atol=_SAME_IK_TOL)
    np.testing.assert_allclose(env.script.delta, a1.script.delta, atol=_SAME_IK_TOL)


def test_pushing_on_go2_steps_finite(monkeypatch):
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: 2 envs, 4 steps
    ep = run_episodes(make("pushing", base="go2", engine="native"), 2, 4, seed=0)
    assert not ep["nan"].any() and not ep["fell"].any()
    assert np.isfinite(ep["return"]).all() and np.isfinite(ep["box_dx"]).all()
