"""Per-run metrics and their aggregation over seeds: the cells of the thesis's tables.

Each run gives a metric only when it has it (:func:`run_value`):

- RAS (in %, as the thesis's tables) once the run has reached its task's budget e; before that
  the run is *incomplete* and shows its episode count. Tasks without a budget have no RAS.
- TTFS / TT50S: the episode of the first / 50th success. A run that reached 1,000 episodes
  (the thesis's horizon) without it scores 1,000, the thesis's convention (the metric is capped
  there); a shorter run without it is *censored*: its value is only known to exceed its episode
  count, and it is shown so.

A cell (one configuration on one task) holds the runs' values: the mean and the sample std
(n - 1), as the thesis prints them. A TTFS or TT50S cell also carries its Kaplan-Meier estimate
(:class:`TimeToEvent`): the median time, with the runs that reached the event, a censored run
counted as what it is, a time known only to exceed its episodes. A cell with a censored run has
no mean: any stand-in for the unknown time (the horizon, or the episodes run) would decide the
mean, so such a cell gives the Kaplan-Meier median alone and enters no comparison or average.
Runs without a value (RAS incomplete or undefined) are listed with the cell, never averaged in. The
Average row is the mean of the task means, as in the thesis, given only when a configuration has
complete cells on every task of the table. Interval estimates are
:mod:`~temporal_torchrl.reports.reliable`'s (rliable), over tasks and seeds, and
:mod:`~temporal_torchrl.reports.thesis_comparison`'s against the thesis, both built on
:mod:`~temporal_torchrl.reports.statistics`, which also holds the Kaplan-Meier estimate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from temporal_torchrl.envs import get_task
from temporal_torchrl.protocol_metrics import (
    DEFAULT_HORIZON,
    DEFAULT_WINDOW,
    ras,
    time_to_successes,
)
from temporal_torchrl.reports.groups import RunGroup, missing_seeds, order_tasks
from temporal_torchrl.reports.published import (
    Configuration,
    PublishedCell,
    PublishedResult,
    find_published,
)
from temporal_torchrl.reports.statistics import EQUIVALENCE_MARGIN, TimeToEvent
from temporal_torchrl.reports.thesis_comparison import ThesisComparison, compare_with_thesis
from temporal_torchrl.runs.readers import Run

#: A run has the metric.
VALUE = "value"
#: RAS: the run has not reached its task's budget yet.
INCOMPLETE = "incomplete"
#: TTFS / TT50S: not reached within a run shorter than the horizon.
CENSORED = "censored"
#: RAS of a task with no budget (only the thesis's six tasks have one).
UNDEFINED = "undefined"


@dataclass(frozen=True)
class Metric:
    """One of the thesis's metrics: its key, title, direction, printed precision and the margin
    within which a cell counts as equivalent to the thesis's (None: never)."""

    name: str
    title: str
    higher_is_better: bool
    decimals: int
    equivalence_margin: float | None = None


METRICS = {
    "ras": Metric("ras", "RAS (%)", higher_is_better=True, decimals=1,
                  equivalence_margin=EQUIVALENCE_MARGIN),
    "ttfs": Metric("ttfs", "TTFS (episodes)", higher_is_better=False, decimals=0),
    "tt50s": Metric("tt50s", "TT50S (episodes)", higher_is_better=False, decimals=0),
}
#: Successes TTFS and TT50S wait for.
SUCCESS_COUNTS = {"ttfs": 1, "tt50s": 50}


@dataclass(frozen=True)
class RunValue:
    """A run's value of a metric, or why it has none (``status``)."""

    run: Run
    value: float | None
    status: str
    budget: int | None = None

    def describe(self) -> str:
        """The value, or why there is none: ``120/300 episodes`` (incomplete), ``> 85 episodes``
        (censored), ``no RAS budget``."""
        if self.status == INCOMPLETE:
            return f"{self.run.episodes}/{self.budget} episodes"
        if self.status == CENSORED:
            return f"> {self.run.episodes} episodes"
        if self.status == UNDEFINED:
            return f"no RAS budget for {self.run.task}"
        return f"{self.value:g}"


