"""The report's tables, each one row model (:class:`~temporal_torchrl.reports.rows.Table`)
written to CSV and to Markdown by one renderer, so that the two cannot disagree.

- :func:`metric_rows`: a :class:`~temporal_torchrl.reports.aggregate.MetricTable`, one row per
  cell with, where the thesis reports the configuration, its value, the difference and its
  interval and reading; the Markdown (:func:`table_markdown`) follows the thesis's layout:
  tasks as rows, configurations as columns, ``mean ± std (n=seeds)``, an Average row, the best
  value of each row in bold (lowest TTFS / TT50S, highest RAS; only cells whose runs all have a
  value compete). A TTFS / TT50S cell gives its Kaplan-Meier median and the runs that reached
  the event, and no mean when a run is censored; runs without a value are written out in their
  cell (``1 incomplete: 120/300 ep``), never as a number. Below it, the rows the thesis reports,
  beside its values.
- :func:`reliable_rows`: a :class:`~temporal_torchrl.reports.reliable.ReliableTable`, one row per
  configuration, its IQM and mean of normalised scores over tasks and seeds and its probability
  of improvement over the baseline, each with its 95% CI, then the probabilities asked for
  (:func:`reliable_markdown`).
- :func:`task_comparison_rows`: one row per pair of configurations and task, the difference of
  their RAS with its intervals and the run pairs won (:func:`task_comparison_markdown`).
- :func:`run_rows`: one row per run (CSV only).

A difference's numbers sit in its row's fields (:func:`difference_fields`); its Markdown is
:meth:`~temporal_torchrl.reports.statistics.Difference.describe` of the difference those fields
hold (:func:`difference_of`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from temporal_torchrl.reports.aggregate import (
    INCOMPLETE,
    METRICS,
    UNDEFINED,
    Cell,
    MetricTable,
    RunValue,
    run_value,
)
from temporal_torchrl.reports.groups import RunGroup, distinguishing_keys
from temporal_torchrl.reports.published import PUBLISHED_ENCODER
from temporal_torchrl.reports.reliable import (
    Improvement,
    Interval,
    ReliableTable,
    Scores,
    score_rule,
)
from temporal_torchrl.reports.rows import (
    EMPTY_CELL,
    Column,
    Row,
    Table,
    Value,
    field_column,
    markdown_table,
)
from temporal_torchrl.reports.statistics import Difference, reading_legend
from temporal_torchrl.reports.task_comparison import FAMILY as COMPARISONS
from temporal_torchrl.reports.task_comparison import TaskComparison
from temporal_torchrl.rewards.config import has_vlm_reward

#: A Difference's fields in a row (:func:`difference_fields`), after ``difference``.
DIFFERENCE_COLUMNS = ("difference", "difference_ci95_low", "difference_ci95_high",
                      "difference_adjusted_low", "difference_adjusted_high",
                      "difference_ci90_low", "difference_ci90_high", "p_value",
                      "degrees_of_freedom", "comparisons", "margin")
CSV_COLUMNS = ("task", "configuration", "runs", "n", "mean", "std", "median", "reached",
               "censored", "censored_episodes", "best", "status", "pending", "without_value",
               "published_tables", "published_mean", "published_std", "note",
               *DIFFERENCE_COLUMNS, "std_assumed", "reading")
RELIABLE_COLUMNS = ("metric", "kind", "configuration", "tasks", "runs_scored", "censored",
                    "unscored", "incomplete", "without_budget", "iqm", "iqm_ci95_low",
                    "iqm_ci95_high", "mean", "mean_ci95_low", "mean_ci95_high", "baseline",
                    "p_improvement", "p_improvement_ci95_low", "p_improvement_ci95_high",
                    "p_improvement_tasks", "note")
TASK_COMPARISON_COLUMNS = ("configuration", "baseline", "task", "n", "baseline_n",
                           *DIFFERENCE_COLUMNS, "pairs_won", "pairs", "reading")
RUN_COLUMNS = ("configuration", "task", "seed", "episodes", "finished", *METRICS, "commits",
               "path")
#: A run's commits when it recorded none (it ran before ``provenance.json``).
NOT_RECORDED = "not recorded"
#: The task of a table's Average row.
AVERAGE = "Average"


def _number(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}"


def _bold(text: str, bold: bool) -> str:
    return f"**{text}**" if bold else text


def difference_fields(difference: Difference | None) -> dict[str, Value]:
    """A difference's fields in a row (:data:`DIFFERENCE_COLUMNS` and ``reading``); None:
    the row has none."""
    if difference is None:
        return {}
    return {"difference": difference.difference, "difference_ci95_low": difference.low,
            "difference_ci95_high": difference.high,
            "difference_adjusted_low": difference.adjusted_low,
            "difference_adjusted_high": difference.adjusted_high,
            "difference_ci90_low": difference.equivalence_low,
            "difference_ci90_high": difference.equivalence_high,
            "p_value": difference.p_value, "degrees_of_freedom": difference.degrees_of_freedom,
            "comparisons": difference.comparisons, "margin": difference.margin,
            "reading": difference.verdict}


def difference_of(row: Row) -> Difference | None:
    """The :class:`~temporal_torchrl.reports.statistics.Difference` a row's fields hold, or
    None (the row has no interval)."""
    if row.get("difference_ci95_low") is None:
        return None
    return Difference(row["difference"], row["difference_ci95_low"],
                      row["difference_ci95_high"], row["difference_adjusted_low"],
                      row["difference_adjusted_high"], row["difference_ci90_low"],
                      row["difference_ci90_high"], row["p_value"], row["degrees_of_freedom"],
                      row["comparisons"], row["margin"])


# ------------------------------------------------------------------- the per-metric tables
def _pending_text(pending: Sequence[RunValue]) -> str:
    """``2 incomplete: 120, 85/300 ep``; ``2 without RAS budget``."""
    parts = []
    incomplete = [value for value in pending if value.status == INCOMPLETE]
    if incomplete:
        episodes = ", ".join(str(value.run.episodes) for value in incomplete)
        parts.append(f"{len(incomplete)} incomplete: {episodes}/{incomplete[0].budget} ep")
    undefined = [value for value in pending if value.status == UNDEFINED]
    if undefined:
        parts.append(f"{len(undefined)} without RAS budget")
    return "; ".join(parts)


def cell_status(cell: Cell) -> str:
    """``complete``, ``partial`` (some runs without a value) or why none has one."""
    if cell.complete:
        return "complete"
    if cell.values:
        return "partial"
    return "+".join(sorted({value.status for value in cell.pending}))


def cell_fields(cell: Cell) -> dict[str, Value]:
    """A cell's fields in a row: its runs, values and statistics."""
    estimate = cell.time_to_event
    return {"runs": len(cell.runs), "n": len(cell.values), "mean": cell.mean, "std": cell.std,
            "median": estimate.median if estimate is not None else None,
            "reached": estimate.reached if estimate is not None else None,
            "censored": len(cell.censored),
            "censored_episodes": ", ".join(str(value.run.episodes) for value in cell.censored),
            "status": cell_status(cell), "pending": _pending_text(cell.pending),
            "without_value": "; ".join(f"seed {value.run.seed}: {value.describe()}"
                                       for value in cell.pending)}


