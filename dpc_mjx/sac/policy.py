"""Moved to `dpc_mjx.policy.policy` (the deployable policy); this old path re-exports it."""

from dpc_mjx.policy.policy import *  # noqa: F403
