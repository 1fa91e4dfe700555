"""`run.eval.evaluate` runs native arms (each arm's controllers one batch, one program) two at a
time on a CPU and hands their cells back in cell order (no compiling: the arms are stand-ins;
that real cells give the same figures either way is checked bit for bit by
experiments/bench_eval_workers.py, docs/benchmarks-cpu.md)."""

import threading
import time
import types

import jax
import pytest

from dpc_mjx import DpcError
from dpc_mjx.run import eval as eval_lib

ARMS = ["regular", "longer", "heavier"]


@pytest.fixture
def stand_in_cells(monkeypatch):
    """`make` and `evaluate_env` replaced: an arm's cells (one per controller, each (arm,
    controller, thread name)) come back after the first two arms have met (so they ran at
    once), the first arm last; 'heavier' fails."""
    met = threading.Barrier(2, timeout=30)
    started = []

    def fake_make(task, arm, controller, **overrides):
        return types.SimpleNamespace(config=types.SimpleNamespace(episode_length=5))

    def fake_arm(env, arm, controllers, episodes, steps, seed, policy, progress, chunk):
        started.append(arm)
        if arm == "heavier":
            raise DpcError("this arm fails")
        met.wait()  # both in flight at once, or a BrokenBarrierError after 30 s
        time.sleep(0.2 if arm == "regular" else 0.0)  # the second arm finishes first
        return [(arm, c, threading.current_thread().name) for c in controllers]

    monkeypatch.setattr(eval_lib, "make", fake_make)
    monkeypatch.setattr(eval_lib, "evaluate_env", fake_arm)
    return started


def test_two_arms_run_at_once_and_come_back_in_cell_order(stand_in_cells):
    seen = []
    cells = eval_lib.evaluate(ARMS[:2], ["mbc", "oracle"], workers=2, on_result=seen.append)
    order = [("regular", "mbc"), ("regular", "oracle"), ("longer", "mbc"), ("longer", "oracle")]
    assert [c[:2] for c in cells] == [c[:2] for c in seen] == order
    assert cells[0][2] != cells[2][2]  # two threads


def test_a_failing_arm_raises_and_no_later_arm_starts(stand_in_cells):
    with pytest.raises(DpcError, match="this arm fails"):
        eval_lib.evaluate(["heavier", *ARMS[:2]], ["mbc"], workers=1)
    assert stand_in_cells == ["heavier"]


def test_two_workers_for_native_cells_on_a_cpu_with_two_cores_else_one(monkeypatch):
    monkeypatch.setattr(eval_lib.os, "sched_getaffinity", lambda pid: {0, 1})
    assert jax.default_backend() == "cpu" and eval_lib.cell_workers("native") == 2
    assert eval_lib.cell_workers("mjx") == 1  # longer compiles, more memory
    monkeypatch.setattr(eval_lib.os, "sched_getaffinity", lambda pid: {0})
    assert eval_lib.cell_workers("native") == 1
    monkeypatch.setattr(eval_lib.os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert eval_lib.cell_workers("native") == 1
