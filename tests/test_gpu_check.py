"""`experiments/gpu_check.sh`, the one prepared device check: its table read back from logs (every
run), and the whole script on the CPU with tiny sizes (slow: `make test-all`), so that the GPU's
few minutes go to measuring, not to fixing the script."""

import json
import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).parents[1]
SCRIPT = ROOT / "experiments" / "gpu_check.sh"
sys.path.insert(0, str(ROOT / "experiments"))
import gpu_check_table  # noqa: E402

BENCH_LOG = """arm regular, 20 calls per row, 1 env steps per env call, device gpu

| batch | env steps/s (full env) | env steps/s (physics only) | env / physics | compile env (s) | compile physics (s) |
|---|---|---|---|---|---|
| 4096 | 167,484 | 269,978 | 0.62 | 33.0 | 15.0 |
rc=0
"""  # noqa: E501
EVAL_LOG = """physics: MJX (engine='mjx')

| arm | controller | fall rate [95% CI] | mean return |
|---|---|---|---|
| regular | mbc | 0.46 [0.43, 0.49] | 1.0 |
| regular | dpc | 0.23 [0.20, 0.26] | 2.0 |
rc=0
"""


BENCH_MPC_LOG = """reaching, regular, MBC, mjx, the device's own threads, gpu

| batch | compile + first call, QP / MPC (s) | env steps/s QP | MPC | ms QP | MPC | cost |
|---|---|---|---|---|---|---|
| 4096 | 40.1 / 75.3 | 51,200 | 20,480 | 80.0 | 200.0 | 2.50 |
rc=0
"""


def test_the_table_reads_each_steps_log_and_says_which_failed(tmp_path):
    (tmp_path / "versions.txt").write_text("jax 0.11.2 devices [CudaDevice(id=0)]\n")
    (tmp_path / "bench.log").write_text(BENCH_LOG)
    (tmp_path / "bench.ms").write_text("61234\n")
    (tmp_path / "eval_warm.log").write_text(EVAL_LOG)
    (tmp_path / "train_cold.log").write_text(
        "adapter: ... held-out NLL 0.401 (constant ...)\nrc=0\n"
    )
    timings = {"data_seconds": 20.0, "adapter_seconds": 6.0, "eval_seconds": 30.0}
    summary = {"timings_seconds": timings, "eval": [{"episodes": 1024}]}
    (tmp_path / "summary_cold.json").write_text(json.dumps(summary))
    (tmp_path / "sac.log").write_text("Traceback ...\nDpcError: out of memory\nrc=1\n")
    (tmp_path / "bench_mpc.log").write_text(BENCH_MPC_LOG)
    rows = gpu_check_table.table(tmp_path).splitlines()
    assert rows[0].startswith("jax 0.11.2")
    bench = next(r for r in rows if r.startswith("| bench, 1 env step"))
    assert "| 61 | 0 |" in bench and "4096: env 167,484 steps/s" in bench and "ratio 0.62" in bench
    evaluation = next(r for r in rows if r.startswith("| eval 4 controllers, warm"))
    assert "MJX" in evaluation and "mbc fall rate 0.46" in evaluation
    train = next(r for r in rows if r.startswith("| default train, cold"))
    assert "data 20 s" in train and "eval 1024 episodes" in train and "NLL 0.401" in train
    mpc = next(r for r in rows if r.startswith("| the env step, MPC against QP"))
    assert "4096: QP 51,200 env steps/s, MPC 20,480, MPC / QP cost 2.50x" in mpc
    assert "compile 40.1 / 75.3 s" in mpc
    sac = next(r for r in rows if r.startswith("| paper recipe"))
    assert "| 1 | failed: Traceback ... / DpcError: out of memory |" in sac
    assert next(r for r in rows if r.startswith("| default train, warm")).endswith("not run |")


@pytest.mark.slow  # three MJX compiles (the bench) and five runs of the CLI: ~15 min on 2 cores
def test_the_whole_check_runs_on_a_cpu_with_tiny_sizes(tmp_path):
    env = {**os.environ, "OUT": str(tmp_path), "GPU_CHECK_SIZE": "tiny", "GPU_CHECK_INSTALL": "0"}
    env |= {"PYTHON": sys.executable, "GPU_CHECK_BUDGET": "3000"}
    subprocess.run(["bash", str(SCRIPT)], cwd=ROOT, env=env, check=True, timeout=3000)
    table = (tmp_path / "table.md").read_text()
    rows = [r for r in table.splitlines() if r.startswith("| ") and not r.startswith("| step")]
    assert len(rows) == len(gpu_check_table.STEPS)
    for row in rows:
        assert "| 0 |" in row and "failed" not in row, row
