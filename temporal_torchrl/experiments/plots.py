"""Figures of a report (matplotlib, written as PNG files).

- :func:`plot_success_curves`: running-average success (window 150, the thesis's Figures
  5.4-5.11), one panel per task, one line per configuration, mean and a ±std band over seeds.
- :func:`plot_logged_metric`: one logged training metric (``sac/loss_qvalue``, ...) the same way,
  against env steps.
- :func:`plot_reward_curves`: r_P and r_D along a positive and a negative episode (Figure 5.12).

Seeds are averaged where all of them have data: up to the shortest run's last episode (or, for
logged metrics, over the step range all runs share). Past that point the longer runs are drawn
one by one as thin lines of the same colour, so a run that stopped early never drags a mean down
or up. Figures are ``matplotlib.figure.Figure`` objects, not pyplot's: nothing opens a window or
changes the process's backend.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from temporal_torchrl.envs import get_task
from temporal_torchrl.experiments.logs import Series
from temporal_torchrl.experiments.reward_curves import EpisodeRewards
from temporal_torchrl.experiments.runs import Run, RunGroup, order_tasks
from temporal_torchrl.metrics import DEFAULT_WINDOW

#: The thesis's colours in Figure 5.12: positive blue, negative orange.
POSITIVE_COLOUR, NEGATIVE_COLOUR = "tab:blue", "tab:orange"


def running_average(successes: Sequence[bool], window: int = DEFAULT_WINDOW) -> np.ndarray:
    """Success rate (%) over the last ``window`` episodes at each episode (fewer at the start:
    the mean of all episodes so far)."""
    values = np.asarray(successes, dtype=float)
    totals = np.cumsum(values)
    lagged = np.concatenate([np.zeros(window), totals])[:values.size]
    counts = np.minimum(np.arange(1, values.size + 1), window)
    return 100.0 * (totals - lagged) / counts


def draw_mean_band(axes: Axes, curves: Sequence[Series], label: str, colour: str) -> None:
    """Mean ± std of ``curves`` on the steps all of them cover (interpolated onto their union
    there), and each curve alone beyond, thin."""
    start = max(curve.steps[0] for curve in curves)
    stop = min(curve.steps[-1] for curve in curves)
    grid = np.unique(np.concatenate([curve.steps for curve in curves]))
    grid = grid[(grid >= start) & (grid <= stop)]
    values = np.stack([np.interp(grid, curve.steps, curve.values) for curve in curves])
    mean = values.mean(axis=0)
    axes.plot(grid, mean, color=colour, label=f"{label} (n={len(curves)})")
    if len(curves) > 1:
        std = values.std(axis=0, ddof=1)
        axes.fill_between(grid, mean - std, mean + std, color=colour, alpha=0.2, linewidth=0)
    for curve in curves:
        beyond = curve.steps >= stop
        if beyond.sum() > 1:
            axes.plot(curve.steps[beyond], curve.values[beyond], color=colour, linewidth=0.7,
                      alpha=0.6)


def _task_panels(tasks: Sequence[str], title: str) -> tuple[Figure, dict[str, Axes]]:
    columns = min(3, len(tasks))
    rows = -(-len(tasks) // columns)
    figure = Figure(figsize=(5 * columns, 3.6 * rows))
    axes = figure.subplots(rows, columns, squeeze=False)
    for extra in axes.flat[len(tasks):]:
        extra.set_visible(False)
    figure.suptitle(title)
    return figure, dict(zip(tasks, axes.flat, strict=False))


def _plot_groups(groups: Sequence[RunGroup], path: Path, title: str, ylabel: str, xlabel: str,
                 curve_of: Callable[[Run], Series | None],
                 decorate: Callable[[Axes, str], None] | None = None) -> None:
    """One panel per task, one mean-band line per group (groups without data left out)."""
    tasks = order_tasks(run.task for group in groups for run in group.runs)
    figure, panels = _task_panels(tasks, title)
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for number, group in enumerate(groups):
        for task in group.tasks:
            curves = [curve for curve in map(curve_of, group.runs_for(task))
                      if curve is not None and curve.steps.size]
            if curves:
                draw_mean_band(panels[task], curves, group.label, colours[number % len(colours)])
    for task, axes in panels.items():
        axes.set_title(task)
        axes.set_xlabel(xlabel)
        axes.set_ylabel(ylabel)
        if decorate is not None:
            decorate(axes, task)
        if axes.lines:
            axes.legend(fontsize="x-small")
    figure.tight_layout()
    figure.savefig(path, dpi=120)


def plot_success_curves(groups: Sequence[RunGroup], path: Path,
                        window: int = DEFAULT_WINDOW) -> None:
    """Running-average success rate per task and configuration (dashed: the RAS budget)."""
    def curve(run: Run) -> Series:
        return Series(np.arange(1, run.episodes + 1, dtype=float),
                      running_average(run.successes, window))

    def mark_budget(axes: Axes, task: str) -> None:
        budget = get_task(task).ras_budget
        if budget is not None:
            axes.axvline(budget, color="grey", linestyle="--", linewidth=0.8)
        axes.set_ylim(-2, 102)

    _plot_groups(groups, path, f"Running average success rate (window {window})",
                 "success rate (%)", "episode", curve, mark_budget)


def plot_logged_metric(groups: Sequence[RunGroup], scalars: Mapping[Path, Mapping[str, Series]],
                       key: str, path: Path) -> None:
    """One logged metric per task and configuration, from ``scalars[run.path][key]`` (runs
    that did not log it are left out)."""
    _plot_groups(groups, path, key, key, "env steps",
                        lambda run: scalars.get(run.path, {}).get(key))


def plot_reward_curves(positive: EpisodeRewards, negative: EpisodeRewards, path: Path,
                       title: str) -> None:
    """r_P and r_D (one panel each, absent parts left out) along both episodes; the first
    success of each is marked."""
    parts = [(name, attribute) for name, attribute in
             (("r_P (positional)", "positional"), ("r_D (directional)", "directional"))
             if getattr(positive, attribute) is not None]
    figure = Figure(figsize=(8, 3.2 * len(parts)))
    axes = figure.subplots(len(parts), 1, squeeze=False, sharex=True)
    for panel, (name, attribute) in zip(axes[:, 0], parts, strict=True):
        for episode, colour in ((positive, POSITIVE_COLOUR), (negative, NEGATIVE_COLOUR)):
            panel.plot(episode.steps, getattr(episode, attribute), color=colour,
                       label=f"{episode.kind} (replay {episode.index})")
            if episode.first_success is not None:
                panel.axvline(episode.first_success, color=colour, linestyle=":",
                              linewidth=1)
        panel.set_ylabel(name)
        panel.legend(fontsize="small")
    axes[-1, 0].set_xlabel("step t (dotted: first success)")
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
