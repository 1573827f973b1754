"""Is a cell's mean the thesis's? The difference with its interval, and what it lets us say.

The thesis prints, for each configuration and task, the mean over its 4 seeds; only its stage-1
tables (5.2, 5.3) print the seeds' std as well. Its mean carries a seed error of its own, so a
comparison that treats it as exact overstates every disagreement. Here a cell of ours (n runs,
mean m, sample std s) and the thesis's (4 seeds, mean m', std s') are compared as two samples,
by :func:`~temporal_torchrl.reports.statistics.welch_difference`: the difference m - m' with
Welch's standard error sqrt(s²/n + s'²/4), where the thesis prints no std ``s' = s`` (a spread
like ours, said so beside the result), its Bonferroni interval over the K cells a table
compares, and the 90% interval for equivalence within a margin fixed in advance. The reading is
:attr:`~temporal_torchrl.reports.statistics.Difference.verdict`, by the Table 5.12 analysis plan
(``docs/results/table_5_12/analysis_plan.md``): *above* / *below*, *equivalent within ±m* or
*not resolved*.

An average over tasks (the tables' Average row) is compared the same way: its variance is the
sum of the task means' variances over T², its degrees of freedom Welch-Satterthwaite's.

Example:
    >>> from temporal_torchrl.reports.thesis_comparison import compare_with_thesis
    >>> sac = compare_with_thesis([48.0, 32.0, 42.0, 44.7], thesis_mean=53.5, margin=10.0)
    >>> round(sac.difference, 1), sac.verdict, sac.std_assumed  # drawer-open SAC, 4 seeds
    (-11.8, 'not resolved', True)
    >>> compare_with_thesis([74.0, 73.3, 82.0, 74.7], 78.5, margin=10.0).describe()
    '-2.5 [-9.5, +4.5]: equivalent within ±10 (90% [-8.1, +3.1])'
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from temporal_torchrl.reports.statistics import (
    LEVEL,
    Difference,
    sample_term,
    welch_difference,
)

#: Seeds behind each of the thesis's means (chapter 5: every configuration, 4 seeds).
THESIS_SEEDS = 4


@dataclass(frozen=True)
class ThesisComparison(Difference):
    """Ours minus the thesis's (:class:`~temporal_torchrl.reports.statistics.Difference`), and
    ``std_assumed``: the thesis printed no std, ours was assumed for it."""

    std_assumed: bool = False


def _thesis_term(ours: Sequence[float], thesis_std: float | None,
                 thesis_seeds: int) -> tuple[float, int]:
    """The variance of the thesis's mean: its std, or ours where it printed none."""
    std = float(np.std(ours, ddof=1)) if thesis_std is None else thesis_std
    return std ** 2 / thesis_seeds, thesis_seeds - 1


def compare_with_thesis(values: Sequence[float], thesis_mean: float,
                        thesis_std: float | None = None, *, thesis_seeds: int = THESIS_SEEDS,
                        cells: int = 1, level: float = LEVEL,
                        margin: float | None = None) -> ThesisComparison:
    """Our runs' ``values`` against the thesis's mean (and std, when it printed one);
    ``cells``: the Bonferroni factor; ``margin``: the equivalence margin (None: the metric has
    none)."""
    difference = welch_difference(
        [sample_term(values), _thesis_term(values, thesis_std, thesis_seeds)],
        float(np.mean(values)) - thesis_mean, comparisons=cells, margin=margin, level=level)
    return ThesisComparison(**vars(difference), std_assumed=thesis_std is None)


def compare_averages(cells: Sequence[tuple[Sequence[float], float, float | None]], *,
                     thesis_seeds: int = THESIS_SEEDS, comparisons: int = 1,
                     level: float = LEVEL, margin: float | None = None) -> ThesisComparison:
    """The mean of our task means against the thesis's mean of its task means over the same
    tasks; ``cells``: per task, our values, the thesis's mean and its std (or None)."""
    if not cells:
        raise ValueError("no task to average over.")
    terms, difference = [], 0.0
    scale = len(cells) ** 2
    for values, thesis_mean, thesis_std in cells:
        for variance, dof in (sample_term(values),
                              _thesis_term(values, thesis_std, thesis_seeds)):
            terms.append((variance / scale, dof))
        difference += (float(np.mean(values)) - thesis_mean) / len(cells)
    result = welch_difference(terms, difference, comparisons=comparisons, margin=margin,
                              level=level)
    assumed = any(thesis_std is None for _, _, thesis_std in cells)
    return ThesisComparison(**vars(result), std_assumed=assumed)
