"""Aggregates over tasks and seeds with ``rliable`` (Agarwal et al., NeurIPS 2021, "Deep RL at
the Edge of the Statistical Precipice").

With 4 seeds per task, as in the thesis, a mean over seeds and a percentile bootstrap of it say
little; Agarwal et al. recommend, and their library ``rliable`` computes, for each
configuration over all its tasks and seeds:

- the interquartile mean (IQM: the mean of the middle 50% of the scores of all its runs, tasks
  pooled; ``rliable.metrics.aggregate_iqm``) and the mean (of the task means;
  ``metrics.aggregate_mean``), each with a 95% *stratified* bootstrap confidence interval
  (``rliable.library.get_interval_estimates``: runs are resampled with replacement within each
  task, so every resample keeps the task mix);
- the probability of improvement P(X > Y) of a configuration X over a baseline Y: on each task,
  the probability that a run of X scores more than a run of Y (ties count half; Mann-Whitney U
  over n_X n_Y), averaged over the tasks both have scores on
  (``metrics.probability_of_improvement``), with its CI (X's and Y's runs resampled
  independently within each task);
- performance profiles: the fraction of runs whose score exceeds each threshold tau in [0, 1]
  (``library.score_distributions``), with 95% CI bands.

Scores are normalised to [0, 1], higher better, one per run that has the metric:

- RAS: the run's RAS as a fraction (the tables' % / 100). A run short of its task's budget
  (incomplete) and a task without a budget have no score, as in the tables.
- TTFS, TT50S: ``score = 1 - TTFS / H`` with H = 1,000 episodes, the thesis's horizon: near 1
  for a success in the first episodes, 0 for a run that reached H without it (its TTFS is H,
  the thesis's convention). A run stopped before H without it (*censored*) ranks 0, below every
  run that succeeded: the probability of improvement and the performance profiles rank it so
  (exact in the probability of improvement when the runs of a task stop at the same episode,
  as the studies' runs do at their budget; a lower bound in the profiles). A configuration
  with a censored run gets no IQM and no mean (:attr:`ReliableTable.no_mean`): its score is
  only known to lie in [0, 1 - N/H] after N episodes, and the Table 5.12 analysis plan lets no
  mean count a stand-in for an unobserved event. The report counts these runs.

A configuration's tasks are those where at least one of its runs has a score; IQM and profiles
pool its runs over them (a task with more scored runs weighs more; with the same seeds on every
task, as in the thesis, the tasks weigh the same), the mean averages task means. With one run per
task there is nothing to resample and the interval is the point.

rliable's bootstraps draw from numpy's global generator (``StratifiedBootstrap.update_indices``
calls ``np.random.choice``; its ``random_state`` argument is not used), so every estimate here
seeds that generator with ``seed`` and restores its state after: the same scores and seed give
the same interval, whatever else is computed before.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
from rliable import library, metrics

from temporal_torchrl.protocol_metrics import DEFAULT_HORIZON
from temporal_torchrl.reports.aggregate import (
    CENSORED,
    METRICS,
    VALUE,
    Metric,
    run_value,
)
from temporal_torchrl.reports.groups import RunGroup
from temporal_torchrl.runs.readers import Run

#: The default baseline of the probability of improvement (``--baseline``).
DEFAULT_BASELINE = "SAC"
#: Thresholds of the performance profiles.
PROFILE_TAUS = np.linspace(0.0, 1.0, 101)
#: Coverage of every interval.
LEVEL = 0.95


def score_rule(metric: str, horizon: int = DEFAULT_HORIZON) -> str:
    """How ``metric``'s runs are normalised to scores (for the report's text)."""
    if metric == "ras":
        return ("score = RAS / 100 (a fraction in [0, 1]); runs short of their budget have no "
                "score")
    title = METRICS[metric].title.split(" ")[0]
    return (f"score = 1 − {title} / {horizon} (the thesis's horizon, {horizon} episodes); a run "
            f"without the success within {horizon} episodes scores 0; a run stopped before "
            f"{horizon} episodes without it (censored) ranks 0 in the probability of "
            f"improvement and the profiles, and its configuration gets no IQM or mean (no "
            f"mean counts a stand-in for an unobserved time)")


@dataclass(frozen=True)
class RunScore:
    """A run's normalised score of a metric (see module doc), or None and why (``status``:
    ``incomplete``/``undefined``); ``status`` is ``censored`` for a censored run scored 0."""

    run: Run
    score: float | None
    status: str


def run_score(run: Run, metric: str, *, horizon: int = DEFAULT_HORIZON) -> RunScore:
    """``run``'s normalised ``metric`` score (``"ras"``, ``"ttfs"``, ``"tt50s"``)."""
    value = run_value(run, metric, horizon=horizon)
    if metric == "ras":
        score = value.value / 100.0 if value.status == VALUE else None
        return RunScore(run, score, value.status)
    if value.status == CENSORED:
        return RunScore(run, 0.0, CENSORED)
    return RunScore(run, 1.0 - value.value / horizon, VALUE)


