"""The one rollout core: a batch of envs stepped with a policy in jitted chunks, with per-env
episode tallies and optional per-step records.

Everything that steps envs goes through here: the evaluation protocol (`run_episodes`, used by
`dpc_mjx.run.eval`), the adapter's data collection (`adapter.data.collect`, on the auto-reset
batch), SAC's periodic evaluation (`scan_steps` inside its jitted trainer), the demo and the
benchmarks (`make_chunk`). Three layers:

    tally_step(step, policy, record)  one env step of the batch and its tally (pure)
    scan_steps(...)                   `len(keys)` steps under `lax.scan` (pure, jit-able)
    make_chunk / chunks               jitted chunks of steps, iterated on the host; the caller
                                      decides when to stop (and shows progress)
    record_episodes                   one scan of per-step records from the reset on (videos,
                                      trajectory figures)
    run_episodes / run_recorded       the evaluation protocol: per-episode tallies (and per-step
                                      records, e.g. a replay's first pass: `envs/ahead.py`)

A tally is per env and ends at the env's first done (fall or NaN reset): its return is the sum of
rewards up to and including the done step (so a fall's penalty counts once), its error sums
run over the steps before the done ("measured" steps), for RMS values, and it keeps the task's
success measures (`DpcEnv.TASK_MEASURES`) as they were at the episode's end. `step` is a
batched step (`jax.vmap(env.step)`, or a `wrap_for_training` env whose auto-reset keeps the
batch running after a done; the tally still ends at the first done).

On several devices (`dpc_mjx.devices`) `start` puts the batch on the batch sharding, padded to a
multiple of the device count with copies of its first envs; the jitted chunks then step each
env on its device, `chunks` and `run_episodes` gather the results to every process and drop the
padding. The same seed gives the same envs on any number of devices and processes.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterator
from typing import Any

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import Env, State
from flax import struct

from dpc_mjx import devices
from dpc_mjx.errors import DpcError
from dpc_mjx.progress import bar

Policy = Callable[[jax.Array, jax.Array], jax.Array]  # (obs (B, n), key) -> action (B, 6)
Step = Callable[[State, jax.Array], State]  # batched: (state (B, ...), action (B, 6)) -> state
# (state before the step, state after) -> a pytree of per-step values, each (B, ...)
Record = Callable[[State, State], Any]
# Env metrics summed over the measured steps (squared errors: rad^2, (m/s)^2, (rad/s)^2).
ERROR_SUMS = (
    *("roll_sq", "pitch_sq", "vx_sq_err", "vy_sq_err", "yaw_rate_sq_err"),
    *("pos_sq_err", "ee_sq_err"),  # m^2: the desired path, the end effector's targets
)


def zero_policy(obs: jax.Array, key: jax.Array) -> jax.Array:
    """Action 0 (what 'mbc' and 'oracle' envs ignore anyway)."""
    del key
    return jp.zeros(obs.shape[:-1] + (6,))


@struct.dataclass
class Tally:
    """Per-env episode sums, each (B,) float32; an env stops counting at its first done."""

    ret: jax.Array  # sum of rewards up to and including the done step
    length: jax.Array  # steps up to and including the done step
    fell: jax.Array  # 1 if the episode ended in a fall
    nan: jax.Array  # 1 if it ended in a NaN reset
    ended: jax.Array  # 1 once done
    measured: jax.Array  # steps before the done (those of the error sums)
    errors: dict[str, jax.Array]  # `ERROR_SUMS` over the measured steps
    final: dict[str, jax.Array]  # the named metrics at the last step counted (the end)

    @classmethod
    def zeros(cls, batch: int, final: tuple[str, ...] = ()) -> Tally:
        """A zero tally of `batch` envs keeping the metrics `final` at each episode's end."""
        z = jp.zeros(batch)
        return cls(z, z, z, z, z, z, dict.fromkeys(ERROR_SUMS, z), dict.fromkeys(final, z))

    def add(self, state: State) -> Tally:
        """The tally after `state` (the step just taken)."""
        live = 1.0 - self.ended  # 1 while the episode runs
        m = state.metrics
        counted = live * (1.0 - state.done)
        return Tally(
            ret=self.ret + live * state.reward,
            length=self.length + live,
            fell=jp.maximum(self.fell, live * m["fall"]),
            nan=jp.maximum(self.nan, live * m["nan_resets"]),
            ended=jp.maximum(self.ended, live * state.done),
            measured=self.measured + counted,
            errors={k: v + counted * m[k] for k, v in self.errors.items()},
            final={k: jp.where(live > 0, m[k], v) for k, v in self.final.items()},
        )


Carry = tuple[State, Tally]


