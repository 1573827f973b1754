"""Figures of a report (matplotlib, written as PNG files).

- :func:`plot_success_curves`: running-average success (window 150, the thesis's Figures
  5.4-5.11), one panel per task, one line per configuration, mean and a ±std band over seeds.
- :func:`plot_logged_metric`: one logged training metric (``sac/loss_qvalue``, ...) the same way,
  against env steps.
- :func:`plot_evaluation_curves`: the success rate of the deterministic policy's evaluations
  (``eval.csv``) against training env steps, the same way, with a 95% t-interval over seeds.
- :func:`plot_reward_curves`: r_P and r_D along a positive and a negative episode (Figure 5.12).
- :func:`plot_aggregate_intervals`, :func:`plot_performance_profiles`,
  :func:`plot_improvement`: the rliable aggregates of
  :mod:`~temporal_torchrl.reports.reliable`, drawn with ``rliable.plot_utils``.

Seeds are averaged where all of them have data: up to the shortest run's last episode (or, for
logged metrics, over the step range all runs share). Past that point the longer runs are drawn
one by one as thin lines of the same colour, so a run that stopped early never drags a mean down
or up. Figures are ``matplotlib.figure.Figure`` objects, not pyplot's: nothing opens a window or
changes the process's backend; the one exception is ``rliable.plot_utils.plot_interval_estimates``,
which makes its own pyplot figure, closed once saved.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import matplotlib
import numpy as np
import seaborn
from matplotlib import pyplot
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from rliable import plot_utils

from temporal_torchrl.envs import get_task
from temporal_torchrl.protocol_metrics import DEFAULT_WINDOW
from temporal_torchrl.reports.groups import RunGroup, order_tasks
from temporal_torchrl.reports.logs import Series
from temporal_torchrl.reports.reliable import ReliableTable
from temporal_torchrl.reports.reward_curves import EpisodeRewards
from temporal_torchrl.reports.statistics import mean_half_width
from temporal_torchrl.runs.readers import Run

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


#: A band around the mean over seeds: ``(values [seeds, steps], mean) -> (low, high)``.
Band = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def std_band(values: np.ndarray, mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean ± sample std over seeds."""
    std = values.std(axis=0, ddof=1)
    return mean - std, mean + std


def t_interval_band(level: float = 0.95, bounds: tuple[float, float] | None = None) -> Band:
    """The ``level`` t-interval of the mean over seeds, mean ± t_(n-1) s / sqrt(n), clipped to
    ``bounds`` when given (a rate's range)."""
    def band(values: np.ndarray, mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        half = mean_half_width(values, level)
        low, high = mean - half, mean + half
        return (low, high) if bounds is None else (np.clip(low, *bounds), np.clip(high, *bounds))
    return band


def draw_mean_band(axes: Axes, curves: Sequence[Series], label: str, colour: str,
                   band: Band = std_band, **style) -> None:
    """Mean of ``curves`` and a ``band`` around it (default ± std) on the steps all of them
    cover (interpolated onto their union there), and each curve alone beyond, thin; ``style``
    goes to the mean's line."""
    start = max(curve.steps[0] for curve in curves)
    stop = min(curve.steps[-1] for curve in curves)
    grid = np.unique(np.concatenate([curve.steps for curve in curves]))
    grid = grid[(grid >= start) & (grid <= stop)]
    values = np.stack([np.interp(grid, curve.steps, curve.values) for curve in curves])
    mean = values.mean(axis=0)
    axes.plot(grid, mean, color=colour, label=f"{label} (n={len(curves)})", **style)
    if len(curves) > 1:
        low, high = band(values, mean)
        axes.fill_between(grid, low, high, color=colour, alpha=0.2, linewidth=0)
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
                 decorate: Callable[[Axes, str], None] | None = None,
                 band: Band = std_band, **style) -> None:
    """One panel per task, one mean-band line per group (groups without data left out)."""
    tasks = order_tasks(run.task for group in groups for run in group.runs)
    figure, panels = _task_panels(tasks, title)
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for number, group in enumerate(groups):
        for task in group.tasks:
            curves = [curve for curve in map(curve_of, group.runs_for(task))
                      if curve is not None and curve.steps.size]
            if curves:
                draw_mean_band(panels[task], curves, group.label, colours[number % len(colours)],
                               band, **style)
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


