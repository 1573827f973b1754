"""The report's statistics (temporal_torchrl.reports.statistics) against computations written
out here, by enumeration or by hand, or scipy's, never against the module itself."""

import doctest
import itertools
import math
import statistics

import numpy as np
import pytest
from scipy import stats

from temporal_torchrl.reports import statistics as report_statistics
from temporal_torchrl.reports.statistics import (
    ABOVE,
    BELOW,
    EQUIVALENT,
    NOT_RESOLVED,
    TimeToEvent,
    exact_stratified_permutation_test,
    holm,
    mean_difference_over_tasks,
    mean_half_width,
    paired_sign_flip_test,
    reading_legend,
    stratified_bootstrap_interval,
    stratified_permutation_test,
    welch_two_samples,
)

# Two tasks, 3 + 2 and 2 + 2 runs: C(5, 3) * C(4, 2) = 60 relabellings; "reach" is X's only.
X = {"door-open": [71.0, 64.0, 80.5], "window-close": [55.0, 62.0], "reach": [90.0]}
Y = {"door-open": [66.0, 58.0], "window-close": [57.5, 49.0]}


def delta(x, y):
    """Δ written out: the mean over shared tasks of the difference of the means."""
    tasks = [task for task in x if task in y]
    return sum(statistics.fmean(x[t]) - statistics.fmean(y[t]) for t in tasks) / len(tasks)


def enumerated_permutation_p(x, y):
    """Exact two-sided p by listing every within-task relabelling with itertools."""
    tasks = [task for task in x if task in y]
    observed = abs(delta(x, y))
    per_task = []
    for task in tasks:
        pooled = list(x[task]) + list(y[task])
        per_task.append([
            ([pooled[i] for i in chosen],
             [pooled[i] for i in range(len(pooled)) if i not in chosen])
            for chosen in itertools.combinations(range(len(pooled)), len(x[task]))])
    extreme = total = 0
    for relabelling in itertools.product(*per_task):
        stat = abs(sum(statistics.fmean(a) - statistics.fmean(b) for a, b in relabelling)
                   / len(tasks))
        extreme += stat >= observed - 1e-9
        total += 1
    return extreme / total, total


def enumerated_sign_flip_p(x, y):
    """Exact two-sided sign-flip p by listing every sign assignment with itertools."""
    tasks = [task for task in x if task in y]
    diffs = [[a - b for a, b in zip(x[t], y[t], strict=True)] for t in tasks]
    observed = abs(delta(x, y))
    sizes = [len(d) for d in diffs]
    extreme = total = 0
    for signs in itertools.product((1, -1), repeat=sum(sizes)):
        stat, start = 0.0, 0
        for d in diffs:
            flipped = zip(signs[start:start + len(d)], d, strict=True)
            stat += statistics.fmean(s * v for s, v in flipped)
            start += len(d)
        extreme += abs(stat / len(tasks)) >= observed - 1e-9
        total += 1
    return extreme / total, total


def test_docstring_example_runs():
    assert doctest.testmod(report_statistics).failed == 0


def test_mean_difference_by_hand():
    # door-open: 71.833... - 62 = 9.8333; window-close: 58.5 - 53.25 = 5.25.
    assert mean_difference_over_tasks(X, Y) == pytest.approx((215.5 / 3 - 62 + 5.25) / 2)
    # Tasks weigh alike whatever their run counts; tasks not shared are left out.
    assert mean_difference_over_tasks({"a": [1.0], "b": [10.0, 20.0, 30.0]},
                                      {"a": [0.0, 2.0], "b": [0.0], "c": [5.0]}) == 10.0


def test_exact_and_monte_carlo_permutation_p_match_enumeration():
    expected, total = enumerated_permutation_p(X, Y)
    assert total == 60
    exact = exact_stratified_permutation_test(X, Y)
    assert exact.exact and exact.permutations == 60
    assert exact.tasks == ("door-open", "window-close")
    assert exact.p_value == pytest.approx(expected, abs=1e-12)
    assert exact.difference == pytest.approx(delta(X, Y))

    random = stratified_permutation_test(X, Y, permutations=100_000)
    assert not random.exact and random.permutations == 100_000
    assert random.difference == pytest.approx(delta(X, Y))
    assert random.p_value == pytest.approx(expected, abs=4e-3)


def test_permutation_p_on_a_second_example():
    x = {"a": [3.0, 1.0, 4.0], "b": [1.0, 5.0, 9.0], "c": [2.0, 6.0]}
    y = {"a": [2.0, 7.0], "b": [1.0, 8.0, 2.0], "c": [8.0, 1.0, 8.0]}
    expected, total = enumerated_permutation_p(x, y)
    assert total == 10 * 20 * 10
    assert exact_stratified_permutation_test(x, y).p_value == pytest.approx(expected, abs=1e-12)
    mc = stratified_permutation_test(x, y, permutations=100_000, seed=7)
    assert mc.p_value == pytest.approx(expected, abs=5e-3)


