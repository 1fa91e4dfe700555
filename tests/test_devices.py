"""Many devices, many processes (`dpc_mjx.devices`): evaluation sharded over 2 forced host devices
and over 2 local processes (`jax.distributed`) gives the 1-device episodes.

`XLA_FLAGS=--xla_force_host_platform_device_count=2` must be set before JAX starts its backend,
so every sharded run is a subprocess running this file (`python tests/test_devices.py ...`, the
`_worker` below), which writes its gathered per-episode arrays to an .npz. The default tests use
`ToyEnv` (a brax-API env that compiles in a second: the sharding, padding and gathering are the
rollout core's and SAC's, not the env's); the slow ones run the reaching task's MJX env
(evaluation, collection, SAC).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import socket
import subprocess
import sys
import types

import jax
import jax.numpy as jp
import numpy as np
import pytest
from brax.envs.base import Env, State
from helpers import recorded_compiles
from test_sac import _CONFIG, reaching_latent_env

from dpc_mjx import DpcError, adapter, devices
from dpc_mjx.envs import DEFAULT_TASK, rollout
from dpc_mjx.envs.registry import make
from dpc_mjx.sac import SacConfig, make_trainer, train

HERE = pathlib.Path(__file__).resolve()
ROOT = HERE.parents[1]
# A sharded run is one XLA program per device over its part of the batch: exactly what one device
# computes for that part alone (measured: bit for bit). The toy env's results do not depend on the
# batch size, so sharded and 1-device runs match to the last bit here (measured); the tolerance
# leaves room for another machine's vector code. Booleans and step counts must match exactly.
RTOL, ATOL = 1e-5, 1e-6
# The MJX env's do depend on the batch size, by the float32 QP solver's tolerance: its solution
# agrees with itself to that tolerance, not to the last bit, once the batch (its SIMD lanes) is
# another size. Measured on one device: batch 4 vs batch 2 from the same keys, qpos differs by
# 2e-4 after one env step (MJX physics alone: 1e-9); over 20 steps the episodes' sums differ by
# up to 0.7% and the collected rows by up to 1.4% of each array's largest value. So on 2 devices
# (2 envs each) the reaching task's arrays must match to this fraction of their largest value.
QP_BATCH_TOLERANCE = 0.03
LEARNED_RETURN = 15.0  # toy SAC: of at most 30 (30 steps, reward <= 1), < 0 if x falls
TIMEOUT = 900  # s, one subprocess (the slow tests compile the MJX env in it)
# XLA's optimisation off in every process of a slow test: the same options in the reference and
# the sharded runs (they round alike), compiles ~40% shorter (tests/helpers.FAST_COMPILE)
FAST_XLA_FLAGS = "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"
EPISODES, STEPS, SEED = 5, 12, 7  # toy evaluation; 5 episodes: padded to 6 on 2 devices


class ToyEnv(Env):
    """A brax env, one unbatched and pure: a point x (3,) drifting outwards under the action
    (its first 3 entries) and per-env noise, 'falling' when |x| > 1.5; reward exp(-|x|^2) a step
    (SAC learns to hold x near 0); the metrics the rollout core tallies."""

    TASK_MEASURES = ("dist",)
    config = types.SimpleNamespace(episode_length=30)  # env steps (SAC's evaluation episodes)

    def reset(self, key: jax.Array) -> State:
        k_x, k_rng = jax.random.split(key)
        x = jax.random.uniform(k_x, (3,), minval=-1.0, maxval=1.0)
        return State(x, x, jp.zeros(()), jp.zeros(()), self._metrics(x, 0.0), {"rng": k_rng})

    def step(self, state: State, action: jax.Array) -> State:
        rng, k = jax.random.split(state.info["rng"])
        x = 1.05 * state.pipeline_state + 0.1 * jp.tanh(action[:3])
        x = x + 0.05 * jax.random.normal(k, (3,))
        fell = (jp.linalg.norm(x) > 1.5).astype(jp.float32)
        reward = jp.exp(-jp.sum(x**2)) - 1000.0 * fell
        metrics = self._metrics(x, fell)
        return state.replace(
            pipeline_state=x,
            obs=x,
            reward=reward,
            done=fell,
            metrics=metrics,
            info={**state.info, "rng": rng},
        )

    @staticmethod
    def _metrics(x, fell) -> dict:
        sq = {k: jp.sum(x**2) for k in rollout.ERROR_SUMS}
        sq["roll_sq"], sq["pitch_sq"] = x[0] ** 2, x[1] ** 2
        return {
            "fall": jp.asarray(fell, jp.float32),
            "nan_resets": jp.zeros(()),
            "dist": x[2],
            **sq,
        }

    observation_size = 3
    action_size = 6
    backend = "toy"


def noisy_policy(obs: jax.Array, key: jax.Array) -> jax.Array:
    """Random actions (B, 6) from one key per step: sharded, each device draws its envs' part."""
    return jax.random.normal(key, obs.shape[:-1] + (6,)) - obs[..., :1]


