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
from temporal_torchrl.reports.groups import RunGroup, missing_seeds, planned_runs
from temporal_torchrl.reports.published import (
    PUBLISHED_ENCODER,
    Configuration,
    PublishedCell,
    PublishedColumn,
    PublishedTable,
    published_tables,
)
from temporal_torchrl.reports.rows import Column, Row, Table, field_column
from temporal_torchrl.reports.statistics import reading_legend
from temporal_torchrl.reports.tables import (
    DIFFERENCE_COLUMNS,
    NOT_RECORDED,
    cell_fields,
    cell_text,
    difference_fields,
    difference_of,
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
        return not missing_seeds(cell.seeds, planned_seeds)

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


THESIS_TABLE_COLUMNS = ("task", "column", "page_column", "our_configuration", "runs", "n",
                        "mean", "std", "median", "reached", "censored", "censored_episodes",
                        "status", "pending", "without_value", "thesis_mean", "thesis_std",
                        *DIFFERENCE_COLUMNS, "std_assumed", "reading", "commits")
#: The ``task`` of the rows of the thesis's average over its six tasks.
THESIS_AVERAGE = "the thesis's average"
AVERAGE_PREFIX = "average of "


def _commits_text(cell: Cell) -> str:
    """The commits of the cell's runs, each once, in run order; the runs that recorded none."""
    commits = dict.fromkeys(commit for value in cell.runs for commit in value.run.commits)
    unrecorded = sum(not value.run.commits for value in cell.runs)
    text = ", ".join(commits)
    if unrecorded:
        runs = f" ({unrecorded} run{'s' if unrecorded > 1 else ''})" if commits else ""
        text += f"{'; ' if text else ''}{NOT_RECORDED}{runs}"
    return text


def thesis_table_rows(page: ThesisTablePage) -> Table:
    """One row per task and column (:data:`THESIS_TABLE_COLUMNS`), then our averages over the
    tasks run and the thesis's over its six."""
    rows = []
    for task in page.table.rows:
        for column in page.columns:
            cell, published = page.cells.get((task, column.key)), page.published(task, column)
            row = {"task": task, "column": column.published.label, "page_column": column.key,
                   "our_configuration": column.group.label if cell else NOT_RUN,
                   "thesis_mean": published.mean, "thesis_std": published.std}
            if cell is not None:
                row.update(cell_fields(cell), commits=_commits_text(cell))
            comparison = page.comparisons.get((task, column.key))
            if comparison is not None:
                row.update(difference_fields(comparison), std_assumed=comparison.std_assumed)
            rows.append(row)
    for column in page.columns:
        average = page.averages.get(column.key)
        if average is None:
            continue
        row = {"task": AVERAGE_PREFIX + " ".join(average.tasks),
               "column": column.published.label, "page_column": column.key,
               "our_configuration": column.group.label, "mean": average.ours,
               "thesis_mean": average.thesis}
        if average.comparison is not None:
            row.update(difference_fields(average.comparison),
                       std_assumed=average.comparison.std_assumed)
        rows.append(row)
    rows += [{"task": THESIS_AVERAGE, "column": column.published.label,
              "page_column": column.key, "thesis_mean": page.table.average[column.index]}
             for column in page.columns]
    return Table(THESIS_TABLE_COLUMNS, rows)


def _encoder_note(column: ThesisColumn) -> str:
    settings = column.group.settings
    encoder = settings.get("encoder.name")
    vlm = has_vlm_reward(settings.get("reward.positional"), settings.get("reward.directional"))
    return f"encoder {encoder}" if vlm and encoder != PUBLISHED_ENCODER else ""


def _is_cell(row: Row) -> bool:
    return row["task"] != THESIS_AVERAGE and not row["task"].startswith(AVERAGE_PREFIX)


def _average_tasks(row: Row) -> list[str]:
    return row["task"].removeprefix(AVERAGE_PREFIX).split()


def thesis_table_markdown(page: ThesisTablePage) -> str:
    """The page in Markdown: the table, the averages over the tasks run, the comparisons, the
    commits; every part from :func:`thesis_table_rows`."""
    decimals = page.metric.decimals
    rows = thesis_table_rows(page)
    keys = [column.key for column in page.columns]
    average_line, thesis_line = "Average over the tasks run", "Thesis's Average (its six tasks)"

    def line(row: Row) -> str:
        if row["task"] == THESIS_AVERAGE:
            return thesis_line
        return row["task"] if _is_cell(row) else average_line

    def ours(row: Row) -> str:
        if not _is_cell(row):
            return _rounded(row["mean"], decimals)
        return NOT_RUN if row.get("runs") is None else cell_text(row, decimals)

    def text(row: Row) -> str:
        thesis = published_text(row["thesis_mean"], row.get("thesis_std"), decimals)
        if row["task"] == THESIS_AVERAGE:
            return f"thesis {thesis}"
        if _is_cell(row):
            return f"{ours(row)} · thesis {thesis}"
        tasks = len(_average_tasks(row))
        return f"{ours(row)} ({tasks} task{'s' if tasks > 1 else ''}) · thesis {thesis}"

    table = rows.pivot_markdown(line, "page_column", text, header="Task",
                                lines=[*page.table.rows, average_line, thesis_line],
                                pivots=keys, missing=NOT_RUN)
    notes = [f"- {column.key}: our runs are {column.group.label}, "
             f"{_encoder_note(column) or 'the thesis’s encoder'}." for column in page.columns
             if column.group is not None and _encoder_note(column)]
    parts = [f"## Thesis Table {page.table.number}: {page.metric.title}, ours beside the thesis",
             "", f"Thesis: {page.table.caption}", "", table, "",
             "Ours: mean ± sample std over seeds (n); the thesis: its mean over 4 seeds with LIV. "
             "Average over the tasks run: our mean of task means over the tasks each column has "
             "complete runs on, beside the thesis's mean over the same tasks."]
    if notes:
        parts += ["", *notes]
    if page.after_looking:
        parts += ["", "Left out of this page, as seeds added after looking (outside the plan's "
                  "seeds; the per-metric tables keep them): " + "; ".join(page.after_looking)
                  + "."]
    compared = sorted((row for row in rows.rows if row.get("reading") is not None),
                      key=lambda row: keys.index(row["page_column"]))
    if compared:
        assumed = any(row["std_assumed"] for row in compared if _is_cell(row))
        cells = sum(_is_cell(row) for row in compared)
        comparison_table = Table(rows.fields, compared).markdown(columns=[
            field_column("Column", "page_column"),
            Column("Task", lambda row: row["task"] if _is_cell(row)
                   else AVERAGE_PREFIX + ", ".join(_average_tasks(row))),
            Column("Ours", ours),
            Column("Thesis", lambda row: published_text(row["thesis_mean"],
                                                        row.get("thesis_std"), decimals)
                   if _is_cell(row) else _rounded(row["thesis_mean"], decimals)),
            Column("Δ (ours − thesis) [95% CI]: reading",
                   lambda row: difference_of(row).describe(decimals))])
        parts += ["", f"### Table {page.table.number}: compared with the thesis", "",
                  comparison_table, "",
                  f"Δ from unrounded means; Welch's interval with the thesis's mean counted as 4 "
                  f"seeds{' with a spread like ours (the thesis prints no std)' if assumed else ''}"
                  f". {reading_legend(cells, page.metric.equivalence_margin)} "
                  f"An average over several tasks is compared likewise, its table-wide "
                  f"interval over the averages compared."]
    commits = Table(rows.fields, [row for row in rows.rows if row.get("runs") is not None
                                  and _is_cell(row)])
    commits = Table(rows.fields, sorted(commits.rows,
                                        key=lambda row: keys.index(row["page_column"])))
    parts += ["", f"### Table {page.table.number}: the commits each cell's runs ran on", "",
              commits.markdown(columns=[field_column("Column", "page_column"),
                                        field_column("Task", "task"),
                                        field_column("Commits", "commits")]), "",
              f"From each run's provenance.json (first 12 hex digits; +dirty: the tracked files "
              f"differed). *{NOT_RECORDED}*: the runs predate the record. A cell naming two "
              f"commits mixes them."]
    return "\n".join(parts) + "\n"
