"""The report's statistics, in one place: every interval, test and reading the reports print.

The registered analysis plan (``docs/results/table_5_12/analysis_plan.md``) fixes them; the
report modules build their tables on these functions and compute nothing of their own.

**Differences of means, by Welch** (:func:`welch_difference`, :func:`welch_two_samples`). A
difference d whose variance is a sum of independent terms v_i (each the variance of a mean,
with its degrees of freedom f_i) has the standard error sqrt(sum v_i) and the
Welch-Satterthwaite degrees of freedom (sum v_i)² / sum(v_i² / f_i): with two samples, the
textbook two-sample interval ``scipy.stats.ttest_ind(..., equal_var=False)`` gives; with
more, an average over tasks. The :class:`Difference` carries its 95% interval, two-sided p, the
interval at the Bonferroni level 1 - 0.05 / K for the K comparisons of a table, and the 90%
interval for equivalence. Its reading, :attr:`Difference.verdict`, one vocabulary for every
table, in this order:

- **above** / **below** (:data:`ABOVE`, :data:`BELOW`): the Bonferroni interval excludes zero;
- **equivalent within ±m** (:data:`EQUIVALENT`): the 90% interval lies inside (-m, +m), two
  one-sided tests at 5% with a margin m fixed before looking (:data:`EQUIVALENCE_MARGIN` for
  RAS); a difference without a margin is never called equivalent;
- **not resolved** (:data:`NOT_RESOLVED`): neither, with the 95% interval printed (and, where
  that one alone excludes zero, the Bonferroni one). An interval that includes zero is not
  agreement: a noisy cell would "agree" more easily than a quiet one.

**Bands over seeds** (:func:`mean_half_width`): the t interval of a mean, for the figures.

**Times to an event** (:class:`TimeToEvent`): Kaplan-Meier (``scipy.stats.ecdf`` on
``CensoredData``) for TTFS and TT50S, whose runs that stop without the event are censored: the
median and how many runs reached the event, never a mean with a stand-in time.

**The primary claim**, X against Y over the tasks as strata. The data are, for each
configuration, a mapping task -> per-run RAS (in RAS points, e.g. 76.0), and the statistic is

    Δ(X, Y) = mean over the tasks both have of (mean RAS of X on the task - mean RAS of Y on it),

each task weighted alike whatever its number of runs:

- :func:`mean_difference_over_tasks`: Δ itself;
- :func:`stratified_permutation_test`: the plan's test. Within each task the pooled runs of X
  and Y are shuffled between the two labels (each side keeping its count), the tasks
  independently; two-sided p = (1 + #{abs(Δ*) >= abs(Δ)}) / (1 + permutations);
- :func:`exact_stratified_permutation_test`: the same test over every relabelling, for small
  cases and as an independent check of the Monte Carlo one;
- :func:`stratified_bootstrap_interval`: the percentile interval of Δ with runs resampled with
  replacement within each task and configuration;
- :func:`paired_sign_flip_test`: the sensitivity analysis that pairs runs by seed within a task;
- :func:`holm`: Holm-Bonferroni adjusted p-values over the family of hypotheses.

Reproducibility: the tasks are taken in sorted order and each function draws from its own
``numpy.random.default_rng(seed)`` (seed 20261207 by default, the plan's), task by task in that
order, so a result depends on the data, the seed and the count only, not on the mappings'
insertion order. "At least as extreme" is ``abs(Δ*) >= abs(Δ) - 1e-12``: the relabelling that
reproduces the data must count although its Δ* is summed in another order.

Example:
    >>> from temporal_torchrl.reports.statistics import (
    ...     exact_stratified_permutation_test, holm, mean_difference_over_tasks,
    ...     welch_two_samples)
    >>> d3 = welch_two_samples([74.0, 73.3, 82.0, 74.7], [30.7, 48.0, 42.7, 45.3],
    ...                        comparisons=9)  # window-close: FuRL + D3 against FuRL
    >>> d3.describe(family="comparisons", p=True)
    '+34.3 [+22.9, +45.8], p = 0.0008: above over 9 comparisons [+13.0, +55.6]'
    >>> x = {"door-open": [70.0, 74.0, 78.0], "window-close": [60.0, 64.0]}
    >>> y = {"door-open": [50.0, 54.0], "window-close": [58.0, 62.0], "push": [10.0]}
    >>> mean_difference_over_tasks(x, y)  # ((74 - 52) + (62 - 60)) / 2; push is not shared
    12.0
    >>> test = exact_stratified_permutation_test(x, y)
    >>> test.tasks, test.permutations, round(test.p_value, 4)  # 2 of the 10 * 6 relabellings
    (('door-open', 'window-close'), 60, 0.0333)
    >>> holm({"FuRL + D3 vs FuRL": 0.01, "FuRL + D3 vs SAC": 0.04})
    {'FuRL + D3 vs FuRL': 0.02, 'FuRL + D3 vs SAC': 0.04}
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Coverage of a difference's interval.
LEVEL = 0.95
#: Coverage of the equivalence interval: two one-sided tests at 5% each.
EQUIVALENCE_LEVEL = 0.90
#: The equivalence margin of a RAS cell, in RAS points, fixed by the Table 5.12 analysis plan
#: before its new runs.
EQUIVALENCE_MARGIN = 10.0

ABOVE = "above"
BELOW = "below"
EQUIVALENT = "equivalent"
NOT_RESOLVED = "not resolved"


# ----------------------------------------------------------------- differences of means (Welch)
@dataclass(frozen=True)
class Difference:
    """A difference of means with Welch's intervals and its reading (module doc).

    Attributes:
        difference: the difference, from unrounded means.
        low, high: its 95% interval.
        adjusted_low, adjusted_high: its interval at level 1 - 0.05 / ``comparisons``.
        equivalence_low, equivalence_high: its 90% interval (two one-sided tests).
        p_value: two-sided, of a zero difference.
        degrees_of_freedom: Welch-Satterthwaite's.
        comparisons: K, the Bonferroni factor: the comparisons of the table it belongs to.
        margin: the equivalence margin, or None (never equivalent).
    """

    difference: float
    low: float
    high: float
    adjusted_low: float
    adjusted_high: float
    equivalence_low: float
    equivalence_high: float
    p_value: float
    degrees_of_freedom: float
    comparisons: int
    margin: float | None

    @property
    def within_margin(self) -> bool:
        """The 90% interval lies inside (-margin, +margin)."""
        return self.margin is not None and (-self.margin < self.equivalence_low
                                            and self.equivalence_high < self.margin)

    @property
    def verdict(self) -> str:
        if self.adjusted_low > 0.0:
            return ABOVE
        if self.adjusted_high < 0.0:
            return BELOW
        return EQUIVALENT if self.within_margin else NOT_RESOLVED

    def describe(self, decimals: int = 1, *, family: str = "cells", p: bool = False) -> str:
        """The difference, its 95% interval (and p) and its reading, as the reports print it:
        ``-2.5 [-9.5, +4.5]: equivalent within ±10 (90% [-8.1, +3.1])``, ``+25.0 [+7.9,
        +42.1]: not resolved (above at 95%, not over 11 cells [-5.8, +55.7])``; ``family``
        names what the Bonferroni factor counts."""
        def signed(value: float) -> str:
            return f"{value:+.{decimals}f}"

        text = f"{signed(self.difference)} [{signed(self.low)}, {signed(self.high)}]"
        if p:
            text += (", p < 0.0001" if self.p_value < 0.00005 else f", p = {self.p_value:.4f}")
        text += ": "
        table_wide = (f"over {self.comparisons} {family} [{signed(self.adjusted_low)}, "
                      f"{signed(self.adjusted_high)}]")
        verdict = self.verdict
        if verdict in (ABOVE, BELOW):
            closeness = f", by less than {self.margin:g}" if self.within_margin else ""
            return text + f"{verdict} {table_wide}{closeness}"
        if verdict == EQUIVALENT:
            return text + (f"equivalent within ±{self.margin:g} (90% "
                           f"[{signed(self.equivalence_low)}, {signed(self.equivalence_high)}])")
        if self.low > 0.0 or self.high < 0.0:
            direction = BELOW if self.difference < 0 else ABOVE
            return text + f"{NOT_RESOLVED} ({direction} at 95%, not {table_wide})"
        return text + NOT_RESOLVED


def reading_legend(comparisons: int, margin: float | None,
                   family: str = "cells compared") -> str:
    """What :attr:`Difference.verdict`'s words mean, as a report prints it under a table of
    ``comparisons`` differences (``family``: what they are; ``margin`` None: no
    equivalence)."""
    equivalent = (f"*equivalent within ±{margin:g}*: the 90% interval lies inside ±{margin:g} "
                  f"(a margin fixed before the runs); " if margin is not None else "")
    return (f"*below* / *above*: the interval over all {comparisons} {family} "
            f"(Bonferroni, shown after it) excludes 0; {equivalent}*not resolved*: neither, "
            f"whatever the 95% interval, which is printed (an interval that includes 0 is not "
            f"agreement).")


def welch_difference(terms: Sequence[tuple[float, float]], difference: float, *,
                     comparisons: int = 1, margin: float | None = None,
                     level: float = LEVEL) -> Difference:
    """``difference`` with the variance the sum of ``terms``' variances, each ``(variance of a
    mean, its degrees of freedom)``: its Welch intervals, p and reading (module doc)."""
    if comparisons < 1:
        raise ValueError(f"comparisons={comparisons}: expected the number of comparisons "
                         "made, at least 1.")
    variance = sum(term for term, _ in terms)
    if variance == 0.0:
        raise ValueError("every run has the same value on both sides: no seed error to "
                         "compare with.")
    dof = variance ** 2 / sum(term ** 2 / df for term, df in terms if term > 0.0)
    error = math.sqrt(variance)

    def half(coverage: float) -> float:
        return float(stats.t.ppf(1 - (1 - coverage) / 2, dof) * error)

    wide, adjusted, equivalence = half(level), half(1 - (1 - level) / comparisons), half(
        EQUIVALENCE_LEVEL)
    p_value = float(2 * stats.t.sf(abs(difference) / error, dof))
    return Difference(difference, difference - wide, difference + wide,
                      difference - adjusted, difference + adjusted,
                      difference - equivalence, difference + equivalence, p_value, float(dof),
                      comparisons, margin)


def sample_term(values: Sequence[float]) -> tuple[float, int]:
    """The variance of ``values``' mean (sample std, n - 1) and its degrees of freedom."""
    if len(values) < 2:
        raise ValueError(f"{len(values)} value(s): a seed error needs at least 2 seeds.")
    return float(np.var(values, ddof=1)) / len(values), len(values) - 1