def _toy(episodes: int = EPISODES, steps: int = STEPS, seed: int = SEED) -> dict:
    """Toy episodes, where the batch lives (devices at the start, after a chunk; envs) and the
    compiles of a second chunk (0: the carry keeps its sharding from chunk to chunk)."""
    env = ToyEnv()
    carry, key = rollout.start(env, episodes, seed)
    run_chunk = rollout.make_chunk(jax.vmap(env.step), noisy_policy, 2)
    after = run_chunk(carry, key)[0]
    with recorded_compiles() as compiles:
        jax.block_until_ready(run_chunk(after, key))
    out = rollout.run_episodes(env, episodes, steps, seed, noisy_policy, chunk=4)
    shards = [len(s.obs.sharding.device_set) for s in (carry[0], after[0])]
    return out | {"_shards": np.array([*shards, after[0].obs.shape[0], len(compiles)])}


def _reaching() -> dict:
    """20 steps of 4 reaching episodes (MBC), and 90 random-motion samples from 3 envs."""
    # MJX on every device count ('auto' would pick native MuJoCo C on one CPU device)
    out = rollout.run_episodes(make(DEFAULT_TASK, arm="regular", engine="mjx"), 4, 20, 3, chunk=10)
    env = make(DEFAULT_TASK, arm="regular", controller="mbc", engine="mjx")
    data = adapter.collect(env, 90, n_envs=3, seed=5, chunk=10, progress=False)
    names = ("s_body", "s_arm", "s_drp_next", "env_id", "u_oracle")
    return out | {f"data_{k}": getattr(data, k) for k in names}


SAC_TOY = dict(  # 4 epochs of 64 actor steps x 8 envs: the toy task is learned by the 3rd
    num_timesteps=2048,
    num_envs=8,
    batch_size=64,
    grad_updates_per_step=4,
    min_replay_size=256,
    max_replay_size=8192,
    epoch_steps=512,
    eval_every=1,
    eval_envs=5,  # padded to 6 on 2 devices
    learning_rate=1e-3,
)


def _sac(kind: str) -> dict:
    """A short SAC run: its evaluations (epoch 0: the starting actor) and the devices its env
    batch lives on after an epoch."""
    if kind == "sac-toy":
        env, config = ToyEnv(), SacConfig(**SAC_TOY)
    else:  # tests/test_sac.py's env and config (3 epochs of 32 actor steps x 8 envs)
        env, config = reaching_latent_env("mjx")[1], _CONFIG
    trainer = make_trainer(env, config)
    carry = trainer.init(jax.random.PRNGKey(config.seed))
    epoch = trainer.compiled("epoch", carry, trainer.reset(jax.random.PRNGKey(0)))
    h = train(trainer, progress=False).history  # the compiled epoch above
    out = {k: np.array([r[k] for r in h]) for k in ("eval_return", "eval_fall_rate")}
    out["critic_loss"] = np.array([r["critic_loss"] for r in h[1:]])
    return out | {"_shards": np.array([len(epoch.output_shardings[1].obs.device_set)])}


