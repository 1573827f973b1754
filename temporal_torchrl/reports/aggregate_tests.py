"""The primary claim's statistics: X against Y over the tasks, the tasks as strata.

The registered analysis plan (``docs/results/table_5_12/analysis_plan.md``, "The primary
claim") tests once, on the aggregate, whether configuration X differs from Y. The data are, for
each configuration, a mapping task -> per-run RAS (in RAS points, e.g. 76.0), and the statistic
is

    Δ(X, Y) = mean over the tasks both have of (mean RAS of X on the task - mean RAS of Y on it),

each task weighted alike whatever its number of runs. This module computes:

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
    >>> from temporal_torchrl.reports.aggregate_tests import (
    ...     exact_stratified_permutation_test, holm, mean_difference_over_tasks)
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