def welch_two_samples(x: Sequence[float], y: Sequence[float], **options) -> Difference:
    """mean(x) - mean(y) by Welch (``options``: :func:`welch_difference`'s)."""
    return welch_difference([sample_term(x), sample_term(y)],
                            float(np.mean(x) - np.mean(y)), **options)


def mean_half_width(values: np.ndarray, level: float = LEVEL) -> np.ndarray:
    """Half the ``level`` t interval of the mean over the first axis (the seeds):
    t_(n-1) s / sqrt(n)."""
    seeds = values.shape[0]
    return (stats.t.ppf(0.5 + level / 2, seeds - 1) * values.std(axis=0, ddof=1)
            / np.sqrt(seeds))


# ------------------------------------------------------------------- times to an event (KM)
@dataclass(frozen=True)
class TimeToEvent:
    """A cell's TTFS or TT50S by Kaplan-Meier (``scipy.stats.ecdf`` on ``CensoredData``): a run
    that stopped without the event is censored at its episodes, one at the horizon at the
    horizon.

    Attributes:
        median: the first time at which the estimated share of runs still waiting is at most
            one half; None when it never falls that far (*not reached*).
        reached: the runs that had the event.
        runs: the runs estimated over.
    """

    median: float | None
    reached: int
    runs: int

    @classmethod
    def estimate(cls, observed: Sequence[float], censored: Sequence[float]) -> TimeToEvent:
        if not observed:
            return cls(None, 0, len(censored))
        data = stats.CensoredData(uncensored=np.asarray(observed, dtype=float),
                                  right=np.asarray(censored, dtype=float))
        survival = stats.ecdf(data).sf
        below_half = survival.quantiles[survival.probabilities <= 0.5]
        median = float(below_half[0]) if below_half.size else None
        return cls(median, len(observed), len(observed) + len(censored))

    def describe(self, decimals: int = 0) -> str:
        """``median 145 (3 of 4 reached)`` or ``median not reached (1 of 4 reached)``."""
        median = "not reached" if self.median is None else f"{self.median:.{decimals}f}"
        return f"median {median} ({self.reached} of {self.runs} reached)"