def _time_to_event_text(row: Row, decimals: int) -> str:
    """``median 145 (3 of 4 reached)``: the row's Kaplan-Meier estimate."""
    median = row["median"]
    runs = row["n"] + row["censored"]
    median = "not reached" if median is None else _number(median, decimals)
    return f"median {median} ({row['reached']} of {runs} reached)"


def cell_text(row: Row, decimals: int, *, bold: bool = False) -> str:
    """A cell's Markdown from its row: ``**41.7 ± 3.2** (n=4)``; a TTFS or TT50S cell with its
    Kaplan-Meier median and the runs that reached it, and its censored runs instead of a mean
    when it has any; the runs that have no value after it."""
    parts = []
    if row["mean"] is not None:
        value = _number(row["mean"], decimals)
        if row["std"] is not None:
            value += f" ± {_number(row['std'], decimals)}"
        count = f"n={row['n']}"
        if row["reached"] is not None and row["reached"] < row["n"] + row["censored"]:
            count += f"; {_time_to_event_text(row, decimals)}, Kaplan-Meier"
        parts.append(f"{_bold(value, bold)} ({count})")
    elif row["reached"] is not None and row["n"] + row["censored"]:
        parts.append(f"{_time_to_event_text(row, decimals)}, Kaplan-Meier; {row['censored']} "
                     f"censored > {row['censored_episodes']} ep; no mean")
    if row["pending"]:
        parts.append(row["pending"])
    return "; ".join(parts)


def published_text(mean: float, std: float | None, decimals: int) -> str:
    text = _number(mean, decimals)
    return text if std is None else f"{text} ± {_number(std, decimals)}"