def test_fully_separated_four_against_four():
    x, y = {"t": [80.0, 81.0, 82.0, 83.0]}, {"t": [10.0, 11.0, 12.0, 13.0]}
    # Only the observed labelling and its mirror reach |Δ| = 70: 2 of C(8, 4) = 70.
    assert math.comb(8, 4) == 70
    exact = exact_stratified_permutation_test(x, y)
    assert exact.p_value == pytest.approx(2 / 70)
    assert exact.difference == 70.0
    mc = stratified_permutation_test(x, y)
    assert mc.p_value == pytest.approx(2 / 70, abs=3e-3)
    assert mc.p_value > 0


def test_permutation_seed_and_task_order():
    a = stratified_permutation_test(X, Y, permutations=2_000, seed=3)
    assert a == stratified_permutation_test(X, Y, permutations=2_000, seed=3)
    reordered = dict(reversed(list(X.items())))
    assert a == stratified_permutation_test(reordered, Y, permutations=2_000, seed=3)
    # p = (1 + count) / (1 + N) lies on that grid.
    assert round(a.p_value * 2_001, 6) == int(round(a.p_value * 2_001))


def test_exact_permutation_refuses_too_many_relabellings():
    x = {f"t{i}": [1.0, 2.0, 3.0, 4.0] for i in range(5)}
    y = {f"t{i}": [5.0, 6.0, 7.0, 8.0] for i in range(5)}
    with pytest.raises(ValueError, match="relabellings"):
        exact_stratified_permutation_test(x, y)


def test_sign_flip_exact_matches_enumeration():
    x = {"a": [70.0, 62.0, 75.0], "b": [50.0, 58.0]}
    y = {"a": [65.0, 64.0, 60.0], "b": [41.0, 57.0]}
    expected, total = enumerated_sign_flip_p(x, y)
    assert total == 32
    test = paired_sign_flip_test(x, y)
    assert test.exact and test.permutations == 32
    assert test.p_value == pytest.approx(expected, abs=1e-12)
    assert test.difference == pytest.approx(delta(x, y))


def test_sign_flip_random_when_assignments_exceed_the_count():
    rng = np.random.default_rng(1)
    x = {t: list(rng.normal(60, 10, 4).round(1)) for t in ("a", "b", "c")}
    y = {t: list(rng.normal(55, 10, 4).round(1)) for t in ("a", "b", "c")}
    expected, total = enumerated_sign_flip_p(x, y)
    assert total == 4096
    test = paired_sign_flip_test(x, y, permutations=4_000)
    assert not test.exact and test.permutations == 4_000
    assert test.p_value == pytest.approx(expected, abs=0.025)
    assert paired_sign_flip_test(x, y, permutations=4_096).p_value == pytest.approx(expected)


def test_holm_by_hand():
    adjusted = holm({"a": 0.01, "b": 0.04, "c": 0.03})
    # sorted 0.01, 0.03, 0.04 -> 3 * 0.01, 2 * 0.03, max(0.06, 1 * 0.04).
    assert list(adjusted) == ["a", "b", "c"]
    assert adjusted == pytest.approx({"a": 0.03, "b": 0.06, "c": 0.06})
    assert holm({"a": 0.5, "b": 0.6}) == {"a": 1.0, "b": 1.0}
    assert holm({"only": 0.02}) == {"only": 0.02}
    assert holm({}) == {}


def test_holm_monotone_and_bounded():
    rng = np.random.default_rng(5)
    raw = {f"h{i}": float(p) for i, p in enumerate(rng.uniform(0, 0.2, 12))}
    adjusted = holm(raw)
    order = sorted(raw, key=raw.get)
    values = [adjusted[name] for name in order]
    assert values == sorted(values)
    assert all(raw[n] <= adjusted[n] <= 1.0 for n in raw)
    assert all(adjusted[n] <= min(1.0, len(raw) * raw[n]) for n in raw)  # never above Bonferroni
    with pytest.raises(ValueError, match="p-value"):
        holm({"bad": 1.5})


def test_bootstrap_interval_contains_delta_and_shrinks():
    rng = np.random.default_rng(2)
    tasks = ("a", "b", "c", "d", "e")
    x = {t: list(rng.normal(60, 10, 4)) for t in tasks}
    y = {t: list(rng.normal(50, 10, 4)) for t in tasks}
    d = delta(x, y)
    low, high = stratified_bootstrap_interval(x, y)
    assert low < d < high

    # Normal approximation written out: Var Δ* = Σ_t (s²_X,t / n + s²_Y,t / n) / T², with the
    # plug-in (ddof = 0) variances the bootstrap resamples from.
    var = sum(np.var(x[t]) / 4 + np.var(y[t]) / 4 for t in tasks) / len(tasks) ** 2
    assert high - low == pytest.approx(2 * 1.959964 * math.sqrt(var), rel=0.1)

    # The same means, half the spread: half the width.
    half = {t: [statistics.fmean(v) + (a - statistics.fmean(v)) / 2 for a in v]
            for t, v in x.items()}
    half_y = {t: [statistics.fmean(v) + (a - statistics.fmean(v)) / 2 for a in v]
              for t, v in y.items()}
    narrow_low, narrow_high = stratified_bootstrap_interval(half, half_y)
    assert narrow_low < d < narrow_high
    assert narrow_high - narrow_low < 0.6 * (high - low)
    half_low, half_high = stratified_bootstrap_interval(x, y, level=0.5)
    assert low < half_low < half_high < high

    still = stratified_bootstrap_interval({"t": [70.0, 70.0]}, {"t": [60.0, 60.0, 60.0]})
    assert still == pytest.approx((10.0, 10.0))