def ras_window(budget: int, window: int = DEFAULT_WINDOW) -> int:
    """The thesis's window, shortened to the budget when the budget is smaller."""
    return min(window, budget)


def run_value(run: Run, metric: str, *, window: int = DEFAULT_WINDOW,
              horizon: int = DEFAULT_HORIZON) -> RunValue:
    """``run``'s ``metric`` (``"ras"``, ``"ttfs"``, ``"tt50s"``) from its episodes (see module
    doc); RAS in %."""
    if metric == "ras":
        budget = get_task(run.task).ras_budget
        if budget is None:
            return RunValue(run, None, UNDEFINED)
        value = ras(run.successes, budget, ras_window(budget, window))
        if value is None:
            return RunValue(run, None, INCOMPLETE, budget)
        return RunValue(run, 100.0 * value, VALUE, budget)
    if metric not in SUCCESS_COUNTS:
        raise ValueError(f"unknown metric {metric!r}; expected one of {', '.join(METRICS)}.")
    count = SUCCESS_COUNTS[metric]
    if not _reached(run, count, horizon) and run.episodes < horizon:
        return RunValue(run, None, CENSORED)
    return RunValue(run, float(time_to_successes(run.successes, count, horizon)), VALUE)


@dataclass(frozen=True)
class Cell:
    """One configuration on one task: its runs' values and their statistics.

    ``mean`` and ``std`` (sample, n - 1) are over the runs' values, None when a run has none
    (RAS incomplete or undefined, or a censored TTFS / TT50S: no stand-in is averaged), ``std``
    None below 2 values; ``time_to_event``: TTFS and TT50S's Kaplan-Meier estimate (None for
    RAS). ``pending`` lists the runs without a value (RAS incomplete or undefined).
    """

    runs: tuple[RunValue, ...]
    mean: float | None
    std: float | None
    time_to_event: TimeToEvent | None = None

    @property
    def seeds(self) -> set[int]:
        """The seeds of its runs, with a value or not."""
        return {value.run.seed for value in self.runs}

    @property
    def values(self) -> list[float]:
        """The runs' values (censored and pending runs have none)."""
        return [run.value for run in self.runs if run.status == VALUE]

    @property
    def censored(self) -> list[RunValue]:
        return [run for run in self.runs if run.status == CENSORED]

    @property
    def pending(self) -> list[RunValue]:
        return [run for run in self.runs if run.status not in (VALUE, CENSORED)]

    @property
    def complete(self) -> bool:
        """Every run has a value (the cell can be compared and averaged)."""
        return bool(self.runs) and all(run.status == VALUE for run in self.runs)

    def comparable_with(self, published: PublishedCell) -> bool:
        """Whether the cell is compared with the thesis's ``published`` value
        (:func:`~temporal_torchrl.reports.thesis_comparison.compare_with_thesis`): it is
        complete, has 2 or more values, and one side at least has a seed error (our spread, or
        the std the thesis prints). Runs that all have one value are compared with a printed
        std; without one there is no seed error to compare with."""
        return self.complete and len(self.values) >= 2 and bool(self.std or published.std)


def make_cell(runs: Sequence[Run], metric: str, *, horizon: int = DEFAULT_HORIZON) -> Cell:
    """The cell of ``runs`` (one configuration, one task) for ``metric``."""
    values = tuple(run_value(run, metric, horizon=horizon) for run in runs)
    time_to_event = None
    if metric in SUCCESS_COUNTS:
        timed = [value for value in values if value.status in (VALUE, CENSORED)]
        reached = [value.status == VALUE and _reached(value.run, SUCCESS_COUNTS[metric], horizon)
                   for value in timed]
        time_to_event = TimeToEvent.estimate(
            [value.value for value, event in zip(timed, reached, strict=True) if event],
            [value.value if value.status == VALUE else float(value.run.episodes)
             for value, event in zip(timed, reached, strict=True) if not event])
    counted = [value.value for value in values if value.status == VALUE]
    if not counted or any(value.status == CENSORED for value in values):
        return Cell(values, None, None, time_to_event)
    return Cell(values, mean=float(np.mean(counted)),
                std=float(np.std(counted, ddof=1)) if len(counted) > 1 else None,
                time_to_event=time_to_event)


