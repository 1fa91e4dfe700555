"""Artefact I/O: export/load round trip, numpy inference, failure messages, SAC checkpoints.

Fast: no env and no MJX; random-initialised float32 networks with random normaliser statistics.
"""

import dataclasses
import json
import math
import pathlib
import shutil
import subprocess
import sys
import types

import jax
import jax.numpy as jp
import numpy as np
import optax
import pytest
from brax.training import replay_buffers
from brax.training.acme import running_statistics
from brax.training.types import Transition
from flax import struct

import dpc_mjx.io as dio
from dpc_mjx import serialization as ser
from dpc_mjx.adapter.networks import (
    AdapterConfig,
    DecoderState,
    EncoderState,
    Normalizer,
    decoder_module,
    encode,
    encoder_module,
)
from dpc_mjx.control import arm_estimate
from dpc_mjx.control.arm_model import arm_model
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.envs.observations import S_BODY_NAMES, U_OBS_NAMES
from dpc_mjx.errors import DpcError
from dpc_mjx.io import arm_dynamics, inference
from dpc_mjx.io.inference import NumpyPolicy
from dpc_mjx.policy.policy import (
    POLICY_INPUTS,
    PolicyState,
    act,
    dpc_policy,
    observation_size,
)
from dpc_mjx.robots import build, layout, spec_json
from dpc_mjx.robots.arms import ArmSpec, Mount, UrdfArm
from dpc_mjx.robots.variants import VARIANTS
from dpc_mjx.rotations import wrench_to_world, wrench_to_yaw_frame
from dpc_mjx.sac import checkpoint
from dpc_mjx.sac.networks import make_networks
from dpc_mjx.sac.train import BestPolicy, Carry, SacConfig, TrainingState

SHIPPED = pathlib.Path(dio.__file__).parent.parent / "artefacts" / "regular"
_NUMPY_TOL = 1e-5  # numpy (float64) vs JAX (float32) inference, absolute, on z and a in [-1, 1]
HIDDEN = (32, 24)  # not the defaults, so sizes must come from the sidecar
CONFIG = AdapterConfig(hidden=HIDDEN)
ENV_CONFIG = EnvConfig(max_force=50.0, max_torque=15.0)
N_IN = {"regular": 26, "long": 26, "so100": 29}  # 11 + 2 n + n_act
ARM_SPECS = {"regular": "regular", "long": ArmSpec(upper_arm_length=0.28)}


def _norm(key: jax.Array, n: int) -> Normalizer:
    k1, k2 = jax.random.split(key)
    mean = jax.random.normal(k1, (n,))
    std = jax.random.uniform(k2, (n,), minval=0.5, maxval=2.0)  # ~ U(0.5, 2)
    return Normalizer(mean=mean, std=std)


def _encoder(seed: int, n_in: int, config: AdapterConfig = CONFIG) -> EncoderState:
    k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
    params = encoder_module(config).init(k1, jp.zeros(n_in))
    return EncoderState(params=params, input_norm=_norm(k2, n_in))


def _decoder(seed: int) -> DecoderState:
    k1, k2, k3 = jax.random.split(jax.random.PRNGKey(seed), 3)
    params = decoder_module(CONFIG).init(k1, jp.zeros(CONFIG.latent_size), jp.zeros(11))
    return DecoderState(params=params, body_norm=_norm(k2, 11), target_norm=_norm(k3, 2))


def _policy(seed: int, inputs: tuple[str, ...] = POLICY_INPUTS["paper"]) -> PolicyState:
    obs_size = observation_size(inputs, CONFIG.latent_size)
    k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
    params = make_networks(obs_size, 6, HIDDEN).policy_network.init(k1)
    norm = _norm(k2, obs_size)
    return PolicyState(params=params, obs_norm=norm, hidden=HIDDEN, action_size=6, inputs=inputs)


def _obs(n_in: int, batch: int = 64, seed: int = 7) -> np.ndarray:
    return np.asarray(2.0 * jax.random.normal(jax.random.PRNGKey(seed), (batch, n_in)))


@pytest.fixture(scope="module")
def trained():
    return {
        "policy": _policy(1),
        "decoder": _decoder(2),
        "encoders": {"regular": _encoder(3, N_IN["regular"]), "long": _encoder(4, N_IN["long"])},
    }


@pytest.fixture(scope="module")
def exported(trained, tmp_path_factory) -> pathlib.Path:
    return dio.export(
        tmp_path_factory.mktemp("export") / "run",
        adapter_config=CONFIG,
        policy=trained["policy"],
        decoder=trained["decoder"],
        encoders=trained["encoders"],
        arms=ARM_SPECS,
        env_config=ENV_CONFIG,
        sac_config={"hidden": HIDDEN, "num_envs": 8},
        extra={"note": "test"},
    )


@pytest.fixture
def export_copy(exported, tmp_path) -> pathlib.Path:
    return pathlib.Path(shutil.copytree(exported, tmp_path / "copy"))


