"""The periodic evaluations of the deterministic policy in a report (runs with ``eval.every``).

A run that evaluated has one row per evaluation in its ``eval.csv``
(:class:`~temporal_torchrl.runs.evaluation_log.EvaluationLog`), read into
:attr:`Run.evaluations <temporal_torchrl.runs.readers.Run>`. Its *final evaluation success* is
the ``success_rate`` of its last evaluation: the fraction of those evaluation episodes that
reached success at any step (not ``final_success_rate``, success at their last step), a score
in [0, 1] that is higher the better, like RAS / 100. The CSV calls it ``last_success_rate``.

:func:`build_evaluation_table` gives, for the configurations with evaluated runs:

- per task, the mean ± sample std over seeds of the final evaluation success (%), the training
  episodes after which those last evaluations were taken, and the RAS cell of the report's RAS
  table beside it;
- over tasks and seeds, with rliable as :mod:`~temporal_torchrl.reports.reliable` does for RAS:
  the IQM (runs pooled over tasks) and the mean (of the task means) of the final evaluation
  successes, each with a 95% stratified-bootstrap CI (runs resampled within each task), beside
  RAS's.

Runs without evaluations are left out (and counted); without any evaluated run the table is
None and a report says nothing about evaluation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from temporal_torchrl.reports.aggregate import METRICS, VALUE, Cell, MetricTable
from temporal_torchrl.reports.groups import RunGroup, order_tasks
from temporal_torchrl.reports.reliable import (
    Interval,
    ReliableTable,
    RunScore,
    Scores,
    aggregate_intervals,
)
from temporal_torchrl.reports.rows import EMPTY_CELL, Column, Row, Table, field_column
from temporal_torchrl.reports.tables import (
    cell_fields,
    cell_text,
    interval_fields,
    interval_text,
)
from temporal_torchrl.runs.readers import Run

#: The columns of ``evaluation.csv``: one row per task and configuration (the mean and std of
#: its runs' last evaluation's ``success_rate``), then one per configuration over its tasks
#: (``task`` ``all``) with the rliable aggregates. Success rates and their aggregates are
#: fractions in [0, 1]; RAS is in %, as in ``ras.csv``.
EVALUATION_TABLE_COLUMNS = (
    "task", "configuration", "tasks", "runs", "evaluated", "last_success_rate_mean",
    "last_success_rate_std", "last_evaluation_episodes", "iqm", "iqm_ci95_low", "iqm_ci95_high",
    "mean", "mean_ci95_low", "mean_ci95_high", "ras_mean", "ras_std", "ras_n", "ras_pending",
    "ras_iqm", "ras_iqm_ci95_low", "ras_iqm_ci95_high", "ras_mean_over_tasks",
    "ras_mean_over_tasks_ci95_low", "ras_mean_over_tasks_ci95_high")
#: The task of the CSV rows over all of a configuration's tasks.
ALL_TASKS = "all"


def final_success(run: Run) -> float | None:
    """The ``success_rate`` of ``run``'s last evaluation, None when it has not evaluated."""
    return run.evaluations[-1]["success_rate"] if run.evaluations else None


@dataclass(frozen=True)
class EvaluationCell:
    """One configuration on one task: the final evaluation success of its evaluated runs.

    Attributes:
        runs: the evaluated runs, by seed.
        unevaluated: how many of the configuration's runs on the task have no evaluation.
    """

    runs: tuple[Run, ...]
    unevaluated: int

    @property
    def rates(self) -> np.ndarray:
        return np.array([final_success(run) for run in self.runs], dtype=float)

    @property
    def mean(self) -> float:
        return float(self.rates.mean())

    @property
    def std(self) -> float | None:
        """Sample std (n - 1), None for one run."""
        return float(self.rates.std(ddof=1)) if len(self.runs) > 1 else None

    @property
    def last_episodes(self) -> list[int]:
        """The training episodes after which the runs' last evaluations were taken (sorted,
        without repeats)."""
        return sorted({int(run.evaluations[-1]["episode"]) for run in self.runs})