def _reached(run: Run, count: int, horizon: int) -> bool:
    return sum(run.successes[:horizon]) >= count


@dataclass(frozen=True)
class MetricTable:
    """One metric over run groups: tasks as rows, configurations as columns (the thesis's
    layout), with the thesis's published values for the configurations it reports.

    Attributes:
        cells: ``(task, label) -> Cell`` where the configuration has runs on that task.
        averages: ``label -> mean of the task means`` for configurations complete on every
            task.
        published: ``label -> PublishedResult`` for configurations the thesis reports.
        planned_seeds: the seeds of the analysis plan, if any: a cell is then judged against
            the thesis only once it has a run of each (a cell still running is shown, not
            judged, and not counted among the cells compared).
    """

    metric: Metric
    tasks: tuple[str, ...]
    groups: tuple[RunGroup, ...]
    cells: dict[tuple[str, str], Cell]
    averages: dict[str, float]
    published: dict[str, PublishedResult]
    planned_seeds: tuple[int, ...] | None = None

    def missing_seeds(self, task: str, label: str) -> tuple[int, ...]:
        """The planned seeds the cell ``(task, label)`` has no run of yet (none without a
        plan)."""
        cell = self.cells.get((task, label))
        return missing_seeds(cell.seeds if cell is not None else (), self.planned_seeds)

    def best(self, task: str | None) -> set[str]:
        """Labels with the best complete value of a row (``None``: the Average row); values
        are compared as printed, so ties are all best."""
        if task is None:
            means = dict(self.averages)
        else:
            means = {group.label: self.cells[task, group.label].mean for group in self.groups
                     if (task, group.label) in self.cells
                     and self.cells[task, group.label].complete}
        if not means:
            return set()
        rounded = {label: round(mean, self.metric.decimals) for label, mean in means.items()}
        best = (max if self.metric.higher_is_better else min)(rounded.values())
        return {label for label, mean in rounded.items() if mean == best}

    def thesis_comparisons(self) -> dict[tuple[str, str], ThesisComparison]:
        """``(task, label) -> ThesisComparison`` for each cell the thesis reports that is
        comparable with it (:meth:`Cell.comparable_with`), its table-wide interval over all of
        them."""
        compared = []
        for group in self.groups:
            result = self.published.get(group.label)
            for task in self.tasks:
                cell = self.cells.get((task, group.label))
                if result is None or cell is None or task not in result.cells \
                        or not cell.comparable_with(result.cells[task]) \
                        or self.missing_seeds(task, group.label):
                    continue
                compared.append(((task, group.label), cell, result.cells[task]))
        return {key: compare_with_thesis(cell.values, published.mean, published.std,
                                         cells=len(compared),
                                         margin=self.metric.equivalence_margin)
                for key, cell, published in compared}


def build_table(groups: Sequence[RunGroup], metric: str,
                planned_seeds: Sequence[int] | None = None) -> MetricTable:
    """The table of ``metric`` over ``groups`` (see module doc); with ``planned_seeds``, a
    cell is compared with the thesis only once it has a run of each."""
    tasks = tuple(order_tasks(run.task for group in groups for run in group.runs))
    cells, averages, published = {}, {}, {}
    for group in groups:
        for task in group.tasks:
            cells[task, group.label] = make_cell(group.runs_for(task), metric)
        own = [cells.get((task, group.label)) for task in tasks]
        if all(cell is not None and cell.complete for cell in own):
            averages[group.label] = float(np.mean([cell.mean for cell in own]))
        result = find_published(Configuration.from_settings(group.settings), metric)
        if result is not None:
            published[group.label] = result
    return MetricTable(METRICS[metric], tasks, tuple(groups), cells, averages, published,
                       None if planned_seeds is None else tuple(sorted(planned_seeds)))
