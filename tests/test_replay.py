"""SAC's ring replay buffer against brax's uniform-sampling queue: the same transitions held and
the same samples drawn, bit for bit, across the wrap, and from a state brax's queue wrote."""

import jax
import jax.numpy as jp
import numpy as np
import pytest
from brax.training.replay_buffers import UniformSamplingQueue

from dpc_mjx import DpcError
from dpc_mjx.sac.replay import RingSamplingQueue

_CAPACITY, _ROWS, _SAMPLES = 50, 8, 12  # 50 is no multiple of 8: inserts straddle the wrap


def _dummy():
    return {"obs": jp.zeros(3), "reward": jp.zeros(()), "flag": jp.zeros(2)}


def _batch(i: int):
    """_ROWS transitions whose values say which insert and row they are."""
    base = 100.0 * i + jp.arange(_ROWS, dtype=jp.float32)
    return {
        "obs": base[:, None] + jp.arange(3.0),
        "reward": -base,
        "flag": jp.stack([base, base + 0.5], axis=1),
    }


def _queues():
    return (
        UniformSamplingQueue(_CAPACITY, _dummy(), _SAMPLES),
        RingSamplingQueue(_CAPACITY, _dummy(), _SAMPLES),
    )


def _ops(queue):
    return jax.jit(queue.insert), jax.jit(queue.sample), jax.jit(queue.size)


def test_the_ring_holds_and_samples_what_braxs_queue_does_across_the_wrap():
    brax_queue, ring = _queues()
    b_insert, b_sample, b_size = _ops(brax_queue)
    r_insert, r_sample, r_size = _ops(ring)
    b_state = r_state = brax_queue.init(jax.random.PRNGKey(7))
    assert jax.tree.structure(ring.init(jax.random.PRNGKey(7))) == jax.tree.structure(b_state)
    for i in range(20):  # 160 rows into 50: the ring wraps three times
        b_state, r_state = b_insert(b_state, _batch(i)), r_insert(r_state, _batch(i))
        assert int(r_size(r_state)) == int(b_size(b_state)) == min(_ROWS * (i + 1), _CAPACITY)
        assert int(r_state.insert_position) < 2 * _CAPACITY
        # the ring read oldest first is brax's buffer
        size = int(b_size(b_state))
        head = max(int(r_state.insert_position) - _CAPACITY, 0)
        logical = np.roll(np.asarray(r_state.data), -head, axis=0)[:size]
        np.testing.assert_array_equal(logical, np.asarray(b_state.data)[:size])
        for _ in range(2):  # the same key, the same samples
            b_state, b_out = b_sample(b_state)
            r_state, r_out = r_sample(r_state)
            jax.tree.map(np.testing.assert_array_equal, r_out, b_out)
            np.testing.assert_array_equal(r_state.key, b_state.key)


def test_the_ring_continues_from_a_state_braxs_queue_wrote():
    """A checkpoint saved before the ring (brax's queue, full) resumes with the same samples."""
    brax_queue, ring = _queues()
    b_insert, b_sample, _ = _ops(brax_queue)
    r_insert, r_sample, _ = _ops(ring)
    state = brax_queue.init(jax.random.PRNGKey(3))
    for i in range(9):  # 72 rows: full, rolled
        state = b_insert(state, _batch(i))
    assert int(state.insert_position) == _CAPACITY
    b_state = r_state = state
    for i in range(9, 15):
        b_state, r_state = b_insert(b_state, _batch(i)), r_insert(r_state, _batch(i))
        b_state, b_out = b_sample(b_state)
        r_state, r_out = r_sample(r_state)
        jax.tree.map(np.testing.assert_array_equal, r_out, b_out)


def test_an_insert_larger_than_the_buffer_is_refused():
    ring = RingSamplingQueue(4, _dummy(), 2)
    with pytest.raises(DpcError, match="max_replay_size"):
        ring.insert(ring.init(jax.random.PRNGKey(0)), _batch(0))
