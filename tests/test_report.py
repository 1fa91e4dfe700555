"""`run/report.py`: per-episode CSVs written by `run.eval` read back, paired and formatted; and the
rule that `experiments/` holds no CSV parsing, statistics or timing code of its own."""

import pathlib
import re

import numpy as np
import pytest

from dpc_mjx.errors import DpcError
from dpc_mjx.run.eval import cell_result, paired_row
from dpc_mjx.run.report import (
    EPISODE_COLUMNS,
    KEY_COLUMNS,
    ci_text,
    pair,
    paired_text,
    read_cells,
    read_controller,
    read_episodes,
    versus_baseline,
    write_episodes_csv,
)
from dpc_mjx.stats import mcnemar_counts, mcnemar_p, mean_ci, paired_diff_ci

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[1] / "experiments"
SQ = ("roll_sq", "pitch_sq", "vx_sq_err", "vy_sq_err", "yaw_rate_sq_err", "pos_sq_err")


def _cell(controller: str, returns, fell, seed: int = 7):
    """A cell of `run.eval` from made-up per-episode arrays (episodes,), one task measure."""
    returns, fell = np.asarray(returns, float), np.asarray(fell, bool)
    n = len(returns)
    r = {
        "return": returns,
        "fell": fell,
        "length": np.where(fell, 40, 100),
        "nan": np.zeros(n),
        "measured": np.full(n, 100.0),
        **{k: np.linspace(0.1, 0.2, n) for k in (*SQ, "ee_sq_err")},
        "box_dx": np.linspace(0.0, 0.3, n),
    }
    return cell_result("regular", controller, r, 100, seed, 1.0, ("box_dx",))


RETURNS = {
    "mbc": ([10.0, 12.0, 9.0, 14.0, 11.0], [1, 1, 0, 1, 0]),
    "dpc": ([15.0, 13.0, 16.0, 18.0, 12.0], [0, 1, 0, 0, 0]),
}


@pytest.fixture
def csv_path(tmp_path: pathlib.Path) -> pathlib.Path:
    cells = [_cell(k, *v) for k, v in RETURNS.items()]
    return write_episodes_csv(tmp_path / "cell.csv", cells)


def test_key_columns_are_columns_of_the_evaluation_csv():
    assert set(KEY_COLUMNS) <= set(EPISODE_COLUMNS)


def test_a_written_csv_reads_back_per_controller(csv_path):
    rows = read_episodes(csv_path, "dpc")
    assert [r["episode"] for r in rows] == ["0", "1", "2", "3", "4"]
    assert list(rows[0])[: len(EPISODE_COLUMNS)] == list(EPISODE_COLUMNS)
    cells = read_cells(csv_path)
    assert set(cells) == {"mbc", "dpc"}
    np.testing.assert_array_equal(cells["dpc"]["return"], RETURNS["dpc"][0])
    np.testing.assert_array_equal(cells["mbc"]["fell"], RETURNS["mbc"][1])
    assert "box_dx" in cells["mbc"] and "fall_step" not in cells["mbc"]


def test_two_controllers_pair_on_the_same_episodes(csv_path):
    dpc, mbc = read_controller(f"{csv_path}:dpc"), read_controller(f"{csv_path}:mbc")
    assert set(dpc) == {("regular", "7", str(i)) for i in range(5)}
    first, second = pair(dpc, mbc)
    np.testing.assert_array_equal(first[1], RETURNS["dpc"][0])
    np.testing.assert_array_equal(second[0], RETURNS["mbc"][1])
    row = paired_row("dpc - mbc", first, second)
    assert row.startswith("| dpc - mbc | +3.6 [")  # mean of (5, 1, 7, 4, 1)
    assert row.endswith(f"| 0 | 2 | {mcnemar_p(0, 2):.2g} |")
    with pytest.raises(DpcError, match="different episodes"):
        pair(dpc, {k: v for k, v in mbc.items() if k[2] != "4"})
    with pytest.raises(DpcError, match="CSV:CONTROLLER"):
        read_controller(str(csv_path))
    with pytest.raises(DpcError, match="no rows of controller 'oracle'"):
        read_controller(f"{csv_path}:oracle")
    # a task's measure, paired the same way (`experiments/paired_csv.py --measure`)
    first, second = pair(*(read_controller(f"{csv_path}:{c}", ("box_dx",)) for c in ("dpc", "mbc")))
    np.testing.assert_array_equal(first[0], np.linspace(0.0, 0.3, 5))
    assert len(first) == len(second) == 1
    with pytest.raises(DpcError, match=r"no column \['ball_on_target'\]"):
        read_controller(f"{csv_path}:dpc", ("ball_on_target",))


