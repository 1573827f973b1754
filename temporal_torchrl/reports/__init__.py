"""Reports over runs of ``recipes/sac_temporal.py``: the thesis's tables and figures.

- :mod:`~temporal_torchrl.reports.groups`: find run directories, read them, group them into
  configurations (runs that differ only in the seed).
- :mod:`~temporal_torchrl.reports.aggregate`: per-run RAS / TTFS / TT50S (or why a run has
  none yet), mean and std over seeds, the thesis-layout tables.
- :mod:`~temporal_torchrl.reports.reliable`: normalised scores and, with rliable, each
  configuration's IQM and mean over tasks and seeds, probability of improvement over a baseline
  and performance profiles, with stratified-bootstrap CIs.
- :mod:`~temporal_torchrl.reports.published`: the thesis's Tables 5.2-5.12 as data, matched
  to run configurations.
- :mod:`~temporal_torchrl.reports.statistics`: every interval, test and reading the reports
  print, in one place: Welch's differences and the plan's readings, Kaplan-Meier times, the
  primary claim's stratified permutation test, bootstrap and Holm.
- :mod:`~temporal_torchrl.reports.thesis_comparison`: a cell or an average against the thesis's,
  its seed error counted: the difference's interval and what it lets us say.
- :mod:`~temporal_torchrl.reports.task_comparison`: two configurations on one task: the
  difference of their RAS with its interval, p-value and the run pairs won.
- :mod:`~temporal_torchrl.reports.thesis_table`: the runs laid out as one of the thesis's tables,
  ours beside it in every cell (``report.py --thesis-table``).
- :mod:`~temporal_torchrl.reports.evaluation`: the runs' periodic evaluations of the
  deterministic policy (``eval.csv``): final evaluation success per task and, with rliable, over
  tasks and seeds, beside RAS.
- :mod:`~temporal_torchrl.reports.rows`: the row model every table is, written to CSV and to
  Markdown by one renderer.
- :mod:`~temporal_torchrl.reports.tables`: the per-metric, rliable and per-task tables as rows.
- :mod:`~temporal_torchrl.reports.logs`: logged training metrics (the run's metrics.jsonl).
- :mod:`~temporal_torchrl.reports.reward_curves`: r_P and r_D along stored episodes with a
  run's saved heads (Figure 5.12).
- :mod:`~temporal_torchrl.reports.plots`: the figures (matplotlib; imported on its own).

``recipes/report.py`` puts them together.
"""

from temporal_torchrl.reports.aggregate import (
    METRICS,
    Cell,
    MetricTable,
    RunValue,
    build_table,
    run_value,
)
from temporal_torchrl.reports.groups import RunGroup, group_runs
from temporal_torchrl.reports.logs import Series, logged_scalars
from temporal_torchrl.reports.published import (
    Configuration,
    PublishedResult,
    find_published,
    published_tables,
)
from temporal_torchrl.reports.reliable import (
    DEFAULT_BASELINE,
    Improvement,
    Interval,
    Profile,
    ReliableTable,
    RunScore,
    Scores,
    aggregate_intervals,
    build_reliable_table,
    configuration_scores,
    performance_profile,
    probability_of_improvement,
    run_score,
)
from temporal_torchrl.reports.reward_curves import EpisodeRewards, reward_curves
from temporal_torchrl.reports.task_comparison import TaskComparison, compare_configurations
from temporal_torchrl.reports.thesis_comparison import (
    ThesisComparison,
    compare_averages,
    compare_with_thesis,
)
from temporal_torchrl.reports.thesis_table import ThesisTablePage, build_thesis_table

__all__ = [
    "DEFAULT_BASELINE",
    "METRICS",
    "Cell",
    "Configuration",
    "EpisodeRewards",
    "Improvement",
    "Interval",
    "MetricTable",
    "Profile",
    "PublishedResult",
    "ReliableTable",
    "RunGroup",
    "RunScore",
    "RunValue",
    "Scores",
    "Series",
    "TaskComparison",
    "ThesisComparison",
    "ThesisTablePage",
    "aggregate_intervals",
    "build_reliable_table",
    "build_table",
    "build_thesis_table",
    "compare_averages",
    "compare_configurations",
    "compare_with_thesis",
    "configuration_scores",
    "find_published",
    "group_runs",
    "logged_scalars",
    "performance_profile",
    "probability_of_improvement",
    "published_tables",
    "reward_curves",
    "run_score",
    "run_value",
]