# ---------------------------------------------------------------------------- the primary claim
#: The plan's generator seed (``numpy.random.default_rng(20261207)``).
SEED = 20261207
#: Slack on "at least as extreme as observed", for the summation order.
TOLERANCE = 1e-12
#: Largest number of relabellings :func:`exact_stratified_permutation_test` enumerates.
MAX_RELABELLINGS = 10_000_000

Runs = Mapping[str, Sequence[float]]


@dataclass(frozen=True)
class PermutationTest:
    """The outcome of a stratified permutation or sign-flip test of Δ(X, Y) = 0.

    Attributes:
        difference: the observed Δ(X, Y), in RAS points.
        p_value: two-sided p-value.
        permutations: relabellings drawn, or, when ``exact``, the number enumerated.
        tasks: the tasks compared (those both configurations have), sorted.
        exact: whether every relabelling was enumerated (p = count / permutations) rather than
            drawn at random (p = (1 + count) / (1 + permutations)).
    """

    difference: float
    p_value: float
    permutations: int
    tasks: tuple[str, ...]
    exact: bool = False


def _shared_runs(x: Runs, y: Runs) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(task, X's runs, Y's runs) for each task both have, sorted; checks the runs."""
    tasks = sorted(set(x) & set(y))
    if not tasks:
        raise ValueError(f"X and Y share no task (X has {sorted(x)}, Y has {sorted(y)}): "
                         "Δ needs at least one task with runs of both.")
    shared = []
    for task in tasks:
        sides = []
        for name, runs in (("X", x[task]), ("Y", y[task])):
            values = np.asarray(runs, dtype=float)
            if values.ndim != 1 or values.size < 1:
                raise ValueError(f"task {task!r}: {name} has {values.size} run(s) "
                                 f"(shape {values.shape}); each side needs at least one run.")
            if not np.all(np.isfinite(values)):
                raise ValueError(f"task {task!r}: {name} has a non-finite RAS: {runs}.")
            sides.append(values)
        shared.append((task, sides[0], sides[1]))
    return shared


def _check_count(name: str, count: int) -> None:
    if int(count) != count or count < 1:
        raise ValueError(f"{name}={count}: expected a positive whole number.")


def mean_difference_over_tasks(x: Runs, y: Runs) -> float:
    """Δ(X, Y): the mean over shared tasks of X's mean RAS minus Y's mean RAS on the task.

    The plan's effect size: every task weighs alike, whatever its number of runs, and tasks only
    one configuration has are left out. Raises ValueError when no task is shared or a shared
    task has no runs on one side.
    """
    shared = _shared_runs(x, y)
    return float(np.mean([xs.mean() - ys.mean() for _, xs, ys in shared]))


def _p_value(null: np.ndarray, observed: float, *, exact: bool) -> float:
    count = int(np.count_nonzero(np.abs(null) >= abs(observed) - TOLERANCE))
    return count / null.size if exact else (1 + count) / (1 + null.size)


def stratified_permutation_test(x: Runs, y: Runs, *, permutations: int = 100_000,
                                seed: int = SEED) -> PermutationTest:
    """The plan's test of Δ(X, Y) = 0: random relabellings of the runs within each task.

    Under the null hypothesis X's and Y's runs on a task are exchangeable, so each draw shuffles
    the pooled runs of every task between the labels (X keeping its count), the tasks
    independently, and recomputes Δ*. Two-sided p = (1 + #{abs(Δ*) >= abs(Δ)}) / (1 + permutations),
    which counts the data as one of the relabellings and so is never 0. Vectorised: one
    ``rng.permuted`` call per task (sorted order) on ``permutations`` copies of its pooled runs.
    """
    _check_count("permutations", permutations)
    shared = _shared_runs(x, y)
    rng = np.random.default_rng(seed)
    null = np.zeros(permutations)
    for _, xs, ys in shared:
        pooled = np.concatenate([xs, ys])
        shuffled = rng.permuted(np.broadcast_to(pooled, (permutations, pooled.size)), axis=1)
        x_sum = shuffled[:, :xs.size].sum(axis=1)
        null += x_sum / xs.size - (pooled.sum() - x_sum) / ys.size
    null /= len(shared)
    difference = float(np.mean([xs.mean() - ys.mean() for _, xs, ys in shared]))
    return PermutationTest(difference, _p_value(null, difference, exact=False), permutations,
                           tuple(task for task, _, _ in shared))


def exact_stratified_permutation_test(x: Runs, y: Runs, *,
                                      max_relabellings: int = MAX_RELABELLINGS
                                      ) -> PermutationTest:
    """:func:`stratified_permutation_test` over every relabelling instead of random ones.

    There are prod over tasks of C(n_X + n_Y, n_X) relabellings, each equally likely under the
    null, so p = #{abs(Δ*) >= abs(Δ)} / total exactly. Feasible for small cases only (ValueError
    above ``max_relabellings``); it checks the Monte Carlo test and gives small designs their
    exact p.
    """
    shared = _shared_runs(x, y)
    total = math.prod(math.comb(xs.size + ys.size, xs.size) for _, xs, ys in shared)
    if total > max_relabellings:
        raise ValueError(f"{total} relabellings exceed max_relabellings={max_relabellings}: "
                         "use stratified_permutation_test for this many.")
    null = np.zeros(1)
    for _, xs, ys in shared:
        pooled = np.concatenate([xs, ys])
        labels = np.array(list(itertools.combinations(range(pooled.size), xs.size)))
        x_sum = pooled[labels].sum(axis=1)
        per_task = x_sum / xs.size - (pooled.sum() - x_sum) / ys.size
        null = (null[:, None] + per_task[None, :]).ravel()
    null /= len(shared)
    difference = float(np.mean([xs.mean() - ys.mean() for _, xs, ys in shared]))
    return PermutationTest(difference, _p_value(null, difference, exact=True), total,
                           tuple(task for task, _, _ in shared), exact=True)


def stratified_bootstrap_interval(x: Runs, y: Runs, *, resamples: int = 50_000,
                                  seed: int = SEED, level: float = 0.95) -> tuple[float, float]:
    """Percentile interval of Δ(X, Y) under resampling of the runs within task and configuration.

    The size of the effect beside the test's p: each resample draws, for every shared task
    (sorted order) and then for X and Y, as many runs as there are with replacement, and
    recomputes Δ; the interval is the (1 - level) / 2 and (1 + level) / 2 quantiles of those.
    """
    _check_count("resamples", resamples)
    if not 0.0 < level < 1.0:
        raise ValueError(f"level={level}: expected a coverage strictly between 0 and 1.")
    shared = _shared_runs(x, y)
    rng = np.random.default_rng(seed)
    deltas = np.zeros(resamples)
    for _, xs, ys in shared:
        for sign, values in ((1.0, xs), (-1.0, ys)):
            draws = rng.integers(0, values.size, size=(resamples, values.size))
            deltas += sign * values[draws].mean(axis=1)
    deltas /= len(shared)
    low, high = np.quantile(deltas, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(low), float(high)


def paired_sign_flip_test(x: Runs, y: Runs, *, permutations: int = 100_000,
                          seed: int = SEED) -> PermutationTest:
    """Sensitivity analysis: pair runs by position (seed order) and flip each pair's sign.

    Under the null each seed's X - Y difference is symmetric about 0, so flipping signs
    independently gives Δ*'s null distribution. With P pairs, every one of the 2^P assignments
    is enumerated when 2^P <= ``permutations`` (p = #{abs(Δ*) >= abs(Δ)} / 2^P), otherwise
    ``permutations`` random ones are drawn (p = (1 + count) / (1 + permutations)). Raises
    ValueError when X and Y have different numbers of runs on a task.
    """
    _check_count("permutations", permutations)
    shared = _shared_runs(x, y)
    for task, xs, ys in shared:
        if xs.size != ys.size:
            raise ValueError(f"task {task!r}: X has {xs.size} run(s) and Y {ys.size}; pairing "
                             "by seed needs the same number of runs on each side.")
    # Δ = sum over pairs of weight * (x - y), each task's pairs weighing 1 / (T * n_task).
    weights = np.concatenate([(xs - ys) / (len(shared) * xs.size) for _, xs, ys in shared])
    difference = float(np.mean([xs.mean() - ys.mean() for _, xs, ys in shared]))
    pairs = weights.size
    exact = 2**pairs <= permutations
    if exact:
        count = 0
        chunk = 1 << 16
        for start in range(0, 2**pairs, chunk):
            codes = np.arange(start, min(start + chunk, 2**pairs), dtype=np.int64)
            flips = (codes[:, None] >> np.arange(pairs)) & 1
            null = (1 - 2 * flips) @ weights
            count += int(np.count_nonzero(np.abs(null) >= abs(difference) - TOLERANCE))
        return PermutationTest(difference, count / 2**pairs, 2**pairs,
                               tuple(task for task, _, _ in shared), exact=True)
    rng = np.random.default_rng(seed)
    signs = np.where(rng.random((permutations, pairs)) < 0.5, -1.0, 1.0)
    null = signs @ weights
    return PermutationTest(difference, _p_value(null, difference, exact=False), permutations,
                           tuple(task for task, _, _ in shared))


def holm(p_values: Mapping[str, float]) -> dict[str, float]:
    """Holm-Bonferroni adjusted p-values, keyed and ordered as given.

    Controls the family-wise error over the plan's hypotheses (reject where adjusted p < α):
    the i-th smallest of m p-values is multiplied by m - i + 1, the results made non-decreasing
    in that order (step-down) and capped at 1.
    """
    for name, p in p_values.items():
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"p-value of {name!r} is {p}: expected a value in [0, 1].")
    m = len(p_values)
    adjusted: dict[str, float] = {}
    running = 0.0
    for rank, (name, p) in enumerate(sorted(p_values.items(), key=lambda item: item[1])):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[name] = running
    return {name: adjusted[name] for name in p_values}
