"""Tables and figures from any set of runs of ``sac_temporal.py``, beside the thesis's.

    python recipes/report.py runs/ --out reports/all
    python recipes/report.py runs/door-open runs/push --out reports/two --metrics sac/loss_qvalue
    python recipes/report.py runs/ --out reports/all --figure-run runs/door-open/<config>/seed0
    python recipes/report.py sweeps/table_5_12 --out reports/t --baseline "FuRL ρ=0.05"
    python recipes/report.py docs/results/*/runs --out reports/t --thesis-table 5.12 \
        --compare "FuRL ρ=1" SAC

Finds every run directory (a directory with ``config.json``) under the given directories,
groups runs that differ only in the seed (printing the config keys that tell the groups apart)
and writes into ``--out``:

- ``ras.md``/``.csv``, ``ttfs.md``/``.csv``, ``tt50s.md``/``.csv``: the thesis's layout, tasks
  as rows, configurations as columns, mean ± std (n seeds), Average row, best in bold, the
  thesis's published value and the difference beside the configurations it reports;
- ``aggregates.md``/``.csv``: per metric and configuration, over all its tasks and seeds, the
  IQM and mean of normalised scores and the probability of improvement over ``--baseline``
  (default SAC) and P(X > Y) for each ``--compare X Y``, each with a 95% stratified-bootstrap
  CI, computed with rliable
  (:mod:`temporal_torchrl.reports.reliable`; scores: RAS / 100, and 1 - TTFS / 1000 with
  runs that have not reached the success ranked 0; no IQM or mean for a configuration with a
  censored run);
- ``comparisons.md``/``.csv``: each pair of configurations above (X over the baseline, each
  ``--compare X Y``) on each task both ran: the difference of their mean RAS with Welch's 95%
  interval, p-value and Bonferroni interval over all these comparisons, and the run pairs X won
  (:mod:`temporal_torchrl.reports.task_comparison`);
- ``aggregate_<metric>.png`` (IQM and mean with their CIs), ``performance_profiles.png``
  (fraction of runs above each score, with CI bands) and ``probability_of_improvement.png``,
  drawn with ``rliable.plot_utils``;
- ``table_<number>.md``/``.csv`` with ``--thesis-table``: the runs laid out as that thesis
  table, ours beside the thesis in every cell, "not run" where we did not, the averages over the
  tasks run and each compared with the thesis (:mod:`temporal_torchrl.reports.thesis_table`);
  ``report.md`` leads with it;
- ``primary_claim.md``/``.csv`` with ``--primary X Y`` (and ``--secondary``): a registered
  plan's test of X against Y over the tasks (:mod:`temporal_torchrl.reports.primary_claim`),
  on the ``--planned-seeds`` only (which the thesis-table page, the aggregates and the
  comparisons then keep to as well; the per-metric tables judge a cell against the thesis only
  once it has each planned seed);
- ``runs.csv``: every run with its episodes and metrics (or why it has none yet);
- ``success_curves.png``: running-average success (window 150) per task and configuration;
- ``evaluation.md``/``.csv`` and ``evaluation_curves.png``, only when some runs evaluated their
  deterministic policy (``eval.every``; their ``eval.csv``): per task and configuration the
  final evaluation success (the last evaluation's success rate) beside RAS, its IQM and mean
  over tasks and seeds with 95% stratified-bootstrap CIs (rliable), and the evaluations'
  success rate against env steps, mean over seeds with a 95% t-interval band
  (:mod:`temporal_torchrl.reports.evaluation`);
- ``metric_<key>.png`` for each ``--metrics`` key (from the runs' ``metrics.jsonl``; older runs:
  their CSV logs);
- ``reward_curves.png`` with ``--figure-run``: r_P and r_D along a positive and a negative
  episode, from that run's saved heads (Figure 5.12);
- ``report.md``: all of the above in one page.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from temporal_torchrl.reports import (
    DEFAULT_BASELINE,
    METRICS,
    build_reliable_table,
    build_table,
    group_runs,
    logged_scalars,
    reward_curves,
)
from temporal_torchrl.reports.evaluation import (
    build_evaluation_table,
    evaluation_markdown,
    evaluation_rows,
)
from temporal_torchrl.reports.groups import (
    configuration_name,
    configuration_settings,
    planned_runs,
)
from temporal_torchrl.reports.plots import (
    configuration_colours,
    plot_aggregate_intervals,
    plot_evaluation_curves,
    plot_improvement,
    plot_logged_metric,
    plot_performance_profiles,
    plot_reward_curves,
    plot_success_curves,
)
from temporal_torchrl.reports.primary_claim import (
    PLANNED_SEEDS,
    build_primary_claim,
    primary_claim_markdown,
    primary_claim_rows,
)
from temporal_torchrl.reports.rows import Table
from temporal_torchrl.reports.tables import (
    RELIABLE_COLUMNS,
    grouping_markdown,
    metric_rows,
    reliable_markdown,
    reliable_rows,
    run_rows,
    table_markdown,
    task_comparison_markdown,
    task_comparison_rows,
)
from temporal_torchrl.reports.task_comparison import compare_configurations
from temporal_torchrl.reports.thesis_table import (
    build_thesis_table,
    thesis_table_markdown,
    thesis_table_rows,
)
from temporal_torchrl.runs import find_runs, load_run
from temporal_torchrl.runs.durable import write_csv

HOW_TO_READ = """\
## How to read this report

