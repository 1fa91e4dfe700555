"""Fixed-length episodes of a batch of envs, without auto-reset, and their summary statistics.

An episode ends at its first done (fall or NaN reset) or after `steps` env steps; its return is
the sum of rewards up to and including the done step (so a fall's penalty counts once).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import Env

from dpc_mjx.progress import bar

Policy = Callable[[jax.Array, jax.Array], jax.Array]  # (obs (B, n), key) -> action (B, 6)


def zero_policy(obs: jax.Array, key: jax.Array) -> jax.Array:
    """Action 0 (what 'mbc' and 'oracle' envs ignore anyway)."""
    del key
    return jp.zeros(obs.shape[:-1] + (6,))


def run_episodes(
    env: Env,
    episodes: int,
    steps: int,
    seed: int = 0,
    policy: Policy = zero_policy,
    chunk: int = 50,
    progress: bool = False,
    desc: str = "episodes",
) -> dict[str, np.ndarray]:
    """Run `episodes` envs (one batch) for `steps` env steps; per-episode arrays (episodes,):

    'return', 'fell' (bool), 'nan' (bool), 'length' (steps until done, inclusive), and the sums
    of the env's squared-error metrics over the 'measured' steps (those before done: 'roll_sq',
    'pitch_sq', 'vx_sq_err', 'vy_sq_err', 'yaw_rate_sq_err'), for RMS values. Steps are run in
    jitted chunks of the largest divisor of `steps` not above `chunk`; `progress` shows a bar
    over the env steps (all episodes together).
    """
    chunk = max(c for c in range(1, min(chunk, steps) + 1) if steps % c == 0)
    sums = ("roll_sq", "pitch_sq", "vx_sq_err", "vy_sq_err", "yaw_rate_sq_err")
    reset = jax.jit(jax.vmap(env.reset))
    vstep = jax.vmap(env.step)

    def run_chunk(carry, key):
        def one(c, k):
            state, acc = c
            live = 1.0 - acc["ended"]  # (B,) 1 while the episode runs
            state = vstep(state, policy(state.obs, k))
            m = state.metrics
            acc = {
                "return": acc["return"] + live * state.reward,
                "length": acc["length"] + live,
                "fell": jp.maximum(acc["fell"], live * m["fall"]),
                "nan": jp.maximum(acc["nan"], live * m["nan_resets"]),
                "ended": jp.maximum(acc["ended"], live * state.done),
                "measured": acc["measured"] + live * (1.0 - state.done),
                **{s: acc[s] + live * (1.0 - state.done) * m[s] for s in sums},
            }
            return (state, acc), None

        return jax.lax.scan(one, carry, jax.random.split(key, chunk))[0]

    run_chunk = jax.jit(run_chunk)
    key = jax.random.PRNGKey(seed)
    key, k_reset = jax.random.split(key)
    state = reset(jax.random.split(k_reset, episodes))
    zeros = jp.zeros(episodes)
    acc = {k: zeros for k in ("return", "length", "fell", "nan", "ended", "measured", *sums)}
    carry = (state, acc)
    with bar(episodes * steps, desc, "step", progress) as pbar:
        for _ in range(steps // chunk):
            key, k = jax.random.split(key)
            carry = run_chunk(carry, k)
            jax.block_until_ready(carry)
            pbar.update(episodes * chunk)
    acc = jax.device_get(carry[1])
    out = {k: np.asarray(v) for k, v in acc.items() if k != "ended"}
    out["fell"] = out["fell"] > 0
    out["nan"] = out["nan"] > 0
    return out


def wilson_ci(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% (z = 1.96) Wilson score interval of a binomial proportion."""
    if n == 0:
        return (math.nan, math.nan)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def mean_ci(x: np.ndarray, z: float = 1.96) -> tuple[float, float, float]:
    """Mean and its normal-approximation 95% interval (mean, low, high)."""
    x = np.asarray(x, float)
    m = float(np.mean(x))
    if x.size < 2:
        return (m, math.nan, math.nan)
    half = z * float(np.std(x, ddof=1)) / math.sqrt(x.size)
    return (m, m - half, m + half)
