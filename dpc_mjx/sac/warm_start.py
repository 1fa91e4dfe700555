"""Moved to `dpc_mjx.policy.regression` (the oracle regression); this old path re-exports it."""

from dpc_mjx.policy.regression import *  # noqa: F403
