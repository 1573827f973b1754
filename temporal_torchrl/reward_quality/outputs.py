"""Tables, JSON and figures of the offline reward-quality benchmark.

A task's result is a plain dict (also written as JSON) with ``"task"``, ``"encoder"``,
``"dataset"``, ``"finetuning"``, ``"run"`` (command, machine, seconds) and ``"rows"``: one dict
per configuration with ``"variant"``, ``"kind"`` (positional, directional), ``"heads"``
(zero-shot, untrained, finetuned), the metrics ``"auroc"``, ``"value_order_correlation"``,
``"value_order_correlation_std"``, ``"direction_accuracy"`` (None where they do not apply) and
``"final_losses"``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure
from torch import Tensor

#: The metric each kind is ranked by, then AUROC; (key, column title).
KIND_METRICS = {
    "positional": ("value_order_correlation", "VOC"),
    "directional": ("direction_accuracy", "direction accuracy"),
}


def _number(value: float | None, signed: bool = False) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:+.2f}" if signed else f"{value:.2f}"


def _voc(row: Mapping[str, Any]) -> str:
    mean = row.get("value_order_correlation")
    if mean is None:
        return "-"
    return f"{_number(mean, signed=True)} ± {row['value_order_correlation_std']:.2f}"


def metric_text(row: Mapping[str, Any]) -> str:
    """A row's metric of its kind and its AUROC, e.g. ``"VOC +0.52, AUROC 0.81"``."""
    key, title = KIND_METRICS[row["kind"]]
    value = _number(row[key], signed=key == "value_order_correlation")
    return f"{title} {value}, AUROC {_number(row['auroc'])}"


def _dataset_line(dataset: Mapping[str, Any], part: str) -> str:
    kinds = dataset[part]
    return ", ".join(f"{kinds[kind]['episodes']} {kind.replace('_', '-')} "
                     f"({kinds[kind]['steps']} steps)" for kind in kinds)


def results_markdown(result: Mapping[str, Any]) -> str:
    """One task's result as Markdown: the settings, then a table per reward kind."""
    encoder, dataset, finetuning, run = (result["encoder"], result["dataset"],
                                         result["finetuning"], result["run"])
    failure_noise = ", ".join(str(n) for n in dataset["failure_noise"]) or "-"
    lines = [
        f"# Reward quality: {result['task']}, {encoder['name']}",
        "",
        f"- {encoder['description']}",
        f"- frames: {dataset['spec']['image_size']}x{dataset['spec']['image_size']}, camera "
        f"{dataset['spec']['camera']}, fast render {dataset['spec']['fast_render']}; goal "
        f"\"{result['goal']}\", baseline \"{result['baseline']}\"",
        f"- dataset (seed {dataset['spec']['seed']}): training part "
        f"{_dataset_line(dataset, 'train')}; held out {_dataset_line(dataset, 'held_out')}; "
        f"expert noise {dataset['spec']['expert_noise']}, failed-expert noise "
        f"{failure_noise}; {dataset['source']}",
        f"- finetuning: stage {finetuning['stage']}, {finetuning['updates']} updates per "
        f"configuration, batch {finetuning['batch_size']}, lr {finetuning['lr']}, delta "
        f"{finetuning['delta']}, gap {finetuning['gap']}, k {finetuning['k']}, alpha "
        f"{finetuning['alpha']}, projection {finetuning['projection']}",
        f"- command: `{run['command']}`",
        f"- machine: {run['machine']}; wall time {run['seconds']:.0f} s (dataset "
        f"{run['dataset_seconds']:.0f} s, finetuning and scoring {run['scoring_seconds']:.0f} s)",
        "",
        "VOC: Spearman correlation of reward and time along held-out successful episodes up to "
        "their first success (mean ± std over episodes). AUROC: per-step reward, successful- "
        "against failed-episode steps. Direction accuracy: fraction of successful-episode steps "
        "where r_D of the real order beats r_D of the episode played backwards. Figures: "
        "`figures/<variant>.png`, the reward along one held-out successful and one failed "
        "episode (solid: finetuned or zero-shot; dashed: untrained heads).",
    ]
    for kind, (_, title) in KIND_METRICS.items():
        rows = [row for row in result["rows"] if row["kind"] == kind]
        if not rows:
            continue
        metric = "VOC" if kind == "positional" else title
        lines += ["", f"## {kind.capitalize()} rewards", "",
                  f"| variant | heads | {metric} | AUROC |", "|---|---|---|---|"]
        for row in rows:
            value = (_voc(row) if kind == "positional"
                     else _number(row["direction_accuracy"]))
            lines.append(f"| {row['variant']} | {row['heads']} | {value} | "
                         f"{_number(row['auroc'])} |")
    return "\n".join(lines) + "\n"