@dataclass(frozen=True)
class EvaluationTable:
    """The final evaluation success of a report's configurations (see module doc).

    Attributes:
        tasks: the tasks with an evaluated run, in the tables' order.
        labels: the configurations with an evaluated run, in the report's order.
        cells: ``(task, label) -> EvaluationCell`` where the configuration has evaluated runs.
        scores: ``label -> Scores`` of the final success rates (rliable's layout).
        iqm, mean: ``label -> Interval`` (95% stratified-bootstrap CIs).
        ras: the report's RAS table, its cells shown beside (None: not shown).
        ras_reliable: its rliable RAS aggregates, shown beside (None: not shown).
        runs, evaluated: how many runs the report has, how many of them evaluated.
        reps, seed: the bootstraps'.
    """

    tasks: tuple[str, ...]
    labels: tuple[str, ...]
    cells: dict[tuple[str, str], EvaluationCell]
    scores: dict[str, Scores]
    iqm: dict[str, Interval]
    mean: dict[str, Interval]
    ras: MetricTable | None
    ras_reliable: ReliableTable | None
    runs: int
    evaluated: int
    reps: int
    seed: int

    def ras_cell(self, task: str, label: str) -> Cell | None:
        """The RAS cell beside ``(task, label)``, None when it has no RAS value."""
        cell = self.ras.cells.get((task, label)) if self.ras is not None else None
        return cell if cell is not None and cell.values else None

    def ras_iqm(self, label: str) -> Interval | None:
        return self.ras_reliable.iqm.get(label) if self.ras_reliable is not None else None

    def ras_mean(self, label: str) -> Interval | None:
        return self.ras_reliable.mean.get(label) if self.ras_reliable is not None else None


def build_evaluation_table(groups: Sequence[RunGroup], *, ras: MetricTable | None = None,
                           ras_reliable: ReliableTable | None = None, reps: int = 2000,
                           seed: int = 0) -> EvaluationTable | None:
    """The final evaluation success of ``groups``' evaluated runs, per task and over tasks
    (each configuration's estimate seeded with ``seed``), with ``ras``'s cells and
    ``ras_reliable``'s aggregates to show beside; None when no run has evaluated."""
    cells, scores = {}, {}
    for group in groups:
        tasks, per_task, run_scores = [], [], []
        for task in group.tasks:
            runs = group.runs_for(task)
            evaluated = tuple(run for run in runs if run.evaluations)
            if not evaluated:
                continue
            cell = EvaluationCell(evaluated, len(runs) - len(evaluated))
            cells[task, group.label] = cell
            tasks.append(task)
            per_task.append(cell.rates.reshape(-1, 1))
            run_scores += [RunScore(run, final_success(run), VALUE) for run in evaluated]
        if tasks:
            scores[group.label] = Scores(group.label, tuple(tasks), tuple(per_task),
                                         tuple(run_scores))
    if not scores:
        return None
    iqm, mean = {}, {}
    for label, each in scores.items():
        iqm[label], mean[label] = aggregate_intervals(each, reps=reps, seed=seed)
    all_runs = [run for group in groups for run in group.runs]
    return EvaluationTable(
        tuple(order_tasks(task for task, _ in cells)), tuple(scores), cells, scores, iqm, mean,
        ras, ras_reliable, len(all_runs), sum(bool(run.evaluations) for run in all_runs), reps,
        seed)


# --------------------------------------------------------------------------- Markdown and CSV
def evaluation_rows(table: EvaluationTable) -> Table:
    """The rows of ``table`` (:data:`EVALUATION_TABLE_COLUMNS`): the cells, then one row per
    configuration over its tasks."""
    rows = []
    for task in table.tasks:
        for label in table.labels:
            cell = table.cells.get((task, label))
            if cell is None:
                continue
            ras = table.ras_cell(task, label)
            rows.append({
                "task": task, "configuration": label,
                "runs": len(cell.runs) + cell.unevaluated, "evaluated": len(cell.runs),
                "last_success_rate_mean": cell.mean, "last_success_rate_std": cell.std,
                "last_evaluation_episodes": " ".join(map(str, cell.last_episodes)),
                **({} if ras is None else {
                    "ras_mean": ras.mean, "ras_std": ras.std, "ras_n": len(ras.values),
                    "ras_pending": cell_fields(ras)["pending"]})})
    for label in table.labels:
        cells = [cell for (_, each), cell in table.cells.items() if each == label]
        rows.append({
            "task": ALL_TASKS, "configuration": label,
            "tasks": " ".join(table.scores[label].tasks),
            "runs": sum(len(cell.runs) + cell.unevaluated for cell in cells),
            "evaluated": table.scores[label].scored,
            **interval_fields("iqm", table.iqm[label]),
            **interval_fields("mean", table.mean[label]),
            **interval_fields("ras_iqm", table.ras_iqm(label)),
            **interval_fields("ras_mean_over_tasks", table.ras_mean(label))})
    return Table(EVALUATION_TABLE_COLUMNS, rows)


