"""Moved to `dpc_mjx.serialization` (a utility under every layer); this old path re-exports it."""

from dpc_mjx.serialization import *  # noqa: F403