def plot_evaluation_curves(groups: Sequence[RunGroup], path: Path, level: float = 0.95) -> None:
    """The evaluations' success rate (%, success at any step of an evaluation episode) against
    the training env steps when taken, per task and configuration: the mean over seeds (markers
    where a seed was evaluated) and its ``level`` t-interval over seeds, clipped to [0, 100].

    Only the runs that evaluated are drawn, and only their tasks get a panel; each group keeps
    its colour of :func:`plot_success_curves`.
    """
    evaluated = [RunGroup(group.label, group.settings,
                          tuple(run for run in group.runs if run.evaluations))
                 for group in groups]
    if not any(group.runs for group in evaluated):
        raise ValueError("no run has evaluations (eval.csv): nothing to plot.")

    def curve(run: Run) -> Series:
        return Series(np.array([row["env_steps"] for row in run.evaluations], dtype=float),
                      np.array([100.0 * row["success_rate"] for row in run.evaluations]))

    def limits(axes: Axes, task: str) -> None:
        axes.set_ylim(-2, 102)

    percent = f"{100 * level:g}%"
    _plot_groups(evaluated, path, "Evaluation success rate of the deterministic policy\n(line: "
                 f"mean over seeds; band: {percent} t-interval over seeds)", "success rate (%)",
                 "training env steps", curve, limits, t_interval_band(level, (0.0, 100.0)),
                 marker="o", markersize=3)


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


# --------------------------------------------------------------------------- rliable aggregates
#: rliable joins the two labels of a pair with a separator and splits them again; labels may
#: hold commas (its default), never a tab.
_PAIR = "\t"


def configuration_colours(labels: Sequence[str]) -> dict[str, tuple[float, float, float]]:
    """One colour per configuration (seaborn's colourblind palette, rliable's default), the
    same in every aggregate figure."""
    return dict(zip(labels, seaborn.color_palette("colorblind", n_colors=len(labels)),
                    strict=True))


def _score_label(table: ReliableTable) -> str:
    return f"{table.metric.title.split(' ')[0]} score"


def plot_aggregate_intervals(table: ReliableTable, path: Path,
                             colours: Mapping[str, tuple[float, float, float]]) -> None:
    """IQM and mean of one metric's scores per configuration, 95% CIs as bars, point estimates
    as ticks (rliable's ``plot_interval_estimates``); the first configuration on top. The
    configurations without a mean (:attr:`ReliableTable.no_mean`) are left out."""
    labels = list(table.iqm)[::-1]
    if not labels:
        raise ValueError(f"no configuration has an IQM and a mean for {table.metric.title}: "
                         "nothing to plot.")
    points = {label: [table.iqm[label].estimate, table.mean[label].estimate] for label in labels}
    intervals = {label: np.array([[table.iqm[label].low, table.mean[label].low],
                                  [table.iqm[label].high, table.mean[label].high]])
                 for label in labels}
    # rliable sizes the figure by rows (0.37 in each by default): too flat for one or two
    # configurations to leave room for the titles.
    row_height = max(0.6, 1.8 / len(labels))
    figure, axes = plot_utils.plot_interval_estimates(
        points, intervals, metric_names=["IQM", "Mean"], algorithms=labels,
        colors=dict(colours), xlabel="", subfigure_width=4.0, row_height=row_height)
    try:
        # rliable writes its x label as figure text at a fixed offset, which collides with the
        # tick labels of a short figure: each panel gets its own instead.
        for panel in axes:
            panel.set_xlabel(f"normalised {_score_label(table)}", fontsize="large")
            low, high = panel.get_xlim()  # scores lie in [0, 1]: no axis far outside
            panel.set_xlim(max(low, -0.02), min(high, 1.02))
        height = figure.get_figheight()
        figure.suptitle(f"{table.metric.title}: 95% stratified-bootstrap CIs",
                        y=1.0 + 0.55 / height, fontsize="x-large")
        figure.savefig(path, dpi=120, bbox_inches="tight")
    finally:
        pyplot.close(figure)


