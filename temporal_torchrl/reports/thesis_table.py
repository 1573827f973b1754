"""A page shaped as one of the thesis's tables: its tasks as rows, its columns, ours beside it.

``python recipes/report.py <runs> --out <dir> --thesis-table 5.12`` lays the runs out as the
thesis's Table 5.12: every task of the table a row, every column of it a column. A cell holds our
runs of that configuration on that task (mean ± std over seeds) beside the thesis's value, or
"not run". Under it:

- the average over the tasks we ran, per column, beside the thesis's average over the same
  tasks (not its printed Average row, which is over all six);
- each cell and each average compared with the thesis, with the difference's interval and its
  reading (:mod:`~temporal_torchrl.reports.thesis_comparison`: the thesis's seed error counted,
  the table-wide interval over every cell compared).

A published column matches the run groups whose configuration is the column's (the thesis ran
LIV; a group with another encoder matches all the same and is named so). Two groups matching
one column (two encoders, say) give two columns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from temporal_torchrl.reports.aggregate import METRICS, Cell, Metric, make_cell
from temporal_torchrl.reports.groups import RunGroup, planned_runs
from temporal_torchrl.reports.published import (
    PUBLISHED_ENCODER,
    Configuration,
    PublishedCell,
    PublishedColumn,
    PublishedTable,
    published_tables,
)
from temporal_torchrl.reports.statistics import reading_legend
from temporal_torchrl.reports.tables import (
    NOT_RECORDED,
    cell_text,
    markdown_table,
    published_text,
)
from temporal_torchrl.reports.thesis_comparison import (
    ThesisComparison,
    compare_averages,
    compare_with_thesis,
)
from temporal_torchrl.rewards.config import has_vlm_reward

NOT_RUN = "not run"


def _rounded(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}"


@dataclass(frozen=True)
class ThesisColumn:
    """One column of the page: a published column and our runs of it (None: not run)."""

    published: PublishedColumn
    index: int  # the column's position in the published table
    group: RunGroup | None

    @property
    def key(self) -> str:
        """The column's name on the page: the thesis's label, our label beside it where the
        two differ."""
        label = self.published.label
        if self.group is None or self.group.label == label:
            return label
        return f"{label} (ours: {self.group.label})"


@dataclass(frozen=True)
class Average:
    """One column's mean of task means over the tasks we ran, beside the thesis's over them."""

    tasks: tuple[str, ...]
    ours: float
    thesis: float
    comparison: ThesisComparison | None  # None over one task: that cell's comparison


@dataclass(frozen=True)
class ThesisTablePage:
    """The page's content (module doc); ``cells``, ``comparisons`` by ``(task, column key)``,
    ``averages`` by column key."""

    table: PublishedTable
    metric: Metric
    columns: tuple[ThesisColumn, ...]
    cells: dict[tuple[str, str], Cell]
    comparisons: dict[tuple[str, str], ThesisComparison]
    averages: dict[str, Average]
    #: Runs left out as added after looking (seeds outside the plan's): "SAC, drawer-open, seed 4".
    after_looking: tuple[str, ...] = ()

    def published(self, task: str, column: ThesisColumn) -> PublishedCell:
        return self.table.rows[task][column.index]


def find_table(number: str) -> PublishedTable:
    """The thesis's table ``number`` (``"5.12"``); a clear error naming the ones there are."""
    tables = {table.number: table for table in published_tables()}
    if number not in tables:
        raise ValueError(f"no thesis table {number!r}; the transcribed ones are "
                         f"{', '.join(tables)}.")
    return tables[number]


