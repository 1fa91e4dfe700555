"""The ONNX graph of an export (`dpc_mjx.io.onnx_graph`, `dpc-mjx onnx`) computes what
`NumpyPolicy.u(obs)` computes, u in the policy's frame, for every encoder of the shipped exports
(the A1's, and the Go2's and B1's of `io.shipped.SHIPPED_BASES`), on observations of real
rollouts; the command writes it; without onnx it says how to install it.

`tests/data/onnx_observations.npz` holds, per shipped encoder (`CELLS`: the A1 export's arms by
name, the other bases' as "<base>/<arm>"), 32 raw env observations
[s_body, s_arm, p_arm, u_obs] (float32) of short episodes on the export's task and env options,
the shipped DPC acting, native MuJoCo C physics (4 envs, seed 31, every 10th of 80 env steps).
Recorded with `python tests/test_onnx.py --record`, which records the cells the file lacks and
keeps the others (its `recorded` entry names the commit and the jax of each recording); delete a
cell's entry to re-record it after a deliberate change of its export.

The graph runs in float32 (its weights are stored so), NumpyPolicy in float64: they agree to
`TOL` of max(1, |u|), per entry (u in N and N·m).
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
from dpc_mjx.io import onnx_graph, sidecar
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
SEED, EPISODES, STEPS, EVERY = 31, 4, 80, 10  # the recording's episodes
README_ONNX = "ort.InferenceSession("  # the README's onnxruntime snippet holds this


def graph_u(policy: NumpyPolicy, obs: np.ndarray) -> np.ndarray:
    """What the graph gives: `policy.u(obs)`, or where the robot adds a wrench of its own
    (action_scaling.base 'gravity' or 'model': the shipped exports' 'model') the policy's part,
    `policy.residual(obs)`."""
    return policy.residual(obs) if policy.base in ("gravity", "model") else policy.u(obs)


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
    (inp,), (out,) = session.get_inputs(), session.get_outputs()
    names = sidecar.ONNX  # the shipped sidecar predates its `onnx` entry
    assert (inp.name, out.name) == (names["input"], names["output"])
    assert inp.shape == ["batch", policy.input_size + 6] and out.shape == ["batch", 6]
    (u,) = session.run(None, {inp.name: obs})
    expected = graph_u(policy, obs)  # the policy's frame ('yaw' for the shipped export)
    assert u.dtype == np.float32 and u.shape == expected.shape == (32, 6)
    err = np.abs(u - expected) / np.maximum(1.0, np.abs(expected))
    assert err.max() <= TOL, f"{key}: max |du| / max(1, |u|) = {err.max():.2e}"
    assert np.abs(expected).max() > 1.0  # the rollouts make the policy act


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
    for batch in (1, 7):
        (u,) = session.run(None, {"obs": obs[:batch]})
        assert u.shape == (batch, 6)
        np.testing.assert_allclose(u, graph_u(policy, obs[:batch]), rtol=TOL, atol=TOL)


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
    expected = graph_u(NumpyPolicy(SHIPPED, "regular"), namespace["obs"])
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
