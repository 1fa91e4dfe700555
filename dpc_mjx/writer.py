"""Which process writes a run's files: process 0 only (docs/scaling.md, "Several processes").

In a run of several processes (`devices.initialize`, `jax.distributed`) every process runs the
whole command; only process 0 writes run folders, CSV logs, checkpoints, TensorBoard events,
plots, tables and exports, so a shared file system gets one set of files. Where a later stage
reads back what process 0 wrote (the adapter's samples, the export that is evaluated), every
process waits at a `barrier` first; so the other processes read process 0's files, and a run of
several processes needs its run folder on a file system that they all see.

    is_writer()     True in process 0, and in a one-process run
    barrier(name)   every process of the run waits there for the others (nothing on one process)
"""

from __future__ import annotations

import jax
from jax.experimental import multihost_utils


def is_writer() -> bool:
    """True in the process that writes the run's files (process 0; a one-process run's)."""
    return jax.process_index() == 0


def barrier(name: str) -> None:
    """Wait until every process of the run reaches the barrier `name` (the same names in the same
    order in every process), e.g. after process 0 wrote a file the others read next."""
    if jax.process_count() > 1:
        multihost_utils.sync_global_devices(name)


__all__ = ["barrier", "is_writer"]