def _assert_trees_equal(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(la, lb, strict=True):
        assert np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


# --------------------------------------------------------------------------- export / load


def test_export_load_round_trip_is_bit_exact(trained, exported):
    loaded = dio.load(exported)
    assert loaded.adapter_config == CONFIG
    assert loaded.policy.hidden == HIDDEN and loaded.policy.action_size == 6
    _assert_trees_equal(loaded.policy, trained["policy"])
    _assert_trees_equal(loaded.decoder, trained["decoder"])
    assert sorted(loaded.encoders) == ["long", "regular"]
    for arm, enc in trained["encoders"].items():
        _assert_trees_equal(loaded.encoders[arm], enc)
        obs = _obs(N_IN[arm])
        z0, z1 = encode(CONFIG, enc, obs), encode(CONFIG, loaded.encoders[arm], obs)
        np.testing.assert_array_equal(np.asarray(z0), np.asarray(z1))
        a0 = act(trained["policy"], jp.concatenate([obs[:, :11], z0], -1))
        a1 = loaded.dpc_policy(arm)(obs, None)
        np.testing.assert_array_equal(np.asarray(a0), np.asarray(a1))


def test_sidecar_describes_the_networks(exported):
    meta = json.loads((exported / dio.SIDECAR).read_text())
    assert meta["format_version"] == dio.FORMAT_VERSION
    assert meta["library_version"].startswith("0.")
    assert meta["created"].endswith("+00:00")
    assert meta["adapter_config"]["hidden"] == list(HIDDEN)
    p = meta["policy"]
    assert (p["hidden"], p["action_size"], p["observation_size"]) == (list(HIDDEN), 6, 13)
    assert p["observation_layout"][:3] == ["roll", "pitch", "wx"]
    assert p["observation_layout"][8:] == ["cmd_vx", "cmd_vy", "cmd_yaw", "z_0", "z_1"]
    assert meta["observation"]["s_body"] == {"start": 0, "stop": 11, "names": list(S_BODY_NAMES)}
    assert p["observation_layout"] == [*S_BODY_NAMES, "z_0", "z_1"]
    assert meta["action_scaling"]["u_scale"] == [50.0] * 3 + [15.0] * 3
    assert meta["encoders"]["regular"]["input_size"] == 26
    assert meta["encoders"]["regular"]["file"] == "encoder_regular.msgpack"
    assert meta["env_config"]["max_force"] == 50.0
    assert meta["sac_config"] == {"hidden": list(HIDDEN), "num_envs": 8}
    assert meta["extra"] == {"note": "test"}
    assert not list(exported.glob("*.tmp"))  # atomic writes leave no temp files


def test_arm_specs_round_trip_through_the_sidecar(exported):
    loaded = dio.load(exported)
    assert loaded.arm_spec("regular") == "regular"
    assert loaded.arm_spec("long") == ArmSpec(upper_arm_length=0.28)
    for spec in (
        VARIANTS["double"],
        UrdfArm("z1", Mount((0.1, 0.0, 0.057), yaw=0.5)),
        ArmSpec(gripper_mass=0.5, ee_shape="plate"),
    ):
        assert spec_json.arm_from_json(json.loads(json.dumps(spec_json.arm_to_json(spec)))) == spec
    with pytest.raises(DpcError, match="Unknown arm variant"):
        spec_json.arm_to_json("no_such_arm")
    with pytest.raises(DpcError, match="not one of"):
        spec_json.arm_from_json({"type": "os.system", "command": "true"})


def test_add_encoder_adds_an_arm(export_copy):
    enc = _encoder(5, N_IN["so100"])
    dio.add_encoder(export_copy, "so100", enc, UrdfArm("so100"))
    loaded = dio.load(export_copy)
    assert sorted(loaded.encoders) == ["long", "regular", "so100"]
    _assert_trees_equal(loaded.encoders["so100"], enc)
    assert loaded.arm_spec("so100") == UrdfArm("so100")
    assert NumpyPolicy(export_copy, "so100").action(_obs(29)).shape == (64, 6)
    with pytest.raises(DpcError, match="already has an encoder for arm 'so100'"):
        dio.add_encoder(export_copy, "so100", enc, "so100")
    dio.add_encoder(export_copy, "so100", _encoder(6, 29), "so100", replace=True)
    assert dio.load(export_copy).arm_spec("so100") == "so100"
    wrong_latent = _encoder(7, 29, AdapterConfig(hidden=HIDDEN, latent_size=3))
    with pytest.raises(DpcError, match="latent_size=2"):
        dio.add_encoder(export_copy, "z1", wrong_latent, "z1")
    with pytest.raises(DpcError, match="has no encoder for arm 'z1'"):
        dio.load(export_copy).encoder("z1")


def test_export_refuses_inconsistent_artefacts(trained, tmp_path):
    kwargs = dict(adapter_config=CONFIG, policy=trained["policy"], decoder=trained["decoder"])
    with pytest.raises(DpcError, match="arm spec"):
        dio.export(tmp_path, **kwargs, encoders=trained["encoders"], arms={"regular": "regular"})
    big = AdapterConfig(hidden=HIDDEN, latent_size=3)
    encoders = {"regular": _encoder(3, 26, big)}
    with pytest.raises(DpcError, match="policy is inconsistent"):
        big_kwargs = kwargs | {"adapter_config": big}
        dio.export(tmp_path, **big_kwargs, encoders=encoders, arms={"regular": "regular"})
    with pytest.raises(DpcError, match="cannot name a file"):
        dio.export(tmp_path, **kwargs, encoders={"a/b": encoders["regular"]}, arms={"a/b": "none"})
    assert not (tmp_path / dio.SIDECAR).exists()


def _edit_sidecar(fn):
    def edit(d: pathlib.Path):
        meta = json.loads((d / dio.SIDECAR).read_text())
        fn(meta)
        (d / dio.SIDECAR).write_text(json.dumps(meta))

    return edit


def _without_arm_models(d: pathlib.Path) -> None:
    """The export `d` as written before the arms' models were recorded."""
    for entry in json.loads((d / dio.SIDECAR).read_text())["encoders"].values():
        (d / entry["arm_model"]["file"]).unlink()
    _edit_sidecar(lambda m: [e.pop("arm_model") for e in m["encoders"].values()])(d)


def _truncate(name):
    def edit(d: pathlib.Path):
        data = (d / name).read_bytes()
        (d / name).write_bytes(data[: len(data) // 2])

    return edit


def _other_policy(d: pathlib.Path):
    ser.write_msgpack(d / "policy.msgpack", _policy(99))  # same shapes, other values


BROKEN = {
    "truncated msgpack": (
        _truncate("policy.msgpack"),
        ["policy.msgpack (policy)", "truncated or corrupt", "re-export"],
    ),
    "garbage bytes": (
        lambda d: (d / "decoder.msgpack").write_bytes(b"not a msgpack file"),
        ["decoder.msgpack (decoder)", "truncated or corrupt"],
    ),
    "missing file": (
        lambda d: (d / "encoder_long.msgpack").unlink(),
        ["encoder for arm 'long'", "does not exist"],
    ),
    "missing sidecar": (lambda d: (d / dio.SIDECAR).unlink(), ["dpc.json", "does not exist"]),
    "corrupt json": (
        lambda d: (d / dio.SIDECAR).write_text('{"format_version": 1,'),
        ["dpc.json", "not valid JSON", "re-export"],
    ),
    "wrong format_version": (
        _edit_sidecar(lambda m: m.update(format_version=99)),
        ["format_version 99", "reads format_version 1", "re-export"],
    ),
    "other major version": (
        _edit_sidecar(lambda m: m.update(library_version="7.0.0")),
        ["dpc_mjx 7.0.0", "another major version"],
    ),
    "missing key": (_edit_sidecar(lambda m: m.pop("decoder")), ["lacks the keys", "decoder"]),
    "hidden size disagrees": (
        _edit_sidecar(lambda m: m["policy"].update(hidden=[64, 24])),
        [
            "policy.msgpack (policy) does not match",
            "hidden_0.kernel",
            "is float32 (13, 32), expected float32 (13, 64)",
        ],
    ),
    "encoder input size disagrees": (
        _edit_sidecar(lambda m: m["encoders"]["regular"].update(input_size=30)),
        ["encoder for arm 'regular'", "input_norm.mean", "(30,)", "encoder trained for this arm"],
    ),
    "observation size disagrees": (
        _edit_sidecar(lambda m: m["policy"].update(observation_size=14)),
        ["observation_size=14", "latent_size (2)"],
    ),
    "file from another export": (_other_policy, ["policy.msgpack (policy)", "sha256 differs"]),
    "file outside the folder": (
        _edit_sidecar(lambda m: m["policy"].update(file="../policy.msgpack")),
        ["policy.file must name a file in the export folder"],
    ),
}


@pytest.mark.parametrize("case", list(BROKEN))
def test_load_fails_with_a_clear_message(export_copy, case):
    edit, fragments = BROKEN[case]
    edit(export_copy)
    _load_error(export_copy, fragments)


def _load_error(folder, fragments: list[str]) -> str:
    """The message of the DpcError `io.load(folder)` raises; it must hold every fragment."""
    with pytest.raises(DpcError) as info:
        dio.load(folder)
    message = str(info.value)
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    return message


def test_read_msgpack_names_the_mismatching_leaf(tmp_path):
    path = tmp_path / "x.msgpack"
    ser.write_msgpack(path, {"a": np.zeros((2, 3), np.float32), "b": {"c": np.zeros(4, np.int32)}})
    template = {"a": np.zeros((2, 3), np.float32), "b": {"c": np.zeros(5, np.int32)}}
    with pytest.raises(DpcError, match=r"'b\.c' is int32 \(4,\), expected int32 \(5,\)"):
        ser.read_msgpack(path, template, "thing")
    with pytest.raises(DpcError, match="missing leaf 'd'"):
        ser.read_msgpack(path, template | {"d": np.zeros(1)}, "thing")
    out = ser.read_msgpack(
        path, {"a": np.ones((2, 3), np.float32), "b": {"c": np.ones(4, np.int32)}}, "x"
    )
    assert out["a"].flags.writeable and not out["a"].any()


def test_read_json_rejects_corrupt_json(tmp_path):
    path = tmp_path / "x.json"
    ser.write_json(path, {"a": np.float32(1.5), "b": (1, 2), "c": np.arange(3)})
    assert ser.read_json(path, "x") == {"a": 1.5, "b": [1, 2], "c": [0, 1, 2]}
    path.write_text("{]")
    with pytest.raises(DpcError, match="not valid JSON"):
        ser.read_json(path, "x")
    with pytest.raises(DpcError, match="Cannot write"):
        ser.write_json(path, {"a": object()})


def test_atomic_writes_get_the_usual_file_mode(tmp_path):
    """Files are written through a temp file (mode 0600) but end up as open() would make them,
    so an export can be shared or shipped."""
    plain, atomic = tmp_path / "plain", tmp_path / "atomic"
    plain.write_bytes(b"x")
    ser.write_bytes(atomic, b"x")
    assert atomic.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777


# --------------------------------------------------------------------------- numpy inference


def test_numpy_policy_matches_jax(trained, exported):
    scale = np.array([50.0] * 3 + [15.0] * 3)  # ENV_CONFIG's max_force (N), max_torque (N·m)
    for arm, enc in trained["encoders"].items():
        obs = _obs(N_IN[arm], seed=11)
        z = encode(CONFIG, enc, obs)
        a = act(trained["policy"], jp.concatenate([obs[:, :11], z], -1))
        policy = NumpyPolicy(exported, arm)
        np.testing.assert_allclose(policy.latent(obs), z, atol=_NUMPY_TOL, rtol=0)
        np.testing.assert_allclose(policy.action(obs), a, atol=_NUMPY_TOL, rtol=0)
        # ENV_CONFIG's u_frame is 'yaw': u(obs, yaw) turns u_scale * a by the heading
        yaw = np.linspace(-3.0, 3.0, len(obs))
        u_world = wrench_to_world(a * scale, yaw)
        np.testing.assert_allclose(policy.u(obs, yaw), u_world, atol=_NUMPY_TOL * 50.0, rtol=0)
        assert policy.action(obs[0]).shape == (6,) and policy.latent(obs[0]).shape == (2,)
        np.testing.assert_allclose(policy.u(obs[3], yaw[3]), policy.u(obs, yaw)[3], atol=1e-12)
        # without the heading: u in the policy's frame, what the ONNX graph gives
        np.testing.assert_allclose(policy.u(obs), a * scale, atol=_NUMPY_TOL * 50.0, rtol=0)


def test_observer_input_policy_round_trips_and_runs_in_numpy(trained, tmp_path):
    """A policy on [s_body, z, u_obs]: the sidecar records its inputs and layout, `load` restores
    it, and the numpy runner reads u_obs after the encoder's input, as the JAX policy does."""
    policy = _policy(5, POLICY_INPUTS["observer"])
    out = dio.export(
        tmp_path / "observer",
        adapter_config=CONFIG,
        policy=policy,
        decoder=trained["decoder"],
        encoders={"regular": trained["encoders"]["regular"]},
        arms={"regular": "regular"},
        env_config=ENV_CONFIG,
    )
    meta = json.loads((out / "dpc.json").read_text())
    assert meta["policy"]["inputs"] == ["s_body", "z", "u_obs"]
    assert meta["policy"]["observation_size"] == 11 + 2 + 6
    assert meta["policy"]["observation_layout"][-7:] == ["z_1", *U_OBS_NAMES]
    assert meta["action_scaling"]["frame"] == "yaw"
    loaded = dio.load(out)
    assert loaded.policy.inputs == ("s_body", "z", "u_obs")
    _assert_trees_equal(loaded.policy.params, policy.params)
    obs = _obs(N_IN["regular"] + 6, seed=12)  # [s_body, s_arm, p_arm, u_obs]
    a = np.asarray(dpc_policy(CONFIG, trained["encoders"]["regular"], loaded.policy)(obs, None))
    z = encode(CONFIG, trained["encoders"]["regular"], obs[:, : N_IN["regular"]])
    expected = act(policy, jp.concatenate([obs[:, :11], z, obs[:, -6:]], -1))
    np.testing.assert_allclose(a, expected, atol=1e-6, rtol=0)
    numpy_policy = NumpyPolicy(out, "regular")
    np.testing.assert_allclose(numpy_policy.action(obs), a, atol=_NUMPY_TOL, rtol=0)
    with pytest.raises(ValueError, match="has 32 entries per row"):
        numpy_policy.action(obs[:, : N_IN["regular"]])  # u_obs missing: refused, not guessed
    _edit_sidecar(lambda m: m["policy"].update(inputs=["s_body", "u_obs"]))(out)
    with pytest.raises(DpcError, match=r"policy.inputs is \["):
        dio.load(out)


def _regular_export(trained, out: pathlib.Path, env_config: EnvConfig) -> pathlib.Path:
    """The trained policy with its `regular` encoder exported to `out` under `env_config`."""
    return dio.export(
        out,
        adapter_config=CONFIG,
        policy=trained["policy"],
        decoder=trained["decoder"],
        encoders={"regular": trained["encoders"]["regular"]},
        arms={"regular": "regular"},
        env_config=env_config,
    )


def test_a_policy_on_the_observer_adds_u_obs_in_numpy_as_the_env_does(trained, exported, tmp_path):
    """u_base='observer': the sidecar records the base and the observer, and the numpy runner's
    u is the observation's u_obs plus the policy's u_scale * a, turned by the heading: by
    linearity the env's u of a tick, the tick's estimate (world) plus the policy's u turned
    (`DpcEnv.controller_u`, `LowLevelController.step(add_estimate=True)`)."""
    config = ENV_CONFIG.replace(u_base="observer", observer_gain=40.0)
    out = _regular_export(trained, tmp_path / "residual", config)
    scaling = json.loads((out / "dpc.json").read_text())["action_scaling"]
    assert scaling["base"] == "observer" and scaling["observer"]["gain"] == 40.0
    obs = _obs(N_IN["regular"] + 6, seed=13)  # [s_body, s_arm, p_arm, u_obs (yaw frame)]
    yaw = np.linspace(-3.0, 3.0, len(obs))
    policy, paper = NumpyPolicy(out, "regular"), NumpyPolicy(exported, "regular")
    residual = policy.residual(obs)
    np.testing.assert_allclose(residual, paper.u(obs), atol=1e-12)  # the same actor
    u_obs_world = np.asarray(wrench_to_world(obs[:, -6:], yaw))
    expected = u_obs_world + np.asarray(wrench_to_world(residual, yaw))
    np.testing.assert_allclose(policy.u(obs, yaw), expected, atol=_NUMPY_TOL * 50.0, rtol=0)
    np.testing.assert_allclose(policy.u(obs), obs[:, -6:] + residual, atol=1e-12)
    with pytest.raises(ValueError, match="has 32 entries per row"):
        policy.u(obs[:, : N_IN["regular"]])  # u_obs missing: refused, not guessed
    _edit_sidecar(lambda m: m["action_scaling"].update(base="zero"))(out)
    with pytest.raises(DpcError, match="action_scaling.base.*env_config.u_base"):
        dio.load(out)


@pytest.mark.parametrize("base", ["gravity", "model"])
def test_a_policy_on_the_arms_wrench_adds_the_given_wrench_in_numpy(
    trained, exported, tmp_path, base
):
    """u_base='gravity' (or 'model'): the sidecar records the base; the numpy runner's u is the
    given arms' gravity (model) wrench, the policy's frame, plus the policy's u_scale * a, then
    turned by the heading, as the env adds `DpcEnv.arm_gravity` (the controller the model
    wrench: world) to the policy's u turned; without the wrench it refuses, and a policy of
    another base refuses one."""
    out = _regular_export(trained, tmp_path / base, ENV_CONFIG.replace(u_base=base))
    assert json.loads((out / "dpc.json").read_text())["action_scaling"]["base"] == base
    if base == "model":  # as an export written before the arms' models were recorded
        _without_arm_models(out)
    obs = _obs(N_IN["regular"] + 6, seed=17)
    yaw = np.linspace(-3.0, 3.0, len(obs))
    wrench = {f"u_{base}": np.random.default_rng(3).normal(0.0, 5.0, (len(obs), 6))}  # yaw frame
    policy, paper = NumpyPolicy(out, "regular"), NumpyPolicy(exported, "regular")
    residual = policy.residual(obs)
    np.testing.assert_allclose(residual, paper.u(obs), atol=1e-12)  # the same actor
    expected = np.asarray(wrench_to_world(wrench[f"u_{base}"] + residual, yaw))
    got = policy.u(obs, yaw, **wrench)
    np.testing.assert_allclose(got, expected, atol=_NUMPY_TOL * 50.0, rtol=0)
    np.testing.assert_allclose(policy.u(obs, **wrench), wrench[f"u_{base}"] + residual, atol=1e-12)
    with pytest.raises(ValueError, match=f"pass u_{base}"):
        policy.u(obs, yaw)
    if base == "model":
        with pytest.raises(ValueError, match=r"before the arms' model.*add_arm_models"):
            policy.u(obs, yaw)
        with pytest.raises(ValueError, match="measured is read only by an export"):
            policy.u(obs, yaw, u_model=wrench["u_model"], measured={"targets": np.zeros(5)})
    with pytest.raises(ValueError, match="base is 'zero'"):
        paper.u(obs, **wrench)
    other = "model" if base == "gravity" else "gravity"
    with pytest.raises(ValueError, match=f"base is '{base}'"):
        policy.u(obs, **wrench, **{f"u_{other}": wrench[f"u_{base}"]})


def _tick_inputs(n: int, batch: int, seed: int) -> dict[str, np.ndarray]:
    """A batch of random tick inputs (`arm_dynamics.MEASURED`): the arm's q, qd and targets
    near its reference, a tilted trunk, turning, accelerating as a balance QP may ask."""
    rng = np.random.default_rng(seed)
    quat = rng.normal(size=(batch, 4)) * [3.0, 0.2, 0.2, 1.0]
    rot = np.array([arm_dynamics.quat_rot(x) for x in quat])
    return {
        "q": rng.uniform(-0.6, 0.6, (batch, n)),
        "qd": rng.normal(0.0, 1.0, (batch, n)),
        "targets": rng.uniform(-0.8, 0.8, (batch, n)),
        "rot": rot,
        "ang_vel": rng.normal(0.0, 0.5, (batch, 3)),
        "desired": rng.normal(0.0, 2.0, (batch, 6)),
        "com": np.einsum("bij,bj->bi", rot, rng.normal(0.0, 0.02, (batch, 3))),
    }


def _controller_u_model(arm: str, x: dict[str, np.ndarray]) -> np.ndarray:
    """(B, 6) world: the arms' model wrench as the env's controller computes it at a tick
    (`arm_estimate.update`, its default config: qdd 'servo', base_acc 'desired'), float32."""
    model = build(arm)
    jax_arm = arm_model(model, layout(model))
    f32 = {k: jp.asarray(v, jp.float32) for k, v in x.items()}
    out = []
    for i in range(len(x["q"])):
        s = types.SimpleNamespace(rot=f32["rot"][i], ang_vel=f32["ang_vel"][i])  # measured
        est = arm_estimate.init(s, f32["qd"][i])
        measured = (jp.zeros(3), f32["q"][i], f32["qd"][i])  # the accelerometer: unread here
        est = arm_estimate.update(
            arm_estimate.ArmEstimateConfig(), jax_arm, est, s, measured, f32["targets"][i],
            f32["com"][i], f32["desired"][i], 0.004,
        )  # fmt: skip
        out.append(np.asarray(est.wrench))
    return np.array(out)


def _model_case(trained, tmp_path: pathlib.Path):
    """(an export on the arms' model wrench, the tick's inputs of 12 rows, its observations with
    s_arm the tick's q and qd, the inputs the robot passes, the trunk's heading)."""
    out = _regular_export(trained, tmp_path / "model", ENV_CONFIG.replace(u_base="model"))
    x = _tick_inputs(5, batch=12, seed=4)
    obs = np.array(_obs(N_IN["regular"] + 6, batch=12, seed=19))
    obs[:, 11:21] = np.concatenate([x["q"], x["qd"]], axis=1)  # s_arm: the tick's q, qd
    measured = {k: x[k] for k in ("targets", "rot", "ang_vel", "desired", "com")}
    yaw = np.arctan2(x["rot"][:, 1, 0], x["rot"][:, 0, 0])  # the trunk's heading
    return out, x, obs, measured, yaw


def test_a_policy_on_the_arms_model_computes_it_as_the_controller_does(trained, tmp_path):
    """u_base='model': the numpy runner's u is the policy's u turned plus the arms' model wrench
    it computes from the tick's measured inputs, the env controller's (`arm_estimate.update`)
    to float32's precision, and the u of the same export without the arm-model file given that
    wrench; an IMU's quaternion and gyro serve as well."""
    out, x, obs, measured, yaw = _model_case(trained, tmp_path)
    policy = NumpyPolicy(out, "regular")
    u_model = _controller_u_model("regular", x)  # world
    scale = np.abs(u_model).max()
    got = policy.u(obs, yaw, measured=measured)
    expected = np.asarray(wrench_to_world(policy.residual(obs), yaw)) + u_model
    np.testing.assert_allclose(got, expected, atol=1e-4 * scale, rtol=0)
    np.testing.assert_allclose(policy.model_wrench(x), u_model, atol=1e-4 * scale, rtol=0)
    in_yaw = np.asarray(wrench_to_yaw_frame(u_model, yaw))  # the policy's frame, as u(obs)
    np.testing.assert_allclose(
        policy.u(obs, measured=measured), policy.residual(obs) + in_yaw, atol=1e-4 * scale
    )
    old = pathlib.Path(shutil.copytree(out, tmp_path / "old"))
    _without_arm_models(old)
    given = NumpyPolicy(old, "regular").u(obs, yaw, u_model=in_yaw)
    np.testing.assert_allclose(got, given, atol=1e-4 * scale, rtol=0)
    imu = {
        **measured,
        "quat": _quats(x["rot"]),
        "gyro": np.einsum("bji,bj->bi", x["rot"], x["ang_vel"]),
    }
    del imu["rot"], imu["ang_vel"]
    np.testing.assert_allclose(policy.u(obs, yaw, measured=imu), got, atol=1e-9)


def test_a_policy_on_the_arms_model_refuses_to_run_without_its_inputs(trained, tmp_path):
    """It names every input missing, of a wrong shape or not finite; it refuses a u_model of the
    caller's, and a policy on another base refuses the inputs."""
    out, x, obs, measured, yaw = _model_case(trained, tmp_path)
    policy = NumpyPolicy(out, "regular")
    with pytest.raises(ValueError, match=r"measured inputs.*missing \['targets', 'rot'"):
        policy.u(obs, yaw)
    with pytest.raises(ValueError, match=r"missing \['com'\]"):
        policy.u(obs, yaw, measured={k: v for k, v in measured.items() if k != "com"})
    with pytest.raises(ValueError, match=r"wrong shape: \[\('targets', \(12, 4\)\)\]"):
        policy.u(obs, yaw, measured=measured | {"targets": x["targets"][:, :4]})
    with pytest.raises(ValueError, match=r"NaN/inf in \['desired'\]"):
        policy.u(obs, yaw, measured=measured | {"desired": np.full(6, np.nan)})
    with pytest.raises(ValueError, match="pass measured=, not u_model"):
        policy.u(obs, yaw, u_model=np.zeros(6), measured=measured)
    with pytest.raises(ValueError, match=r"missing \['q', 'qd'\]"):
        policy.model_wrench(measured)  # q and qd: from an observation or given
    with pytest.raises(ValueError, match="measured is read only by"):
        NumpyPolicy(_regular_export(trained, tmp_path / "zero", ENV_CONFIG), "regular").u(
            obs, yaw, measured=measured
        )


def test_the_arm_model_files_are_recorded_and_checked(trained, tmp_path):
    """The export records the arm's model (arm_model_<arm>.json, its sha256 in the sidecar), so
    does `add_encoder`; `add_arm_models` writes the same file into an export without it; a file
    changed since is refused by the runner and by `load`."""
    out = _model_case(trained, tmp_path)[0]
    entry = json.loads((out / dio.SIDECAR).read_text())["encoders"]["regular"]["arm_model"]
    assert entry["file"] == "arm_model_regular.json" and len(entry["joints"]) == 5
    assert ser.sha256_bytes((out / entry["file"]).read_bytes()) == entry["sha256"]
    old = pathlib.Path(shutil.copytree(out, tmp_path / "old"))
    _without_arm_models(old)
    assert dio.add_arm_models(old) == ["regular"]  # recorded again: the same file
    assert (old / entry["file"]).read_bytes() == (out / entry["file"]).read_bytes()
    assert json.loads((old / dio.SIDECAR).read_text())["encoders"]["regular"]["arm_model"] == entry
    dio.add_encoder(out, "so100", _encoder(5, N_IN["so100"]), "so100")  # its model too
    so100 = NumpyPolicy(out, "so100")
    assert so100.arm_model.n == 6 and so100.meta["encoders"]["so100"]["arm_model"]["joints"]
    (out / entry["file"]).write_text((out / entry["file"]).read_text().replace("0.", "1.", 1))
    with pytest.raises(ValueError, match="sha256 differs"):
        NumpyPolicy(out, "regular")
    with pytest.raises(DpcError, match=r"sha256 differs.*arm model of 'regular'"):
        dio.load(out)


def _quats(rot: np.ndarray) -> np.ndarray:
    """(B, 4) w, x, y, z of the rotations (B, 3, 3) (w > 0; no rotation near 180 degrees)."""
    w = np.sqrt(1.0 + np.trace(rot, axis1=1, axis2=2)) / 2.0
    v = np.stack(
        [rot[:, 2, 1] - rot[:, 1, 2], rot[:, 0, 2] - rot[:, 2, 0], rot[:, 1, 0] - rot[:, 0, 1]], 1
    )
    return np.concatenate([w[:, None], v / (4.0 * w[:, None])], axis=1)


def test_numpy_policy_rejects_bad_input(exported, export_copy):
    policy = NumpyPolicy(exported, "regular")
    with pytest.raises(
        ValueError, match=r"has 32 entries per row \(the encoder reads the first 26"
    ):
        policy.action(np.zeros(29))
    obs = np.zeros((2, 26))
    obs[1, 4] = np.nan
    with pytest.raises(ValueError, match=r"1 NaN/inf entries \(first at index \(1, 4\)\)"):
        policy.u(obs)
    with pytest.raises(ValueError, match="no encoder for arm 'z1'"):
        NumpyPolicy(exported, "z1")
    _truncate("policy.msgpack")(export_copy)
    with pytest.raises(ValueError, match="sha256 differs"):
        NumpyPolicy(export_copy, "regular")
    _edit_sidecar(lambda m: m.update(format_version=2))(export_copy)
    with pytest.raises(ValueError, match="format_version 2"):
        NumpyPolicy(export_copy, "regular")


def test_inference_imports_no_jax(exported, tmp_path):
    """inference.py alone, in a Python where jax and flax cannot be imported, runs an export; with
    arm_dynamics.py next to it, the shipped one (on the arms' model wrench, computed there)."""
    assert inference.FORMAT_VERSION == dio.FORMAT_VERSION
    assert inference.SIDECAR == dio.SIDECAR
    alone, both = tmp_path / "alone", tmp_path / "both"
    for folder, files in ((alone, [inference]), (both, [inference, arm_dynamics])):
        folder.mkdir()
        for module in files:
            shutil.copy(module.__file__, folder)
    old = pathlib.Path(shutil.copytree(SHIPPED, tmp_path / "old"))
    _without_arm_models(old)
    script = f"""
import importlib.abc, importlib.util, sys
class NoJax(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("jax", "jaxlib", "flax", "dpc_mjx"):
            raise ImportError(f"inference.py imported {{name}}")
sys.meta_path.insert(0, NoJax())
import numpy as np
def runner(folder):
    path = f"{{folder}}/inference.py"
    spec = importlib.util.spec_from_file_location(f"dpc_inference_{{len(sys.modules)}}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
alone, both = runner({str(alone)!r}), runner({str(both)!r})
still = {{"targets": np.zeros(5), "rot": np.eye(3), "gyro": np.zeros(3)}}
still |= {{"desired": np.zeros(6), "com": np.zeros(3)}}
obs = np.zeros(32)  # [s_body, s_arm, p_arm, u_obs]
assert alone.NumpyPolicy({str(exported)!r}, "regular").u(obs, 0.5).shape == (6,)
old = alone.NumpyPolicy({str(old)!r}, "regular")  # on the model, written before its file
assert old.u(obs, 0.5, u_model=np.zeros(6)).shape == (6,)
try:
    alone.NumpyPolicy({str(SHIPPED)!r}, "regular")
    raise AssertionError("ran without arm_dynamics.py")
except ValueError as e:
    assert "copy dpc_mjx/io/arm_dynamics.py there" in str(e), e
shipped = both.NumpyPolicy({str(SHIPPED)!r}, "regular")
assert shipped.u(obs, 0.5, measured=still).shape == (6,)
assert "jax" not in sys.modules
loaded = [m for m in sys.modules if m.split(".")[0] in ("jax", "jaxlib", "flax", "dpc_mjx")]
assert not loaded, loaded
"""
    result = subprocess.run(
        [sys.executable, "-c", script],
        check=False,
        capture_output=True,
        text=True,
        cwd="/",
        timeout=120,
    )
    assert result.returncode == 0, result.stderr


# --------------------------------------------------------------------------- sidecar vs files
# Each case corrupts one field of the shipped export's sidecar, or replaces one of its files with
# a network of other sizes (its sha256 updated, so only the size check can catch it); `load` must
# name the file, the field, both values and what to do.


@pytest.fixture
def shipped_copy(tmp_path) -> pathlib.Path:
    return pathlib.Path(shutil.copytree(SHIPPED, tmp_path / "regular"))


def _shipped_encoder(config: AdapterConfig) -> EncoderState:
    return _encoder(21, 26, config)


def _shipped_decoder(config: AdapterConfig, body: int = 11, target: int = 2) -> DecoderState:
    k1, k2, k3 = jax.random.split(jax.random.PRNGKey(22), 3)
    s_body = jp.zeros(11) if config.decoder_sees_body else None
    params = decoder_module(config).init(k1, jp.zeros(config.latent_size), s_body)
    return DecoderState(params=params, body_norm=_norm(k2, body), target_norm=_norm(k3, target))


def _shipped_policy(obs_size=13, action_size=6, hidden=(128, 128), norm=None) -> PolicyState:
    k1, k2 = jax.random.split(jax.random.PRNGKey(23))
    params = make_networks(obs_size, action_size, hidden).policy_network.init(k1)
    return PolicyState(params, _norm(k2, norm or obs_size), hidden, action_size)


def _swap_file(name: str, tree):
    """Replace file `name` with `tree`, its sha256 updated in the sidecar."""

    def edit(d: pathlib.Path):
        meta = json.loads((d / dio.SIDECAR).read_text())
        entries = [meta["policy"], meta["decoder"], *meta["encoders"].values()]
        (entry,) = [e for e in entries if e["file"] == name]
        entry["sha256"] = ser.write_msgpack(d / name, tree() if callable(tree) else tree)
        (d / dio.SIDECAR).write_text(json.dumps(meta))

    return edit


def _set(*keys, value):
    def fn(meta):
        node = meta
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value

    return _edit_sidecar(fn)


_NAMES = list(S_BODY_NAMES)
_SHIPPED_META = json.loads((SHIPPED / dio.SIDECAR).read_text())
_BIG_S_BODY = {"start": 0, "stop": 12, "names": [*_NAMES, "extra"]}
_SWAPPED = [*_NAMES[:5], "vy", "vx", *_NAMES[7:], "z_0", "z_1"]
SIDECAR_DISAGREES = {  # one field of dpc.json against another (or this library)
    "decoder latent vs adapter_config": (
        _set("decoder", "latent_size", value=3),
        ["dpc.json", "decoder.latent_size is 3", "adapter_config.latent_size gives 2", "re-export"],
    ),
    "adapter_config latent vs policy input": (
        _set("adapter_config", "latent_size", value=3),
        ["dpc.json", "policy.observation_size=13", "latent_size (3) make 14", "re-export"],
    ),
    "decoder sees_body vs adapter_config": (
        _set("decoder", "sees_body", value=False),
        ["dpc.json", "decoder.sees_body is false", "decoder_sees_body gives true", "re-export"],
    ),
    "decoder out_size vs this library": (
        _set("decoder", "out_size", value=3),
        ["dpc.json", "decoder.out_size is 3", "predicts 2 values", "re-export"],
    ),
    "decoder target_layout vs out_size": (
        _set("decoder", "target_layout", value=["roll_rate"]),
        ["dpc.json", 'target_layout is ["roll_rate"]', "out_size is 2", "re-export"],
    ),
    "policy observation_layout vs s_body names": (
        _set("policy", "observation_layout", value=_SWAPPED),
        ["dpc.json", "policy.observation_layout is", '"vy", "vx"', '"vx", "vy"', "re-export"],
    ),
    "s_body names vs its start..stop": (
        _set("observation", "s_body", "names", value=_NAMES[:10]),
        ["dpc.json", "s_body.names has 10 names", "0..11 spans 11", "re-export"],
    ),
    "s_body vs this library's observations": (
        _set("observation", "s_body", value=_BIG_S_BODY),
        ["dpc.json", '"stop": 12', '"stop": 11', "dpc_mjx.envs.observations", "re-export"],
    ),
    "encoder input_size vs s_body": (
        _set("encoders", "regular", "input_size", value=5),
        ["dpc.json", "encoders.regular.input_size is 5", "s_body ends at 11", "re-export"],
    ),
    "u_scale vs policy action_size": (
        _set("action_scaling", "u_scale", value=[15.0, 15.0, 60.0, 12.0, 12.0]),
        ["dpc.json", "u_scale has 5 entries", "policy.action_size is 6", "re-export"],
    ),
    "u_scale vs env_config bounds": (
        _set("action_scaling", "u_scale", value=[16.0, 6.0, 6.0, 3.0, 3.0, 3.0]),
        ["dpc.json", "u_scale is [16.0,", "max_torque", "gives [6.0,", "re-export"],
    ),
    "arm_model entry vs its form": (
        _set("encoders", "regular", "arm_model", value={"file": 3}),
        ["dpc.json", "encoders.regular.arm_model is", "only on base 'model'", "re-export"],
    ),
    "arm model joints vs encoder input_size": (
        _set(
            "encoders", "regular", "arm_model", value=_SHIPPED_META["encoders"]["z1"]["arm_model"]
        ),
        ["arm_model_z1.json", "so an input of 32", "input_size is 26", "re-export"],
    ),
    "sac_config hidden vs policy hidden": (
        _set("sac_config", "hidden", value=[64, 64]),
        ["dpc.json", "sac_config.hidden is [64, 64]", "policy.hidden gives [128, 128]"],
    ),
}
_SHIPPED_CONFIG = AdapterConfig()  # the shipped adapter: latent 2, 2 x 128, decoder sees s_body
FILE_DISAGREES = {  # a size in dpc.json against the file that holds it
    "decoder file latent (the issue's case)": (
        _swap_file("decoder.msgpack", lambda: _shipped_decoder(AdapterConfig(latent_size=3))),
        ["decoder.msgpack (decoder)", "decoder.latent_size + s_body", "is 13 there but 14"],
    ),
    "decoder file sees no body": (
        _swap_file(
            "decoder.msgpack", lambda: _shipped_decoder(AdapterConfig(decoder_sees_body=False))
        ),
        ["decoder.msgpack (decoder)", "(decoder.sees_body=true) is 13 there but 2"],
    ),
    "decoder file hidden width": (
        _swap_file("decoder.msgpack", lambda: _shipped_decoder(AdapterConfig(hidden=(128, 64)))),
        ["decoder.msgpack (decoder)", "adapter_config.hidden[1] is 128 there but 64"],
    ),
    "decoder file target normaliser": (
        _swap_file("decoder.msgpack", lambda: _shipped_decoder(_SHIPPED_CONFIG, target=3)),
        ["decoder.msgpack", "decoder.out_size is 2 there but 3", "'target_norm.mean'"],
    ),
    "decoder file body normaliser": (
        _swap_file("decoder.msgpack", lambda: _shipped_decoder(_SHIPPED_CONFIG, body=12)),
        ["decoder.msgpack", "observation.s_body (stop - start) is 11 there but 12"],
    ),
    "decoder file depth": (
        _swap_file(
            "decoder.msgpack", lambda: _shipped_decoder(AdapterConfig(hidden=(128, 128, 128)))
        ),
        ["decoder.msgpack", "adapter_config.hidden lists 2 hidden layers", "the file has 3"],
    ),
    "adapter_config hidden vs decoder file": (
        _set("adapter_config", "hidden", value=[128, 64]),
        ["decoder.msgpack (decoder)", "adapter_config.hidden[1] is 64 there but 128"],
    ),
    "encoder file latent": (
        _swap_file(
            "encoder_regular.msgpack", lambda: _shipped_encoder(AdapterConfig(latent_size=3))
        ),
        ["encoder_regular.msgpack", "adapter_config.latent_size is 2 there but 3", "'params."],
    ),
    "encoder file hidden width": (
        _swap_file(
            "encoder_regular.msgpack", lambda: _shipped_encoder(AdapterConfig(hidden=(96, 128)))
        ),
        ["encoder_regular.msgpack", "adapter_config.hidden[0] is 128 there but 96"],
    ),
    "encoder input_size vs encoder file": (
        _set("encoders", "regular", "input_size", value=29),
        ["encoder_regular.msgpack", "encoders.regular.input_size is 29 there but 26", "(29,)"],
    ),
    "policy file action size": (
        _swap_file("policy.msgpack", lambda: _shipped_policy(action_size=5)),
        ["policy.msgpack (policy)", "2 * policy.action_size is 12 there but 10"],
    ),
    "policy file hidden width": (
        _swap_file("policy.msgpack", lambda: _shipped_policy(hidden=(128, 64))),
        ["policy.msgpack (policy)", "policy.hidden[1] is 128 there but 64"],
    ),
    "policy file depth": (
        _swap_file("policy.msgpack", lambda: _shipped_policy(hidden=(128, 128, 128))),
        ["policy.msgpack", "policy.hidden lists 2 hidden layers, so 3 layers", "the file has 4"],
    ),
    "policy file input size": (
        _swap_file("policy.msgpack", lambda: _shipped_policy(obs_size=14, norm=13)),
        ["policy.msgpack", "policy.observation_size is 13 there but 14", "hidden_0.kernel"],
    ),
    "policy file normaliser": (
        _swap_file("policy.msgpack", lambda: _shipped_policy(norm=14)),
        ["policy.msgpack", "policy.observation_size is 13 there but 14", "'obs_norm.mean'"],
    ),
}


@pytest.mark.parametrize("case", list(SIDECAR_DISAGREES) + list(FILE_DISAGREES))
def test_load_refuses_a_sidecar_that_disagrees(shipped_copy, case):
    edit, fragments = (SIDECAR_DISAGREES | FILE_DISAGREES)[case]
    dio.load(shipped_copy)  # the copy loads before the edit
    edit(shipped_copy)
    message = _load_error(shipped_copy, fragments)
    assert "re-export" in message or "dpc_mjx.io.add_encoder" in message, message


def test_shipped_export_records_its_layout_and_old_sidecars_still_load(shipped_copy):
    """The shipped sidecar was rewritten with the layout (its msgpack files unchanged); a sidecar
    written before the layout was recorded gives the same networks and outputs."""
    meta = json.loads((SHIPPED / dio.SIDECAR).read_text())
    assert meta["observation"]["s_body"] == {"start": 0, "stop": 11, "names": list(S_BODY_NAMES)}
    obs = _obs(26, batch=8, seed=5)
    art, numpy_policy = dio.load(SHIPPED), NumpyPolicy(SHIPPED, "regular")
    assert numpy_policy.s_body == slice(0, 11)
    _edit_sidecar(lambda m: m.pop("observation"))(shipped_copy)
    old, old_numpy = dio.load(shipped_copy), NumpyPolicy(shipped_copy, "regular")
    _assert_trees_equal(old.policy, art.policy)
    a, a_old = art.dpc_policy("regular")(obs, None), old.dpc_policy("regular")(obs, None)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(a_old))
    yaw = np.linspace(-1.0, 1.0, len(obs))
    measured = {"targets": obs[:, 21:26], "rot": np.eye(3), "ang_vel": np.ones(3)}
    measured |= {"desired": np.arange(6.0), "com": np.zeros(3)}  # the shipped export's base
    np.testing.assert_array_equal(
        old_numpy.u(obs, yaw, measured=measured), numpy_policy.u(obs, yaw, measured=measured)
    )
    assert old_numpy.s_body == slice(0, 11)


def test_numpy_policy_takes_the_layout_from_the_sidecar(shipped_copy):
    moved = {"start": 1, "stop": 12, "names": list(S_BODY_NAMES)}  # after one other entry
    _set("observation", "s_body", value=moved)(shipped_copy)
    assert NumpyPolicy(shipped_copy, "regular").s_body == slice(1, 12)
    with pytest.raises(DpcError, match="dpc_mjx.envs.observations"):
        dio.load(shipped_copy)  # the library's envs observe s_body at 0..11
    _set("observation", "s_body", value={"start": 0, "stop": 12, "names": _BIG_S_BODY["names"]})(
        shipped_copy
    )
    with pytest.raises(ValueError, match=r"do not fit policy.observation_size 13"):
        NumpyPolicy(shipped_copy, "regular")


# --------------------------------------------------------------------------- checkpoints


@struct.dataclass
class _Carry:
    """A small stand-in for `sac.train.Carry`."""

    params: dict
    opt: optax.OptState
    key: jax.Array
    epoch: jax.Array  # () int32


META = {"sac_config": {"batch_size": 256, "hidden": (128, 128)}, "observation_size": 13}
HISTORY = [{"epoch": 1, "mean_return": float("nan")}, {"epoch": 2, "mean_return": -3.5}]


def _carry(seed: int, epoch: int, rows: int = 3) -> _Carry:
    k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
    params = {"w": jax.random.normal(k1, (rows, 4)), "b": jp.zeros(4)}
    tx = optax.adam(1e-3)
    opt = tx.init(params)
    for _ in range(2):  # non-trivial moments and count
        grads = jax.tree.map(lambda p: p + 1.0, params)
        updates, opt = tx.update(grads, opt)
        params = optax.apply_updates(params, updates)
    return _Carry(params=params, opt=opt, key=k2, epoch=jp.asarray(epoch, jp.int32))


def test_checkpoint_round_trip_is_exact(tmp_path):
    carry = _carry(0, epoch=2)
    checkpoint.save(tmp_path, carry, META, HISTORY)
    restored, history = checkpoint.restore(tmp_path, _carry(1, epoch=0), META)
    _assert_trees_equal(restored, carry)
    assert all(isinstance(x, jax.Array) for x in jax.tree.leaves(restored))
    assert int(restored.epoch) == 2
    assert math.isnan(history[0]["mean_return"]) and history[1] == HISTORY[1]
    assert sorted(p.name for p in tmp_path.iterdir()) == [checkpoint.RECORD, checkpoint.MSGPACK]


def test_checkpoint_restore_without_checkpoint(tmp_path):
    with pytest.raises(DpcError, match="No checkpoint.*without resume=True"):
        checkpoint.restore(tmp_path, _carry(0, 0), META)


def test_checkpoint_meta_mismatch_names_the_keys(tmp_path):
    checkpoint.save(tmp_path, _carry(0, 2), META, HISTORY)
    other = {"sac_config": {"batch_size": 128, "hidden": (128, 128)}, "observation_size": 14}
    with pytest.raises(DpcError) as info:
        checkpoint.restore(tmp_path, _carry(1, 0), other)
    message = str(info.value)
    assert "sac_config.batch_size: saved 256, now 128" in message
    assert "observation_size: saved 13, now 14" in message
    assert "hidden" not in message  # a tuple saved as a JSON list is not a difference


CKPT_BROKEN = {
    "truncated": (
        _truncate(checkpoint.MSGPACK),
        3,
        ["SAC checkpoint", "truncated or corrupt"],
    ),
    "other shapes": (lambda d: None, 5, ["params.w", "expected float32 (5, 4)"]),
    "not this record's msgpack": (
        lambda d: ser.write_msgpack(d / checkpoint.MSGPACK, _carry(3, 2)),
        3,
        ["sha256"],
    ),
    "corrupt record": (
        lambda d: (d / checkpoint.RECORD).write_text("{"),
        3,
        ["checkpoint record", "not valid JSON"],
    ),
    "missing msgpack": (
        lambda d: (d / checkpoint.MSGPACK).unlink(),
        3,
        ["does not exist", "without resume=True"],
    ),
}


@pytest.mark.parametrize("case", list(CKPT_BROKEN))
def test_checkpoint_corrupt_or_mismatched(tmp_path, case):
    edit, rows, fragments = CKPT_BROKEN[case]
    checkpoint.save(tmp_path, _carry(0, 2), META, HISTORY)
    edit(tmp_path)
    with pytest.raises(DpcError) as info:
        checkpoint.restore(tmp_path, _carry(1, 0, rows), META)
    for fragment in fragments:
        assert fragment in str(info.value), (fragment, str(info.value))


def test_checkpoint_round_trips_a_sac_carry(tmp_path):
    """The real `sac.train.Carry`: brax running statistics, replay buffer, optax states."""
    obs_size, action_size = 13, 6
    nets = make_networks(obs_size, action_size, (16, 16))
    dummy = Transition(
        observation=jp.zeros(obs_size),
        action=jp.zeros(action_size),
        reward=0.0,
        discount=0.0,
        next_observation=jp.zeros(obs_size),
        extras={"state_extras": {"truncation": 0.0}, "policy_extras": {}},
    )
    buffer = replay_buffers.UniformSamplingQueue(64, dummy, sample_batch_size=8)

    @jax.jit
    def init(key):
        k1, k2, k3, k4, key = jax.random.split(key, 5)
        pi, q, log_alpha = nets.policy_network.init(k1), nets.q_network.init(k2), jp.zeros(())
        stats = running_statistics.init_state(jax.ShapeDtypeStruct((obs_size,), jp.float32))
        stats = running_statistics.update(stats, jax.random.normal(k3, (5, obs_size)))
        batch = jax.tree.map(lambda x: jp.broadcast_to(x, (10, *jp.shape(x))) + 1.0, dummy)
        training = TrainingState(
            policy_params=pi,
            policy_opt=optax.adam(1e-3).init(pi),
            q_params=q,
            q_opt=optax.adam(1e-3).init(q),
            target_q_params=q,
            log_alpha=log_alpha,
            alpha_opt=optax.adam(3e-4).init(log_alpha),
            normalizer=stats,
            env_steps=jp.asarray(640, jp.int32),
            grad_steps=jp.asarray(160, jp.int32),
        )
        buf = buffer.insert(buffer.init(k4), batch)
        best = BestPolicy(pi, stats, jp.asarray(12.5), jp.asarray(2, jp.int32))
        return Carry(training, buf, key, jp.asarray(4, jp.int32), best)

    carry = init(jax.random.PRNGKey(0))
    meta = {"sac_config": dataclasses.asdict(SacConfig()), "observation_size": obs_size}
    checkpoint.save(tmp_path, carry, meta, HISTORY)
    template = init(jax.random.PRNGKey(1))
    restored, _ = checkpoint.restore(tmp_path, template, meta)
    _assert_trees_equal(restored, carry)
    weak = [x.weak_type for x in jax.tree.leaves(template)]
    assert [x.weak_type for x in jax.tree.leaves(restored)] == weak and any(weak)


class _Killed(Exception):
    pass


def _kill(*args, **kwargs):
    raise _Killed


def test_checkpoint_kill_before_commit_keeps_previous(tmp_path, monkeypatch):
    first, second = _carry(0, 2), _carry(5, 3)
    checkpoint.save(tmp_path, first, META, HISTORY)
    monkeypatch.setattr(ser, "write_json", _kill)  # killed after staging, before the record
    with pytest.raises(_Killed):
        checkpoint.save(tmp_path, second, META, [*HISTORY, {"epoch": 3}])
    monkeypatch.undo()
    restored, history = checkpoint.restore(tmp_path, _carry(1, 0), META)
    _assert_trees_equal(restored, first)
    assert len(history) == 2


def test_checkpoint_kill_after_commit_rolls_forward(tmp_path, monkeypatch):
    first, second = _carry(0, 2), _carry(5, 3)
    checkpoint.save(tmp_path, first, META, HISTORY)
    monkeypatch.setattr(checkpoint, "_promote", _kill)  # killed after the record, before rename
    with pytest.raises(_Killed):
        checkpoint.save(tmp_path, second, META, [*HISTORY, {"epoch": 3}])
    monkeypatch.undo()
    restored, history = checkpoint.restore(tmp_path, _carry(1, 0), META)
    _assert_trees_equal(restored, second)
    assert len(history) == 3 and not (tmp_path / checkpoint.STAGED).exists()


def test_an_export_is_evaluated_with_the_engine_it_records_where_the_device_runs_it(monkeypatch):
    """b1's export records the native engine: a CPU evaluates it there without being told; an
    export that records none gets 'auto'; on an accelerator native becomes 'auto' (MJX)."""
    from dpc_mjx.io import shipped  # noqa: PLC0415 (the function under test)

    b1, regular = dio.load(shipped.SHIPPED_BASES["b1"]), dio.load(shipped.SHIPPED)
    assert b1.meta["env_config"]["engine"] == "native"
    assert shipped.engine_of(b1) == "native" and shipped.engine_of(regular) == "auto"
    _, _, options = shipped.export_cells(shipped.SHIPPED_BASES["b1"], None, ["mbc"], "reaching")
    assert options["engine"] == "native"
    monkeypatch.setattr(shipped, "resolve_engine", lambda engine: "mjx")  # as on a GPU
    assert shipped.engine_of(b1) == "auto"


def test_a_policy_compiles_as_a_function_or_as_data(exported):
    """`jax.jit(policy)` (its weights constants of the program, as a user writes it) and the
    policy passed as data (`rollout.make_chunk`'s one program for every export) act alike."""
    policy = dio.load(exported).dpc_policy("regular")
    obs = jp.asarray(_obs(N_IN["regular"] + 6, seed=23), jp.float32)
    as_function = jax.jit(policy)(obs, None)
    as_data = jax.jit(lambda p, x: p(x, None))(policy, obs)
    np.testing.assert_allclose(as_function, as_data, atol=1e-6)
    assert as_function.shape == (len(obs), 6)