def _notes(table: MetricTable, group: RunGroup, task: str | None = None) -> str:
    """The row's notes; ``task``: a cell's row (``None``: the Average row)."""
    notes = []
    missing = table.missing_seeds(task, group.label) if task is not None else ()
    if missing:
        notes.append(f"still running (no run yet of planned seed{'s' if len(missing) > 1 else ''}"
                     f" {', '.join(map(str, missing))}): shown, not judged")
    encoder = group.settings.get("encoder.name")
    if has_vlm_reward(group.settings.get("reward.positional"),
                      group.settings.get("reward.directional")) and encoder != PUBLISHED_ENCODER:
        notes.append(f"encoder {encoder} (thesis: {PUBLISHED_ENCODER})")
    if table.published[group.label].baseline_unstated:
        notes.append("the thesis does not state this column's baseline")
    return "; ".join(notes)


def metric_rows(table: MetricTable) -> Table:
    """One row per cell (:data:`CSV_COLUMNS`), then the Average rows; where the thesis reports
    the configuration, its value, the difference and, where comparable, its interval and
    reading (:mod:`~temporal_torchrl.reports.thesis_comparison`)."""
    rows, comparisons = [], table.thesis_comparisons()
    for task in table.tasks:
        best = table.best(task)
        for group in table.groups:
            cell = table.cells.get((task, group.label))
            if cell is None:
                continue
            row = {"task": task, "configuration": group.label, **cell_fields(cell),
                   "best": group.label in best}
            result = table.published.get(group.label)
            published = result.cells.get(task) if result is not None else None
            if published is not None:
                comparison = comparisons.get((task, group.label))
                row.update({"published_tables": " ".join(result.tables),
                            "published_mean": published.mean, "published_std": published.std,
                            "note": _notes(table, group, task),
                            "difference": (cell.mean - published.mean
                                           if cell.complete else None),
                            **difference_fields(comparison)})
                if comparison is not None:
                    row["std_assumed"] = comparison.std_assumed
            rows.append(row)
    best = table.best(None)
    for group in table.groups:
        average = table.averages.get(group.label)
        if average is None:
            continue
        row = {"task": AVERAGE, "configuration": group.label, "runs": len(group.runs),
               "mean": average, "best": group.label in best, "status": "complete"}
        result = table.published.get(group.label)
        if result is not None and set(table.tasks) == set(result.cells):
            row.update({"published_tables": " ".join(result.tables),
                        "published_mean": result.average, "note": _notes(table, group),
                        "difference": average - result.average})
        rows.append(row)
    return Table(CSV_COLUMNS, rows)


def table_markdown(table: MetricTable) -> str:
    """The thesis-layout table of one metric, then its comparison with the thesis."""
    decimals = table.metric.decimals
    rows = metric_rows(table)

    def text(row: Row) -> str:
        if row["task"] == AVERAGE:
            return _bold(_number(row["mean"], decimals), row["best"])
        return cell_text(row, decimals, bold=row["best"])

    parts = [f"### {table.metric.title}", "",
             rows.pivot_markdown("task", "configuration", text, header="Task",
                                 lines=[*table.tasks, AVERAGE],
                                 pivots=[group.label for group in table.groups]), "",
             "Mean ± sample std over seeds (n = seeds with a value); best complete value of each "
             "row in bold. Average: mean of the task means, only for configurations with every "
             "task's runs complete."]
    comparison = published_markdown(table, rows)
    if comparison:
        parts += ["", comparison]
    return "\n".join(parts) + "\n"


