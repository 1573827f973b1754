"""Is a cell's mean the thesis's? The difference with its interval, and what it lets us say.

The thesis prints, for each configuration and task, the mean over its 4 seeds; only its stage-1
tables (5.2, 5.3) print the seeds' std as well. Its mean carries a seed error of its own, so a
comparison that treats it as exact overstates every disagreement. Here a cell of ours (n runs,
mean m, sample std s) and the thesis's (4 seeds, mean m', std s') are compared as two samples:

- the difference m - m' with Welch's standard error sqrt(s²/n + s'²/4) and a t interval at
  the Welch-Satterthwaite degrees of freedom (the textbook two-sample interval, as
  ``scipy.stats.ttest_ind(..., equal_var=False)`` gives it);
- where the thesis prints no std, ``s' = s``: a spread like ours, said so beside the result;
- a second interval at the Bonferroni level 1 - 0.05 / m for the m cells a table compares, so
  that "does not agree" holds for the whole table, not for one cell picked out of many.

The reading (:attr:`ThesisComparison.verdict`):

- **agrees**: the 95% interval includes zero. Its half-width is printed with it: ±12 points is
  consistent with the thesis, not a precise agreement;
- **not resolved**: the 95% interval excludes zero but the table-wide one does not;
- **does not agree**: the table-wide interval excludes zero.

An average over tasks (the tables' Average row) is compared the same way: its variance is the
sum of the task means' variances over T², its degrees of freedom Welch-Satterthwaite's.

Example:
    >>> from temporal_torchrl.reports.thesis_comparison import compare_with_thesis
    >>> sac = compare_with_thesis([48.0, 32.0, 42.0, 44.7], thesis_mean=53.5)  # drawer-open SAC
    >>> round(sac.difference, 1), sac.verdict, sac.std_assumed
    (-11.8, 'agrees', True)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Coverage of the per-cell interval.
LEVEL = 0.95
#: Seeds behind each of the thesis's means (chapter 5: every configuration, 4 seeds).
THESIS_SEEDS = 4

AGREES = "agrees"
NOT_RESOLVED = "not resolved"
DOES_NOT_AGREE = "does not agree"


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
        cells: how many cells the table compares (the Bonferroni factor).
        std_assumed: the thesis printed no std; ours was assumed for it.
        degrees_of_freedom: Welch-Satterthwaite's.
    """

    difference: float
    low: float
    high: float
    adjusted_low: float
    adjusted_high: float
    cells: int
    std_assumed: bool
    degrees_of_freedom: float

    @property
    def half_width(self) -> float:
        return (self.high - self.low) / 2

    @property
    def verdict(self) -> str:
        if self.low <= 0.0 <= self.high:
            return AGREES
        if self.adjusted_low <= 0.0 <= self.adjusted_high:
            return NOT_RESOLVED
        return DOES_NOT_AGREE

    def describe(self, decimals: int = 1) -> str:
        """``-11.8 [-23.7, +0.1]: agrees (±11.9)``, the reading as the report prints it."""
        def signed(value: float) -> str:
            return f"{value:+.{decimals}f}"

        text = f"{signed(self.difference)} [{signed(self.low)}, {signed(self.high)}]: "
        direction = "below" if self.difference < 0 else "above"
        if self.verdict == AGREES:
            return text + f"agrees (±{self.half_width:.{decimals}f})"
        if self.verdict == NOT_RESOLVED:
            return text + (f"{direction} at 95%, not resolved over {self.cells} cells "
                           f"[{signed(self.adjusted_low)}, {signed(self.adjusted_high)}]")
        return text + (f"does not agree, {direction} over {self.cells} cells "
                       f"[{signed(self.adjusted_low)}, {signed(self.adjusted_high)}]")


def _welch(terms: Sequence[tuple[float, int]], difference: float, cells: int,
           std_assumed: bool, level: float) -> ThesisComparison:
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
    return ThesisComparison(difference, difference - half, difference + half,
                            difference - adjusted, difference + adjusted, cells, std_assumed,
                            float(dof))


def compare_with_thesis(values: Sequence[float], thesis_mean: float,
                        thesis_std: float | None = None, *, thesis_seeds: int = THESIS_SEEDS,
                        cells: int = 1, level: float = LEVEL) -> ThesisComparison:
    """Our runs' ``values`` against the thesis's mean (and std, when it printed one)."""
    ours = Sample.of(values)
    theirs = Sample(thesis_mean, ours.std if thesis_std is None else thesis_std, thesis_seeds)
    return _welch([(ours.variance_of_mean, ours.n - 1),
                   (theirs.variance_of_mean, theirs.n - 1)],
                  ours.mean - theirs.mean, cells, thesis_std is None, level)


def compare_averages(cells: Sequence[tuple[Sequence[float], float, float | None]], *,
                     thesis_seeds: int = THESIS_SEEDS, comparisons: int = 1,
                     level: float = LEVEL) -> ThesisComparison:
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
    return _welch(terms, difference, comparisons, assumed, level)
