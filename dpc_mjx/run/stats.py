"""Moved to `dpc_mjx.stats` (a utility module); this path keeps working."""

from dpc_mjx.stats import mcnemar_counts, mcnemar_p, mean_ci, paired_diff_ci, wilson_ci  # noqa: F401