def test_errors_name_the_problem():
    with pytest.raises(ValueError, match="share no task"):
        mean_difference_over_tasks({"a": [1.0]}, {"b": [2.0]})
    with pytest.raises(ValueError, match="share no task"):
        stratified_permutation_test({"a": [1.0]}, {"b": [2.0]})
    with pytest.raises(ValueError, match=r"'a'.*Y has 0 run"):
        stratified_bootstrap_interval({"a": [1.0]}, {"a": []})
    with pytest.raises(ValueError, match=r"'b'.*X has 3 run\(s\) and Y 2.*same number"):
        paired_sign_flip_test({"a": [1.0], "b": [1.0, 2.0, 3.0]}, {"a": [0.0], "b": [1.0, 2.0]})
    with pytest.raises(ValueError, match="permutations=0"):
        stratified_permutation_test(X, Y, permutations=0)
    with pytest.raises(ValueError, match="level"):
        stratified_bootstrap_interval(X, Y, level=1.0)
    with pytest.raises(ValueError, match="non-finite"):
        mean_difference_over_tasks({"a": [float("nan")]}, {"a": [1.0]})


# --------------------------------------------------------------------- Welch, against scipy's
def test_welch_two_samples_is_scipys_interval_and_p():
    x, y = [74.0, 73.3, 82.0, 74.7], [30.7, 48.0, 42.7, 45.3, 39.0]
    result = stats.ttest_ind(x, y, equal_var=False)
    welch = welch_two_samples(x, y, comparisons=9, margin=10.0)
    assert welch.difference == pytest.approx(np.mean(x) - np.mean(y))
    assert (welch.low, welch.high) == pytest.approx(tuple(result.confidence_interval(0.95)))
    assert (welch.adjusted_low, welch.adjusted_high) == pytest.approx(
        tuple(result.confidence_interval(1 - 0.05 / 9)))
    assert (welch.equivalence_low, welch.equivalence_high) == pytest.approx(
        tuple(result.confidence_interval(0.90)))
    assert welch.p_value == pytest.approx(result.pvalue)
    assert welch.degrees_of_freedom == pytest.approx(result.df)


def test_one_vocabulary_of_readings():
    above = welch_two_samples([90.0, 92.0, 95.0, 93.0], [30.0, 35.0, 33.0, 31.0], comparisons=9)
    assert above.verdict == ABOVE and above.p_value < 0.00005
    assert ", p < 0.0001: above over 9 comparisons [" in above.describe(
        p=True, family="comparisons")
    below = welch_two_samples([30.0, 35.0, 33.0, 31.0], [90.0, 92.0, 95.0, 93.0])
    assert below.verdict == BELOW
    level = welch_two_samples([50.0, 52.0, 51.0, 49.0], [50.5, 51.5, 50.0, 49.5], margin=10.0)
    assert level.verdict == EQUIVALENT and "equivalent within ±10 (90% [" in level.describe()
    assert welch_two_samples([50.0, 52.0, 51.0, 49.0], [50.5, 51.5, 50.0, 49.5]).verdict == (
        NOT_RESOLVED)  # no margin: never equivalent
    legend = reading_legend(9, None, "comparisons of this table")
    assert "over all 9 comparisons of this table" in legend and "equivalent" not in legend
    with pytest.raises(ValueError, match="no seed error"):
        welch_two_samples([1.0, 1.0], [2.0, 2.0])
    with pytest.raises(ValueError, match="at least 2 seeds"):
        welch_two_samples([1.0], [2.0, 3.0])


def test_mean_half_width_is_scipys_t_interval():
    values = np.array([[1.0, 10.0], [3.0, 14.0], [2.0, 11.0]])
    for step in range(2):
        low, high = stats.t.interval(0.95, 2, loc=values[:, step].mean(),
                                     scale=stats.sem(values[:, step]))
        assert mean_half_width(values)[step] == pytest.approx((high - low) / 2)


def test_kaplan_meier_median_by_hand():
    # 4 runs: events at 100 and 150, censored at 120 and 200. Survival: 3/4 after 100; the run
    # censored at 120 leaves 2 at risk, so 3/4 * 1/2 = 3/8 <= 1/2 after 150: the median is 150.
    estimate = TimeToEvent.estimate([100.0, 150.0], [120.0, 200.0])
    assert estimate == TimeToEvent(150.0, 2, 4)
    assert TimeToEvent.estimate([100.0], [120.0, 200.0, 300.0]).median is None
    assert TimeToEvent.estimate([], [200.0]).describe() == "median not reached (0 of 1 reached)"
