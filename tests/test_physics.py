"""The native MuJoCo engine (`dpc_mjx.physics`): what it hands back equals MuJoCo C's own
mj_step / mj_forward, and bit for bit the engine's former loop over one MjData (`_loop`, kept
here as the reference); an unstable step or one in which MuJoCo raises comes back as NaN; under
the env, MJX and MuJoCo C agree on a short episode (the engines' contact models differ, so only
to a tolerance)."""

import json
import pathlib
from csv import DictReader

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import fast_jit
from mujoco import mjx

import dpc_mjx
from dpc_mjx import sim
from dpc_mjx.envs import DEFAULT_TASK
from dpc_mjx.envs.registry import get_config
from dpc_mjx.errors import DpcError
from dpc_mjx.physics import (
    _BAD_STATE,
    AUTO,
    INPUTS,
    OUTPUTS,
    NativePhysics,
    make_physics,
    resolve_engine,
)
from dpc_mjx.robots import build
from dpc_mjx.run.cli import main
from dpc_mjx.run.eval import evaluate

# float32 round trip of the inputs and outputs (the env's dtype) against MuJoCo in float64
FLOAT32_TOL = 1e-5
# MJX vs MuJoCo C, the same episode, 0.2-2 s: their contact solvers differ, so the robots drift
# apart by ~1e-3 rad and the returns by ~1e-4 of their value; a wrong field or frame would tip
# the robot over or change the return by far more.
ENGINE_RETURN_TOL = 0.01  # relative


@pytest.fixture(scope="module")
def model():
    return build("regular")


