"""The Python snippets of the README and of the docs guides run as written (`exec`, in the order
of `PAGES`, each page's in its order). `test_every_page_with_a_snippet_is_read` keeps every page
that holds a ```python block (README.md, docs/**/*.md) in `PAGES`.

A reader runs them as one session: the snippets of docs/python.md share one namespace (later ones
use the names of earlier ones). Two snippets need more than the page gives them:
- the training pipeline runs on a tiny budget (`TINY`: each of its texts is replaced by a small
  one, and each must occur in the snippet exactly once, so an edit of the page that drops one
  fails here instead of training for hours); it is `slow` (a dozen compiles);
- the deployment loop gets `measurement`, the robot's reading: what exact sensors read on the
  shipped export's robot standing at its home pose (tests/test_deploy.py has noisy ones);
- the numpy runner gets the shipped export for "export/", a zero observation but for the arm's
  joints at their reference, and a robot standing level and still (`_still_robot`).
`test_every_snippet_is_run` fails on a snippet that no test runs (the README's ONNX snippet runs in
tests/test_onnx.py). The default suite runs the deployment snippet (its compile is
tests/test_deploy.py's, from the compilation cache) and imports every name the snippets import;
the session's snippets (a few minutes of compiling and 20 s of walking) and the pipeline are
`slow` (`make test-all`).
The README's `dpc-mjx` command lines are parsed by the CLI (`test_every_readme_command_parses`).
"""

import ast
import dataclasses
import importlib
import importlib.util
import pathlib
import re
import shlex

import mujoco
import numpy as np
import pytest
from test_sac import _CONFIG

from dpc_mjx.deploy import Measurement
from dpc_mjx.io import arm_dynamics
from dpc_mjx.io.inference import NumpyPolicy
from dpc_mjx.io.shipped import SHIPPED
from dpc_mjx.robots import build, layout
from dpc_mjx.run import cli

ROOT = pathlib.Path(__file__).resolve().parents[1]
# The pages whose ```python blocks run, in a reader's order: the README's Quick start (ONNX), the
# library in Python (the session, then the pipeline), the robot's loop.
PAGES = ("README.md", "docs/python.md", "docs/deployment.md")
PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", flags=re.S | re.M)

SESSION = "import jax, numpy as np"  # the first line of docs/python.md's first snippet
PIPELINE = "sac.train("  # the training pipeline's snippet holds this
DEPLOY = "Deployment("  # the deployment loop's snippet holds this
NUMPY_RUNNER = "measured=measured"  # the numpy runner's snippet (docs/deployment.md) holds this
ONNX = "ort.InferenceSession("  # the ONNX snippet, run by tests/test_onnx.py

# The tiny SAC of tests/test_sac.py (3 epochs of 32 actor steps x 8 envs), without evaluations.
_TINY_FIELDS = ("num_timesteps", "num_envs", "batch_size", "grad_updates_per_step")
_TINY_FIELDS += ("min_replay_size", "max_replay_size", "epoch_steps")
TINY_SAC = {name: getattr(_CONFIG, name) for name in _TINY_FIELDS} | {"eval_every": 0}
# The snippet's text -> what the test runs instead: one chunk of 64 envs x 50 steps of data, the
# tiny SAC above, 2 episodes of 10 steps in each evaluation cell.
TINY = {
    "samples=100_000": "samples=3_200",
    '"so100", controller="mbc"), 30_000)': '"so100", controller="mbc"), 3_200)',
    'recipe("paper").sac,': 'dataclasses.replace(recipe("paper").sac, **TINY_SAC),',
    "dpc_policy_for=art.dpc_policy)": "dpc_policy_for=art.dpc_policy, episodes=2, steps=10)",
}


def snippets() -> list[str]:
    """Every ```python block of the `PAGES`, in order."""
    return [b for page in PAGES for b in PYTHON_BLOCK.findall((ROOT / page).read_text())]


def _run(code: str, namespace: dict, name: str) -> None:
    exec(compile(code, f"docs snippet ({name})", "exec"), namespace)  # noqa: S102 (our docs)


def _session() -> list[str]:
    """The session's snippets: from the first through the last before the pipeline's."""
    blocks = snippets()
    first = next(i for i, b in enumerate(blocks) if b.startswith(SESSION))
    end = next(i for i, b in enumerate(blocks) if PIPELINE in b)
    return blocks[first:end]


def test_every_snippet_is_run():
    blocks = snippets()
    run = _session() + [
        b for b in blocks if any(key in b for key in (PIPELINE, DEPLOY, ONNX, NUMPY_RUNNER))
    ]
    assert len(blocks) >= 6, f"{PAGES} lost their Python snippets"
    assert sorted(run) == sorted(blocks), "a snippet no test runs"


def test_every_page_with_a_snippet_is_read():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    with_code = {
        p.relative_to(ROOT).as_posix() for p in pages if PYTHON_BLOCK.search(p.read_text())
    }
    unread = sorted(with_code - set(PAGES))
    assert not unread, f"pages with ```python snippets that no test reads: {unread}"


def readme_commands() -> list[list[str]]:
    """The `dpc-mjx` command lines of the README's ```bash blocks, each as its arguments (a
    trailing `# comment` dropped)."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M)
    lines = [line.split(" #")[0] for block in blocks for line in block.splitlines()]
    return [shlex.split(line)[1:] for line in lines if line.startswith("dpc-mjx ")]


def test_every_readme_command_parses():
    """The cheap check of the README's Quick start commands: each is one the CLI accepts."""
    commands = readme_commands()
    assert len(commands) >= 8, "the README lost its Quick start commands"
    for argv in commands:
        cli._parser().parse_args(argv)  # argparse exits on a command it does not accept


