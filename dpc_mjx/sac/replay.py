"""SAC's replay buffer: brax's uniform-sampling queue as a ring, so a full buffer is never moved.

brax's `UniformSamplingQueue` keeps its transitions oldest first: once full, every insert rolls
the whole buffer (`jnp.roll`, the paper recipe's 200,000 x 71 floats, 57 MB) to drop the oldest.
`RingSamplingQueue` writes each insert over the oldest transitions in place instead, and reads
logical index i (0 = the oldest) at physical row `(head + i) mod N`. It holds the same
transitions, and from the same buffer key draws the same indices and so the same samples as
brax's queue, bit for bit (tested), with brax's `ReplayBufferState` unchanged:

    insert_position  in [0, 2N): below N, the buffer holds that many transitions (head 0);
                     from N on it is full, and head = insert_position - N (the oldest row)
    sample_position  0 (brax's queue only moves it when it rolls; sampling starts there)

A full buffer of brax's queue (insert_position N, oldest first) is the ring's with head 0, so
checkpoints written before this module resume unchanged.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from brax.training import replay_buffers
from brax.training.replay_buffers import ReplayBufferState

from dpc_mjx.errors import DpcError


class RingSamplingQueue(replay_buffers.UniformSamplingQueue):
    """brax's `UniformSamplingQueue` (same constructor, state and samples) as a ring buffer."""

    @property
    def capacity(self) -> int:
        return self._data_shape[0]

    def check_can_insert(self, buffer_state, samples, shards) -> None:
        rows = jax.tree_util.tree_leaves(samples)[0].shape[0] // shards
        if rows > self.capacity:
            raise DpcError(
                f"Cannot insert {rows} transitions at once into a replay buffer of "
                f"{self.capacity}: raise sac.max_replay_size to at least sac.num_envs."
            )

    def insert_internal(self, buffer_state: ReplayBufferState, samples) -> ReplayBufferState:
        """Write the k rows of `samples` over the oldest (or the free) rows, in place."""
        update = self._flatten_fn(samples)  # (k, data_size)
        n, k = self.capacity, update.shape[0]
        position = buffer_state.insert_position  # () in [0, 2N)
        rows = (position + jp.arange(k)) % n  # the next write is at the head (full) or the end
        data = buffer_state.data.at[rows].set(update, unique_indices=True)
        after = position + k
        after = jp.where(after >= n, n + (after - n) % n, after)
        return buffer_state.replace(data=data, insert_position=after)

    def sample_internal(self, buffer_state: ReplayBufferState):
        """`sample_batch_size` transitions drawn uniformly with replacement, as brax's queue
        draws them (the same key split, the same logical indices)."""
        key, sample_key = jax.random.split(buffer_state.key)
        idx = jax.random.randint(
            sample_key,
            (self._sample_batch_size,),
            minval=buffer_state.sample_position,
            maxval=jp.minimum(buffer_state.insert_position, self.capacity),  # the logical end
        )
        rows = (self._head(buffer_state) + idx) % self.capacity
        batch = jp.take(buffer_state.data, rows, axis=0, mode="clip")
        return buffer_state.replace(key=key), self._unflatten_fn(batch)

    def size(self, buffer_state: ReplayBufferState) -> jax.Array:
        """() transitions held."""
        return (
            jp.minimum(buffer_state.insert_position, self.capacity) - buffer_state.sample_position
        )

    def _head(self, buffer_state: ReplayBufferState) -> jax.Array:
        """() the physical row of the oldest transition."""
        return jp.maximum(buffer_state.insert_position - self.capacity, 0)


__all__ = ["RingSamplingQueue"]
