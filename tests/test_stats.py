"""The evaluation's intervals and the fit scores (R^2, RMSE) against values computed by hand
(textbook formulas)."""

import math

import numpy as np
import pytest
from scipy.stats import binomtest

from dpc_mjx.run.eval import CellResult, paired_rows
from dpc_mjx.stats import (
    explained_variance,
    mcnemar_counts,
    mcnemar_p,
    mean_ci,
    paired_diff_ci,
    r2,
    rmse,
    wilson_ci,
)

TOL = 1e-9  # exact formulas: only float rounding


def test_wilson_interval_matches_the_formula_and_stays_in_0_1():
    lo, hi = wilson_ci(39, 128)
    p, n, z = 39 / 128, 128, 1.96
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert lo == pytest.approx(centre - half, abs=TOL) and hi == pytest.approx(centre + half)
    assert wilson_ci(0, 64)[0] == 0.0 and 0.0 < wilson_ci(0, 64)[1] < 0.1
    assert wilson_ci(64, 64)[1] == 1.0 and all(math.isnan(x) for x in wilson_ci(0, 0))


def test_mean_interval_is_the_normal_approximation():
    x = np.array([1.0, 2.0, 4.0, 7.0])
    m, lo, hi = mean_ci(x)
    half = 1.96 * np.std(x, ddof=1) / 2.0
    assert (m, lo, hi) == pytest.approx((3.5, 3.5 - half, 3.5 + half), abs=TOL)


def test_paired_difference_uses_the_per_episode_differences():
    rng = np.random.default_rng(0)
    base = rng.normal(0.0, 100.0, 64)  # episodes differ a lot, controllers a little
    a, b = base + 5.0 + rng.normal(0.0, 1.0, 64), base
    m, lo, hi = paired_diff_ci(a, b)
    assert lo > 0.0 and m == pytest.approx(5.0, abs=0.5)  # paired: the shift is significant
    assert mean_ci(a)[1] < mean_ci(b)[2]  # unpaired intervals overlap on the same data
    with pytest.raises(ValueError, match="same episodes"):
        paired_diff_ci(a, b[:10])


def test_mcnemar_counts_only_the_discordant_episodes():
    fell_a = np.array([1, 1, 0, 0, 1], bool)
    fell_b = np.array([1, 0, 1, 0, 0], bool)
    assert mcnemar_counts(fell_a, fell_b) == (2, 1)


def test_exact_mcnemar_p_matches_the_binomial_test():
    for only_a, only_b in [(19, 2), (15, 8), (3, 3), (0, 7), (1, 0)]:
        expected = binomtest(only_a, only_a + only_b, 0.5).pvalue
        assert mcnemar_p(only_a, only_b) == pytest.approx(expected, rel=1e-12)
    assert mcnemar_p(0, 0) == 1.0


def _cell(controller: str, returns, fell) -> CellResult:
    fell = np.asarray(fell, bool)
    return CellResult(
        *("regular", controller, len(fell), 100, int(fell.sum()), (0.0, 1.0), 0.0, (0.0, 0.0)),
        *(0.0, 0.0, 0.0, 0.0, 0.0, 0, 0.0),
        per_episode={"return": np.asarray(returns, float), "fell": fell},
    )


def test_paired_rows_compare_dpc_with_each_controller_on_the_same_episodes():
    cells = [
        _cell("mbc", [0.0, 1.0, 2.0, 3.0], [1, 1, 1, 0]),
        _cell("dpc", [2.0, 3.0, 4.0, 5.0], [0, 1, 0, 0]),
        _cell("oracle", [3.0, 4.0, 5.0, 6.0], [0, 0, 0, 0]),
    ]
    rows = paired_rows(cells)
    # fall-rate difference: the mean of the per-episode differences (-1, 0, -1, 0) and its
    # normal interval, -0.5 +- 1.96 * std / 2
    half = 1.96 * np.std([-1, 0, -1, 0], ddof=1) / 2
    assert rows[0].startswith(
        f"| regular: dpc - mbc | +2.0 [+2.0, +2.0] | -0.500 [{-0.5 - half:+.3f}, "
        f"{-0.5 + half:+.3f}] | 0 | 2 | 0.5 |"
    )
    assert rows[1].startswith(
        "| regular: dpc - oracle | -1.0 [-1.0, -1.0] | +0.250 [-0.240, +0.740] | 1 | 0 | 1 |"
    )
    assert "dpc closes 67% of the MBC-to-oracle gap" in rows[2]  # (3 - 1) / (3 - 0)


def test_r2_per_column_matches_a_hand_computed_case():
    y = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 3.0]])  # (N=3, k=2)
    y_hat = np.array([[1.0, 1.0], [2.0, 1.0], [4.0, 1.0]])
    # column 0: SS_res 1, SS_tot 2 (mean 2); column 1: SS_res 1 + 1 + 4 = 6, SS_tot 1 + 1 + 4 = 6
    np.testing.assert_allclose(r2(y, y_hat), [0.5, 0.0], atol=TOL)
    np.testing.assert_allclose(r2(y, y), [1.0, 1.0], atol=TOL)
    assert r2(y[:, 0], y_hat[:, 0]) == pytest.approx(0.5, abs=TOL)  # (N,) -> a scalar
    np.testing.assert_allclose(rmse(y, y_hat), [np.sqrt(1 / 3), np.sqrt(6 / 3)], atol=TOL)
    constant = np.ones((3, 1))
    assert r2(constant, constant + 1.0, floor=1e-12)[0] == pytest.approx(1.0 - 3.0 / 1e-12)


def test_r2_of_a_linear_least_squares_fit_is_the_squared_correlation():
    rng = np.random.default_rng(1)
    x = rng.normal(size=200)
    y = 2.0 * x + 0.5 + rng.normal(0.0, 1.0, 200)
    slope, intercept = np.polyfit(x, y, 1)
    expected = np.corrcoef(x, y)[0, 1] ** 2
    assert r2(y, slope * x + intercept) == pytest.approx(expected, abs=1e-12)
    assert explained_variance(y, slope * x + intercept) == pytest.approx(expected, abs=1e-12)


def test_r2_reproduces_the_formulas_it_replaced_bit_for_bit():
    """The R^2 once written out in `sac/warm_start.py` (floored SS_tot), `experiments/
    u_estimation.py` (SS_res / SS_tot) and `experiments/figure_latent.py` (variances, float32 y
    from a strided column against a float64 fit): the same bits."""
    rng = np.random.default_rng(2)
    truth = rng.normal(size=(500, 6)).astype(np.float32) * [1, 5, 20, 0.1, 1, 3]
    pred = (truth + rng.normal(size=(500, 6)) * 0.7).astype(np.float32)
    resid = ((pred - truth) ** 2).sum(0)
    spread = ((truth - truth.mean(0)) ** 2).sum(0)
    assert np.array_equal(r2(truth, pred), 1.0 - resid / spread)  # u_estimation
    assert np.array_equal(rmse(truth, pred), np.sqrt(resid / len(truth)))
    floored = np.maximum(spread, 1e-12)  # warm_start (the actor's regression)
    assert np.array_equal(r2(truth, pred, floor=1e-12), 1.0 - resid / floored)
    z, rates = truth[:, :2], truth[:, 2:4]  # figure_latent: one column of a (N, 2) array
    a = np.concatenate([z, np.ones((len(z), 1))], 1)
    for i in (0, 1):
        y = rates[:, i]
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        assert explained_variance(y, a @ coef) == 1.0 - (y - a @ coef).var() / y.var()
        assert explained_variance(y, a @ coef) == pytest.approx(r2(y, a @ coef), abs=1e-6)