- RAS (%) is RAS(e; w = 150) at the task's budget e (thesis Table 5.1). A run short of its budget
  is *incomplete*: shown with its episode count, never scored.
- TTFS / TT50S are the episode of the first / 50th success. A run that reached 1,000 episodes
  without it counts 1,000 (the thesis's convention). A shorter run without it is *censored*
  (`> N ep`: not reached in its N episodes): its cell gives the Kaplan-Meier median and how
  many runs reached the event, and no mean, since any stand-in for the unknown time would
  decide the mean.
- A cell's mean ± sample std and its n are over its runs, as the thesis prints them. With a
  few seeds a mean says little: the comparisons with the thesis and the rliable section give
  intervals.
- The thesis's values are LIV's (4 seeds); runs with another encoder are compared with them
  all the same, and the Note column says so. A difference from the thesis comes with its 95%
  interval, the thesis's mean counted as 4 seeds with a spread like ours where it prints no
  std, and a reading: *below* or *above* (the interval over every cell compared excludes 0),
  *equivalent within ±10* (RAS only: the 90% interval lies inside ±10 points, a margin fixed
  before the runs) or *not resolved* (neither; an interval that includes 0 is not agreement).
- *Over tasks and seeds (rliable)*: each configuration's runs on all its tasks, scored in
  [0, 1] (higher is better): RAS / 100; for TTFS and TT50S, 1 − TTFS / 1000, with a run that
  has not reached the success (within 1,000 episodes, or censored before) ranked 0, below every
  run that succeeded; a configuration with a censored run gets no IQM and no mean (they would
  need a stand-in for its unobserved times). The interquartile mean (IQM, the mean of the
  middle 50% of the run scores) and the mean, and the probability of improvement
  P(X > {baseline}) (a run of X scores more than a run of {baseline} on the same task), each
  with a 95% stratified-bootstrap CI ({resamples} resamples, seed {seed}), as Agarwal et al.
  (NeurIPS 2021) recommend, computed with rliable.
"""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Tables (RAS, TTFS, TT50S) and figures from runs of sac_temporal.py.")
    parser.add_argument("dirs", nargs="+", type=Path,
                        help="run directories or sweep directories containing them")
    parser.add_argument("--out", type=Path, required=True, help="directory for the report")
    parser.add_argument("--figure-run", type=Path, default=None,
                        help="a run with reward heads: plot r_P and r_D along a positive and a "
                             "negative episode (Figure 5.12)")
    parser.add_argument("--figure-episodes", type=int, nargs=2, default=None,
                        metavar=("POSITIVE", "NEGATIVE"),
                        help="replay indices of the two episodes (default: the first expert, "
                             "the last failed training episode)")
    parser.add_argument("--metrics", nargs="*", default=[],
                        help="logged metrics to plot, e.g. sac/loss_qvalue relabelled/r_P_mean")
    parser.add_argument("--baseline", default=None, metavar="LABEL",
                        help="the configuration the probability of improvement compares with, "
                             f"by its label as printed (default {DEFAULT_BASELINE!r}; when no "
                             "configuration has it, the report says so)")
    parser.add_argument("--compare", nargs=2, action="append", default=[],
                        metavar=("X", "Y"),
                        help="also give P(X > Y) for these two configurations, by their labels "
                             "as printed (repeatable)")
    parser.add_argument("--primary", nargs=2, action="append", default=[],
                        metavar=("X", "Y"),
                        help="a primary hypothesis of a registered plan, X against Y over the "
                             "tasks (repeatable; Holm's correction over them): "
                             "primary_claim.md")
    parser.add_argument("--secondary", nargs=2, action="append", default=[],
                        metavar=("X", "Y"),
                        help="a secondary hypothesis, tested alike outside Holm's family")
    parser.add_argument("--planned-seeds", type=int, nargs="+", default=None, metavar="SEED",
                        help="the seeds a plan fixed: runs of other seeds were added after "
                             "looking, and the --thesis-table page, the primary claim, the "
                             "rliable aggregates and the per-task comparisons leave them out "
                             "(the per-metric tables keep them, and judge a cell against the "
                             "thesis only once it has every planned seed; default: every seed; "
                             "the claim: 0 1 2 3)")
    parser.add_argument("--thesis-table", default=None, metavar="NUMBER",
                        help="lay the runs out as this thesis table (e.g. 5.12), ours beside "
                             "the thesis, and lead the report with it")
    parser.add_argument("--bootstrap", type=int, default=2000,
                        help="stratified-bootstrap resamples for the 95%% CIs (default 2000)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    args = parser.parse_args(argv)
    if args.bootstrap < 1:
        parser.error(f"--bootstrap {args.bootstrap}: expected at least 1 resample.")
    if args.figure_episodes is not None and args.figure_run is None:
        parser.error("--figure-episodes needs --figure-run.")
    return args


def import_reward_modules(run_dir: Path) -> None:
    """Import the run's ``reward.modules`` (its own registered rewards), as the recipe does."""
    modules = json.loads((run_dir / "config.json").read_text())["reward"].get("modules") or []
    if modules:
        # The config rules import the envs, encoders and rewards: only for runs that need them.
        from temporal_torchrl.configs.rules import import_reward_modules as load_modules

        load_modules(modules)


def portable_path(path: Path) -> str:
    """``path`` as a report may print it: relative to the working directory when inside it
    (as typed in the README's commands), else its name alone (no machine's paths)."""
    resolved, here = path.resolve(), Path.cwd().resolve()
    return resolved.relative_to(here).as_posix() if here in resolved.parents else path.name


def metric_file(key: str) -> str:
    """``sac/loss_qvalue`` -> ``metric_sac-loss_qvalue.png``."""
    return "metric_" + re.sub(r"[^A-Za-z0-9_.]+", "-", key).strip("-") + ".png"


def write_table(out: Path, name: str, markdown: str, rows: Table) -> str:
    """``name``.md and ``name``.csv in ``out``, the Markdown written from ``rows`` (the
    table's one row model); the Markdown printed and returned."""
    (out / f"{name}.md").write_text(markdown)
    write_csv(out / f"{name}.csv", rows.csv_rows(), rows.fields)
    print(markdown)
    return markdown


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    groups = group_runs(find_runs(args.dirs))
    labels = [group.label for group in groups]
    if args.baseline is not None and args.baseline not in labels:
        raise SystemExit(f"--baseline {args.baseline!r}: no configuration has that label; "
                         f"the configurations are: {'; '.join(map(repr, labels))}.")
    baseline = args.baseline or DEFAULT_BASELINE
    for option, pairs in (("--compare", args.compare), ("--primary", args.primary),
                          ("--secondary", args.secondary)):
        for label in {label for pair in pairs for label in pair} - set(labels):
            raise SystemExit(f"{option} {label!r}: no configuration has that label; the "
                             f"configurations are: {'; '.join(map(repr, labels))}.")
    claim = None
    if args.primary or args.secondary:
        try:
            claim = build_primary_claim(groups, [tuple(pair) for pair in args.primary],
                                        [tuple(pair) for pair in args.secondary],
                                        args.planned_seeds or PLANNED_SEEDS)
        except ValueError as error:
            raise SystemExit(f"--primary/--secondary: {error}") from None
    page = None
    if args.thesis_table is not None:
        try:
            page = build_thesis_table(groups, args.thesis_table, args.planned_seeds)
        except ValueError as error:
            raise SystemExit(f"--thesis-table {args.thesis_table}: {error}") from None
    scalars = {run.path: logged_scalars(run.path) for group in groups for run in group.runs
               if args.metrics}
    logged = set().union(*scalars.values())
    for key in args.metrics:
        if key not in logged:
            raise SystemExit(f"--metrics {key}: no run logged it (looked in each run's "
                             f"metrics.jsonl, else its logs/*/scalars); logged keys: "
                             f"{', '.join(sorted(logged)) or 'none'}.")
    args.out.mkdir(parents=True, exist_ok=True)
    sections = ["# Report", "", f"Runs from: {', '.join(map(portable_path, args.dirs))}", "",
                HOW_TO_READ.format(resamples=args.bootstrap, seed=args.seed,
                                   baseline=baseline),
                grouping_markdown(groups)]
    print(grouping_markdown(groups))
    if page is not None:
        name = "table_" + page.table.number.replace(".", "_")
        markdown = write_table(args.out, name, thesis_table_markdown(page),
                               thesis_table_rows(page))
        sections.insert(4, markdown)  # the report leads with it, before how to read it
    if claim is not None:
        sections.insert(5 if page is not None else 4, write_table(
            args.out, "primary_claim", primary_claim_markdown(claim),
            primary_claim_rows(claim)))

    tables = {}
    for metric in METRICS:
        table = tables[metric] = build_table(groups, metric, args.planned_seeds)
        sections.append(write_table(args.out, metric, table_markdown(table),
                                    metric_rows(table)))
    runs = run_rows(groups, args.dirs)
    write_csv(args.out / "runs.csv", runs.csv_rows(), runs.fields)

    # The intervals and the comparisons are statistics a plan fixes: on its seeds only.
    planned = groups if args.planned_seeds is None else planned_runs(groups,
                                                                      args.planned_seeds)[0]
    reliable = [build_reliable_table(planned, metric, baseline=baseline, reps=args.bootstrap,
                                     seed=args.seed, pairs=[tuple(pair) for pair in args.compare])
                for metric in METRICS]
    ras_reliable = reliable[list(METRICS).index("ras")]
    sections.append(write_table(
        args.out, "aggregates",
        "\n".join(["## Over tasks and seeds (rliable)", "", *map(reliable_markdown, reliable)]),
        Table(RELIABLE_COLUMNS, [row for table in reliable for row in reliable_rows(table).rows])))

    comparisons = compare_configurations(ras_reliable)
    if comparisons:
        sections.append(write_table(args.out, "comparisons",
                                    task_comparison_markdown(comparisons),
                                    task_comparison_rows(comparisons)))

    # Only runs that evaluated (eval.csv) make this section: without any, nothing is said.
    evaluation = build_evaluation_table(groups, ras=tables["ras"], ras_reliable=ras_reliable,
                                        reps=args.bootstrap, seed=args.seed)
    if evaluation is not None:
        sections.append(write_table(args.out, "evaluation", evaluation_markdown(evaluation),
                                    evaluation_rows(evaluation)))

    figures = ["## Figures"]
    colours = configuration_colours(labels)
    for table in reliable:
        if table.iqm:
            name = f"aggregate_{table.metric.name}.png"
            plot_aggregate_intervals(table, args.out / name, colours)
            figures.append(f"![{table.metric.title}: IQM and mean with 95% CIs]({name})")
    plot_performance_profiles(reliable, args.out / "performance_profiles.png", colours)
    figures.append("![performance profiles](performance_profiles.png)")
    plot_improvement(reliable, args.out / "probability_of_improvement.png", colours)
    figures.append(f"![probability of improvement over {baseline}]"
                   "(probability_of_improvement.png)")
    plot_success_curves(groups, args.out / "success_curves.png")
    figures.append("![running-average success](success_curves.png)")
    if evaluation is not None:
        plot_evaluation_curves(groups, args.out / "evaluation_curves.png")
        figures.append("![evaluation success rate against env steps: mean over seeds, 95% "
                       "t-interval band](evaluation_curves.png)")
    for key in args.metrics:
        name = metric_file(key)
        plot_logged_metric(groups, scalars, key, args.out / name)
        figures.append(f"![{key}]({name})")
    if args.figure_run is not None:
        import_reward_modules(args.figure_run)
        episodes = args.figure_episodes or (None, None)
        positive, negative = reward_curves(args.figure_run, *episodes)
        run = load_run(args.figure_run)
        title = (f"{configuration_name(configuration_settings(run))}, {run.task}, seed "
                 f"{run.seed}: heads of the last checkpoint")
        plot_reward_curves(positive, negative, args.out / "reward_curves.png", title)
        figures.append(f"![r_P and r_D along a positive and a negative episode]"
                       f"(reward_curves.png)\n\n{title}; positive: replay {positive.index} "
                       f"({positive.kind}), negative: replay {negative.index} ({negative.kind}).")
    sections.append("\n\n".join(figures) + "\n")
    (args.out / "report.md").write_text("\n".join(sections))
    print(f"wrote {args.out}: report.md, {', '.join(f'{m}.md/.csv' for m in METRICS)}, "
          "aggregates.md/.csv, "
          f"{'comparisons.md/.csv, ' if comparisons else ''}runs.csv and the figures")


if __name__ == "__main__":
    main()
