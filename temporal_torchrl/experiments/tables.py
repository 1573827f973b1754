"""Markdown and CSV renderings of :class:`~temporal_torchrl.experiments.aggregate.MetricTable`.

The Markdown follows the thesis's tables: tasks as rows, configurations as columns, ``mean ±
std (n=seeds)``, an Average row, the best value of each row in bold (lowest TTFS / TT50S,
highest RAS; only cells whose runs all have a value compete). Runs without a value are written
out in their cell (``1 incomplete: 120/300 ep``, ``1 censored: > 85 ep``), never as a number.
The CSV has one row per cell with the 95% bootstrap confidence interval of the mean and the
thesis's published value and the difference where the configuration matches.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

from temporal_torchrl.experiments.aggregate import (
    CENSORED,
    INCOMPLETE,
    METRICS,
    UNDEFINED,
    Cell,
    MetricTable,
    RunValue,
    run_value,
)
from temporal_torchrl.experiments.published import PUBLISHED_ENCODER, PublishedCell
from temporal_torchrl.experiments.runs import RunGroup, distinguishing_keys, uses_vlm

CSV_COLUMNS = ("task", "configuration", "runs", "n", "mean", "std", "ci95_low", "ci95_high",
               "best", "status", "without_value", "published_tables", "published_mean",
               "published_std", "difference")
RUN_COLUMNS = ("configuration", "task", "seed", "episodes", "finished", *METRICS, "path")
EMPTY_CELL = "—"


def _number(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}"


def _pending_text(pending: Sequence[RunValue]) -> str:
    """``2 incomplete: 120, 85/300 ep``; ``1 censored: > 85 ep``; ``2 without RAS budget``."""
    parts = []
    incomplete = [value for value in pending if value.status == INCOMPLETE]
    if incomplete:
        episodes = ", ".join(str(value.run.episodes) for value in incomplete)
        parts.append(f"{len(incomplete)} incomplete: {episodes}/{incomplete[0].budget} ep")
    censored = [value for value in pending if value.status == CENSORED]
    if censored:
        episodes = ", ".join(f"> {value.run.episodes}" for value in censored)
        parts.append(f"{len(censored)} censored: {episodes} ep")
    undefined = [value for value in pending if value.status == UNDEFINED]
    if undefined:
        parts.append(f"{len(undefined)} without RAS budget")
    return "; ".join(parts)


def cell_text(cell: Cell | None, decimals: int, *, bold: bool = False) -> str:
    """A Markdown cell: ``**41.7 ± 3.2** (n=4)``, with the runs that have no value after it."""
    if cell is None:
        return EMPTY_CELL
    parts = []
    if cell.values:
        value = _number(cell.mean, decimals)
        if cell.std is not None:
            value += f" ± {_number(cell.std, decimals)}"
        parts.append(f"{f'**{value}**' if bold else value} (n={len(cell.values)})")
    if cell.pending:
        parts.append(_pending_text(cell.pending))
    return "; ".join(parts)


def cell_status(cell: Cell) -> str:
    """``complete``, ``partial`` (some runs without a value) or why none has one."""
    if cell.complete:
        return "complete"
    if cell.values:
        return "partial"
    return "+".join(sorted({value.status for value in cell.pending}))


def _published_text(cell: PublishedCell, decimals: int) -> str:
    text = _number(cell.mean, decimals)
    return text if cell.std is None else f"{text} ± {_number(cell.std, decimals)}"


def _markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def table_markdown(table: MetricTable) -> str:
    """The thesis-layout table of one metric, then its comparison with the thesis."""
    decimals = table.metric.decimals
    labels = [group.label for group in table.groups]
    rows = []
    for task in table.tasks:
        best = table.best(task)
        rows.append([task, *(cell_text(table.cells.get((task, label)), decimals,
                                       bold=label in best) for label in labels)])
    best = table.best(None)
    average = []
    for label in labels:
        if label in table.averages:
            text = _number(table.averages[label].mean, decimals)
            average.append(f"**{text}**" if label in best else text)
        else:
            average.append(EMPTY_CELL)
    rows.append(["Average", *average])
    parts = [f"### {table.metric.title}", "",
             _markdown_table(["Task", *labels], rows), "",
             "Mean ± sample std over seeds (n = seeds with a value); best complete value of each "
             "row in bold. Average: mean of the task means, only for configurations with every "
             "task's runs complete."]
    comparison = published_markdown(table)
    if comparison:
        parts += ["", comparison]
    return "\n".join(parts) + "\n"


def _notes(table: MetricTable, group: RunGroup) -> str:
    notes = []
    encoder = group.settings.get("encoder.name")
    if uses_vlm(group.settings) and encoder != PUBLISHED_ENCODER:
        notes.append(f"encoder {encoder} (thesis: {PUBLISHED_ENCODER})")
    if table.published[group.label].baseline_unstated:
        notes.append("the thesis does not state this column's baseline")
    return "; ".join(notes)


def _difference(ours: float, published: float, decimals: int) -> str:
    return f"{ours - published:+.{decimals}f}"


def published_markdown(table: MetricTable) -> str:
    """Configurations the thesis reports, side by side with its values (empty if none)."""
    decimals = table.metric.decimals
    rows = []
    for group in table.groups:
        result = table.published.get(group.label)
        if result is None:
            continue
        tables, notes = ", ".join(result.tables), _notes(table, group)
        for task in table.tasks:
            cell = table.cells.get((task, group.label))
            if cell is None or task not in result.cells:
                continue
            published = result.cells[task]
            difference = (_difference(cell.mean, published.mean, decimals) if cell.complete
                          else EMPTY_CELL)
            rows.append([group.label, task, cell_text(cell, decimals),
                         _published_text(published, decimals), difference, tables, notes])
        if set(table.tasks) == set(result.cells) and group.label in table.averages:
            ours = table.averages[group.label].mean
            rows.append([group.label, "Average", _number(ours, decimals),
                         _number(result.average, decimals),
                         _difference(ours, result.average, decimals), tables, notes])
    if not rows:
        return ""
    header = ["Configuration", "Task", "This report", "Thesis", "Δ (report − thesis)",
              "Thesis tables", "Note"]
    if not any(row[-1] for row in rows):
        header, rows = header[:-1], [row[:-1] for row in rows]
    return "\n".join([
        f"#### {table.metric.title}: compared with the thesis", "",
        _markdown_table(header, rows), "",
        "The thesis's values are LIV's, 4 seeds; matched on the reward variants, rho, lambda, "
        "baseline, alpha and protocol. Δ only where every run of the cell has a value."])


def _optional(value: float | None) -> str:
    return "" if value is None else f"{value:.10g}"


def table_rows(table: MetricTable) -> list[dict[str, str]]:
    """The CSV rows of ``table`` (:data:`CSV_COLUMNS`), cells then the Average rows."""
    rows = []
    for task in table.tasks:
        best = table.best(task)
        for group in table.groups:
            cell = table.cells.get((task, group.label))
            if cell is None:
                continue
            result = table.published.get(group.label)
            published = result.cells.get(task) if result is not None else None
            rows.append({
                "task": task, "configuration": group.label, "runs": str(len(cell.runs)),
                "n": str(len(cell.values)), "mean": _optional(cell.mean),
                "std": _optional(cell.std),
                "ci95_low": _optional(cell.ci[0] if cell.ci else None),
                "ci95_high": _optional(cell.ci[1] if cell.ci else None),
                "best": str(group.label in best).lower(), "status": cell_status(cell),
                "without_value": "; ".join(f"seed {value.run.seed}: {value.describe()}"
                                           for value in cell.pending),
                "published_tables": " ".join(result.tables) if published else "",
                "published_mean": _optional(published.mean if published else None),
                "published_std": _optional(published.std if published else None),
                "difference": (_optional(cell.mean - published.mean)
                               if published and cell.complete else "")})
    best = table.best(None)
    for group in table.groups:
        average = table.averages.get(group.label)
        if average is None:
            continue
        result = table.published.get(group.label)
        comparable = result is not None and set(table.tasks) == set(result.cells)
        rows.append({
            "task": "Average", "configuration": group.label, "runs": str(len(group.runs)),
            "n": "", "mean": _optional(average.mean), "std": "",
            "ci95_low": _optional(average.ci[0] if average.ci else None),
            "ci95_high": _optional(average.ci[1] if average.ci else None),
            "best": str(group.label in best).lower(), "status": "complete", "without_value": "",
            "published_tables": " ".join(result.tables) if comparable else "",
            "published_mean": _optional(result.average if comparable else None),
            "published_std": "",
            "difference": _optional(average.mean - result.average) if comparable else ""})
    return rows


def write_csv(path: Path, rows: Sequence[dict[str, str]], columns: Sequence[str]) -> None:
    with path.open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)


def run_rows(groups: Sequence[RunGroup]) -> list[dict[str, str]]:
    """One row per run (:data:`RUN_COLUMNS`): its metrics, or why it has none."""
    rows = []
    for group in groups:
        for run in group.runs:
            row = {"configuration": group.label, "task": run.task, "seed": str(run.seed),
                   "episodes": str(run.episodes), "finished": str(run.finished).lower(),
                   "path": str(run.path)}
            for metric in METRICS:
                value = run_value(run, metric)
                row[metric] = (value.describe() if value.value is not None
                               else f"{value.status}: {value.describe()}")
            rows.append(row)
    return rows


def grouping_markdown(groups: Sequence[RunGroup]) -> str:
    """Which configurations were found and the config keys that tell them apart."""
    keys = distinguishing_keys([group.settings for group in groups])
    rows = [[group.label, str(len(group.runs)), ", ".join(group.tasks),
             *(str(group.settings.get(key, "(absent)")) for key in keys)]
            for group in groups]
    explanation = (f"Runs are grouped by their config without env.seed, env.task and the "
                   f"process keys; {len(groups)} configuration(s). ")
    explanation += (f"Keys that tell them apart: {', '.join(keys)}." if keys else
                    "No key tells them apart.")
    return "\n".join(["## Configurations", "", explanation, "",
                      _markdown_table(["Configuration", "Runs", "Tasks", *keys], rows)]) + "\n"