@dataclass(frozen=True)
class Scores:
    """One configuration's scores of one metric.

    Attributes:
        label: the configuration's label.
        tasks: the tasks where it has scores.
        per_task: one ``(runs, 1)`` array per task, rliable's ``num_runs x num_tasks`` layout
            for one task (tasks may have different numbers of runs).
        runs: every run's :class:`RunScore`, scored or not.
    """

    label: str
    tasks: tuple[str, ...]
    per_task: tuple[np.ndarray, ...]
    runs: tuple[RunScore, ...]

    @property
    def scored(self) -> int:
        return sum(array.shape[0] for array in self.per_task)

    @property
    def censored(self) -> int:
        return sum(run.status == CENSORED for run in self.runs)

    @property
    def unscored(self) -> list[RunScore]:
        return [run for run in self.runs if run.score is None]

    def task_scores(self, task: str) -> np.ndarray:
        return self.per_task[self.tasks.index(task)]


def configuration_scores(group: RunGroup, metric: str, *,
                         horizon: int = DEFAULT_HORIZON) -> Scores:
    """The scores of ``group``'s runs (tasks in the tables' order)."""
    runs, tasks, per_task = [], [], []
    for task in group.tasks:
        scores = [run_score(run, metric, horizon=horizon) for run in group.runs_for(task)]
        runs += scores
        present = [score.score for score in scores if score.score is not None]
        if present:
            tasks.append(task)
            per_task.append(np.asarray(present, dtype=float).reshape(-1, 1))
    return Scores(group.label, tuple(tasks), tuple(per_task), tuple(runs))


@contextmanager
def seeded(seed: int) -> Iterator[None]:
    """numpy's global generator seeded for one rliable estimate, its state restored after
    (rliable resamples with it; see module doc)."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


@dataclass(frozen=True)
class Interval:
    """A point estimate and its 95% stratified-bootstrap confidence interval."""

    estimate: float
    low: float
    high: float


def _intervals(arrays: Sequence[np.ndarray], statistic: Callable[..., np.ndarray], *,
               reps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """rliable's point estimates and ``(2, k)`` CIs of ``statistic(*arrays)``, each array
    resampled over its runs on its own."""
    if reps < 1:
        raise ValueError(f"reps={reps}: expected at least 1 bootstrap resample.")
    with seeded(seed):
        points, intervals = library.get_interval_estimates(
            {"x": list(arrays)}, statistic, reps=reps, confidence_interval_size=LEVEL)
    return np.asarray(points["x"], dtype=float), np.asarray(intervals["x"], dtype=float)


def _iqm_and_mean(*tasks: np.ndarray) -> np.ndarray:
    return np.array([metrics.aggregate_iqm(np.concatenate(tasks)),
                     np.mean([metrics.aggregate_mean(task) for task in tasks])])


def aggregate_intervals(scores: Scores, *, reps: int = 2000,
                        seed: int = 0) -> tuple[Interval, Interval]:
    """IQM and mean of ``scores`` over its tasks and runs, with their 95% CIs."""
    if not scores.per_task:
        raise ValueError(f"{scores.label} has no scored run: nothing to aggregate.")
    points, intervals = _intervals(scores.per_task, _iqm_and_mean, reps=reps, seed=seed)
    iqm, mean = (Interval(float(points[index]), float(intervals[0, index]),
                          float(intervals[1, index])) for index in range(2))
    return iqm, mean


@dataclass(frozen=True)
class Improvement:
    """P(X > Y) of configuration ``label`` over ``baseline`` on their common ``tasks``, with
    its CI; ``interval`` is None when they have no task in common (``reason`` says so)."""

    label: str
    baseline: str
    tasks: tuple[str, ...]
    interval: Interval | None
    reason: str | None = None


def probability_of_improvement(x: Scores, y: Scores, *, reps: int = 2000,
                               seed: int = 0) -> Improvement:
    """P(X > Y) averaged over the tasks both ``x`` and ``y`` have scores on (module doc)."""
    tasks = tuple(task for task in x.tasks if task in y.tasks)
    if not tasks:
        return Improvement(x.label, y.label, (), None, (
            f"no scored run on {y.label}'s tasks ({', '.join(y.tasks)}); {x.label} has scores "
            f"on {', '.join(x.tasks) or 'no task'}"))
    arrays = [x.task_scores(task) for task in tasks] + [y.task_scores(task) for task in tasks]

    def average(*arrays: np.ndarray) -> np.ndarray:
        # Per task: rliable's probability for one column, i.e. one task of its runs x tasks.
        return np.array([np.mean([
            metrics.probability_of_improvement(first, second)
            for first, second in zip(arrays[:len(tasks)], arrays[len(tasks):], strict=True)])])

    points, intervals = _intervals(arrays, average, reps=reps, seed=seed)
    return Improvement(x.label, y.label, tasks,
                       Interval(float(points[0]), float(intervals[0, 0]),
                                float(intervals[1, 0])))


@dataclass(frozen=True)
class Profile:
    """A performance profile: ``fraction[i]`` of the runs score above ``taus[i]``, with its
    95% CI band ``low``..``high``."""

    taus: np.ndarray
    fraction: np.ndarray
    low: np.ndarray
    high: np.ndarray


def performance_profile(scores: Scores, taus: np.ndarray = PROFILE_TAUS, *, reps: int = 2000,
                        seed: int = 0) -> Profile:
    """The score distribution of ``scores``' runs (tasks pooled) at each of ``taus``."""
    if not scores.per_task:
        raise ValueError(f"{scores.label} has no scored run: no profile.")

    def distribution(*tasks: np.ndarray) -> np.ndarray:
        return library.score_distributions(np.concatenate(tasks), taus)

    points, intervals = _intervals(scores.per_task, distribution, reps=reps, seed=seed)
    return Profile(np.asarray(taus, dtype=float), points, intervals[0], intervals[1])


