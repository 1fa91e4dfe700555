"""`run.eval.evaluate` runs native cells two at a time on a CPU and hands them back in cell order
(no compiling: the cells are stand-ins; that real cells give the same figures either way is
checked bit for bit by experiments/bench_eval_workers.py, docs/benchmarks.md)."""

import threading
import time
import types

import jax
import pytest

from dpc_mjx import DpcError
from dpc_mjx.run import eval as eval_lib

CONTROLLERS = ["mbc", "observer", "oracle"]


@pytest.fixture
def stand_in_cells(monkeypatch):
    """`make` and `evaluate_env` replaced: a cell returns (controller, thread name) after the
    first two cells have met (so they ran at once), the first cell last."""
    met = threading.Barrier(2, timeout=30)
    started = []

    def fake_make(task, arm, controller, **overrides):
        return types.SimpleNamespace(config=types.SimpleNamespace(episode_length=5))

    def fake_cell(env, arm, controller, episodes, steps, seed, policy, progress):
        started.append(controller)
        if controller == "oracle":
            raise DpcError("this cell fails")
        if controller in ("mbc", "observer"):
            met.wait()  # both in flight at once, or a BrokenBarrierError after 30 s
        time.sleep(0.2 if controller == "mbc" else 0.0)  # the second cell finishes first
        return (controller, threading.current_thread().name)

    monkeypatch.setattr(eval_lib, "make", fake_make)
    monkeypatch.setattr(eval_lib, "evaluate_env", fake_cell)
    return started


def test_two_cells_run_at_once_and_come_back_in_cell_order(stand_in_cells):
    seen = []
    cells = eval_lib.evaluate(["regular"], CONTROLLERS[:2], workers=2, on_result=seen.append)
    assert [c[0] for c in cells] == [c[0] for c in seen] == ["mbc", "observer"]
    assert cells[0][1] != cells[1][1]  # two threads


def test_a_failing_cell_raises_and_no_later_cell_starts(stand_in_cells):
    with pytest.raises(DpcError, match="this cell fails"):
        eval_lib.evaluate(["regular"], ["oracle", *CONTROLLERS[:2]], workers=1)
    assert stand_in_cells == ["oracle"]


def test_two_workers_for_native_cells_on_a_cpu_with_two_cores_else_one(monkeypatch):
    monkeypatch.setattr(eval_lib.os, "sched_getaffinity", lambda pid: {0, 1})
    assert jax.default_backend() == "cpu" and eval_lib.cell_workers("native") == 2
    assert eval_lib.cell_workers("mjx") == 1  # longer compiles, more memory
    monkeypatch.setattr(eval_lib.os, "sched_getaffinity", lambda pid: {0})
    assert eval_lib.cell_workers("native") == 1
    monkeypatch.setattr(eval_lib.os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert eval_lib.cell_workers("native") == 1
