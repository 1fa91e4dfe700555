"""Objects in the task scenes (`robots.objects`, placed by `envs.tasks`): they compile, rest where
they should, touch only what they should; the weld carries a ball in MJX, and a welded ball weighs
on the mount sensor (MuJoCo C, one MJX check)."""

import itertools

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from mujoco import mjx
from mujoco.mjx._src import collision_driver

from dpc_mjx import DpcError, sim
from dpc_mjx.envs import registry
from dpc_mjx.envs.tasks import carrying, lifting
from dpc_mjx.robots import VARIANTS, ArmSpec, build, objects
from dpc_mjx.robots.layout import layout, mount_wrench
from dpc_mjx.robots.standing import home_ctrl, with_leg_servos

_SCENES = [  # (task, arm): the paper's pairings, and the double arm with two balls
    ("reaching", "regular"),
    ("pushing", "pusher"),
    ("carrying", "regular"),
    ("carrying_high", "longer"),
    ("carrying", "double"),
    ("lifting", "regular"),
]
_REST_TOL = 5e-3  # m, object height after 1 s vs resting exactly on its support
_WELD_GAP_TOL = 1e-2  # m, welded ball centre to grasp site
_LIFT_RTOL = 1e-2  # mount force change vs the ball's weight
_G = 9.81


def _build(task: str, arm: str | None = None) -> mujoco.MjModel:
    """Task `task`'s scene alone (robot at the origin), as its module builds it."""
    return registry.build_scene(task, arm)


@pytest.fixture(scope="module", params=_SCENES, ids="-".join)
def scene(request):
    task, arm = request.param
    return task, arm, _build(task, arm)