def published_markdown(table: MetricTable, rows: Table) -> str:
    """The rows the thesis reports, configuration by configuration, beside its values with the
    difference, its interval and reading; empty if the thesis reports none of them."""
    decimals = table.metric.decimals
    order = [group.label for group in table.groups]
    shown = sorted((row for row in rows.rows if row.get("published_mean") is not None),
                   key=lambda row: order.index(row["configuration"]))
    if not shown:
        return ""

    def ours(row: Row) -> str:
        return (_number(row["mean"], decimals) if row["task"] == AVERAGE
                else cell_text(row, decimals))

    def difference(row: Row) -> str:
        welch = difference_of(row)
        if welch is not None:
            return welch.describe(decimals)
        return EMPTY_CELL if row["difference"] is None else f"{row['difference']:+.{decimals}f}"

    columns = [field_column("Configuration", "configuration"), field_column("Task", "task"),
               Column("This report", ours),
               Column("Thesis", lambda row: published_text(row["published_mean"],
                                                           row.get("published_std"), decimals)),
               Column("Δ (report − thesis) [95% CI]: reading", difference),
               Column("Thesis tables", lambda row: ", ".join(row["published_tables"].split()))]
    if any(row["note"] for row in shown):
        columns.append(Column("Note", lambda row: row["note"]))
    compared = [row for row in rows.rows if row.get("reading") is not None]
    text = ("The thesis's values are LIV's, 4 seeds; matched on the reward variants, rho, lambda, "
            "baseline, alpha and protocol. Δ only where every run of the cell has a value; its "
            "interval is Welch's, the thesis's mean counted as 4 seeds")
    text += (" with a spread like ours where the thesis prints no std"
             if any(row.get("std_assumed") for row in compared) else "")
    text += (f". {reading_legend(len(compared), table.metric.equivalence_margin)}"
             if compared else ".")
    return "\n".join([f"#### {table.metric.title}: compared with the thesis", "",
                      Table(rows.fields, shown).markdown(columns=columns), "", text])


def relative_run_path(path: Path, roots: Sequence[Path]) -> str:
    """``path`` relative to the first of ``roots`` that holds it (POSIX separators), prefixed
    with that root when there are several (as given relative to the working directory when
    inside it, else its name alone: no machine's paths); ``path``'s last three parts (task,
    configuration, seed) when none holds it."""
    resolved, here = Path(path).resolve(), Path.cwd().resolve()
    for root in roots:
        root = Path(root).resolve()
        if resolved == root or root in resolved.parents:
            relative = resolved.relative_to(root).as_posix()
            if len(roots) == 1:
                return relative
            prefix = root.relative_to(here).as_posix() if here in root.parents else root.name
            return f"{prefix}/{relative}"
    return Path(*resolved.parts[-3:]).as_posix()


def run_rows(groups: Sequence[RunGroup], roots: Sequence[Path]) -> Table:
    """One row per run (:data:`RUN_COLUMNS`): its metrics, or why it has none. Its path is
    written relative to the one of ``roots`` (the directories given to the report) it is in,
    so that the table holds no machine's paths; with several roots it starts with that root's
    name."""
    rows = []
    for group in groups:
        for run in group.runs:
            row = {"configuration": group.label, "task": run.task, "seed": run.seed,
                   "episodes": run.episodes, "finished": run.finished,
                   "commits": " ".join(run.commits) or NOT_RECORDED,
                   "path": relative_run_path(run.path, roots)}
            for metric in METRICS:
                value = run_value(run, metric)
                row[metric] = (value.describe() if value.value is not None
                               else f"{value.status}: {value.describe()}")
            rows.append(row)
    return Table(RUN_COLUMNS, rows)


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
                      markdown_table(["Configuration", "Runs", "Tasks", *keys], rows)]) + "\n"


# --------------------------------------------------------------------------- rliable aggregates
#: A row of the rliable table: a configuration's aggregates, or a probability asked for.
CONFIGURATION_ROW, PAIR_ROW = "configuration", "pair"


def interval_fields(prefix: str, interval: Interval | None) -> dict[str, Value]:
    """An interval's fields in a row: ``prefix``, ``prefix_ci95_low``, ``prefix_ci95_high``."""
    if interval is None:
        return {}
    return {prefix: interval.estimate, f"{prefix}_ci95_low": interval.low,
            f"{prefix}_ci95_high": interval.high}


def interval_text(row: Row, prefix: str) -> str:
    """``0.80 [0.74, 0.84]`` from a row's interval fields; — without."""
    if row.get(prefix) is None:
        return EMPTY_CELL
    return f"{row[prefix]:.2f} [{row[f'{prefix}_ci95_low']:.2f}, {row[f'{prefix}_ci95_high']:.2f}]"