def _batch(model, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """`n` states near the home keyframe with random ctrl offsets and a push on the trunk."""
    rng = np.random.default_rng(seed)
    qpos = np.tile(model.key_qpos[0], (n, 1))
    qpos[:, 7:] += rng.uniform(-0.1, 0.1, (n, model.nq - 7))
    qvel = rng.normal(0, 0.2, (n, model.nv))
    ctrl = np.tile(model.key_ctrl[0], (n, 1)) + rng.normal(0, 0.5, (n, model.nu))
    xfrc = np.zeros((n, model.nbody, 6))
    xfrc[:, 1, :3] = rng.normal(0, 20.0, (n, 3))
    return {"qpos": qpos, "qvel": qvel, "ctrl": ctrl, "xfrc_applied": xfrc}


def _reference(model, state: dict, i: int, advance: bool) -> mujoco.MjData:
    d = mujoco.MjData(model)
    d.qpos[:] = np.float32(state["qpos"][i])
    d.qvel[:] = np.float32(state["qvel"][i])
    d.ctrl[:] = np.float32(state["ctrl"][i])
    d.xfrc_applied[:] = np.float32(state["xfrc_applied"][i])
    (mujoco.mj_step if advance else mujoco.mj_forward)(model, d)
    return d


@pytest.mark.parametrize("advance", [True, False], ids=["step", "forward"])
def test_native_engine_equals_mujoco_c(model, advance):
    """Every field the engine hands back, for a batch split over 2 threads under jit(vmap),
    equals a fresh MjData stepped by MuJoCo C from the same inputs."""
    n = 5
    state = _batch(model, n)
    physics = NativePhysics(model, threads=2)
    d0 = mjx.make_data(sim.put_model(model))
    batch = jax.vmap(lambda q, v, u, x: d0.replace(qpos=q, qvel=v, ctrl=u, xfrc_applied=x))(
        *(jp.asarray(state[k], jp.float32) for k in ("qpos", "qvel", "ctrl", "xfrc_applied"))
    )
    fn = physics.step if advance else physics.forward
    out = jax.device_get(jax.jit(jax.vmap(fn))(batch))
    for i in range(n):
        ref = _reference(model, state, i, advance)
        for k in OUTPUTS:
            want = np.reshape(getattr(ref, k), np.shape(getattr(out, k))[1:])
            got = np.asarray(getattr(out, k)[i], np.float64)
            scale = max(1.0, float(np.max(np.abs(want))))
            assert np.max(np.abs(got - want)) <= FLOAT32_TOL * scale, (k, i)
    if advance:  # the state moved on
        assert np.all(out.time > 0)


def _loop(model, advance: bool, x: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The native engine before `mujoco.batch` (the reference): `INPUTS` `x` (each (n, ...), the
    env's dtypes) -> `OUTPUTS` (n, ...) through one MjData, env after env, in Python."""
    template = mjx.make_data(model, impl="jax")
    n = len(x["qpos"])
    out = {
        k: np.empty((n, *getattr(template, k).shape), getattr(template, k).dtype) for k in OUTPUTS
    }
    d = mujoco.MjData(model)
    for i in range(n):
        d.time = x["time"][i]
        for k in INPUTS[1:]:
            getattr(d, k)[:] = x[k][i]
        for w in _BAD_STATE:
            d.warning[w].number = 0
        (mujoco.mj_step if advance else mujoco.mj_forward)(model, d)
        for k in OUTPUTS:
            out[k][i] = np.reshape(getattr(d, k), out[k].shape[1:])
        if any(d.warning[w].number > 0 for w in _BAD_STATE):
            out["qpos"][i] = out["qvel"][i] = np.nan
    return out


def _inputs(model, n: int) -> dict[str, np.ndarray]:
    """`INPUTS` for `n` envs as the env holds them (float32, eq_active bool): `_batch`'s states
    at random times and warm starts; env 2 so fast that MuJoCo flags its step as unstable."""
    rng = np.random.default_rng(1)
    x = {
        **_batch(model, n),
        "time": rng.uniform(0, 2, n),
        "qacc_warmstart": rng.normal(0, 5, (n, model.nv)),
        "eq_active": np.zeros((n, model.neq), bool),
    }
    x["qvel"][2] = 1e12
    template = mjx.make_data(model, impl="jax")
    return {k: np.asarray(x[k], getattr(template, k).dtype) for k in INPUTS}


def _engine(physics, advance: bool, x: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`OUTPUTS` of the engine under vmap (`vmap_method="broadcast_all"`: one call for the whole
    batch) for `INPUTS` `x`, each (n, ...); only the outputs, so nothing is broadcast."""
    d0 = mjx.make_data(physics.model, impl="jax")

    def one(*inputs):
        d = d0.replace(**dict(zip(INPUTS, inputs, strict=True)))
        d = physics.step(d) if advance else physics.forward(d)
        return {k: getattr(d, k) for k in OUTPUTS}

    return jax.device_get(jax.vmap(one)(*(x[k] for k in INPUTS)))


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("advance", [True, False], ids=["step", "forward"])
def test_native_engine_equals_its_former_loop_bit_for_bit(
    model, advance, threads, monkeypatch, tmp_path
):
    """vmap of the engine over a batch (an unstable env among them), three ticks in a row
    (each from the last one's state): every output equals the former loop's exactly, the
    unstable env's too (NaN after a step; as MuJoCo computed it after a forward)."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warning to MUJOCO_LOG.TXT here
    physics = NativePhysics(model, threads=threads)
    x = _inputs(model, 5)
    for _ in range(3):
        out, want = _engine(physics, advance, x), _loop(model, advance, x)
        for k in OUTPUTS:
            np.testing.assert_array_equal(out[k], want[k], err_msg=k)
        assert np.isfinite(want["qpos"][[0, 1, 3, 4]]).all()
        if advance:  # the unstable step: NaN
            assert np.isnan(want["qpos"][2]).all() and np.isnan(want["qvel"][2]).all()
        else:  # mj_forward checks and resets nothing
            assert np.all(want["qvel"][2] == np.float32(1e12))
        x = {**x, **{k: out[k] for k in ("time", "qpos", "qvel", "qacc_warmstart")}}


def test_a_sim_in_which_mujoco_raises_comes_back_as_nan(monkeypatch, tmp_path):
    """Twenty boxes piled into one spot overflow a small arena: MuJoCo raises in that sim
    (`mujoco.batch.SimulationError`), which comes back as NaN with a warning; the other sim of
    the batch runs as the former loop runs it."""
    monkeypatch.chdir(tmp_path)
    boxes = "".join(
        f'<body pos="{i} 0 1"><freejoint/><geom type="box" size=".1 .1 .1"/></body>'
        for i in range(20)
    )
    model = mujoco.MjModel.from_xml_string(
        f'<mujoco><size memory="20K"/><worldbody><geom type="plane" size="50 50 .1"/>{boxes}'
        "</worldbody></mujoco>"
    )
    d0 = mjx.make_data(model, impl="jax")
    qpos = np.tile(np.asarray(d0.qpos), (2, 1))
    qpos[1, 0::7], qpos[1, 2::7] = 0.0, 0.05  # sim 1: every box at the origin, in the floor
    x = {k: np.tile(np.asarray(getattr(d0, k)), (2,) + (1,) * getattr(d0, k).ndim) for k in INPUTS}
    x["qpos"] = qpos.astype(np.float32)
    physics = NativePhysics(model)
    with pytest.warns(RuntimeWarning, match="stack overflow"):
        out = _engine(physics, True, x)
    assert np.isnan(out["qpos"][1]).all() and np.isnan(out["qvel"][1]).all()
    want = _loop(model, True, {k: v[:1] for k, v in x.items()})
    for k in OUTPUTS:
        np.testing.assert_array_equal(out[k][:1], want[k], err_msg=k)


def test_unstable_step_comes_back_as_nan(model, monkeypatch, tmp_path):
    """MuJoCo resets the data to qpos0 on a huge velocity; the engine reports NaN instead, which
    the env's NaN guard turns into a reset of that env."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warning to MUJOCO_LOG.TXT here
    physics = NativePhysics(model, threads=1)
    d = mjx.make_data(sim.put_model(model))
    d = d.replace(qpos=jp.asarray(model.key_qpos[0], jp.float32), qvel=jp.full(model.nv, 1e12))
    out = jax.jit(physics.step)(d)
    assert np.all(np.isnan(np.asarray(out.qpos)))
    assert np.all(np.isnan(np.asarray(out.qvel)))


def test_native_engine_reproduces_the_mjx_recording():
    """The reaching env (MBC, exact sensors) under MuJoCo C, 4 episodes of 2 s from seed 4242:
    the episodes of the MJX recording `tests/data/eval_regression.json` (test_eval_regression),
    to the engines' contact differences (`ENGINE_RETURN_TOL`), and not bit for bit."""
    recording = json.loads(
        (pathlib.Path(__file__).parent / "data" / "eval_regression.json").read_text()
    )
    assert (recording["seed"], recording["episodes"], recording["steps"]) == (4242, 4, 100)
    mbc = recording["per_episode"]["mbc"]
    overrides = {"sensor_noise": 0.0, "sensor_delay": 0, "engine": "native"}
    (cell,) = evaluate(["regular"], ["mbc"], episodes=4, steps=100, seed=4242, overrides=overrides)
    ret = cell.per_episode["return"]
    np.testing.assert_allclose(ret, mbc["return"], rtol=ENGINE_RETURN_TOL)
    assert np.all(cell.per_episode["fell"] == np.asarray(mbc["fell"], bool))
    assert not np.array_equal(ret, np.asarray(mbc["return"], np.float32))  # another engine


def test_engine_flags_that_contradict_each_other_fail_before_anything_runs(capsys):
    assert main(["eval", "--engine", "native", "--env", "engine=mjx"]) == 2
    assert "--engine native and --env engine=mjx disagree" in capsys.readouterr().err
    assert main(["sim2sim", "--env", "engine=native"]) == 2
    assert "sim2sim runs both engines itself" in capsys.readouterr().err


@pytest.mark.slow
def test_sim2sim_runs_both_engines_on_the_same_episodes(monkeypatch, tmp_path, capsys):
    """`dpc-mjx sim2sim` (MBC, exact sensors, 2 episodes of 0.2 s): both engines' rows, the
    paired native - MJX row, and per episode the same robot under both engines, to their
    contact differences (`ENGINE_RETURN_TOL`)."""
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: 10 steps of each env
    out, csv = tmp_path / "s2s.md", tmp_path / "s2s.csv"
    args = ["sim2sim", "--controllers", "mbc", "--episodes", "2", "--steps", "10", "--seed", "4"]
    args += ["--env", "sensor_noise=0", "sensor_delay=0", "--out", str(out), "--csv", str(csv)]
    assert main(args) == 0
    table = out.read_text()
    for engine in ("mjx", "native"):
        assert f"| regular | mbc | {engine} | 0.00 [" in table
    assert "| regular mbc: native - mjx |" in table
    rows = list(DictReader(csv.open()))
    assert [r["engine"] for r in rows] == ["mjx", "mjx", "native", "native"]
    ret = {(r["engine"], r["episode"]): float(r["return"]) for r in rows}
    for episode in ("0", "1"):
        mjx_ret, native_ret = ret["mjx", episode], ret["native", episode]
        assert abs(native_ret - mjx_ret) < ENGINE_RETURN_TOL * abs(mjx_ret)
        assert native_ret != mjx_ret  # two engines, not one twice
    assert "per-episode rows" in capsys.readouterr().out


def test_engine_errors(model):
    with pytest.raises(DpcError, match="engine='bullet' is not valid"):
        dpc_mjx.make(DEFAULT_TASK, engine="bullet")
    with pytest.raises(DpcError, match="engine='bullet' is not valid"):
        make_physics("bullet", model, None)
    spec = mujoco.MjSpec()
    spec.worldbody.add_body(name="target", mocap=True).add_geom(size=[0.1, 0, 0])
    with pytest.raises(DpcError, match="threads >= 1"):
        NativePhysics(model, threads=0)
    with pytest.raises(DpcError, match="mocap bodies"):
        NativePhysics(spec.compile())


def test_the_default_engine_is_native_on_one_cpu_device_and_mjx_elsewhere(model, monkeypatch):
    """'auto' (`EnvConfig`'s default): native MuJoCo C on this one-device CPU, and the built env's
    config names it; MJX on an accelerator, over several devices, or for a model whose state the
    native engine does not copy (mocap bodies)."""
    assert get_config(DEFAULT_TASK).engine == AUTO
    env = dpc_mjx.make(DEFAULT_TASK, arm="none")  # builds, compiles nothing
    assert env.config.engine == "native" and isinstance(env.physics, NativePhysics)
    assert dpc_mjx.make(DEFAULT_TASK, arm="none", engine="mjx").config.engine == "mjx"
    spec = mujoco.MjSpec()
    spec.worldbody.add_body(name="target", mocap=True).add_geom(size=[0.1, 0, 0])
    assert (resolve_engine(AUTO, model), resolve_engine(AUTO, spec.compile())) == ("native", "mjx")
    monkeypatch.setattr(jax, "device_count", lambda: 2)
    assert resolve_engine(AUTO, model) == "mjx"
    monkeypatch.setattr(jax, "device_count", lambda: 1)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert resolve_engine(AUTO, model) == "mjx" and resolve_engine("native") == "native"
    with pytest.raises(DpcError, match="engine='bullet' is not valid"):
        resolve_engine("bullet")