def _note(axes: Axes, text: str) -> None:
    axes.text(0.5, 0.5, text, ha="center", va="center", wrap=True, transform=axes.transAxes)
    axes.set_xticks([])
    axes.set_yticks([])


def plot_performance_profiles(tables: Sequence[ReliableTable], path: Path,
                              colours: Mapping[str, tuple[float, float, float]]) -> None:
    """One panel per metric: the fraction of runs scoring above tau, with 95% CI bands
    (rliable's ``plot_performance_profiles``)."""
    figure = Figure(figsize=(5.5 * len(tables), 4.4))
    panels = figure.subplots(1, len(tables), squeeze=False)[0]
    for axes, table in zip(panels, tables, strict=True):
        axes.set_title(table.metric.title)
        if not table.scored:
            _note(axes, "no scored run")
            continue
        plot_utils.plot_performance_profiles(
            {label: table.profiles[label].fraction for label in table.scored},
            table.profiles[table.scored[0]].taus,
            performance_profile_cis={label: (table.profiles[label].low,
                                             table.profiles[label].high)
                                     for label in table.scored},
            ax=axes, colors=dict(colours), xlabel=rf"normalised {_score_label(table)} $\tau$",
            ylabel=r"fraction of runs with score $> \tau$", labelsize="medium",
            ticklabelsize="medium")
    # One legend for all panels, below them, where it covers no curve.
    shown = [label for label in colours if any(label in table.profiles for table in tables)]
    if shown:
        handles = [Line2D([], [], color=colours[label], linewidth=2) for label in shown]
        figure.legend(handles, shown, loc="lower center", ncol=min(3, len(shown)),
                      fontsize="small", frameon=False)
    figure.suptitle("Performance profiles (runs pooled over tasks; bands: 95% CIs)")
    figure.tight_layout(rect=(0, 0.06 * -(-len(shown) // 3), 1, 1))
    figure.savefig(path, dpi=120)


def plot_improvement(tables: Sequence[ReliableTable], path: Path,
                     colours: Mapping[str, tuple[float, float, float]]) -> None:
    """One panel per metric: P(X > baseline) of each configuration X with its 95% CI
    (rliable's ``plot_probability_of_improvement``); configurations without a common task, and
    metrics without a scored baseline, are left out and named in the panel."""
    rows = [max(1, sum(each.interval is not None for each in table.improvements.values()))
            for table in tables]
    figure = Figure(figsize=(8, sum(0.55 * count + 1.4 for count in rows)))
    panels = figure.subplots(len(tables), 1, squeeze=False,
                             gridspec_kw={"height_ratios": rows})[:, 0]
    for axes, table in zip(panels, tables, strict=True):
        axes.set_title(table.metric.title, loc="left")
        # rliable draws the first pair at the bottom: reversed, the report's order reads down.
        shown = {label: each for label, each in reversed(table.improvements.items())
                 if each.interval is not None}
        if not shown:
            _note(axes, table.no_baseline or "no configuration has a task in common with "
                  f"{table.baseline}")
            continue
        pairs = {f"{label}{_PAIR}{table.baseline}": each for label, each in shown.items()}
        plot_utils.plot_probability_of_improvement(
            {pair: each.interval.estimate for pair, each in pairs.items()},
            {pair: [each.interval.low, each.interval.high] for pair, each in pairs.items()},
            pair_separator=_PAIR, ax=axes, colors=[colours[label] for label in shown],
            xticks=[0.0, 0.25, 0.5, 0.75, 1.0], xlabel="", left_ylabel="X",
            right_ylabel="baseline", ticklabelsize="small", labelsize="medium")
        axes.set_xlim(-0.02, 1.02)
        axes.axvline(0.5, color="grey", linestyle="--", linewidth=0.8)
    panels[-1].set_xlabel("P(X > baseline): a run of X scores more than one of the baseline, "
                          "same task")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