def reliable_rows(table: ReliableTable) -> Table:
    """One row per configuration (:data:`RELIABLE_COLUMNS`), its IQM, mean and probability of
    improvement over the baseline, then one per probability asked for (``kind`` pair)."""
    rows = []
    for label, scores in table.scores.items():
        improvement = table.improvements.get(label)
        note = (table.no_baseline if table.no_baseline is not None
                else improvement.reason if improvement is not None else None)
        rows.append({
            "metric": table.metric.name, "kind": CONFIGURATION_ROW, "configuration": label,
            "tasks": " ".join(scores.tasks), "runs_scored": scores.scored,
            "censored": scores.censored, "unscored": len(scores.unscored),
            "incomplete": sum(run.status == INCOMPLETE for run in scores.unscored),
            "without_budget": sum(run.status == UNDEFINED for run in scores.unscored),
            **interval_fields("iqm", table.iqm.get(label)),
            **interval_fields("mean", table.mean.get(label)),
            "baseline": table.baseline,
            **interval_fields("p_improvement",
                              improvement.interval if improvement is not None else None),
            "p_improvement_tasks": " ".join(improvement.tasks) if improvement else None,
            "note": note})
    for (x, y), improvement in table.pairs.items():
        rows.append({"metric": table.metric.name, "kind": PAIR_ROW, "configuration": x,
                     "baseline": y, **interval_fields("p_improvement", improvement.interval),
                     "p_improvement_tasks": " ".join(improvement.tasks),
                     "note": improvement.reason})
    return Table(RELIABLE_COLUMNS, rows)


def _runs_text(row: Row) -> str:
    """``4``, ``4 (1 censored)``, ``0 (2 incomplete)``."""
    notes = []
    if row["censored"]:
        notes.append(f"{row['censored']} censored")
    if row["incomplete"]:
        notes.append(f"{row['incomplete']} incomplete")
    if row["without_budget"]:
        notes.append(f"{row['without_budget']} without RAS budget")
    return f"{row['runs_scored']}" + (f" ({', '.join(notes)})" if notes else "")


def _iqm_text(row: Row) -> str:
    """The IQM's interval, or why there is none: ``— (1 censored: no mean)``."""
    if row.get("iqm") is None and row["censored"]:
        return f"{EMPTY_CELL} ({row['censored']} censored: no mean)"
    return interval_text(row, "iqm")


def _improvement_text(row: Row) -> str:
    if row["configuration"] == row["baseline"]:
        return "baseline"
    if row["p_improvement_tasks"] is None:
        return EMPTY_CELL
    if row.get("p_improvement") is None:
        return f"{EMPTY_CELL} (no task in common)"
    text = interval_text(row, "p_improvement")
    common, own = len(row["p_improvement_tasks"].split()), len(row["tasks"].split())
    if common < own:
        text += f" (on {common} of its {own} tasks)"
    return text


def reliable_markdown(table: ReliableTable) -> str:
    """One metric's IQM, mean and probability of improvement per configuration, explained."""
    title = table.metric.title
    baseline = table.baseline
    rows = reliable_rows(table)
    columns = [field_column("Configuration", "configuration"),
               Column("Tasks", lambda row: str(len(row["tasks"].split()))),
               Column("Runs scored", _runs_text),
               Column("IQM [95% CI]", _iqm_text),
               Column("Mean [95% CI]", lambda row: interval_text(row, "mean"))]
    if table.no_baseline is None:
        columns.append(Column(f"P(X > {baseline}) [95% CI]", _improvement_text))
    rule = score_rule(table.metric.name, table.horizon)
    parts = [f"### {title}: over tasks and seeds (rliable)", "",
             rows.markdown(lambda row: row["kind"] == CONFIGURATION_ROW, columns), "",
             f"Normalised scores in [0, 1], higher is better: {rule}. IQM: the mean of the "
             "middle 50% of all the configuration's run scores, tasks pooled; Mean: the mean of "
             "its task means."]
    if table.no_baseline is None:
        parts[-1] += (f" P(X > {baseline}): the probability that a run of X scores more than a "
                      f"run of {baseline} on the same task (ties count half), averaged over the "
                      f"tasks both have scores on.")
    parts[-1] += (f" 95% stratified-bootstrap CIs (runs resampled within each task, "
                  f"{table.reps} resamples, seed {table.seed}); with one run per task an "
                  f"interval is its point.")
    if table.no_mean:
        parts[-1] += (" A configuration with a censored run has no IQM and no mean: its "
                      "unobserved times would need a stand-in (the analysis plan allows none); "
                      "its runs still enter the probabilities of improvement and the profiles.")
    if table.no_baseline is not None:
        parts += ["", f"No probability of improvement: {table.no_baseline}."]
    unmatched = [row for row in rows.rows if row["kind"] == CONFIGURATION_ROW
                 and row["p_improvement_tasks"] is not None and row.get("p_improvement") is None]
    if unmatched:
        parts += [""] + [f"- {row['configuration']}: {row['note']}." for row in unmatched]
    if table.pairs:
        parts += ["", f"#### {title}: probabilities of improvement asked for", "", rows.markdown(
            lambda row: row["kind"] == PAIR_ROW,
            [Column("Comparison", lambda row: f"P({row['configuration']} > {row['baseline']})"),
             Column("Tasks in common", lambda row: ", ".join(row["p_improvement_tasks"].split())
                    or EMPTY_CELL),
             Column("P [95% CI]", lambda row: interval_text(row, "p_improvement")
                    if row.get("p_improvement") is not None
                    else f"{EMPTY_CELL} ({row['note']})")])]
    shown = {(each.label, each.baseline): each
             for each in [*table.improvements.values(), *table.pairs.values()]}
    degenerate = [note for improvement in shown.values()
                  if (note := degenerate_note(improvement, table.scores)) is not None]
    if degenerate:
        parts += [""] + [f"- {note}" for note in degenerate]
    return "\n".join(parts) + "\n"