def build_thesis_table(groups: Sequence[RunGroup], number: str,
                       planned_seeds: Sequence[int] | None = None) -> ThesisTablePage:
    """The page of the thesis's table ``number`` for ``groups`` (module doc); with
    ``planned_seeds``, on the runs of those seeds only, the others named as added after
    looking, and a cell compared with the thesis only once it has all of them."""
    table = find_table(number)
    after_looking = ()
    if planned_seeds is not None:
        groups, after_looking = planned_runs(groups, planned_seeds)
    columns = []
    for index, published in enumerate(table.columns):
        matching = [group for group in groups
                    if published.configuration.matches(Configuration.from_settings(
                        group.settings))]
        columns += [ThesisColumn(published, index, group) for group in matching] or [
            ThesisColumn(published, index, None)]
    cells = {(task, column.key): make_cell(column.group.runs_for(task), table.metric)
             for column in columns if column.group is not None
             for task in table.rows if task in column.group.tasks}
    by_key = {column.key: column for column in columns}

    def comparable(task: str, column: ThesisColumn) -> bool:
        """A cell with a seed error; with a plan, one with every planned seed (a cell still
        running is shown, not judged)."""
        cell = cells.get((task, column.key))
        if cell is None or not cell.comparable_with(table.rows[task][column.index]):
            return False
        return planned_seeds is None or set(planned_seeds) <= {
            value.run.seed for value in cell.runs}

    compared = [(task, key) for task, key in cells if comparable(task, by_key[key])]
    comparisons = {}
    for task, key in compared:
        published = table.rows[task][by_key[key].index]
        comparisons[task, key] = compare_with_thesis(
            cells[task, key].values, published.mean, published.std, cells=len(compared),
            margin=METRICS[table.metric].equivalence_margin)
    averaged = {}
    for column in columns:
        tasks = tuple(task for task in table.rows if comparable(task, column))
        if tasks:
            averaged[column.key] = (column, tasks)
    # An average over one task is that task's cell, compared above already.
    several = sum(len(tasks) > 1 for _, tasks in averaged.values())
    averages = {}
    for key, (column, tasks) in averaged.items():
        published = [table.rows[task][column.index] for task in tasks]
        ours = [cells[task, key] for task in tasks]
        comparison = compare_averages(
            [(cell.values, each.mean, each.std)
             for cell, each in zip(ours, published, strict=True)],
            comparisons=several, margin=METRICS[table.metric].equivalence_margin
        ) if len(tasks) > 1 else None
        averages[key] = Average(tasks, float(np.mean([cell.mean for cell in ours])),
                                float(np.mean([cell.mean for cell in published])), comparison)
    return ThesisTablePage(table, METRICS[table.metric], tuple(columns), cells, comparisons,
                           averages, after_looking)


def _ours_text(cell: Cell | None, decimals: int) -> str:
    return NOT_RUN if cell is None else cell_text(cell, decimals)


def _encoder_note(column: ThesisColumn) -> str:
    settings = column.group.settings
    encoder = settings.get("encoder.name")
    vlm = has_vlm_reward(settings.get("reward.positional"), settings.get("reward.directional"))
    return f"encoder {encoder}" if vlm and encoder != PUBLISHED_ENCODER else ""


def thesis_table_markdown(page: ThesisTablePage) -> str:
    """The page in Markdown: the table, the averages over the tasks run, the comparisons."""
    decimals = page.metric.decimals
    header = ["Task", *(column.key for column in page.columns)]
    rows = [[task, *(f"{_ours_text(page.cells.get((task, column.key)), decimals)} · thesis "
                     f"{published_text(page.published(task, column), decimals)}"
                     for column in page.columns)]
            for task in page.table.rows]
    average_row = ["Average over the tasks run"]
    for column in page.columns:
        average = page.averages.get(column.key)
        average_row.append(NOT_RUN if average is None else (
            f"{_rounded(average.ours, decimals)} ({len(average.tasks)} "
            f"task{'s' if len(average.tasks) > 1 else ''}) · thesis "
            f"{_rounded(average.thesis, decimals)}"))
    rows.append(average_row)
    rows.append(["Thesis's Average (its six tasks)", *(
        f"thesis {_rounded(page.table.average[column.index], decimals)}"
        for column in page.columns)])
    notes = [f"- {column.key}: our runs are {column.group.label}, "
             f"{_encoder_note(column) or 'the thesis’s encoder'}." for column in page.columns
             if column.group is not None and _encoder_note(column)]
    comparison_rows = []
    for column in page.columns:
        for task in page.table.rows:
            comparison = page.comparisons.get((task, column.key))
            if comparison is not None:
                comparison_rows.append([column.key, task,
                                        _ours_text(page.cells[task, column.key], decimals),
                                        published_text(page.published(task, column), decimals),
                                        comparison.describe(decimals)])
        average = page.averages.get(column.key)
        if average is not None and average.comparison is not None:
            comparison_rows.append([column.key, f"average of {', '.join(average.tasks)}",
                                    _rounded(average.ours, decimals),
                                    _rounded(average.thesis, decimals),
                                    average.comparison.describe(decimals)])
    parts = [f"## Thesis Table {page.table.number}: {page.metric.title}, ours beside the thesis",
             "", f"Thesis: {page.table.caption}", "", markdown_table(header, rows), "",
             "Ours: mean ± sample std over seeds (n); the thesis: its mean over 4 seeds with LIV. "
             "Average over the tasks run: our mean of task means over the tasks each column has "
             "complete runs on, beside the thesis's mean over the same tasks."]
    if notes:
        parts += ["", *notes]
    if page.after_looking:
        parts += ["", "Left out of this page, as seeds added after looking (outside the plan's "
                  "seeds; the per-metric tables keep them): " + "; ".join(page.after_looking)
                  + "."]
    if comparison_rows:
        assumed = any(each.std_assumed for each in page.comparisons.values())
        parts += ["", f"### Table {page.table.number}: compared with the thesis", "",
                  markdown_table(["Column", "Task", "Ours", "Thesis",
                                   "Δ (ours − thesis) [95% CI]: reading"], comparison_rows), "",
                  f"Δ from unrounded means; Welch's interval with the thesis's mean counted as 4 "
                  f"seeds{' with a spread like ours (the thesis prints no std)' if assumed else ''}"
                  f". {reading_legend(len(page.comparisons), page.metric.equivalence_margin)} "
                  f"An average over several tasks is compared likewise, its table-wide "
                  f"interval over the averages compared."]
    parts += ["", f"### Table {page.table.number}: the commits each cell's runs ran on", "",
              markdown_table(["Column", "Task", "Commits"], commit_rows(page)), "",
              f"From each run's provenance.json (first 12 hex digits; +dirty: the tracked files "
              f"differed). *{NOT_RECORDED}*: the runs predate the record. A cell naming two "
              f"commits mixes them."]
    return "\n".join(parts) + "\n"


