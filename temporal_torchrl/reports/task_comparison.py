"""Is configuration X above Y on one task? The difference of their RAS with its interval.

rliable's P(X > Y) (:mod:`~temporal_torchrl.reports.reliable`) pools the tasks; a reading of
one task asks how far apart X's and Y's runs are there and whether their seeds resolve it. For
each pair the report compares (every configuration over the baseline, and each
``report.py --compare X Y``) and each task both have scored runs on:

- the difference of the mean RAS, X - Y, from unrounded means, with Welch's 95% interval and
  two-sided p (:func:`~temporal_torchrl.reports.statistics.welch_two_samples`: no equal-spread
  assumption, which a 2-seed cell against an 8-seed one would not meet);
- its interval at the Bonferroni level 1 - 0.05 / m for the m (pair, task) comparisons of the
  report, so that "above" holds for the whole set, not for one comparison picked out of many;
- the run pairs won: of the n_X n_Y pairs of a run of X and a run of Y, those where X's scored
  more (ties count half): rliable's P(X > Y) on this task alone, times n_X n_Y.

The reading is :attr:`~temporal_torchrl.reports.statistics.Difference.verdict`'s, as against the
thesis but without a margin (the plan claims no equivalence between configurations): *above* /
*below* when the Bonferroni interval excludes zero, else *not resolved*. With 4 runs against 4
no exact test of one cell gets below p = 0.029, so the plan leaves claims between
configurations to the aggregate test (:mod:`~temporal_torchrl.reports.primary_claim`).

TTFS and TT50S are not compared this way: a run without the success has only a bound, and a
mean of bounds has no t interval.

Example:
    >>> from temporal_torchrl.reports.task_comparison import compare_on_task
    >>> d3 = compare_on_task("FuRL + D3", "FuRL", "window-close", [74.0, 73.3, 82.0, 74.7],
    ...                      [30.7, 48.0, 42.7, 45.3], comparisons=9)  # our window-close
    >>> round(d3.difference, 1), d3.verdict, d3.pairs_won
    (34.3, 'above', 16.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from temporal_torchrl.reports.reliable import ReliableTable
from temporal_torchrl.reports.statistics import (
    LEVEL,
    NOT_RESOLVED,
    Difference,
    welch_two_samples,
)

#: What the Bonferroni factor of a table of task comparisons counts.
FAMILY = "comparisons"


@dataclass(frozen=True)
class TaskComparison:
    """X's runs against Y's on one task (module doc).

    Attributes:
        label, baseline: X's and Y's configuration labels.
        task: the task.
        values, baseline_values: their runs' RAS (%).
        difference: mean of ``values`` minus mean of ``baseline_values``.
        comparisons: m, the Bonferroni factor.
        pairs_won: the run pairs where X scored more, ties counting half.
        welch: the difference with its intervals, p and reading; None (with ``reason``) when
            there is no seed error.
        reason: why there is no interval.
    """

    label: str
    baseline: str
    task: str
    values: tuple[float, ...]
    baseline_values: tuple[float, ...]
    difference: float
    comparisons: int
    pairs_won: float
    welch: Difference | None = None
    reason: str | None = None

    @property
    def pairs(self) -> int:
        return len(self.values) * len(self.baseline_values)

    @property
    def verdict(self) -> str:
        return NOT_RESOLVED if self.welch is None else self.welch.verdict

    def describe(self, decimals: int = 1) -> str:
        """``+34.3 [+22.9, +45.8], p = 0.0008: above over 9 comparisons [+13.0, +55.6]``, as
        the report prints it."""
        if self.welch is None:
            return f"{self.difference:+.{decimals}f}: {NOT_RESOLVED} ({self.reason})"
        return self.welch.describe(decimals, family=FAMILY, p=True)


def pairs_won(values: Sequence[float], baseline_values: Sequence[float]) -> float:
    """How many (x, y) run pairs have x > y, ties counting half."""
    x = np.asarray(values, dtype=float)[:, None]
    y = np.asarray(baseline_values, dtype=float)[None, :]
    return float(np.sum(x > y) + 0.5 * np.sum(x == y))


def compare_on_task(label: str, baseline: str, task: str, values: Sequence[float],
                    baseline_values: Sequence[float], *, comparisons: int = 1,
                    level: float = LEVEL) -> TaskComparison:
    """``label``'s runs (``values``, RAS %) against ``baseline``'s on ``task``."""
    if comparisons < 1:
        raise ValueError(f"comparisons={comparisons}: expected the number of comparisons "
                         "made, at least 1.")
    if len(values) == 0 or len(baseline_values) == 0:
        raise ValueError(f"{task}: {label} has {len(values)} run(s) and {baseline} "
                         f"{len(baseline_values)}; both need at least one.")
    x, y = np.asarray(values, dtype=float), np.asarray(baseline_values, dtype=float)
    runs = {"label": label, "baseline": baseline, "task": task,
            "values": tuple(map(float, x)), "baseline_values": tuple(map(float, y)),
            "difference": float(x.mean() - y.mean()), "comparisons": comparisons,
            "pairs_won": pairs_won(x, y)}
    if min(len(x), len(y)) < 2:
        return TaskComparison(**runs, reason="a single run has no seed error")
    if x.std() == 0.0 and y.std() == 0.0:
        return TaskComparison(**runs, reason="every run of each scored the same")
    return TaskComparison(**runs, welch=welch_two_samples(x, y, comparisons=comparisons,
                                                          level=level))


def compared_pairs(table: ReliableTable) -> list[tuple[str, str]]:
    """The pairs ``table`` gives a probability of improvement for: each configuration over the
    baseline, then each pair asked for, once each."""
    pairs = [(each.label, each.baseline) for each in table.improvements.values()]
    pairs += [pair for pair in table.pairs if pair not in pairs]
    return pairs


def compare_configurations(ras: ReliableTable) -> list[TaskComparison]:
    """Every pair of :func:`compared_pairs` on every task both have RAS scores on, the
    Bonferroni factor the number of these comparisons."""
    if ras.metric.name != "ras":
        raise ValueError(f"{ras.metric.title}: only RAS is compared per task (module doc); "
                         "pass the report's RAS table.")
    jobs = []
    for label, baseline in compared_pairs(ras):
        x, y = ras.scores[label], ras.scores[baseline]
        jobs += [(label, baseline, task, 100 * x.task_scores(task)[:, 0],
                  100 * y.task_scores(task)[:, 0])
                 for task in x.tasks if task in y.tasks]
    return [compare_on_task(*job, comparisons=len(jobs)) for job in jobs]