def tally_step(step: Step, policy: Policy, record: Record | None = None):
    """`((state, tally), key) -> ((state, tally), per-step record or None)`: one env step of
    the batch with action `policy(state.obs, key)`."""

    def one(carry: Carry, key: jax.Array):
        state, tally = carry
        new = step(state, policy(state.obs, key))
        return (new, tally.add(new)), (None if record is None else record(state, new))

    return one


def scan_steps(step: Step, policy: Policy, carry: Carry, keys: jax.Array, record=None):
    """`len(keys)` steps under `lax.scan` (pure; jit it or call it inside a jitted function).
    Returns the carry and the records stacked (steps, B, ...)."""
    return jax.lax.scan(tally_step(step, policy, record), carry, keys)


def make_chunk(step: Step, policy: Policy, chunk: int, record: Record | None = None):
    """jit of `(carry, key) -> (carry, records)`: `chunk` steps, one key per step split from
    `key`. A policy that is a pytree of arrays (`policy.DpcPolicy`) is an argument of the
    compiled program, its weights not constants in it; a plain function is part of it."""

    def chunk_steps(carry: Carry, key: jax.Array, policy: Policy):
        carry, records = scan_steps(step, policy, carry, jax.random.split(key, chunk), record)
        # several devices: the carry stays on the batch sharding it came in (one compile)
        return devices.constrain(carry, len(carry[1].ret)), records

    if _is_data(policy):
        compiled = jax.jit(chunk_steps)
        return lambda carry, key: compiled(carry, key, policy)
    return jax.jit(functools.partial(chunk_steps, policy=policy))


def _is_data(policy: Policy) -> bool:
    """Whether `policy` is a pytree whose leaves are all arrays (its weights)."""
    leaves = jax.tree.leaves(policy)
    return bool(leaves) and all(isinstance(x, jax.Array | np.ndarray) for x in leaves)


def batch_fns(env: Env) -> tuple[Callable[[jax.Array], State], Step]:
    """The batch's reset (keys (B, 2) -> State (B, ...)) and step: `jax.vmap` of the env's
    own, or an env's that is batched already (`batched = True`: `model_batch.ModelBatchEnv`)."""
    if getattr(env, "batched", False):
        return env.reset, env.step
    return jax.vmap(env.reset), jax.vmap(env.step)


