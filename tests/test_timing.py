"""`dpc_mjx.timing`, the benchmarks' timing helper: what is called, how often, what comes back."""

import math
import time

import jax
import jax.numpy as jp

from dpc_mjx.timing import Stopwatch, run_calls, time_calls, timed


def test_stopwatch_times_a_block_and_runs_outside_one():
    clock = Stopwatch()
    assert math.isnan(clock.seconds) and clock.elapsed() >= 0.0
    with Stopwatch() as sw:
        time.sleep(0.01)
    assert 0.01 <= sw.seconds < 5.0 and sw.elapsed() >= sw.seconds


def test_timed_returns_the_finished_result_and_its_seconds():
    out, seconds = timed(jax.jit(lambda x, y: x * y), jp.arange(3.0), y=2.0)
    assert out.tolist() == [0.0, 2.0, 4.0] and seconds > 0.0


def test_time_calls_runs_one_first_call_then_the_steady_state_calls():
    calls = []

    def step(x):
        calls.append(x)
        return x + 1

    first, per_call, x = time_calls(step, 0, calls=4)
    assert x == 5 and calls == [0, 1, 2, 3, 4]  # the first call, then 4 timed apart
    assert first >= 0.0 and per_call >= 0.0
    seconds, x = run_calls(step, jp.zeros(2), 3)
    assert x.tolist() == [3.0, 3.0] and seconds >= 0.0