def commit_rows(page: ThesisTablePage) -> list[list[str]]:
    """Per column and task run, the commits of the cell's runs (each once, in run order)."""
    rows = []
    for column in page.columns:
        for task in page.table.rows:
            cell = page.cells.get((task, column.key))
            if cell is None:
                continue
            commits = dict.fromkeys(commit for value in cell.runs
                                    for commit in value.run.commits)
            unrecorded = sum(not value.run.commits for value in cell.runs)
            text = ", ".join(commits)
            if unrecorded:
                runs = f" ({unrecorded} run{'s' if unrecorded > 1 else ''})" if commits else ""
                text += f"{'; ' if text else ''}{NOT_RECORDED}{runs}"
            rows.append([column.key, task, text])
    return rows


THESIS_TABLE_COLUMNS = ("task", "column", "our_configuration", "n", "mean", "std", "thesis_mean",
                        "thesis_std", "difference", "difference_ci95_low",
                        "difference_ci95_high", "cells_compared", "adjusted_ci_low",
                        "adjusted_ci_high", "reading")


def thesis_table_rows(page: ThesisTablePage) -> list[dict[str, str]]:
    """One CSV row per task and column (:data:`THESIS_TABLE_COLUMNS`), then the averages."""
    def optional(value: float | None) -> str:
        return "" if value is None else f"{value:.10g}"

    def comparison_fields(comparison: ThesisComparison | None) -> dict[str, str]:
        if comparison is None:
            return dict.fromkeys(THESIS_TABLE_COLUMNS[8:], "")
        return {"difference": optional(comparison.difference),
                "difference_ci95_low": optional(comparison.low),
                "difference_ci95_high": optional(comparison.high),
                "cells_compared": str(comparison.comparisons),
                "adjusted_ci_low": optional(comparison.adjusted_low),
                "adjusted_ci_high": optional(comparison.adjusted_high),
                "reading": comparison.verdict}

    rows = []
    for task in page.table.rows:
        for column in page.columns:
            cell, published = page.cells.get((task, column.key)), page.published(task, column)
            rows.append({"task": task, "column": column.published.label,
                         "our_configuration": column.group.label if cell else NOT_RUN,
                         "n": str(len(cell.values)) if cell else "",
                         "mean": optional(cell.mean if cell else None),
                         "std": optional(cell.std if cell else None),
                         "thesis_mean": optional(published.mean),
                         "thesis_std": optional(published.std),
                         **comparison_fields(page.comparisons.get((task, column.key)))})
    for column in page.columns:
        average = page.averages.get(column.key)
        if average is not None:
            rows.append({"task": "average of " + " ".join(average.tasks),
                         "column": column.published.label,
                         "our_configuration": column.group.label, "n": "",
                         "mean": optional(average.ours), "std": "",
                         "thesis_mean": optional(average.thesis), "thesis_std": "",
                         **comparison_fields(average.comparison)})
    return rows
