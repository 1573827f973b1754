"""Two configurations on one task: Welch's interval and p against a hand computation, the
Bonferroni reading, the run pairs won against rliable's probability of improvement."""

import math

import numpy as np
import pytest
from helpers import make_run
from rliable import metrics
from scipy import stats

from temporal_torchrl.reports import build_reliable_table, group_runs
from temporal_torchrl.reports.statistics import ABOVE, BELOW, NOT_RESOLVED
from temporal_torchrl.reports.tables import task_comparison_markdown, task_comparison_rows
from temporal_torchrl.reports.task_comparison import (
    compare_configurations,
    compare_on_task,
    compared_pairs,
    pairs_won,
)
from temporal_torchrl.runs import find_runs

# drawer-open's committed RAS: FuRL + D3 seeds 0-1 and SAC seeds 0-7 (docs/results)
D3 = [88.667, 100.0]
SAC = [48.0, 32.0, 42.0, 44.667, 18.667, 52.0, 16.0, 71.333]


def welch_by_hand(x, y, level):
    """The textbook Welch interval and p, from the formulas: no scipy test function."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    vx, vy = x.var(ddof=1) / len(x), y.var(ddof=1) / len(y)
    error = math.sqrt(vx + vy)
    dof = (vx + vy) ** 2 / (vx ** 2 / (len(x) - 1) + vy ** 2 / (len(y) - 1))
    difference = x.mean() - y.mean()
    half = stats.t.ppf(1 - (1 - level) / 2, dof) * error
    p = 2 * stats.t.sf(abs(difference) / error, dof)
    return difference, difference - half, difference + half, p


def test_interval_and_p_are_welchs():
    comparison = compare_on_task("FuRL + D3", "SAC", "drawer-open", D3, SAC, comparisons=9)
    difference, low, high, p = welch_by_hand(D3, SAC, 0.95)
    assert comparison.difference == pytest.approx(difference)
    welch = comparison.welch
    assert (welch.low, welch.high) == pytest.approx((low, high))
    assert welch.p_value == pytest.approx(p)
    _, adjusted_low, adjusted_high, _ = welch_by_hand(D3, SAC, 1 - 0.05 / 9)
    assert (welch.adjusted_low, welch.adjusted_high) == pytest.approx(
        (adjusted_low, adjusted_high))
    assert welch.adjusted_low < welch.low and welch.adjusted_high > welch.high
    assert comparison.verdict == ABOVE and comparison.pairs_won == 16 == comparison.pairs
    assert comparison.describe() == (
        "+53.8 [+30.5, +77.0], p = 0.0027: above over 9 comparisons [+9.1, +98.4]")


def test_readings_from_not_resolved_to_below():
    # 95% excludes zero, the interval over 9 comparisons does not
    two = compare_on_task("FuRL + D3", "FuRL", "drawer-open", D3, [33.333, 50.667],
                          comparisons=9)
    assert two.verdict == NOT_RESOLVED and two.welch.low > 0 > two.welch.adjusted_low
    assert two.describe().endswith(
        "not resolved (above at 95%, not over 9 comparisons [-138.7, +243.3])")
    # the same cell alone: one comparison, nothing to correct for
    assert compare_on_task("a", "b", "t", D3, [33.333, 50.667]).verdict == ABOVE
    level = compare_on_task("FuRL", "SAC", "drawer-open", [33.333, 50.667], SAC)
    assert level.verdict == NOT_RESOLVED and level.welch.low < 0 < level.welch.high
    assert level.describe().endswith(": not resolved")
    assert compare_on_task("SAC", "FuRL + D3", "drawer-open", SAC, D3).verdict == BELOW


def test_no_interval_without_a_seed_error():
    single = compare_on_task("a", "b", "t", [80.0], [10.0, 20.0])
    assert single.welch is None and single.verdict == NOT_RESOLVED
    assert single.describe() == "+65.0: not resolved (a single run has no seed error)"
    flat = compare_on_task("a", "b", "t", [100.0, 100.0], [0.0, 0.0])
    assert flat.reason == "every run of each scored the same" and flat.pairs_won == 4
    with pytest.raises(ValueError, match="a has 1 run.s. and b 0; both need at least one"):
        compare_on_task("a", "b", "t", [1.0], [])
    with pytest.raises(ValueError, match="comparisons=0"):
        compare_on_task("a", "b", "t", D3, SAC, comparisons=0)


def test_pairs_won_is_rliables_probability_times_the_pairs():
    x, y = [0.2, 0.6, 0.6, 0.9], [0.4, 0.6, 0.1]
    probability = metrics.probability_of_improvement(np.array(x)[:, None],
                                                     np.array(y)[:, None])
    assert pairs_won(x, y) == pytest.approx(probability * len(x) * len(y))
    assert pairs_won(x, y) == 9.0  # 0.2: 1; 0.6: 2 and a tie, twice; 0.9: 3


def test_the_reports_pairs_on_their_common_tasks(tmp_path):
    """Each configuration over the baseline and each pair asked for, once, on the tasks both
    have RAS on; m counts them all."""
    furl = ("preset=furl", "protocol=stage2")
    for seed in range(3):
        make_run(tmp_path, f"furl{seed}", [False] * (150 + 40 * seed) + [True] * (150 - 40 * seed),
                 *furl, f"env.seed={seed}")
        make_run(tmp_path, f"sac{seed}", [True] * seed + [False] * (300 - seed),
                 "preset=sac", "protocol=stage2", f"env.seed={seed}")
        make_run(tmp_path, f"p2{seed}", [False] * 299 + [seed == 0], "preset=p2",
                 "protocol=stage2", f"env.seed={seed}")
    make_run(tmp_path, "door", [True] * 400, *furl, "env.task=door-open")
    groups = group_runs(find_runs([tmp_path]))
    ras = build_reliable_table(groups, "ras", reps=50, pairs=[("FuRL ρ=0.05", "P2 ρ=0.05 (b_g)"),
                                                             ("FuRL ρ=0.05", "SAC")])
    assert compared_pairs(ras) == [("FuRL ρ=0.05", "SAC"), ("P2 ρ=0.05 (b_g)", "SAC"),
                                   ("FuRL ρ=0.05", "P2 ρ=0.05 (b_g)")]
    comparisons = compare_configurations(ras)
    assert [(each.label, each.baseline, each.task) for each in comparisons] == [
        (pair[0], pair[1], "drawer-open") for pair in compared_pairs(ras)]  # not door-open
    assert {each.comparisons for each in comparisons} == {3}
    first = comparisons[0]
    assert first.values == pytest.approx((100.0, 100 * 110 / 150, 100 * 70 / 150))
    assert first.baseline_values == (0.0, 0.0, 0.0) and first.pairs_won == 9
    markdown = task_comparison_markdown(comparisons)
    assert "| FuRL ρ=0.05 − SAC | drawer-open | 3 · 3 | +73.3 [" in markdown
    assert "the interval over all 3 comparisons of this table (Bonferroni" in markdown
    rows = task_comparison_rows(comparisons).csv_rows()
    assert rows[1]["reading"] == NOT_RESOLVED and rows[0]["pairs"] == "9"
    with pytest.raises(ValueError, match="only RAS is compared"):
        compare_configurations(build_reliable_table(groups, "ttfs", reps=10))
    assert task_comparison_markdown([]) == ""