def start(env: Env, batch: int, seed: int, groups: int = 1) -> tuple[Carry, jax.Array]:
    """The batch reset from `seed` (env i from the i-th key of one split) with a zero tally
    (keeping the env's `TASK_MEASURES`), and the key that the chunks continue from. With
    `groups` > 1 the batch is `groups` repeats of the same `batch // groups` episodes (env
    g * E + i from the i-th key of a split in E): a sweep meets the same episodes at every
    grid point, and the episodes of a `groups = 1` batch of E. On several devices the batch
    is sharded over them, padded to `devices.padded(batch)` envs with copies of the first ones
    (drop them with `[:batch]` after `devices.to_host`); a batched env (one model per env) is
    not padded: its batch must be a multiple of the device count."""
    if groups < 1 or batch % groups:
        raise DpcError(f"A batch of {batch} envs does not split into {groups} equal groups.")
    key, k_reset = jax.random.split(jax.random.PRNGKey(seed))
    keys = jp.tile(jax.random.split(k_reset, batch // groups), (groups, 1))  # (batch, 2)
    if getattr(env, "batched", False):  # one model per env: no copies to pad with
        devices.check_divisible(batch, "a batch of models (grid points x episodes)")
    size = devices.padded(batch)
    keys = devices.shard(devices.pad(keys, size), size)

    # every leaf on the batch sharding (constant leaves, e.g. zeros, would come out replicated)
    def reset_batch(keys: jax.Array) -> State:
        return devices.constrain(batch_fns(env)[0](keys), size)

    state = jax.jit(reset_batch)(keys)
    tally = devices.shard(Tally.zeros(size, getattr(env, "TASK_MEASURES", ())), size)
    return (state, tally), key


def chunks(
    run_chunk: Callable, carry: Carry, key: jax.Array, count: int | None = None
) -> Iterator[tuple[Carry, Any]]:
    """Run `run_chunk` (from `make_chunk`) again and again, `count` times (None: until the caller
    leaves the loop), yielding `(carry, records as numpy)` after each chunk. The next chunk is
    dispatched before this one's records are copied to the host, so the device runs it while
    the host reads (a caller that leaves early leaves one chunk computed for nothing)."""
    key, k = jax.random.split(key)
    pending, done = run_chunk(carry, k), 1
    while pending is not None:
        carry, records = pending
        pending = None
        if count is None or done < count:
            key, k = jax.random.split(key)
            pending, done = run_chunk(carry, k), done + 1
        yield jax.block_until_ready(carry), devices.to_host(records)


def record_episodes(
    env: Env, episodes: int, steps: int, seed: int, record: Record, policy: Policy = zero_policy
) -> Any:
    """`record` of every step of `episodes` envs (one batch from `seed`, as `run_episodes`, no
    auto-reset) for `steps` env steps, from the reset on (`record(reset, reset)` first): the
    records as numpy, each (steps + 1, episodes, ...). One jitted scan of `steps` steps."""
    carry, key = start(env, episodes, seed)
    first = devices.to_host(jax.jit(record)(carry[0], carry[0]))
    _, rest = devices.to_host(make_chunk(batch_fns(env)[1], policy, steps, record)(carry, key))
    # the padding of several devices dropped
    return jax.tree.map(
        lambda f, r: np.concatenate([f[None, :episodes], r[:, :episodes]]), first, rest
    )


def run_episodes(
    env: Env,
    episodes: int,
    steps: int,
    seed: int = 0,
    policy: Policy = zero_policy,
    chunk: int = 50,
    progress: bool = False,
    desc: str = "episodes",
    groups: int = 1,
) -> dict[str, np.ndarray]:
    """Run `episodes` envs (one batch, no auto-reset) for `steps` env steps; per-episode arrays
    (episodes,): 'return', 'fell' (bool), 'nan' (bool), 'length' (steps until done,
    inclusive), 'measured' (steps before the done), the `ERROR_SUMS` over the measured
    steps and the env's `TASK_MEASURES` at each episode's end. Steps run in jitted chunks of
    the largest divisor of `steps` not above `chunk`. `groups`: the batch is that many repeats
    of the same episodes (`start`; sweeps)."""
    run = _Run(episodes, steps, seed, chunk, progress, desc, groups)
    return _run(env, policy, run)[0]


def run_recorded(
    env: Env,
    episodes: int,
    steps: int,
    record: Record | None,
    seed: int = 0,
    prepare: Callable[[State], State] | None = None,
    progress: bool = False,
    desc: str = "episodes",
) -> tuple[dict[str, np.ndarray], Any]:
    """`run_episodes` (action 0) with `record` of every step: (the per-episode arrays, the
    records as numpy, each (steps, episodes, ...); None without `record`); `prepare` edits the
    reset batch first (a replay's recordings: `envs.ahead.attach`)."""
    run = _Run(episodes, steps, seed, 50, progress, desc, 1, record, prepare)
    return _run(env, zero_policy, run)


@dataclasses.dataclass(frozen=True)
class _Run:
    """How `_run` runs: `run_episodes`' and `run_recorded`'s arguments."""

    episodes: int
    steps: int
    seed: int
    chunk: int
    progress: bool
    desc: str
    groups: int
    record: Record | None = None
    prepare: Callable[[State], State] | None = None


def _run(env: Env, policy: Policy, run: _Run) -> tuple[dict[str, np.ndarray], Any]:
    """The per-episode arrays of `run_episodes` and the records (None without `run.record`)."""
    episodes, steps = run.episodes, run.steps
    if episodes < 1 or steps < 1 or run.chunk < 1:
        raise DpcError(
            f"run_episodes needs episodes, steps and chunk >= 1, got {episodes}, {steps}, "
            f"{run.chunk}."
        )
    chunk = max(c for c in range(1, min(run.chunk, steps) + 1) if steps % c == 0)
    carry, key = start(env, episodes, run.seed, run.groups)
    if run.prepare is not None:
        carry = (run.prepare(carry[0]), carry[1])
    run_chunk = make_chunk(batch_fns(env)[1], policy, chunk, run.record)
    records = []
    with bar(episodes * steps, run.desc, "step", run.progress) as pbar:
        for carry, rec in chunks(run_chunk, carry, key, steps // chunk):
            records.append(rec)
            pbar.update(episodes * chunk)
    t = jax.tree.map(lambda x: x[:episodes], devices.to_host(carry[1]))  # padding dropped
    stacked = None
    if run.record is not None:  # (steps, episodes, ...), the padding dropped
        stacked = jax.tree.map(lambda *r: np.concatenate(r)[:, :episodes], *records)
    per_episode = {
        "return": np.asarray(t.ret),
        "length": np.asarray(t.length),
        "fell": np.asarray(t.fell) > 0,
        "nan": np.asarray(t.nan) > 0,
        "measured": np.asarray(t.measured),
        **{k: np.asarray(v) for k, v in t.errors.items()},
        **{k: np.asarray(v) for k, v in t.final.items()},
    }
    return per_episode, stacked
