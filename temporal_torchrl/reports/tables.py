"""Markdown and CSV renderings of the report's tables.

:class:`~temporal_torchrl.reports.aggregate.MetricTable` (:func:`table_markdown`,
:func:`table_rows`) follows the thesis's tables: tasks as rows, configurations as columns,
``mean ± std (n=seeds)``, an Average row, the best value of each row in bold (lowest TTFS /
TT50S, highest RAS; only cells whose runs all have a value compete). Censored TTFS / TT50S runs
count at the horizon and are named in their cell with the median beside the mean
(``n=4; 1 censored > 200 ep, counted 1000; median 151``); runs without a value are written out
in their cell (``1 incomplete: 120/300 ep``), never as a number. The CSV has one row per cell
with the thesis's published value and the difference, its interval and its reading where the
configuration matches.

:class:`~temporal_torchrl.reports.reliable.ReliableTable` (:func:`reliable_markdown`,
:func:`reliable_rows`): one row per configuration, its IQM and mean of normalised scores over
tasks and seeds and its probability of improvement over the baseline, each with its 95% CI.

:class:`~temporal_torchrl.reports.task_comparison.TaskComparison`
(:func:`task_comparison_markdown`, :func:`task_comparison_rows`): one row per pair of
configurations and task, the difference of their RAS with its intervals and the run pairs won.
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
from temporal_torchrl.reports.published import PUBLISHED_ENCODER, PublishedCell
from temporal_torchrl.reports.reliable import (
    Improvement,
    Interval,
    ReliableTable,
    Scores,
    score_rule,
)
from temporal_torchrl.reports.statistics import reading_legend
from temporal_torchrl.reports.task_comparison import TaskComparison
from temporal_torchrl.reports.thesis_comparison import ThesisComparison
from temporal_torchrl.rewards.config import has_vlm_reward

CSV_COLUMNS = ("task", "configuration", "runs", "n", "mean", "std", "median", "reached", "censored",
               "best", "status", "without_value", "published_tables", "published_mean",
               "published_std", "difference", "difference_ci95_low", "difference_ci95_high",
               "reading")
RELIABLE_COLUMNS = ("metric", "configuration", "tasks", "runs_scored", "censored_as_zero",
                    "unscored", "iqm", "iqm_ci95_low", "iqm_ci95_high", "mean", "mean_ci95_low",
                    "mean_ci95_high", "baseline", "p_improvement", "p_improvement_ci95_low",
                    "p_improvement_ci95_high", "p_improvement_tasks", "note")
TASK_COMPARISON_COLUMNS = ("configuration", "baseline", "task", "n", "baseline_n", "difference",
                           "difference_ci95_low", "difference_ci95_high", "p_value",
                           "comparisons", "difference_adjusted_low",
                           "difference_adjusted_high", "pairs_won", "pairs", "reading")
RUN_COLUMNS = ("configuration", "task", "seed", "episodes", "finished", *METRICS, "commits",
               "path")
#: A run's commits when it recorded none (it ran before ``provenance.json``).
NOT_RECORDED = "not recorded"
EMPTY_CELL = "—"


def _number(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}"


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


def _censored_text(cell: Cell) -> str:
    """``1 censored > 200 ep``: the runs that stopped before the horizon without the event."""
    episodes = ", ".join(str(value.run.episodes) for value in cell.censored)
    return f"{len(cell.censored)} censored > {episodes} ep"


def cell_text(cell: Cell | None, decimals: int, *, bold: bool = False) -> str:
    """A Markdown cell: ``**41.7 ± 3.2** (n=4)``; a TTFS or TT50S cell with its Kaplan-Meier
    median and the runs that reached it, and its censored runs instead of a mean when it has
    any; the runs that have no value after it."""
    if cell is None:
        return EMPTY_CELL
    parts = []
    if cell.mean is not None:
        value = _number(cell.mean, decimals)
        if cell.std is not None:
            value += f" ± {_number(cell.std, decimals)}"
        count = f"n={len(cell.values)}"
        estimate = cell.time_to_event
        if estimate is not None and estimate.reached < estimate.runs:  # some at the horizon
            count += f"; {estimate.describe(decimals)}, Kaplan-Meier"
        parts.append(f"{f'**{value}**' if bold else value} ({count})")
    elif cell.time_to_event is not None and cell.time_to_event.runs:
        parts.append(f"{cell.time_to_event.describe(decimals)}, Kaplan-Meier; "
                     f"{_censored_text(cell)}; no mean")
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


def published_text(cell: PublishedCell, decimals: int) -> str:
    text = _number(cell.mean, decimals)
    return text if cell.std is None else f"{text} ± {_number(cell.std, decimals)}"


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
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
            text = _number(table.averages[label], decimals)
            average.append(f"**{text}**" if label in best else text)
        else:
            average.append(EMPTY_CELL)
    rows.append(["Average", *average])
    parts = [f"### {table.metric.title}", "",
             markdown_table(["Task", *labels], rows), "",
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
    if has_vlm_reward(group.settings.get("reward.positional"),
                      group.settings.get("reward.directional")) and encoder != PUBLISHED_ENCODER:
        notes.append(f"encoder {encoder} (thesis: {PUBLISHED_ENCODER})")
    if table.published[group.label].baseline_unstated:
        notes.append("the thesis does not state this column's baseline")
    return "; ".join(notes)


def _difference(ours: float, published: float, decimals: int) -> str:
    return f"{ours - published:+.{decimals}f}"


def published_markdown(table: MetricTable) -> str:
    """Configurations the thesis reports, side by side with its values and the difference with
    its interval and reading (:mod:`~temporal_torchrl.reports.thesis_comparison`); empty if the
    thesis reports none of them."""
    decimals = table.metric.decimals
    comparisons = table.thesis_comparisons()
    rows, assumed = [], False
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
            comparison = comparisons.get((task, group.label))
            if comparison is not None:
                difference = comparison.describe(decimals)
                assumed |= comparison.std_assumed
            elif cell.complete:
                difference = _difference(cell.mean, published.mean, decimals)
            else:
                difference = EMPTY_CELL
            rows.append([group.label, task, cell_text(cell, decimals),
                         published_text(published, decimals), difference, tables, notes])
        if set(table.tasks) == set(result.cells) and group.label in table.averages:
            ours = table.averages[group.label]
            rows.append([group.label, "Average", _number(ours, decimals),
                         _number(result.average, decimals),
                         _difference(ours, result.average, decimals), tables, notes])
    if not rows:
        return ""
    header = ["Configuration", "Task", "This report", "Thesis",
              "Δ (report − thesis) [95% CI]: reading", "Thesis tables", "Note"]
    if not any(row[-1] for row in rows):
        header, rows = header[:-1], [row[:-1] for row in rows]
    text = ("The thesis's values are LIV's, 4 seeds; matched on the reward variants, rho, lambda, "
            "baseline, alpha and protocol. Δ only where every run of the cell has a value; its "
            "interval is Welch's, the thesis's mean counted as 4 seeds")
    text += (" with a spread like ours where the thesis prints no std" if assumed else "")
    text += (f". {reading_legend(len(comparisons), table.metric.equivalence_margin)}"
             if comparisons else ".")
    return "\n".join([f"#### {table.metric.title}: compared with the thesis", "",
                      markdown_table(header, rows), "", text])


def _optional(value: float | None) -> str:
    return "" if value is None else f"{value:.10g}"


def _comparison_fields(comparison: ThesisComparison | None) -> dict[str, str]:
    if comparison is None:
        return {"difference_ci95_low": "", "difference_ci95_high": "", "reading": ""}
    return {"difference_ci95_low": _optional(comparison.low),
            "difference_ci95_high": _optional(comparison.high), "reading": comparison.verdict}


def _time_to_event_fields(cell: Cell) -> dict[str, str]:
    """``median`` (Kaplan-Meier; empty when not reached) and ``reached`` (runs with the event)
    of a TTFS or TT50S cell; empty for RAS."""
    estimate = cell.time_to_event
    if estimate is None:
        return {"median": "", "reached": ""}
    return {"median": _optional(estimate.median), "reached": str(estimate.reached)}


def table_rows(table: MetricTable) -> list[dict[str, str]]:
    """The CSV rows of ``table`` (:data:`CSV_COLUMNS`), cells then the Average rows."""
    rows, comparisons = [], table.thesis_comparisons()
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
                "std": _optional(cell.std), **_time_to_event_fields(cell),
                "censored": str(len(cell.censored)),
                "best": str(group.label in best).lower(), "status": cell_status(cell),
                "without_value": "; ".join(f"seed {value.run.seed}: {value.describe()}"
                                           for value in cell.pending),
                "published_tables": " ".join(result.tables) if published else "",
                "published_mean": _optional(published.mean if published else None),
                "published_std": _optional(published.std if published else None),
                "difference": (_optional(cell.mean - published.mean)
                               if published and cell.complete else ""),
                **_comparison_fields(comparisons.get((task, group.label)))})
    best = table.best(None)
    for group in table.groups:
        average = table.averages.get(group.label)
        if average is None:
            continue
        result = table.published.get(group.label)
        comparable = result is not None and set(table.tasks) == set(result.cells)
        rows.append({
            "task": "Average", "configuration": group.label, "runs": str(len(group.runs)),
            "n": "", "mean": _optional(average), "std": "", "median": "", "reached": "",
            "censored": "",
            "best": str(group.label in best).lower(), "status": "complete", "without_value": "",
            "published_tables": " ".join(result.tables) if comparable else "",
            "published_mean": _optional(result.average if comparable else None),
            "published_std": "",
            "difference": _optional(average - result.average) if comparable else "",
            **_comparison_fields(None)})
    return rows


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


def run_rows(groups: Sequence[RunGroup], roots: Sequence[Path]) -> list[dict[str, str]]:
    """One row per run (:data:`RUN_COLUMNS`): its metrics, or why it has none. Its path is
    written relative to the one of ``roots`` (the directories given to the report) it is in,
    so that the table holds no machine's paths; with several roots it starts with that root's
    name."""
    rows = []
    for group in groups:
        for run in group.runs:
            row = {"configuration": group.label, "task": run.task, "seed": str(run.seed),
                   "episodes": str(run.episodes), "finished": str(run.finished).lower(),
                   "commits": " ".join(run.commits) or NOT_RECORDED,
                   "path": relative_run_path(run.path, roots)}
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
                      markdown_table(["Configuration", "Runs", "Tasks", *keys], rows)]) + "\n"


# --------------------------------------------------------------------------- rliable aggregates
def _interval_text(interval: Interval | None) -> str:
    if interval is None:
        return EMPTY_CELL
    return f"{interval.estimate:.2f} [{interval.low:.2f}, {interval.high:.2f}]"


def _runs_text(scores: Scores) -> str:
    """``4``, ``4 (1 censored → 0)``, ``0 (2 incomplete)``."""
    notes = []
    if scores.censored:
        notes.append(f"{scores.censored} censored → 0")
    for status in (INCOMPLETE, UNDEFINED):
        count = sum(run.status == status for run in scores.unscored)
        if count:
            notes.append(f"{count} {'without RAS budget' if status == UNDEFINED else status}")
    return f"{scores.scored}" + (f" ({', '.join(notes)})" if notes else "")


def _improvement_text(table: ReliableTable, label: str) -> str:
    if label == table.baseline:
        return "baseline"
    improvement = table.improvements.get(label)
    if improvement is None:
        return EMPTY_CELL
    if improvement.interval is None:
        return f"{EMPTY_CELL} (no task in common)"
    text = _interval_text(improvement.interval)
    own = table.scores[label].tasks
    if len(improvement.tasks) < len(own):
        text += f" (on {len(improvement.tasks)} of its {len(own)} tasks)"
    return text


def reliable_markdown(table: ReliableTable) -> str:
    """One metric's IQM, mean and probability of improvement per configuration, explained."""
    title = table.metric.title
    baseline = table.baseline
    header = ["Configuration", "Tasks", "Runs scored", "IQM [95% CI]", "Mean [95% CI]"]
    if table.no_baseline is None:
        header.append(f"P(X > {baseline}) [95% CI]")
    rows = []
    for label, scores in table.scores.items():
        row = [label, str(len(scores.tasks)), _runs_text(scores),
               _interval_text(table.iqm.get(label)), _interval_text(table.mean.get(label))]
        if table.no_baseline is None:
            row.append(_improvement_text(table, label))
        rows.append(row)
    rule = score_rule(table.metric.name, table.horizon)
    parts = [f"### {title}: over tasks and seeds (rliable)", "",
             markdown_table(header, rows), "",
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
    if table.no_baseline is not None:
        parts += ["", f"No probability of improvement: {table.no_baseline}."]
    unmatched = [improvement for improvement in table.improvements.values()
                 if improvement.interval is None]
    if unmatched:
        parts += [""] + [f"- {improvement.label}: {improvement.reason}." for improvement in
                         unmatched]
    if table.pairs:
        parts += ["", _pairs_markdown(table)]
    shown = {(each.label, each.baseline): each
             for each in [*table.improvements.values(), *table.pairs.values()]}
    degenerate = [note for improvement in shown.values()
                  if (note := degenerate_note(improvement, table.scores)) is not None]
    if degenerate:
        parts += [""] + [f"- {note}" for note in degenerate]
    return "\n".join(parts) + "\n"


def _pairs_markdown(table: ReliableTable) -> str:
    rows = []
    for (x, y), improvement in table.pairs.items():
        tasks = ", ".join(improvement.tasks) if improvement.tasks else EMPTY_CELL
        text = (_interval_text(improvement.interval) if improvement.interval is not None
                else f"{EMPTY_CELL} ({improvement.reason})")
        rows.append([f"P({x} > {y})", tasks, text])
    return "\n".join([f"#### {table.metric.title}: probabilities of improvement asked for", "",
                      markdown_table(["Comparison", "Tasks in common", "P [95% CI]"], rows)])


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


def _interval_fields(prefix: str, interval: Interval | None) -> dict[str, str]:
    return {prefix: _optional(interval.estimate if interval else None),
            f"{prefix}_ci95_low": _optional(interval.low if interval else None),
            f"{prefix}_ci95_high": _optional(interval.high if interval else None)}


def reliable_rows(table: ReliableTable) -> list[dict[str, str]]:
    """The CSV rows of ``table`` (:data:`RELIABLE_COLUMNS`), one per configuration."""
    rows = []
    for label, scores in table.scores.items():
        improvement = table.improvements.get(label)
        note = (table.no_baseline if table.no_baseline is not None
                else improvement.reason if improvement is not None else None)
        rows.append({
            "metric": table.metric.name, "configuration": label,
            "tasks": " ".join(scores.tasks),
            "runs_scored": str(scores.scored), "censored_as_zero": str(scores.censored),
            "unscored": str(len(scores.unscored)),
            **_interval_fields("iqm", table.iqm.get(label)),
            **_interval_fields("mean", table.mean.get(label)),
            "baseline": table.baseline,
            **_interval_fields("p_improvement",
                               improvement.interval if improvement is not None else None),
            "p_improvement_tasks": " ".join(improvement.tasks) if improvement else "",
            "note": note or ""})
    return rows


def task_comparison_markdown(comparisons: Sequence[TaskComparison]) -> str:
    """The per-task comparisons of configurations, explained (empty when there is none)."""
    if not comparisons:
        return ""
    rows = [[f"{each.label} − {each.baseline}", each.task,
             f"{len(each.values)} · {len(each.baseline_values)}", each.describe(),
             f"{each.pairs_won:g} of {each.pairs}"] for each in comparisons]
    m = comparisons[0].comparisons
    return "\n".join([
        "## RAS (%): configurations compared on each task", "",
        markdown_table(["Comparison (X − Y)", "Task", "Runs (X · Y)",
                        "Δ [95% CI], p: reading", "Run pairs X won"], rows), "",
        "Δ: X's mean RAS minus Y's, from unrounded means, with Welch's 95% interval and "
        "two-sided p (no equal-spread assumption). "
        f"{reading_legend(m, None, 'comparisons of this table')} Run pairs X won: of the "
        "pairs of a run of X and a run of Y on the task, those where X's RAS is higher (ties "
        "count half), rliable's P(X > Y) on this task times the number of pairs; all of them "
        "won is what these runs show, not certainty.",
        ""])


def task_comparison_rows(comparisons: Sequence[TaskComparison]) -> list[dict[str, str]]:
    """The CSV rows of ``comparisons`` (:data:`TASK_COMPARISON_COLUMNS`)."""
    return [{"configuration": each.label, "baseline": each.baseline, "task": each.task,
             "n": str(len(each.values)), "baseline_n": str(len(each.baseline_values)),
             "difference": _optional(each.difference),
             "difference_ci95_low": _optional(each.welch and each.welch.low),
             "difference_ci95_high": _optional(each.welch and each.welch.high),
             "p_value": _optional(each.welch and each.welch.p_value),
             "comparisons": str(each.comparisons),
             "difference_adjusted_low": _optional(each.welch and each.welch.adjusted_low),
             "difference_adjusted_high": _optional(each.welch and each.welch.adjusted_high),
             "pairs_won": f"{each.pairs_won:g}", "pairs": str(each.pairs),
             "reading": each.verdict if each.reason is None
             else f"{each.verdict} ({each.reason})"} for each in comparisons]