def test_every_name_a_snippet_imports_exists():
    """The cheap part (default suite): each `import` and `from ... import` of every snippet."""
    for code in snippets():
        for node in ast.walk(ast.parse(code)):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    importlib.import_module(alias.name)
            elif isinstance(node, ast.ImportFrom):
                module = importlib.import_module(node.module)
                for alias in node.names:
                    assert hasattr(module, alias.name) or importlib.util.find_spec(
                        f"{node.module}.{alias.name}"
                    ), f"{PAGES}: `from {node.module} import {alias.name}` fails"


@pytest.mark.slow
def test_quick_start_snippets(capsys):
    namespace: dict = {}
    for i, code in enumerate(_session()):
        _run(code, namespace, f"docs/python.md, snippet {i + 1}")
    assert "fall" in capsys.readouterr().out  # closed_loop.summarize's line
    assert namespace["ep"]["return"].shape == (8,)  # run_episodes' 8 episodes


@pytest.mark.slow
def test_training_pipeline_snippet_on_a_tiny_budget(tmp_path, monkeypatch):
    # Full compiles (37 min on 2 loaded cores, 2026-12-02): FAST_COMPILE saves little of XLA's
    # time here and runs the programs ~35x slower; with it the test had not ended after 28 min.
    (code,) = [b for b in snippets() if PIPELINE in b]
    for readme, tiny in TINY.items():
        assert code.count(readme) == 1, f"the training snippet no longer holds {readme!r}"
        code = code.replace(readme, tiny)
    monkeypatch.chdir(tmp_path)  # the snippet writes runs/sac and runs/export
    namespace = {"dataclasses": dataclasses, "TINY_SAC": TINY_SAC}
    _run(code, namespace, "the training pipeline")
    cells = namespace["cells"]
    assert len(cells) == 6  # 2 arms x 3 controllers
    assert (tmp_path / "runs/export").is_dir()


def _standing_measurement(arm: str):
    """What exact sensors read on the A1 with `arm` standing still at its home pose."""
    model = build(arm)
    lay = layout(model)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    rot = data.xmat[lay.trunk].reshape(3, 3)
    return Measurement(
        quat=data.qpos[3:7].copy(),
        gyro=np.zeros(3),
        accel=rot.T @ np.array([0.0, 0.0, 9.81]),  # at rest: specific force, trunk frame
        leg_q=data.qpos[lay.leg_qpos].copy(),
        leg_qd=np.zeros(12),
        arm_q=data.qpos[lay.arm_qpos].copy(),
        arm_qd=np.zeros(len(lay.arm_dof)),
        arm_targets=data.ctrl[lay.arm_act].copy(),
        command=np.zeros(3),
    )


def test_deployment_snippet():
    (code,) = [b for b in snippets() if DEPLOY in b]
    namespace = {"measurement": _standing_measurement("regular")}  # the shipped export's arm
    _run(code, namespace, "the deployment loop")
    tau = np.asarray(namespace["tau"])
    assert tau.shape == (12,) and np.all(np.isfinite(tau))


_WEIGHT_RTOL = 1e-6  # of the arm's weight: float64 arithmetic, the servos at their targets


def _still_robot(policy) -> dict:
    """The names the numpy runner's snippet reads, for a robot standing level and still with its
    arm still at the joints' references, its servos' targets offset by the arm's gravity torques
    over their gains (kp (T - q) = h(q, 0): no joint accelerates)."""
    arm = policy.arm_model
    obs = np.zeros(policy.input_size + 6)
    start = policy.s_body.stop
    obs[start : start + arm.n] = arm.q_ref  # s_arm: q at the reference, qd 0
    still = arm_dynamics.base_motion(np.eye(3), np.zeros(3), np.zeros(6), np.zeros(3))
    zero = np.zeros(arm.n)
    holding = arm_dynamics._joint_torques(  # noqa: SLF001 (h at rest: the test's equilibrium)
        arm,
        arm_dynamics._forward(arm, still, arm.q_ref, zero, zero),  # noqa: SLF001
    )
    return {
        "NumpyPolicy": NumpyPolicy,
        "obs": obs,
        "yaw": 0.0,
        "arm_targets": arm.q_ref + holding / arm.kp,
        "R": np.eye(3),
        "gyro": np.zeros(3),
        "qdd_des": np.zeros(6),
        "com_offset": np.zeros(3),
    }


def test_numpy_runner_snippet():
    """docs/deployment.md's numpy runner, on the shipped export: still and level, its u is the
    policy's residual plus the arm's weight (f_z = -m g)."""
    (code,) = [b for b in snippets() if NUMPY_RUNNER in b]
    code = code.replace('NumpyPolicy("export/"', f'NumpyPolicy("{SHIPPED}"')
    namespace = _still_robot(NumpyPolicy(SHIPPED, "regular"))
    _run(code, namespace, "the numpy runner")
    policy, u = namespace["policy"], np.asarray(namespace["u"])
    weight = -np.sum(policy.arm_model.mass) * 9.81  # N, f_z of the arm's weight on the base
    f_z = u[2] - policy.residual(namespace["obs"])[2]
    np.testing.assert_allclose(f_z, weight, rtol=_WEIGHT_RTOL)
