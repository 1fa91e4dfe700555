"""Many devices, many processes: the env batch sharded over every device of a run.

A run sees the devices of all its processes (`jax.devices()`); on one machine that is one CPU,
or several GPUs, or N host devices forced with `XLA_FLAGS=--xla_force_host_platform_device_count=N`.
Several processes (one per host) form one run once `initialize` has started `jax.distributed`;
then a jitted program spans every process (on CPU its collectives go over gloo, jax's default)
and each process computes its own devices' part of the batch.

    mesh(local)           a 1-D mesh, axis 'batch', over every device of the run (or this
                          process's own, `local=True`: what SAC trains on)
    padded(batch, mesh)   the batch rounded up to a multiple of the device count
    shard(tree, batch)    put the leaves with a leading axis `batch` on the batch sharding (the
                          rest replicated): the batch split evenly over the devices
    constrain(tree, batch) the same inside a jitted function (keeps a scan's carry sharded)
    to_host(tree)         numpy arrays of the whole batch, on every process (gathered)

Padding rule: a batch that is not a multiple of the device count is padded with copies of its
first envs (the same reset keys), whose results are dropped (`pad`); so `rollout.run_episodes`
and `adapter.collect` give the same envs from the same seeds on any number of devices. Where
extra envs would change the result (SAC's env batch fills its replay buffer; a batch of models
has one model per env), `check_divisible` raises.

On a single device every function here returns its input unchanged, so a 1-device run runs
exactly the programs it ran before sharding existed.
"""

from __future__ import annotations

import os

import jax
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from dpc_mjx.errors import DpcError

BATCH_AXIS = "batch"
# Ours, beside jax's own JAX_COORDINATOR_ADDRESS (jax reads the other two only from a cluster
# manager: SLURM, Open MPI, Kubernetes)
NUM_PROCESSES_VAR, PROCESS_ID_VAR = "DPC_NUM_PROCESSES", "DPC_PROCESS_ID"
AUTO = "auto"  # coordinator: let jax find everything in the cluster manager's environment


def initialize(
    coordinator: str | None = None, num_processes: int | None = None, process_id: int | None = None
) -> bool:
    """Join a run of several processes (`jax.distributed.initialize`) before anything touches a
    device. Each argument left None is read from the environment: `JAX_COORDINATOR_ADDRESS`
    (host:port of process 0), `DPC_NUM_PROCESSES`, `DPC_PROCESS_ID`. No coordinator at all: a
    single-process run, nothing to do (returns False). `coordinator='auto'`: jax reads all three
    from SLURM, Open MPI or Kubernetes. Returns True once the run spans its processes."""
    coordinator = coordinator or os.environ.get("JAX_COORDINATOR_ADDRESS")
    num_processes = _int_option(num_processes, NUM_PROCESSES_VAR, "--num-processes")
    process_id = _int_option(process_id, PROCESS_ID_VAR, "--process-id")
    if coordinator is None:
        if num_processes is not None or process_id is not None:
            raise DpcError(
                "A run of several processes needs the coordinator's address: pass --coordinator "
                "HOST:PORT (process 0's host, a free port) or set JAX_COORDINATOR_ADDRESS."
            )
        return False
    if jax.distributed.is_initialized():
        return True
    if coordinator != AUTO:
        if num_processes is None or process_id is None:
            raise DpcError(
                f"With --coordinator {coordinator}, give --num-processes N and --process-id I "
                f"(or {NUM_PROCESSES_VAR}, {PROCESS_ID_VAR}); or --coordinator auto on SLURM, "
                "Open MPI or Kubernetes."
            )
        if not 0 <= process_id < num_processes:
            raise DpcError(f"process id {process_id} must be in [0, {num_processes}).")
    try:
        jax.distributed.initialize(
            None if coordinator == AUTO else coordinator, num_processes, process_id
        )
    except (RuntimeError, ValueError) as e:
        raise DpcError(
            f"Cannot start jax.distributed ({e}); start it before any JAX computation, with "
            "the same coordinator and process count in every process."
        ) from e
    return True