def degenerate_note(improvement: Improvement, scores: dict[str, Scores]) -> str | None:
    """What a collapsed interval (P = 1.00 [1.00, 1.00], or 0.00 [0.00, 0.00]) means, or None
    when the interval is not one."""
    interval = improvement.interval
    if interval is None or interval.low != interval.high or interval.estimate not in (0.0, 1.0):
        return None
    winner, loser = ((improvement.label, improvement.baseline) if interval.estimate == 1.0
                     else (improvement.baseline, improvement.label))
    runs = " and ".join(
        f"{sum(scores[label].task_scores(task).shape[0] for task in improvement.tasks)} "
        f"of {label}" for label in (winner, loser))
    return (f"P({improvement.label} > {improvement.baseline}) = {interval.estimate:.2f} "
            f"[{interval.low:.2f}, {interval.high:.2f}]: every run of {winner} scored above "
            f"every run of {loser} on each of the {len(improvement.tasks)} task(s) in common "
            f"({runs} runs). A bootstrap resamples only the runs seen, so the interval "
            f"collapses onto them: this is what these runs show, not certainty.")


# ------------------------------------------------------------------ configurations on a task
def task_comparison_rows(comparisons: Sequence[TaskComparison]) -> Table:
    """One row per comparison (:data:`TASK_COMPARISON_COLUMNS`)."""
    return Table(TASK_COMPARISON_COLUMNS, [
        {"configuration": each.label, "baseline": each.baseline, "task": each.task,
         "n": len(each.values), "baseline_n": len(each.baseline_values),
         **difference_fields(each.welch), "difference": each.difference,
         "comparisons": each.comparisons, "pairs_won": each.pairs_won, "pairs": each.pairs,
         "reading": each.verdict if each.reason is None else f"{each.verdict} ({each.reason})"}
        for each in comparisons])


def _comparison_text(row: Row) -> str:
    """``+34.3 [+22.9, +45.8], p = 0.0008: above over 9 comparisons [+13.0, +55.6]``."""
    welch = difference_of(row)
    if welch is None:
        return f"{row['difference']:+.1f}: {row['reading']}"
    return welch.describe(family=COMPARISONS, p=True)


def task_comparison_markdown(comparisons: Sequence[TaskComparison]) -> str:
    """The per-task comparisons of configurations, explained (empty when there is none)."""
    if not comparisons:
        return ""
    table = task_comparison_rows(comparisons).markdown(columns=[
        Column("Comparison (X − Y)", lambda row: f"{row['configuration']} − {row['baseline']}"),
        field_column("Task", "task"),
        Column("Runs (X · Y)", lambda row: f"{row['n']} · {row['baseline_n']}"),
        Column("Δ [95% CI], p: reading", _comparison_text),
        Column("Run pairs X won", lambda row: f"{row['pairs_won']:g} of {row['pairs']}")])
    m = comparisons[0].comparisons
    return "\n".join([
        "## RAS (%): configurations compared on each task", "", table, "",
        "Δ: X's mean RAS minus Y's, from unrounded means, with Welch's 95% interval and "
        "two-sided p (no equal-spread assumption). "
        f"{reading_legend(m, None, f'{COMPARISONS} of this table')} Run pairs X won: of the "
        "pairs of a run of X and a run of Y on the task, those where X's RAS is higher (ties "
        "count half), rliable's P(X > Y) on this task times the number of pairs; all of them "
        "won is what these runs show, not certainty.",
        ""])