def _percent(rate: float) -> str:
    return f"{100 * rate:.{METRICS['ras'].decimals}f}"


def _success_text(row: Row) -> str:
    """``62.5 ± 17.7 (n=2)``, and the runs without evaluation."""
    text = _percent(row["last_success_rate_mean"])
    if row["last_success_rate_std"] is not None:
        text += f" ± {_percent(row['last_success_rate_std'])}"
    text += f" (n={row['evaluated']})"
    unevaluated = row["runs"] - row["evaluated"]
    if unevaluated:
        text += f"; {unevaluated} not evaluated"
    return text


def _episodes_text(row: Row) -> str:
    episodes = row["last_evaluation_episodes"].split()
    return episodes[0] if len(episodes) == 1 else f"{episodes[0]}–{episodes[-1]}"


def _ras_text(row: Row) -> str:
    """The RAS cell's text (:func:`~temporal_torchrl.reports.tables.cell_text`) from the row's
    ``ras_*`` fields."""
    if row.get("ras_n") is None:
        return EMPTY_CELL
    return cell_text({"mean": row["ras_mean"], "std": row["ras_std"], "n": row["ras_n"],
                      "reached": None, "censored": 0, "censored_episodes": "",
                      "pending": row["ras_pending"]}, METRICS["ras"].decimals)


def evaluation_markdown(table: EvaluationTable) -> str:
    """The report's evaluation section: per task, then over tasks and seeds (rliable)."""
    rows = evaluation_rows(table)
    with_ras = any(row.get("ras_n") is not None for row in rows.rows)
    columns = [field_column("Task", "task"), field_column("Configuration", "configuration"),
               Column("Final evaluation success (%)", _success_text),
               Column("Last evaluation after (episodes)", _episodes_text)]
    if with_ras:
        columns.append(Column("RAS (%)", _ras_text))
    per_task = ("Final evaluation success: the success rate of a run's last evaluation of its "
                "deterministic policy (the fraction of its evaluation episodes with success at "
                "any step: eval.csv's success_rate), mean ± sample std over the seeds evaluated "
                "(n).")
    if with_ras:
        per_task += (" RAS: the RAS table's cell, over all the configuration's runs on the task "
                     "(evaluated or not).")

    over_tasks = [row for row in rows.rows if row["task"] == ALL_TASKS]
    ras_aggregates = any(row.get("ras_iqm") is not None for row in over_tasks)
    columns_all = [field_column("Configuration", "configuration"),
                   Column("Tasks", lambda row: str(len(row["tasks"].split()))),
                   field_column("Runs evaluated", "evaluated"),
                   Column("IQM [95% CI]", lambda row: interval_text(row, "iqm")),
                   Column("Mean [95% CI]", lambda row: interval_text(row, "mean"))]
    if ras_aggregates:
        columns_all += [Column("RAS IQM [95% CI]", lambda row: interval_text(row, "ras_iqm")),
                        Column("RAS Mean [95% CI]",
                               lambda row: interval_text(row, "ras_mean_over_tasks"))]
    over = ("Scores: each evaluated run's final evaluation success rate, in [0, 1]. IQM: the "
            "mean of the middle 50% of the configuration's run scores, tasks pooled; Mean: the "
            f"mean of its task means; 95% stratified-bootstrap CIs (runs resampled within each "
            f"task, {table.reps} resamples, seed {table.seed}), computed with rliable; with one "
            "run per task an interval is its point.")
    if ras_aggregates:
        over += (" RAS IQM and Mean: the rliable RAS table's (score RAS / 100, over all the "
                 "configuration's runs with a RAS).")
    return "\n".join([
        "## Evaluation of the deterministic policy", "",
        f"{table.evaluated} of {table.runs} runs evaluated their deterministic policy "
        "periodically (eval.every); the runs without evaluations are left out of this section. "
        "Figure: [evaluation_curves.png](evaluation_curves.png).", "",
        "### Final evaluation success per task", "",
        rows.markdown(lambda row: row["task"] != ALL_TASKS, columns), "", per_task, "",
        "### Final evaluation success over tasks and seeds (rliable)", "",
        rows.markdown(lambda row: row["task"] == ALL_TASKS, columns_all), "", over]) + "\n"