def _settle(model: mujoco.MjModel, seconds: float, tail: int = 50):
    """Stand on leg servos from the home key for `seconds`; data and the mount force (N, up) of
    all arms averaged over the last `tail` steps."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    data.ctrl[:] = home_ctrl(model)
    arms = layout(model).arms
    n = round(seconds / model.opt.timestep)
    fz = []
    for k in range(n):
        mujoco.mj_step(model, data)
        if k >= n - tail:
            fz.append(-sum(mount_wrench(a, data)[0][2] for a in arms))
    return data, float(np.mean(fz))


def test_scene_compiles_and_loads_into_mjx(scene):
    task, arm, model = scene
    lay, p = layout(model), objects.prop_layout(model)
    assert len(lay.arms) == len(VARIANTS[arm].arms)
    n_balls = {"pushing": 0, "reaching": 0}.get(task, len(lay.arms))
    assert len(p.balls) == len(p.welds) == len(p.grasp_sites) == n_balls
    assert (p.box is not None) == (task == "pushing")
    assert len(p.table_geoms) == (2 if task.startswith("carrying") else 0)
    assert model.nq == 7 + 12 + lay.arm_qpos.size + 7 * len(p.objects)
    np.testing.assert_array_equal(model.eq_active0, [task == "lifting"] * n_balls)
    for obj in p.objects:  # the home key starts every object at its body's initial pose
        np.testing.assert_allclose(model.key_qpos[0][obj.qpos[:3]], model.body_pos[obj.body])
    mx = sim.put_model(model)
    assert mx.neq == n_balls


def test_object_rests_on_its_support():
    for task, arm, support in (("pushing", "pusher", 0.0), ("carrying", "regular", 0.3)):
        model = with_leg_servos(_build(task, arm))
        p = objects.prop_layout(model)
        data, _ = _settle(model, 1.0)
        for obj in p.objects:
            half = model.geom_size[obj.geom][2 if obj is p.box else 0]
            assert data.qpos[obj.qpos[2]] == pytest.approx(support + half, abs=_REST_TOL), task
            assert np.linalg.norm(data.qpos[obj.qpos[:2]] - model.key_qpos[0][obj.qpos[:2]]) < 1e-3
        if p.table_geoms.size:
            assert p.table_tops[:, 2] == pytest.approx(support)


def _label(model: mujoco.MjModel, g: int) -> str:
    return model.geom(g).name or f"{model.body(model.geom_bodyid[g]).name}#{g}"  # gripper boxes


def _mask_pairs(model: mujoco.MjModel) -> set:
    """Geom pairs (by label) whose contype/conaffinity bits allow a contact (other bodies)."""
    ct, ca, body = model.geom_contype, model.geom_conaffinity, model.geom_bodyid
    return {
        (g1, g2)
        for g1, g2 in itertools.combinations(range(model.ngeom), 2)
        if body[g1] != body[g2] and (ct[g1] & ca[g2] or ct[g2] & ca[g1])
    }


def _expected_pairs(task: str, model: mujoco.MjModel) -> set:
    geoms = {model.geom(g).name: g for g in range(model.ngeom) if model.geom(g).name}
    ee = set()
    for arm in layout(model).arms:
        ee_body = model.site_bodyid[arm.ee_site]
        ee |= {g for g in range(model.ngeom) if _in_subtree(model, model.geom_bodyid[g], ee_body)}
    pairs = {("floor", f"{leg}_foot") for leg in ("FR", "FL", "RR", "RL")}
    if task == "pushing":
        pairs |= {("floor", "box")} | {("box", _label(model, g)) for g in ee}
    balls = [n for n in geoms if n.startswith("ball")]
    tables = [n for n in geoms if n.startswith("table") and not n.endswith("pedestal")]
    pairs |= {("floor", b) for b in balls} | {(t, b) for t in tables for b in balls}
    return {tuple(sorted(p)) for p in pairs}


def _in_subtree(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > root:
        body = model.body_parentid[body]
    return body == root


def test_contact_pairs_are_exactly_the_intended_ones(scene):
    task, _, model = scene
    by_masks = {tuple(sorted((_label(model, a), _label(model, b)))) for a, b in _mask_pairs(model)}
    assert by_masks == _expected_pairs(task, model)
    n_balls = len(objects.prop_layout(model).balls)
    n_expected = {"pushing": 4 + 1 + 1, "lifting": 4 + n_balls}.get(task, 4 + 3 * n_balls)
    assert len(by_masks) == n_expected  # feet; box: floor, plate; balls: floor (+ 2 tables)
    # MJX's own list of geom pairs to collide agrees with the masks.
    mjx_pairs = {tuple(sorted((g1, g2))) for g1, g2, _ in collision_driver.geom_pairs(model)}
    assert mjx_pairs == {tuple(sorted(p)) for p in _mask_pairs(model)}


def test_regular_gripper_touches_the_box_with_its_three_boxes():
    model = _build("pushing", "regular")
    box, floor = model.geom("box").id, model.geom("floor").id
    others = [a + b - box for a, b in _mask_pairs(model) if box in (a, b)]
    names = sorted(model.body(model.geom_bodyid[g]).name for g in others if g != floor)
    assert names == ["arm0/finger", "arm0/gripper", "arm0/gripper"]  # finger; palm and jaw


def test_mjx_weld_switched_on_in_jit_carries_the_ball():
    """Env 0: ball put at the grasp site, weld switched on inside the jitted step, robot crouches
    (the gripper drops ~10 cm): the ball follows. Env 1: weld off, the ball stays on the table."""
    model = with_leg_servos(_build("carrying", "regular"))
    p, lay = objects.prop_layout(model), layout(model)
    ball = p.balls[0]
    home = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, home, 0)
    mujoco.mj_kinematics(model, home)
    qpos = np.tile(model.key_qpos[0], (2, 1))
    qpos[0, ball.qpos[:3]] = home.site_xpos[p.grasp_sites[0]]
    ctrl = np.tile(home_ctrl(model), (2, 1))
    ctrl[:, lay.leg_act] = np.tile([0.0, 1.2, -2.3], 4)  # crouch: hip, thigh, calf targets (rad)
    mx = sim.put_model(model)
    data = sim.batched_data(mx, qpos, ctrl)
    assert not np.asarray(data.eq_active).any()  # carrying starts with the welds off

    @jax.jit
    def run(d, active):
        def one(d, a):
            d = objects.set_welds(d, p, a)  # in the jitted function, as an env step would
            d = jax.lax.scan(lambda d, _: (mjx.step(mx, d), None), d, None, length=100)[0]
            return d, objects.grasp_gaps(d, p)

        return jax.vmap(one)(d, active)

    active = jp.array([[True], [False]])
    gaps = []
    for _ in range(3):  # 1.2 s
        data, gap = run(data, active)
        gaps.append(np.asarray(gap))
    gaps = np.concatenate(gaps, axis=1)
    grasp = np.asarray(data.site_xpos[0, p.grasp_sites[0]])
    assert np.asarray(data.eq_active).tolist() == [[True], [False]]
    assert home.site_xpos[p.grasp_sites[0], 2] - grasp[2] > 0.05  # the gripper moved down
    assert (gaps[0] < _WELD_GAP_TOL).all(), gaps[0]
    z = np.asarray(data.qpos[:, ball.qpos[2]])
    assert z[1] == pytest.approx(carrying.TABLE_HEIGHT + objects.BALL_RADIUS, abs=_REST_TOL)
    assert np.isfinite(np.asarray(data.qpos)).all()


@pytest.mark.parametrize("arm", ["regular", "double"])
def test_welded_ball_weighs_on_the_mount_sensor(arm):
    with_ball = with_leg_servos(_build("lifting", arm))
    p = objects.prop_layout(with_ball)
    data, fz = _settle(with_ball, 1.5)
    _, fz0 = _settle(with_leg_servos(build(arm)), 1.5)
    ball_weight = lifting.BALL_MASS * _G * len(p.balls)
    assert fz - fz0 == pytest.approx(ball_weight, rel=_LIFT_RTOL)
    gaps = np.linalg.norm(data.site_xpos[p.grasp_sites] - data.site_xpos[p.ball_sites], axis=1)
    assert (gaps < _WELD_GAP_TOL).all()


def test_pusher_has_a_heavy_plate_and_four_joints():
    model = build("pusher")
    arm = layout(model).arms[0]
    assert arm.act.size == 4
    assert model.body_subtreemass[model.body("arm0/gripper").id] == pytest.approx(0.5)
    ee_body = model.site_bodyid[arm.ee_site]
    assert model.geom("arm0/plate").bodyid[0] == ee_body


def test_unknown_task_and_bad_pairings_raise():
    with pytest.raises(DpcError, match="known tasks: .*carrying"):
        _build("juggling")
    with pytest.raises(DpcError, match="gripper arm"):
        _build("carrying", "pusher")
    with pytest.raises(DpcError, match="needs an arm"):
        _build("pushing", "none")
    with pytest.raises(DpcError, match="ee_shape"):
        build(ArmSpec(ee_shape="spoon"))
    with pytest.raises(DpcError, match="n_balls"):
        carrying.add_tables_and_balls(mujoco.MjSpec(), n_balls=3)