def _int_option(value: int | None, var: str, flag: str) -> int | None:
    if value is not None or var not in os.environ:
        return value
    try:
        return int(os.environ[var])
    except ValueError as e:
        raise DpcError(f"{var}={os.environ[var]!r} must be an int (as {flag}).") from e


def is_main_process() -> bool:
    """True in process 0 (the one that writes files and shows progress), and in a 1-process run."""
    return jax.process_index() == 0


def mesh(local: bool = False) -> Mesh:
    """A 1-D mesh, axis `BATCH_AXIS`, over every device of the run (`local`: of this process)."""
    devices = jax.local_devices() if local else jax.devices()
    # Auto axes (jax.sharding.Mesh's default; jax.make_mesh's explicit axes break threefry's
    # random bits under vmap in jax 0.9.2)
    return Mesh(np.array(devices), (BATCH_AXIS,))


def padded(batch: int, on: Mesh | None = None) -> int:
    """`batch` rounded up to a multiple of the mesh's device count."""
    n = (on or mesh()).size
    return -(-batch // n) * n


def pad(x, size: int):
    """`x` (batch, ...) grown to (size, ...) by repeating its rows from the first (numpy or jax)."""
    if len(x) == size:
        return x
    return x[np.arange(size) % len(x)]


def check_divisible(batch: int, what: str, on: Mesh | None = None) -> None:
    """`DpcError` unless `batch` splits evenly over the mesh (where padding would alter results)."""
    n = (on or mesh()).size
    if batch % n:
        raise DpcError(
            f"{what}={batch} must be a multiple of the {n} devices it is sharded over: set it to "
            f"{padded(batch, on)} (or run on fewer devices)."
        )


def _spec(x, batch: int) -> P:
    return P(BATCH_AXIS) if getattr(x, "ndim", 0) >= 1 and x.shape[0] == batch else P()


def shard(tree, batch: int, on: Mesh | None = None):
    """`tree` on the mesh: leaves with a leading axis of `batch` split over the devices (batch must
    divide their count: `padded`), others replicated. Every process passes the same whole values
    (each keeps its devices' part). Unchanged on one device."""
    on = on or mesh()
    if on.size == 1:
        return tree
    check_divisible(batch, "the batch", on)
    return jax.tree.map(lambda x: jax.device_put(x, NamedSharding(on, _spec(x, batch))), tree)


def constrain(tree, batch: int, on: Mesh | None = None):
    """`shard` inside a jitted function (`jax.lax.with_sharding_constraint`), e.g. on a scan's
    carry, so that the compiler keeps each env on its device. Unchanged on one device."""
    on = on or mesh()
    if on.size == 1:
        return tree
    return jax.tree.map(
        lambda x: jax.lax.with_sharding_constraint(x, NamedSharding(on, _spec(x, batch))), tree
    )


def to_host(tree):
    """Numpy arrays of every leaf, whole (a batch sharded over several processes is gathered to
    every process, `multihost_utils.process_allgather`)."""

    def get(x):
        if isinstance(x, jax.Array) and not x.is_fully_addressable:
            return np.asarray(multihost_utils.process_allgather(x, tiled=True))
        return np.asarray(jax.device_get(x))

    return jax.tree.map(get, tree)


def describe() -> str:
    """'N devices (platform) in M processes' of this run, for logs and benchmark tables."""
    devices = jax.devices()
    return f"{len(devices)} {devices[0].platform} devices in {jax.process_count()} processes"


__all__ = [
    "AUTO",
    "BATCH_AXIS",
    "NUM_PROCESSES_VAR",
    "PROCESS_ID_VAR",
    "check_divisible",
    "constrain",
    "describe",
    "initialize",
    "is_main_process",
    "mesh",
    "pad",
    "padded",
    "shard",
    "to_host",
]