def test_a_csv_without_the_key_columns_is_refused(tmp_path):
    path = tmp_path / "other.csv"
    path.write_text("arm,controller\nregular,mbc\n")
    with pytest.raises(DpcError, match=r"lacks the columns \['seed', 'episode'"):
        read_cells(path)


def test_table_cells_format_means_and_paired_differences(csv_path):
    c = read_cells(csv_path)
    m, lo, hi = mean_ci(c["dpc"]["return"])
    assert ci_text(c["dpc"]["return"], ".1f") == f"{m:.1f} [{lo:.1f}, {hi:.1f}]"
    d, lo, hi = paired_diff_ci(c["dpc"]["fell"], c["mbc"]["fell"])
    assert paired_text(c["dpc"]["fell"], c["mbc"]["fell"]) == f"{d:+.3f} [{lo:+.3f}, {hi:+.3f}]"


def test_versus_baseline_pairs_returns_and_falls_and_shares_the_gain():
    mbc, dpc = _cell("mbc", *RETURNS["mbc"]), _cell("dpc", *RETURNS["dpc"])
    assert versus_baseline(mbc, mbc, 20.0) == ("", "", "")
    paired, p, share = versus_baseline(dpc, mbc, full_return=mbc.mean_return + 7.2)
    d, lo, hi = paired_diff_ci(dpc.per_episode["return"], mbc.per_episode["return"])
    assert paired == f"{d:+.1f} [{lo:+.1f}, {hi:+.1f}]" and paired.startswith("+3.6 [")
    only_dpc, only_mbc = mcnemar_counts(dpc.per_episode["fell"], mbc.per_episode["fell"])
    assert (only_dpc, only_mbc) == (0, 2) and p == f"{mcnemar_p(0, 2):.2g} (0 vs 2)"
    assert share == "50%"  # a gain of 3.6 of the full policy's 7.2
    assert versus_baseline(dpc, mbc)[2] == "" == versus_baseline(dpc, mbc, mbc.mean_return)[2]


# What `experiments/` may not write out itself (issue 25: thin scripts over `run/report.py`,
# `dpc_mjx.stats` and `dpc_mjx.timing`): (what, pattern, a line it must catch).
FORBIDDEN = (
    ("timing", r"perf_counter|\btime\.(time|monotonic|process_time)\(", "t0 = time.perf_counter()"),
    ("CSV parsing", r"\bcsv\.(reader|DictReader)\b|^\s*(import csv|from csv import)", "import csv"),
    ("CSV parsing", r"\b(read_csv|loadtxt|genfromtxt)\(", "np.loadtxt(path, delimiter=',')"),
    ("R^2", r"\b1(\.0*)?\s*-\s*\(?\s*[\w.]*(res|sse|ss_)\w*[\w.()]*\s*/", "1.0 - resid / spread"),
    ("R^2", r"\.var\([^)]*\)\s*/\s*[\w.]+\.var\(", "1.0 - resid.var() / y.var()"),
    ("R^2", r"\bcorrcoef\(|\br2_score\b", "np.corrcoef(x, y)[0, 1] ** 2"),
    ("paired statistics", r"\bddof\s*=|\b1\.96\b|\bmath\.comb\(", "np.std(d, ddof=1)"),
    # the intervals come formatted from run.report (ci_text, paired_text, versus_baseline)
    (
        "paired statistics",
        r"\b(paired_diff_ci|mcnemar_counts|mcnemar_p|mean_ci)\b",
        "mcnemar_p(a, b)",
    ),
)


@pytest.mark.parametrize("what, pattern, example", FORBIDDEN, ids=[f[0] for f in FORBIDDEN])
def test_experiments_hold_no_parsing_statistics_or_timing_of_their_own(what, pattern, example):
    rule = re.compile(pattern, re.MULTILINE)
    assert rule.search(example), f"the pattern for {what} no longer catches {example!r}"
    scripts = sorted(EXPERIMENTS.glob("*.py"))
    assert scripts, f"no scripts in {EXPERIMENTS}"
    found = [
        f"{path.name}:{text[: m.start()].count(chr(10)) + 1}: {m.group(0)!r}"
        for path in scripts
        for text in [path.read_text()]
        for m in rule.finditer(text)
    ]
    assert not found, (
        f"{what} written out in experiments/ ({found}): use dpc_mjx.run.report (CSVs, pairing, "
        "table cells), dpc_mjx.stats (intervals, r2, rmse) or dpc_mjx.timing instead."
    )