def _worker(argv: list[str]) -> None:
    """One run (a subprocess of the tests): join the processes, run, write the gathered arrays."""
    p = argparse.ArgumentParser()
    p.add_argument("--kind", choices=["toy", "reaching", "sac-toy", "sac-reaching"])
    p.add_argument("--out", required=True)
    p.add_argument("--coordinator")
    p.add_argument("--num-processes", type=int)
    p.add_argument("--process-id", type=int)
    args = p.parse_args(argv)
    devices.initialize(args.coordinator, args.num_processes, args.process_id)
    cache = os.environ.get("DPC_JAX_CACHE", str(ROOT / ".cache" / "jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    kinds = {"toy": _toy, "reaching": _reaching}
    out = kinds[args.kind]() if args.kind in kinds else _sac(args.kind)
    out["_devices"] = np.array([jax.device_count(), jax.process_count()])
    np.savez(args.out, **out)


def _launch(tmp: pathlib.Path, kind: str, n_processes: int, n_devices: int) -> list:
    """Start `n_processes` workers of `kind` on localhost, each with `n_devices` (forced host)
    devices; `_results` waits for them."""
    env = _subprocess_env()
    flags = [f"--xla_force_host_platform_device_count={n_devices}"] if n_devices > 1 else []
    if "reaching" in kind:
        flags.append(FAST_XLA_FLAGS)
    env["XLA_FLAGS"] = " ".join([env.get("XLA_FLAGS", ""), *flags]).strip()
    tmp.mkdir(parents=True, exist_ok=True)
    args = [f"--kind={kind}"]
    if n_processes > 1:
        args += [f"--coordinator=127.0.0.1:{_free_port()}", f"--num-processes={n_processes}"]
    procs = []
    for i in range(n_processes):
        pid = [f"--process-id={i}"] if n_processes > 1 else []
        out = tmp / f"out{i}.npz"
        cmd = [sys.executable, str(HERE), *args, *pid, f"--out={out}"]
        procs.append(
            (subprocess.Popen(cmd, env=env, cwd=ROOT, stderr=subprocess.PIPE, text=True), out)
        )
    return procs


def _results(procs: list) -> list[dict]:
    """The arrays each worker wrote, one dict per process."""
    errors = [proc.communicate(timeout=TIMEOUT)[1] for proc, _ in procs]
    logs = [f"process {i}:\n{err[-3000:]}" for i, err in enumerate(errors)]
    assert all(p.returncode == 0 for p, _ in procs), "\n".join(logs)
    return [dict(np.load(out)) for _, out in procs]


def _subprocess_env() -> dict:
    path = [p for p in (os.environ.get("PYTHONPATH"), str(ROOT)) if p]
    return dict(os.environ, PYTHONPATH=os.pathsep.join(path), JAX_PLATFORMS="cpu")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _assert_same_episodes(got: dict, expected: dict, scale_rtol: float | None = None) -> None:
    """The per-episode arrays (not the '_' entries: devices, shards) within RTOL, or within
    `scale_rtol` times each array's largest value."""
    expected = {k: v for k, v in expected.items() if not k.startswith("_")}
    assert set(expected) <= set(got) and len(expected) > 10
    for k, v in expected.items():
        if v.dtype == bool or k in ("length", "measured", "data_env_id"):
            np.testing.assert_array_equal(got[k], v, err_msg=k)
        elif scale_rtol is None:
            np.testing.assert_allclose(got[k], v, rtol=RTOL, atol=ATOL, err_msg=k)
        else:
            atol = scale_rtol * np.max(np.abs(v))
            np.testing.assert_allclose(got[k], v, rtol=0.0, atol=atol, err_msg=k)


def test_evaluation_on_two_forced_host_devices_equals_one_device(tmp_path):
    (sharded,) = _results(_launch(tmp_path, "toy", 1, 2))
    assert list(sharded["_devices"]) == [2, 1]
    # padded to 6 envs, 3 per device, before and after a chunk; no compile of a second chunk
    assert list(sharded["_shards"]) == [2, 2, EPISODES + 1, 0]
    reference = _toy()  # this process: one device
    assert jax.device_count() == 1 and list(reference["_shards"]) == [1, 1, EPISODES, 0]
    assert 0 < reference["fell"].sum() < EPISODES  # episodes end at different steps
    _assert_same_episodes(sharded, reference)


def test_two_local_processes_gather_the_one_process_result(tmp_path):
    results = _results(_launch(tmp_path, "toy", 2, 1))
    reference = _toy()
    for r in results:  # every process holds the whole, gathered batch
        assert list(r["_devices"]) == [2, 2]
        assert list(r["_shards"]) == [2, 2, EPISODES + 1, 0]
        _assert_same_episodes(r, reference)


def test_sac_sharded_over_two_devices_learns_as_on_one(tmp_path):  # ~20 s: 2 toy SAC runs
    """Not bit for bit (the normaliser's sums and the buffer's gathering run across devices),
    but the same starting actor scores the same, and both runs learn the task."""
    (sharded,) = _results(_launch(tmp_path, "sac-toy", 1, 2))
    reference = _sac("sac-toy")
    assert list(sharded["_shards"]) == [2]  # the env batch is still split after an epoch
    for run in (sharded, reference):
        assert run["eval_return"][0] < 0 < LEARNED_RETURN < run["eval_return"][-1]
        assert run["eval_fall_rate"][-1] == 0.0
    np.testing.assert_allclose(sharded["eval_return"][0], reference["eval_return"][0], RTOL)


@pytest.mark.slow  # compiles of the MJX env (~1-2 min each on 2 cores); `make test-all`
def test_reaching_evaluation_and_collection_sharded_equal_one_device(tmp_path):
    reference, two_devices = (
        _launch(tmp_path / "1", "reaching", 1, 1),
        _launch(tmp_path / "2", "reaching", 1, 2),
    )
    (reference,), (two_devices,) = _results(reference), _results(two_devices)
    two_processes = _results(_launch(tmp_path / "p", "reaching", 2, 1))
    for r in (two_devices, *two_processes):
        _assert_same_episodes(r, reference, QP_BATCH_TOLERANCE)


@pytest.mark.slow  # SAC's epoch and evaluation compiled twice on the MJX env
def test_sac_on_the_reaching_task_runs_sharded(tmp_path):
    one, two = (
        _launch(tmp_path / "1", "sac-reaching", 1, 1),
        _launch(tmp_path / "2", "sac-reaching", 1, 2),
    )
    (one,), (two,) = _results(one), _results(two)
    assert list(two["_shards"]) == [2]
    assert np.isfinite(two["critic_loss"]).all() and np.isfinite(two["eval_return"]).all()
    # the starting actor on the same evaluation episodes: the same score (to the QP's tolerance)
    np.testing.assert_allclose(two["eval_return"][0], one["eval_return"][0], QP_BATCH_TOLERANCE)


def test_importing_the_library_leaves_jax_unstarted():
    """`jax.distributed` must start before JAX's backend does: no import may touch a device (a
    module-level `jp.array` would), or `dpc-mjx --coordinator ...` could not start it."""
    code = (
        "import dpc_mjx, dpc_mjx.run.cli, dpc_mjx.run.pipeline\n"
        "from jax._src import xla_bridge\n"
        "assert not xla_bridge.backends_are_initialized(), 'an import started the backend'"
    )
    run = subprocess.run(
        [sys.executable, "-c", code],
        check=False,
        env=_subprocess_env(),
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr[-2000:]


def test_padding_and_its_error():
    assert devices.padded(5, _FakeMesh(2)) == 6 and devices.padded(6, _FakeMesh(2)) == 6
    np.testing.assert_array_equal(devices.pad(np.arange(3), 5), [0, 1, 2, 0, 1])
    devices.check_divisible(8, "sac.num_envs", _FakeMesh(2))
    with pytest.raises(DpcError, match=r"sac.num_envs=9 must be a multiple of the 2 devices.*10"):
        devices.check_divisible(9, "sac.num_envs", _FakeMesh(2))


def test_batches_that_padding_would_change_must_divide_the_devices(monkeypatch):
    monkeypatch.setattr(devices, "mesh", lambda local=False: _FakeMesh(2))

    class ModelGrid:  # a batch of models (`ModelBatchEnv`): one model per env
        batched = True

    with pytest.raises(DpcError, match=r"grid points x episodes\)=3 must be a multiple of the 2"):
        rollout.start(ModelGrid(), 3, seed=0)
    with pytest.raises(DpcError, match="sac.num_envs=9 must be a multiple of the 2 devices"):
        make_trainer(ToyEnv(), SacConfig(**(SAC_TOY | {"num_envs": 9})))


def test_one_device_leaves_arrays_as_they_are():
    x = {"a": jp.arange(4.0), "b": jp.zeros(())}
    assert devices.shard(x, 4) is x and devices.constrain(x, 4) is x
    host = devices.to_host(x)
    assert isinstance(host["a"], np.ndarray)
    np.testing.assert_array_equal(host["a"], [0, 1, 2, 3])


def test_distributed_options_are_checked_before_starting(monkeypatch):
    for var in ("JAX_COORDINATOR_ADDRESS", devices.NUM_PROCESSES_VAR, devices.PROCESS_ID_VAR):
        monkeypatch.delenv(var, raising=False)
    assert devices.initialize() is False  # nothing asked: one process
    with pytest.raises(DpcError, match="coordinator's address"):
        devices.initialize(num_processes=2, process_id=0)
    with pytest.raises(DpcError, match="--num-processes N and --process-id I"):
        devices.initialize("127.0.0.1:1234", num_processes=2)
    with pytest.raises(DpcError, match=r"process id 2 must be in \[0, 2\)"):
        devices.initialize("127.0.0.1:1234", num_processes=2, process_id=2)
    monkeypatch.setenv(devices.PROCESS_ID_VAR, "one")
    with pytest.raises(DpcError, match="DPC_PROCESS_ID='one' must be an int"):
        devices.initialize("127.0.0.1:1234", num_processes=2)
    assert not jax.distributed.is_initialized()


class _FakeMesh:
    def __init__(self, size: int):
        self.size = size


if __name__ == "__main__":
    _worker(sys.argv[1:])
