"""Progress bars with an ETA for every long loop (tqdm on stderr), off with `enabled=False`."""

from __future__ import annotations

import sys

from tqdm import tqdm


def bar(total: int, desc: str, unit: str = "it", enabled: bool = True) -> tqdm:
    """A progress bar of `total` units; use as a context manager and call `.update(n)`."""
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        unit_scale=True,
        dynamic_ncols=True,
        disable=not enabled,
        file=sys.stderr,
        smoothing=0.1,
    )
