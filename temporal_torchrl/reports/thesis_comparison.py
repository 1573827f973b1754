"""Is a cell's mean the thesis's? The difference with its interval, and what it lets us say.

The thesis prints, for each configuration and task, the mean over its 4 seeds; only its stage-1
tables (5.2, 5.3) print the seeds' std as well. Its mean carries a seed error of its own, so a
comparison that treats it as exact overstates every disagreement. Here a cell of ours (n runs,
mean m, sample std s) and the thesis's (4 seeds, mean m', std s') are compared as two samples:

- the difference m - m' with Welch's standard error sqrt(s²/n + s'²/4) and a t interval at
  the Welch-Satterthwaite degrees of freedom (the textbook two-sample interval, as
  ``scipy.stats.ttest_ind(..., equal_var=False)`` gives it);
- where the thesis prints no std, ``s' = s``: a spread like ours, said so beside the result;
- a second interval at the Bonferroni level 1 - 0.05 / K for the K cells a table compares, so
  that "below" or "above" holds for the whole table, not for one cell picked out of many;
- a 90% interval, for equivalence within a margin fixed in advance.

The reading (:attr:`ThesisComparison.verdict`), by the Table 5.12 analysis plan
(``docs/results/table_5_12/analysis_plan.md``), in this order:

- **below** / **above**: the table-wide interval excludes zero; "by less than m" is added when
  the 90% interval also lies inside ±m;
- **equivalent within ±m**: the 90% interval lies inside (-m, +m), two one-sided tests at 5%
  with a margin m fixed before looking (:data:`EQUIVALENCE_MARGIN` for RAS; a metric without a
  margin is never called equivalent);
- **not resolved**: neither, with the 95% interval (and, when that one alone excludes zero,
  the table-wide one). An interval that includes zero is not agreement: a noisy cell would
  "agree" more easily than a quiet one.

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

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Coverage of the per-cell interval.
LEVEL = 0.95
#: Coverage of the equivalence interval: two one-sided tests at 5% each.
EQUIVALENCE_LEVEL = 0.90
#: The equivalence margin of a RAS cell, in RAS points, fixed by the Table 5.12 analysis plan
#: before its new runs.
EQUIVALENCE_MARGIN = 10.0
#: Seeds behind each of the thesis's means (chapter 5: every configuration, 4 seeds).
THESIS_SEEDS = 4

BELOW = "below"
ABOVE = "above"
EQUIVALENT = "equivalent"
NOT_RESOLVED = "not resolved"


@dataclass(frozen=True)
class Sample:
    """A mean over seeds: its value, sample std (n - 1) and number of seeds."""

    mean: float
    std: float
    n: int

    @classmethod
    def of(cls, values: Sequence[float]) -> Sample:
        if len(values) < 2:
            raise ValueError(f"{len(values)} value(s): a seed error needs at least 2 seeds.")
        return cls(float(np.mean(values)), float(np.std(values, ddof=1)), len(values))

    @property
    def variance_of_mean(self) -> float:
        return self.std ** 2 / self.n


@dataclass(frozen=True)
class ThesisComparison:
    """Ours minus the thesis's, with its 95% and table-wide intervals (module doc).

    Attributes:
        difference: our mean minus the thesis's (from unrounded means).
        low, high: its 95% interval.
        adjusted_low, adjusted_high: its interval at level 1 - 0.05 / ``cells``.
        equivalence_low, equivalence_high: its 90% interval (two one-sided tests).
        margin: the equivalence margin, or None (the metric has none: never equivalent).
        cells: how many cells the table compares (the Bonferroni factor).
        std_assumed: the thesis printed no std; ours was assumed for it.
        degrees_of_freedom: Welch-Satterthwaite's.
    """

    difference: float
    low: float
    high: float
    adjusted_low: float
    adjusted_high: float
    equivalence_low: float
    equivalence_high: float
    margin: float | None
    cells: int
    std_assumed: bool
    degrees_of_freedom: float

    @property
    def half_width(self) -> float:
        return (self.high - self.low) / 2

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

    def describe(self, decimals: int = 1) -> str:
        """``-2.5 [-9.5, +4.5]: equivalent within ±10 (90% [-8.1, +3.1])``, the reading as the
        report prints it."""
        def signed(value: float) -> str:
            return f"{value:+.{decimals}f}"

        text = f"{signed(self.difference)} [{signed(self.low)}, {signed(self.high)}]: "
        table_wide = (f"over {self.cells} cells [{signed(self.adjusted_low)}, "
                      f"{signed(self.adjusted_high)}]")
        if self.verdict in (ABOVE, BELOW):
            closeness = f", by less than {self.margin:g}" if self.within_margin else ""
            return text + f"{self.verdict} {table_wide}{closeness}"
        if self.verdict == EQUIVALENT:
            return text + (f"equivalent within ±{self.margin:g} (90% "
                           f"[{signed(self.equivalence_low)}, {signed(self.equivalence_high)}])")
        if self.low > 0.0 or self.high < 0.0:
            direction = "below" if self.difference < 0 else "above"
            return text + f"not resolved ({direction} at 95%, not {table_wide})"
        return text + "not resolved"


def reading_legend(cells: int, margin: float | None) -> str:
    """What the readings mean, as the report prints it under a table of ``cells`` comparisons
    with ``margin`` (None: the metric has no equivalence margin)."""
    equivalent = (f"*equivalent within ±{margin:g}*: the 90% interval lies inside ±{margin:g} "
                  f"(a margin fixed before the runs); " if margin is not None else "")
    return (f"*below* / *above*: the interval over all {cells} cells compared (Bonferroni, "
            f"shown after it) excludes 0; {equivalent}*not resolved*: neither, whatever the "
            f"95% interval, which is printed (an interval that includes 0 is not agreement).")


def _welch(terms: Sequence[tuple[float, int]], difference: float, cells: int,
           std_assumed: bool, level: float, margin: float | None) -> ThesisComparison:
    """The interval of ``difference`` whose variance is the sum of ``terms``' variances, each
    ``(variance, degrees of freedom)``."""
    if cells < 1:
        raise ValueError(f"cells={cells}: expected the number of cells compared, at least 1.")
    variance = sum(term for term, _ in terms)
    if variance == 0.0:
        raise ValueError("every seed has the same value on both sides: no seed error to "
                         "compare with.")
    dof = variance ** 2 / sum(term ** 2 / df for term, df in terms if term > 0.0)
    error = math.sqrt(variance)
    half = stats.t.ppf(1 - (1 - level) / 2, dof) * error
    adjusted = stats.t.ppf(1 - (1 - level) / (2 * cells), dof) * error
    equivalence = stats.t.ppf(1 - (1 - EQUIVALENCE_LEVEL) / 2, dof) * error
    return ThesisComparison(difference, difference - half, difference + half,
                            difference - adjusted, difference + adjusted,
                            difference - equivalence, difference + equivalence, margin, cells,
                            std_assumed, float(dof))


def compare_with_thesis(values: Sequence[float], thesis_mean: float,
                        thesis_std: float | None = None, *, thesis_seeds: int = THESIS_SEEDS,
                        cells: int = 1, level: float = LEVEL,
                        margin: float | None = None) -> ThesisComparison:
    """Our runs' ``values`` against the thesis's mean (and std, when it printed one);
    ``margin``: the equivalence margin (None: the metric has none)."""
    ours = Sample.of(values)
    theirs = Sample(thesis_mean, ours.std if thesis_std is None else thesis_std, thesis_seeds)
    return _welch([(ours.variance_of_mean, ours.n - 1),
                   (theirs.variance_of_mean, theirs.n - 1)],
                  ours.mean - theirs.mean, cells, thesis_std is None, level, margin)


def compare_averages(cells: Sequence[tuple[Sequence[float], float, float | None]], *,
                     thesis_seeds: int = THESIS_SEEDS, comparisons: int = 1,
                     level: float = LEVEL, margin: float | None = None) -> ThesisComparison:
    """The mean of our task means against the thesis's mean of its task means over the same
    tasks; ``cells``: per task, our values, the thesis's mean and its std (or None)."""
    if not cells:
        raise ValueError("no task to average over.")
    terms, difference, assumed = [], 0.0, False
    scale = len(cells) ** 2
    for values, thesis_mean, thesis_std in cells:
        ours = Sample.of(values)
        theirs = Sample(thesis_mean, ours.std if thesis_std is None else thesis_std,
                        thesis_seeds)
        assumed |= thesis_std is None
        terms += [(ours.variance_of_mean / scale, ours.n - 1),
                  (theirs.variance_of_mean / scale, theirs.n - 1)]
        difference += (ours.mean - theirs.mean) / len(cells)
    return _welch(terms, difference, comparisons, assumed, level, margin)