@dataclass(frozen=True)
class ReliableTable:
    """One metric's aggregates over the configurations of a report.

    Attributes:
        metric: the metric (its title, direction).
        horizon: H of the TTFS / TT50S scores.
        scores: ``label -> Scores`` for every configuration, in the report's order.
        iqm, mean: ``label -> Interval`` for the configurations with a scored run and no
            censored one.
        profiles: ``label -> Profile`` for the configurations with a scored run.
        baseline: the baseline's label.
        improvements: ``label -> Improvement`` over the baseline for the other scored
            configurations; empty when the baseline has no score (``no_baseline`` says why).
        reps, seed: the bootstraps'.
        pairs: ``(x, y) -> Improvement`` P(X > Y) for the pairs asked for
            (``report.py --compare X Y``).
    """

    metric: Metric
    horizon: int
    scores: dict[str, Scores]
    iqm: dict[str, Interval]
    mean: dict[str, Interval]
    profiles: dict[str, Profile]
    baseline: str
    improvements: dict[str, Improvement]
    no_baseline: str | None
    reps: int
    seed: int
    pairs: dict[tuple[str, str], Improvement] = field(default_factory=dict)

    @property
    def scored(self) -> list[str]:
        """Labels of the configurations with at least one scored run."""
        return list(self.profiles)

    @property
    def no_mean(self) -> dict[str, str]:
        """``label -> why`` for the scored configurations without an IQM and a mean."""
        return {label: f"{self.scores[label].censored} censored: no mean"
                for label in self.profiles if label not in self.iqm}


def build_reliable_table(groups: Sequence[RunGroup], metric: str, *,
                         baseline: str = DEFAULT_BASELINE, reps: int = 2000, seed: int = 0,
                         horizon: int = DEFAULT_HORIZON,
                         pairs: Sequence[tuple[str, str]] = ()) -> ReliableTable:
    """``metric``'s IQM, mean, profiles and probabilities of improvement over ``baseline`` (a
    configuration's label) and for each ``(x, y)`` of ``pairs`` for ``groups``; each estimate
    seeded with ``seed`` on its own."""
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; expected one of {', '.join(METRICS)}.")
    scores = {group.label: configuration_scores(group, metric, horizon=horizon)
              for group in groups}
    for pair in pairs:
        for label in pair:
            if label not in scores:
                raise ValueError(f"{label!r} is no configuration of the report; the "
                                 f"configurations are: {'; '.join(map(repr, scores))}.")
    iqm, mean, profiles = {}, {}, {}
    for label, each in scores.items():
        if each.per_task:
            if not each.censored:
                iqm[label], mean[label] = aggregate_intervals(each, reps=reps, seed=seed)
            profiles[label] = performance_profile(each, reps=reps, seed=seed)
    improvements, no_baseline = {}, None
    if baseline not in scores:
        no_baseline = (f"no configuration is labelled {baseline!r} (configurations: "
                       f"{', '.join(scores) or 'none'}); choose one with --baseline")
    elif baseline not in profiles:
        no_baseline = f"{baseline} has no scored run for {METRICS[metric].title}"
    else:
        for label in profiles:
            if label != baseline:
                improvements[label] = probability_of_improvement(
                    scores[label], scores[baseline], reps=reps, seed=seed)
    compared = {(x, y): probability_of_improvement(scores[x], scores[y], reps=reps, seed=seed)
                for x, y in pairs}
    return ReliableTable(METRICS[metric], horizon, scores, iqm, mean, profiles, baseline,
                         improvements, no_baseline, reps, seed, compared)
