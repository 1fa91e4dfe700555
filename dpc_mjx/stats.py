"""Statistics of the evaluation tables and the regressions, in numpy: confidence intervals (fall
rates, mean returns, paired differences, McNemar), and per-column fit scores (R^2, explained
variance, RMSE)."""

from __future__ import annotations

import math

import numpy as np


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


def paired_diff_ci(a: np.ndarray, b: np.ndarray, z: float = 1.96) -> tuple[float, float, float]:
    """Mean of the per-episode differences a - b (the same episodes under two controllers) and
    its normal-approximation 95% interval (mean, low, high): the paired comparison."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        raise ValueError(f"paired samples need the same episodes, got {a.shape} and {b.shape}")
    return mean_ci(a - b, z)


def mcnemar_counts(fell_a: np.ndarray, fell_b: np.ndarray) -> tuple[int, int]:
    """Discordant pairs of a paired fall comparison: (episodes where only a fell, only b fell).
    An exact McNemar test compares them against Binomial(n, 1/2), n their sum."""
    fell_a, fell_b = np.asarray(fell_a, bool), np.asarray(fell_b, bool)
    return int(np.sum(fell_a & ~fell_b)), int(np.sum(fell_b & ~fell_a))


def mcnemar_p(only_a: int, only_b: int) -> float:
    """Exact two-sided McNemar p-value of the discordant counts (`mcnemar_counts`):
    P(a count as far from n/2 as this | Binomial(n, 1/2)), n = only_a + only_b."""
    n = only_a + only_b
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, k) for k in range(min(only_a, only_b) + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def r2(y: np.ndarray, y_hat: np.ndarray, floor: float | None = None) -> np.ndarray:
    """Coefficient of determination per column, 1 - SS_res / SS_tot: y, y_hat (N, k) or (N,)
    (rows are samples) -> (k,) or (); SS_res = sum over rows of (y_hat - y)^2, SS_tot of
    (y - mean over rows)^2, floored at `floor` when given (a constant column then scores
    1 - SS_res / floor instead of dividing by 0). 1 is a perfect fit, 0 the column's mean, below 0
    worse than the mean. In the arrays' dtype."""
    resid = ((y_hat - y) ** 2).sum(0)
    spread = ((y - y.mean(0)) ** 2).sum(0)
    if floor is not None:
        spread = np.maximum(spread, floor)
    return 1.0 - resid / spread


def explained_variance(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """1 - Var(y - y_hat) / Var(y) per column (y, y_hat (N, k) or (N,) -> (k,) or ()): `r2` with
    the residual's mean removed, equal to it (up to float rounding) for a least-squares fit with
    an intercept, whose residual has zero mean."""
    return 1.0 - (y - y_hat).var(0) / y.var(0)


def rmse(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """Root mean square error per column: y, y_hat (N, k) or (N,) -> (k,) or (), y's units."""
    return np.sqrt(((y_hat - y) ** 2).sum(0) / len(y))