def _best_rows(result: Mapping[str, Any], heads: str) -> dict[str, Mapping[str, Any]]:
    """Rows by variant: ``heads`` rows, and the zero-shot rows of variants without heads."""
    chosen = {}
    for row in result["rows"]:
        if row["heads"] == heads or (row["heads"] == "zero-shot" and heads == "finetuned"):
            chosen[row["variant"]] = row
    return chosen


def summary_markdown(results: Sequence[Mapping[str, Any]]) -> str:
    """Several tasks' results side by side: per metric, variants x tasks, mean and rank.

    Ranks are by the mean over tasks of the finetuned (zero-shot for heads-free variants)
    configurations, 1 the best; the untrained heads' mean is given for comparison.
    """
    tasks = [result["task"] for result in results]
    finetuned = [_best_rows(result, "finetuned") for result in results]
    untrained = [_best_rows(result, "untrained") for result in results]
    first = results[0]
    seconds = sum(result["run"]["seconds"] for result in results)
    lines = [
        f"# Reward quality over {len(tasks)} tasks, {first['encoder']['name']}", "",
        f"- {first['encoder']['description']}",
        f"- finetuning: stage {first['finetuning']['stage']}, {first['finetuning']['updates']} "
        "updates per configuration; one held-out split per task (see each task's results.md)",
        f"- command: `{first['run']['command']}`",
        f"- machine: {first['run']['machine']}; wall time {seconds / 60:.1f} min for the "
        f"{len(tasks)} tasks",
        "- rank: by the mean over tasks (1 = best); finetuned heads, zero-shot for variants "
        "without heads; 'untrained' is the mean of the same heads before finetuning",
    ]
    for kind, (metric, title) in KIND_METRICS.items():
        for key, name in ((metric, title), ("auroc", "AUROC")):
            variants = [row["variant"] for row in first["rows"]
                        if row["kind"] == kind and row["heads"] != "untrained"]
            if not variants:
                continue
            means = {}
            for variant in variants:
                values = [rows[variant][key] for rows in finetuned if variant in rows]
                means[variant] = sum(values) / len(values)
            order = sorted(variants, key=lambda v: -means[v])
            lines += ["", f"## {kind.capitalize()} rewards: {name}", "",
                      "| variant | " + " | ".join(tasks) + " | mean | rank | untrained mean |",
                      "|---" * (len(tasks) + 4) + "|"]
            signed = key == "value_order_correlation"
            for variant in variants:
                cells = [_number(rows[variant][key], signed) if variant in rows else "-"
                         for rows in finetuned]
                before = [rows[variant][key] for rows in untrained if variant in rows]
                before_mean = _number(sum(before) / len(before), signed) if before else "-"
                lines.append(f"| {variant} | " + " | ".join(cells)
                             + f" | {_number(means[variant], signed)} | "
                             f"{order.index(variant) + 1} | {before_mean} |")
    return "\n".join(lines) + "\n"


def plot_variant_curves(path: str | Path, title: str, positive: Mapping[str, Tensor],
                       negative: Mapping[str, Tensor], success_step: int,
                       ylabel: str = "reward") -> None:
    """A PNG in the style of the thesis's Figure 5.12: one reward variant along one successful
    (blue) and one failed (orange) episode, one curve per label (finetuned, untrained heads).
    A training run's r_P and r_D curves are
    :func:`temporal_torchrl.reports.plots.plot_reward_curves`.

    Args:
        path: the PNG to write.
        title: the figure's title.
        positive, negative: reward curves ``[T]`` (steps 1 .. T) by label, e.g.
            ``{"finetuned": ..., "untrained": ...}``; the first label is drawn solid, the
            others dashed and lighter.
        success_step: the successful episode's first success step, marked by a dotted line.
        ylabel: the y axis label.
    """
    figure = Figure(figsize=(8.5, 3.6), dpi=100)
    axes = figure.subplots()
    for index, (label, curve) in enumerate(positive.items()):
        style = {"linestyle": "-", "alpha": 1.0} if index == 0 else \
            {"linestyle": "--", "alpha": 0.5}
        steps = range(1, curve.numel() + 1)
        axes.plot(steps, curve.tolist(), color="tab:blue", label=f"successful, {label}", **style)
    for index, (label, curve) in enumerate(negative.items()):
        style = {"linestyle": "-", "alpha": 1.0} if index == 0 else \
            {"linestyle": "--", "alpha": 0.5}
        steps = range(1, curve.numel() + 1)
        axes.plot(steps, curve.tolist(), color="tab:orange", label=f"failed, {label}", **style)
    axes.axvline(success_step, color="tab:blue", linestyle=":", linewidth=1.0)
    axes.annotate("first success", (success_step, 1.0), xycoords=("data", "axes fraction"),
                  xytext=(3, -12), textcoords="offset points", color="tab:blue", fontsize=8)
    axes.set_xlabel("env step t")
    axes.set_ylabel(ylabel)
    axes.set_title(title, fontsize=10)
    axes.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    figure.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
