"""The ONNX graph of an export (`dpc_mjx.io.onnx_graph`, `dpc-mjx onnx`) computes what
`NumpyPolicy.u(obs, measured=...)` computes, u in the policy's frame (and in the world's), for
every encoder of the shipped exports (the A1's, and the Go2's and B1's of
`io.shipped.SHIPPED_BASES`), on observations of real rollouts: on the arms' model wrench
(action_scaling.base 'model'), the graph computes it (`io.onnx_arm`) from the observation's s_arm
and the tick's measured inputs, and refuses to run without them; the command writes it; without
onnx it says how to install it.

`tests/data/onnx_observations.npz` holds, per shipped encoder (`CELLS`: the A1 export's arms by
name, the other bases' as "<base>/<arm>"), 32 raw env observations
[s_body, s_arm, p_arm, u_obs] (float32) of short episodes on the export's task and env options,
the shipped DPC acting, native MuJoCo C physics (4 envs, seed 31, every 10th of 80 env steps).
Recorded with `python tests/test_onnx.py --record`, which records the cells the file lacks and
keeps the others (its `recorded` entry names the commit and the jax of each recording); delete a
cell's entry to re-record it after a deliberate change of its export.

The graph runs in float32 (its weights are stored so), NumpyPolicy in float64: they agree to
`TOL` of max(1, |u|), per entry (u in N and N·m), plus `MODEL_TOL` of the model wrench's scale
(its largest |entry| over the batch; measured: below 2e-6 on random states over the joints' whole
ranges).
"""

import ast
import dataclasses
import json
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest

from dpc_mjx.adapter.networks import Normalizer
from dpc_mjx.envs.config import EnvConfig
from dpc_mjx.errors import DpcError
from dpc_mjx.io import arm_dynamics, onnx_arm, onnx_graph, sidecar
from dpc_mjx.io.export import export
from dpc_mjx.io.inference import NumpyPolicy
from dpc_mjx.io.load import load
from dpc_mjx.io.shipped import SHIPPED, SHIPPED_BASES
from dpc_mjx.policy.policy import POLICY_INPUTS, PolicyState, observation_size
from dpc_mjx.run import cli

DATA = pathlib.Path(__file__).parent / "data" / "onnx_observations.npz"
ARMS = list(json.loads((SHIPPED / sidecar.SIDECAR).read_text())["encoders"])
# every shipped encoder: key -> (export folder, arm); the A1's by the arm's name
CELLS = {arm: (SHIPPED, arm) for arm in ARMS} | {
    f"{base}/{arm}": (SHIPPED_BASES[base], arm) for base, arm in (("go2", "regular"), ("b1", "z1"))
}
TOL = 1e-5  # max |du| / max(1, |u|), per entry
MODEL_TOL = 1e-5  # max |du| / max |u_model| where the graph computes u_model (float32 vs float64)
SEED, EPISODES, STEPS, EVERY = 31, 4, 80, 10  # the recording's episodes
README_ONNX = "ort.InferenceSession("  # the README's onnxruntime snippet holds this


def graph_u(policy: NumpyPolicy, obs: np.ndarray, measured: dict | None = None) -> np.ndarray:
    """What the graph gives: `policy.u(obs, measured=measured)` where it computes the arms'
    model wrench (a 'model' export that records the arm's model: the shipped ones), else
    `policy.u(obs)`, or where the robot adds a wrench of its own (action_scaling.base 'gravity',
    or 'model' without the arm's model) the policy's part, `policy.residual(obs)`."""
    if policy.arm_model is not None:
        return policy.u(obs, measured=measured)
    return policy.residual(obs) if policy.base in ("gravity", "model") else policy.u(obs)


def measured_inputs(policy: NumpyPolicy, obs: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    """Random float32 measured inputs (`onnx_arm.MEASURED`) of a tick for each row of `obs`:
    servo targets within 0.6 rad (m) of the observation's q, a tilted trunk turning, desired
    accelerations and a COM offset of a few cm."""
    rng = np.random.default_rng(seed)
    batch, n, start = len(obs), policy.arm_model.n, policy.s_body.stop
    quat = rng.normal(size=(batch, 4)) * [3.0, 0.3, 0.3, 1.0]  # tilted, any heading
    rot = np.array([arm_dynamics.quat_rot(x) for x in quat])
    measured = {
        "targets": obs[:, start : start + n] + rng.uniform(-0.6, 0.6, (batch, n)),
        "rot": rot,
        "ang_vel": rng.normal(0.0, 0.8, (batch, 3)),
        "desired": rng.normal(0.0, 3.0, (batch, 6)),
        "com": np.einsum("bij,bj->bi", rot, rng.normal(0.0, 0.03, (batch, 3))),
    }
    return {k: np.asarray(v, np.float32) for k, v in measured.items()}


def assert_graph_u(session, policy: NumpyPolicy, obs: np.ndarray, measured: dict, key: str):
    """The graph's outputs equal `graph_u` (and the world frame's, `u(obs, heading, ...)`)
    within `TOL` of max(1, |u|) plus `MODEL_TOL` of the model wrench's scale; the errors."""
    outputs = session.run(None, {"obs": obs, **measured})
    expected = [graph_u(policy, obs, measured)]
    scale = 0.0
    if policy.arm_model is not None:
        rot = measured["rot"].astype(np.float64)
        heading = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
        expected.append(policy.u(obs, heading, measured=measured))
        scale = np.abs(policy.model_wrench(measured, obs)).max()
    assert len(outputs) == len(expected), key
    errors = []
    for got, want in zip(outputs, expected, strict=True):
        assert got.dtype == np.float32 and got.shape == want.shape == (len(obs), 6), key
        err = np.abs(got - want) / (np.maximum(1.0, np.abs(want)) * TOL + MODEL_TOL * scale)
        assert err.max() <= 1.0, f"{key}: |du| is {err.max():.2f} of the tolerance"
        errors.append(np.abs(got - want).max() / max(scale, 1.0))
    return errors


def _observations() -> dict[str, np.ndarray]:
    with np.load(DATA) as data:  # no pickle (np.load's default)
        return {key: data[key] for key in CELLS}


@pytest.fixture(scope="module")
def sessions() -> dict:
    """An onnxruntime session of each shipped encoder's graph (`CELLS`), built in memory."""
    ort = pytest.importorskip("onnxruntime", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    arts = {folder: load(folder) for folder, _ in CELLS.values()}  # each read once
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    return {
        key: ort.InferenceSession(
            onnx_graph.onnx_model(folder, arm, arts[folder]).SerializeToString(),
            options,
            ["CPUExecutionProvider"],
        )
        for key, (folder, arm) in CELLS.items()
    }


def test_recording_covers_every_shipped_arm():
    observations = _observations()
    for key, (folder, arm) in CELLS.items():
        obs = observations[key]
        n = NumpyPolicy(folder, arm).input_size + 6  # [s_body, s_arm, p_arm, u_obs]
        assert obs.shape == (32, n) and obs.dtype == np.float32, key
        assert np.isfinite(obs).all() and len(np.unique(obs, axis=0)) == 32, key


@pytest.mark.parametrize("key", list(CELLS))
def test_graph_matches_numpy_policy(sessions, key):
    obs = _observations()[key]
    folder, arm = CELLS[key]
    policy = NumpyPolicy(folder, arm)
    session = sessions[key]
    inputs, outputs = session.get_inputs(), session.get_outputs()
    names = sidecar.ONNX  # the shipped sidecar predates its `onnx` entry
    n = policy.arm_model.n  # the shipped exports compute u_model in the graph
    assert [(t.name, t.shape) for t in inputs] == [
        (names["input"], ["batch", policy.input_size + 6]),
        ("targets", ["batch", n]),
        ("rot", ["batch", 3, 3]),
        ("ang_vel", ["batch", 3]),
        ("desired", ["batch", 6]),
        ("com", ["batch", 3]),
    ]
    assert [(t.name, t.shape) for t in outputs] == [
        (names["output"], ["batch", 6]),
        (f"{names['output']}_world", ["batch", 6]),
    ]
    assert_graph_u(session, policy, obs, measured_inputs(policy, obs, seed=len(key)), key)
    assert np.abs(policy.residual(obs)).max() > 1.0  # the rollouts make the policy act


MODEL_ARMS = ("regular", "double", "so100", "z1")  # one arm, two, the SO-100, the Z1 (friction)


@pytest.mark.parametrize("arm", MODEL_ARMS)
def test_the_graph_holds_joints_at_their_ends_and_by_friction_as_numpy_does(sessions, arm):
    """States over the joints' whole ranges: every joint at its lower end (one row), at its
    upper end (another; held where pushed further), still joints aimed where they are (dry
    friction holds some: the Z1's), targets far off (the servo's torque bound)."""
    policy = NumpyPolicy(SHIPPED, arm)
    model, rng = policy.arm_model, np.random.default_rng(3)
    obs = _observations()[arm].copy()
    n, start = model.n, policy.s_body.stop
    q = rng.uniform(model.q_min, model.q_max, (len(obs), n))  # the shipped ranges are finite
    q[0], q[1] = model.q_min, model.q_max
    qd = rng.normal(0.0, 1.5, q.shape) * (rng.random(q.shape) > 0.4)
    qd[2:6] = 0.0
    obs[:, start : start + 2 * n] = np.concatenate([q, qd], axis=1)
    measured = measured_inputs(policy, obs, seed=4)
    measured["targets"][2:6] = obs[2:6, start : start + n]  # still, aimed where they are
    measured["targets"][6:8] += 3.0  # far off
    assert_graph_u(sessions[arm], policy, obs, measured, arm)
    q, qd = (obs[:, start + i * n : start + (i + 1) * n].astype(np.float64) for i in (0, 1))
    bases = zip(*(measured[k] for k in ("rot", "ang_vel", "desired", "com")), strict=True)
    rows = zip(bases, q, qd, measured["targets"], strict=True)  # numpy's qdd: the paths taken
    qdd = np.array(
        [arm_dynamics.servo_motion(model, arm_dynamics.base_motion(*b), *x)[1] for b, *x in rows]
    )
    at_end = (q <= model.q_min) | (q >= model.q_max)
    assert (qdd[at_end] == 0.0).any() and (qdd[~at_end] != 0.0).any()
    assert (np.abs(model.kp * (measured["targets"] - q) - model.kv * qd) > model.limit).any()
    if model.friction.any():  # held inside its range: still, its torque within the friction
        assert (qdd[~at_end & (qd == 0.0)] == 0.0).any()


def test_the_graph_refuses_to_run_without_a_measured_input(sessions):
    """Its measured inputs are required graph inputs: onnxruntime names the one missing."""
    policy = NumpyPolicy(SHIPPED, "double")
    obs = _observations()["double"][:3]
    measured = measured_inputs(policy, obs, seed=0)
    for key in onnx_arm.MEASURED:
        feed = {"obs": obs} | {k: v for k, v in measured.items() if k != key}
        with pytest.raises(ValueError, match=rf"Required inputs \(\['{key}'\]\) are missing"):
            sessions["double"].run(None, feed)
    with pytest.raises(ValueError, match="measured="):  # as the numpy runner refuses
        policy.u(obs)
    shapes = json.loads((SHIPPED / sidecar.SIDECAR).read_text())["onnx"]["shapes"]
    assert all(f"{key} (batch" in shapes for key in onnx_arm.MEASURED)  # the sidecar names them


def test_the_graph_passes_the_full_check_and_its_metadata_names_the_inputs():
    onnx = pytest.importorskip("onnx", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    model = onnx_graph.onnx_model(SHIPPED, "z1")
    onnx.checker.check_model(model, full_check=True)
    assert model.opset_import[0].version == sidecar.ONNX["opset"]  # no higher opset needed
    props = {p.key: p.value for p in model.metadata_props}
    inputs = json.loads(props["inputs"])
    assert list(inputs) == ["obs", *onnx_arm.MEASURED] and inputs["targets"][0] == [7]
    assert json.loads(props["outputs"]) == {"u": [6], "u_world": [6]}
    assert props["u_model"].startswith("computed in the graph")


def test_a_model_export_without_the_arms_model_gives_the_residual():
    """An export on the model wrench written before the arm's model was recorded: the graph
    gives the policy's part, the robot adds u_model, and its metadata says so."""
    ort = pytest.importorskip("onnxruntime", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    art = load(SHIPPED)
    meta = json.loads(json.dumps(art.meta))
    del meta["encoders"]["z1"]["arm_model"]
    model = onnx_graph.onnx_model(SHIPPED, "z1", dataclasses.replace(art, meta=meta))
    props = {p.key: p.value for p in model.metadata_props}
    assert props["u_model"].startswith("added by the robot")
    session = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    assert [t.name for t in session.get_inputs() + session.get_outputs()] == ["obs", "u"]
    obs = _observations()["z1"]
    (u,) = session.run(None, {"obs": obs})
    np.testing.assert_allclose(u, NumpyPolicy(SHIPPED, "z1").residual(obs), rtol=TOL, atol=TOL)


def test_a_world_frame_policy_on_the_model_wrench(tmp_path):
    """u_frame='world': u and u_world are the same, u_model added untouched."""
    ort = pytest.importorskip("onnxruntime", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    out = _shipped_z1_export(tmp_path / "world", EnvConfig(u_base="model", u_frame="world"))
    model = onnx_graph.onnx_model(out, "z1")
    session = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    obs, policy = _observations()["z1"], NumpyPolicy(out, "z1")
    assert (policy.frame, policy.base) == ("world", "model") and policy.arm_model is not None
    measured = measured_inputs(policy, obs, seed=9)
    assert_graph_u(session, policy, obs, measured, "z1 (world)")
    u, u_world = session.run(None, {"obs": obs, **measured})
    np.testing.assert_array_equal(u, u_world)


def _observer_policy(latent: int, hidden=(32, 32)) -> PolicyState:
    """Random weights of a policy on [s_body, z, u_obs] (12 outputs: loc and scale of 6)."""
    rng = np.random.default_rng(5)
    sizes = [observation_size(POLICY_INPUTS["observer"], latent), *hidden, 12]
    params = {
        f"hidden_{i}": {
            "kernel": rng.normal(0.0, 1.0 / np.sqrt(n), (n, m)).astype(np.float32),
            "bias": rng.normal(0.0, 0.1, m).astype(np.float32),
        }
        for i, (n, m) in enumerate(zip(sizes, sizes[1:], strict=False))
    }
    std = rng.uniform(0.5, 2.0, sizes[0])
    std[-6:] = 30.0  # u_obs: N, N·m, so that the standardised inputs are O(1) as trained ones
    norm = Normalizer(
        mean=rng.normal(0.0, 0.1, sizes[0]).astype(np.float32), std=std.astype(np.float32)
    )
    return PolicyState({"params": params}, norm, hidden, 6, POLICY_INPUTS["observer"])


def test_observer_input_world_frame_export(tmp_path):
    """A policy that also reads u_obs, acting in the world frame: the graph reads u_obs after
    the encoder's input; an export records the `onnx` entry, whose opset and names the graph
    takes."""
    ort = pytest.importorskip("onnxruntime")
    art = load(SHIPPED)
    out = export(
        tmp_path / "observer",
        adapter_config=art.adapter_config,
        policy=_observer_policy(art.adapter_config.latent_size),
        decoder=art.decoder,
        encoders={"z1": art.encoder("z1")},
        arms={"z1": art.arm_spec("z1")},
        env_config=EnvConfig(u_frame="world"),
    )
    meta = json.loads((out / sidecar.SIDECAR).read_text())
    assert {k: meta["onnx"][k] for k in sidecar.ONNX} == sidecar.ONNX  # what export records
    meta["onnx"].update(opset=18, input="observation", output="wrench")
    (out / sidecar.SIDECAR).write_text(json.dumps(meta))
    model = onnx_graph.onnx_model(out, "z1")
    assert model.opset_import[0].version == 18
    session = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    assert [t.name for t in session.get_inputs() + session.get_outputs()] == [
        "observation",
        "wrench",
    ]
    obs = _observations()["z1"]
    policy = NumpyPolicy(out, "z1")
    assert policy.frame == "world" and policy.inputs == ["s_body", "z", "u_obs"]
    (u,) = session.run(None, {"observation": obs})
    expected = policy.u(obs)
    err = np.abs(u - expected) / np.maximum(1.0, np.abs(expected))
    assert err.max() <= TOL, f"max |du| / max(1, |u|) = {err.max():.2e}"
    changed = obs.copy()
    changed[:, -6:] += 1.0  # u_obs reaches the policy
    assert np.abs(session.run(None, {"observation": changed})[0] - u).max() > 1e-3


def _shipped_z1_export(out: pathlib.Path, env_config: EnvConfig) -> pathlib.Path:
    """The shipped policy with its `z1` encoder exported to `out` under `env_config`."""
    art = load(SHIPPED)
    return export(
        out,
        adapter_config=art.adapter_config,
        policy=art.policy,
        decoder=art.decoder,
        encoders={"z1": art.encoder("z1")},
        arms={"z1": art.arm_spec("z1")},
        env_config=env_config,
    )


def test_a_policy_on_the_observer_adds_u_obs_in_the_graph(tmp_path):
    """u_base='observer': the graph's u is u_obs + u_scale * a, as `NumpyPolicy.u(obs)`."""
    ort = pytest.importorskip("onnxruntime")
    out = _shipped_z1_export(tmp_path / "residual", EnvConfig(u_base="observer"))
    model = onnx_graph.onnx_model(out, "z1")
    session = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    obs = _observations()["z1"]
    policy = NumpyPolicy(out, "z1")
    (u,) = session.run(None, {"obs": obs})
    expected = policy.u(obs)
    err = np.abs(u - expected) / np.maximum(1.0, np.abs(expected))
    assert err.max() <= TOL, f"max |du| / max(1, |u|) = {err.max():.2e}"
    np.testing.assert_allclose(expected - obs[:, -6:], policy.residual(obs), atol=1e-9)


def test_a_policy_on_gravity_gives_its_residual_in_the_graph(tmp_path):
    """u_base='gravity': the graph's u is u_scale * a, `NumpyPolicy.residual(obs)`; the robot adds
    its arms' gravity wrench (the graph has no kinematics)."""
    ort = pytest.importorskip("onnxruntime")
    out = _shipped_z1_export(tmp_path / "gravity", EnvConfig(u_base="gravity"))
    session = ort.InferenceSession(
        onnx_graph.onnx_model(out, "z1").SerializeToString(), providers=["CPUExecutionProvider"]
    )
    obs = _observations()["z1"]
    (u,) = session.run(None, {"obs": obs})
    expected = NumpyPolicy(out, "z1").residual(obs)
    err = np.abs(u - expected) / np.maximum(1.0, np.abs(expected))
    assert err.max() <= TOL, f"max |du| / max(1, |u|) = {err.max():.2e}"


def test_cli_writes_a_graph_with_a_dynamic_batch_axis(tmp_path, capsys):
    ort = pytest.importorskip("onnxruntime", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    out = tmp_path / "graphs" / "policy.onnx"
    assert cli.main(["onnx", "--export", str(SHIPPED), "--arm", "so100", "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    meta = session.get_modelmeta().custom_metadata_map
    assert (meta["arm"], meta["frame"]) == ("so100", "yaw")
    obs = _observations()["so100"]
    policy = NumpyPolicy(SHIPPED, "so100")
    assert meta["u_model"].startswith("computed in the graph")
    for batch in (1, 7):
        measured = measured_inputs(policy, obs[:batch], seed=batch)
        assert_graph_u(session, policy, obs[:batch], measured, "so100")


def test_readme_snippet_runs(tmp_path, monkeypatch):
    """The README's five lines, on the graph the command its comment names writes."""
    pytest.importorskip("onnxruntime", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    readme = (pathlib.Path(__file__).resolve().parents[1] / "README.md").read_text()
    blocks = re.findall(r"^```python\n(.*?)^```", readme, flags=re.S | re.M)
    (code,) = [b for b in blocks if README_ONNX in b]
    assert "dpc-mjx onnx --arm regular --out policy.onnx" in code
    monkeypatch.chdir(tmp_path)
    assert cli.main(["onnx", "--arm", "regular", "--out", "policy.onnx"]) == 0
    namespace: dict = {}
    exec(compile(code, "README.md (onnx)", "exec"), namespace)  # noqa: S102 (our README)
    expected = graph_u(NumpyPolicy(SHIPPED, "regular"), namespace["obs"], namespace["measured"])
    np.testing.assert_allclose(namespace["u"], expected, rtol=TOL, atol=TOL)


def test_cli_refuses_a_missing_arm(tmp_path, capsys):
    pytest.importorskip("onnx", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    out = tmp_path / "policy.onnx"
    assert cli.main(["onnx", "--export", str(SHIPPED), "--arm", "nope", "--out", str(out)]) == 2
    assert "no encoder for arm 'nope'" in capsys.readouterr().err
    assert not out.exists()


def test_a_malformed_onnx_entry_is_refused():
    """The sidecar's `onnx` entry (here given in place of the shipped sidecar's) is checked."""
    pytest.importorskip("onnx", reason="the onnx extra: pip install 'dpc-mjx[onnx]'")
    art = load(SHIPPED)
    cases = [
        ({"opset": 17, "input": "obs"}, r"onnx must be \{opset \(int >= 13\), input, output"),
        ({"opset": 17, "input": "u", "output": "u"}, "two names"),
        ({"opset": 10_000, "input": "obs", "output": "u"}, "onnx.opset is 10000, onnx .* knows"),
        ({"opset": 17, "input": "rot", "output": "u"}, "take a name of the arm model's inputs"),
    ]
    for entry, message in cases:
        meta = {**art.meta, "onnx": entry}
        with pytest.raises(DpcError, match=message):
            onnx_graph.onnx_model(SHIPPED, "regular", dataclasses.replace(art, meta=meta))


def test_without_onnx_the_command_says_how_to_install_it(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "onnx", None)  # `import onnx` raises ImportError
    with pytest.raises(DpcError, match=r"pip install 'dpc-mjx\[onnx\]'"):
        onnx_graph.onnx_model(SHIPPED, "regular")
    out = tmp_path / "policy.onnx"
    assert cli.main(["onnx", "--export", str(SHIPPED), "--arm", "regular", "--out", str(out)]) == 2
    assert "pip install 'dpc-mjx[onnx]'" in capsys.readouterr().err
    assert not out.exists()


def _module_level_imports(tree: ast.AST):
    """The modules imported outside any function or class body of a module's syntax tree."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            yield node.module or ""
        elif not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            yield from _module_level_imports(node)  # if/try blocks at module level


def test_import_dpc_mjx_imports_no_onnx():
    """onnx is imported only when a graph is built: `import dpc_mjx` and the CLI load no
    optional package, and no module of the package imports onnx or onnxruntime at module level
    (so neither does importing any of them, `dpc_mjx.io.onnx_graph` included)."""
    code = (
        "import sys, dpc_mjx, dpc_mjx.run.cli; "
        "print(sorted(m for m in ('onnx', 'onnxruntime') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
    package = pathlib.Path(onnx_graph.__file__).parents[1]
    found = {
        str(path.relative_to(package)): name
        for path in package.rglob("*.py")
        for name in _module_level_imports(ast.parse(path.read_text(encoding="utf-8")))
        if name.split(".")[0] in ("onnx", "onnxruntime")
    }
    assert not found, f"module-level imports of the onnx extra: {found}"
    assert "import onnx  #" in pathlib.Path(onnx_graph.__file__).read_text()  # checked by the scan


def _record() -> None:
    """Run short episodes of every shipped encoder the recording lacks and write `DATA`, the
    recorded cells kept as they are (see the module docstring)."""
    import datetime  # noqa: PLC0415 (recording only)

    import jax  # noqa: PLC0415 (recording only)

    from dpc_mjx.controllers import Controller  # noqa: PLC0415 (recording only)
    from dpc_mjx.envs.registry import make  # noqa: PLC0415 (recording only)
    from dpc_mjx.envs.rollout import record_episodes  # noqa: PLC0415 (recording only)
    from dpc_mjx.io.shipped import env_overrides  # noqa: PLC0415 (recording only)

    kept = {}
    if DATA.exists():
        with np.load(DATA) as data:  # no pickle (np.load's default)
            kept = {k: data[k] for k in data.files}
    observations = {k: v for k, v in kept.items() if k != "recorded"}
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    added = [key for key in CELLS if key not in observations]
    for key in added:
        folder, arm = CELLS[key]
        art = load(folder)
        task = art.meta["extra"]["task"]
        options = {**env_overrides(art, task), "engine": "native"}
        env = make(task, arm=art.arm_spec(arm), controller=Controller.DPC, **options)
        obs = record_episodes(
            env, EPISODES, STEPS, SEED, lambda _, after: after.obs, art.dpc_policy(arm)
        )  # (STEPS + 1, EPISODES, n), from the reset on
        observations[key] = np.asarray(obs[EVERY::EVERY], np.float32).reshape(-1, obs.shape[-1])
        print(key, observations[key].shape, flush=True)
    recorded = str(kept.get("recorded", ""))
    recorded += f"{'; ' if recorded else ''}{', '.join(added)}: {datetime.date.today()} on top "
    recorded += f"of {commit}, jax {jax.__version__}"
    np.savez_compressed(DATA, recorded=np.array(recorded), **observations)
    print(f"recorded {DATA}: {recorded}")


if __name__ == "__main__" and sys.argv[1:] == ["--record"]:
    _record()
