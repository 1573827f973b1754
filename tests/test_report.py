"""Reports over runs (temporal_torchrl.reports, recipes/report.py) on hand-made run
directories with known success sequences, and one tiny real run for the reward curves."""

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import report
import sac_temporal
import torch
from helpers import RECIPES, SEED0, SEED1, config, make_run
from hydra import compose, initialize_config_dir
from scipy import stats as scipy_stats

from temporal_torchrl.data import NEGATIVE
from temporal_torchrl.envs import EVALUATION_TASKS, get_task
from temporal_torchrl.reports import (
    Configuration,
    build_table,
    find_published,
    group_runs,
    logged_scalars,
    published_tables,
    reward_curves,
    run_value,
)
from temporal_torchrl.reports.aggregate import CENSORED, INCOMPLETE
from temporal_torchrl.reports.groups import distinguishing_keys, missing_seeds
from temporal_torchrl.reports.logs import csv_scalars
from temporal_torchrl.reports.reliable import (
    Scores,
    aggregate_intervals,
    build_reliable_table,
    performance_profile,
    probability_of_improvement,
    run_score,
)
from temporal_torchrl.reports.reward_curves import EXPERT, FAILED
from temporal_torchrl.reports.statistics import TimeToEvent
from temporal_torchrl.reports.tables import (
    grouping_markdown,
    metric_rows,
    reliable_markdown,
    reliable_rows,
    table_markdown,
)
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.runs import find_runs

FURL = ("preset=furl", "protocol=stage2")


def rows_by(table, task):
    return {row["configuration"]: row for row in metric_rows(table).csv_rows()
            if row["task"] == task}


def markdown_row(markdown: str, task: str) -> list[str]:
    line = next(line for line in markdown.splitlines() if line.startswith(f"| {task} |"))
    return [cell.strip() for cell in line.strip("|").split("|")]


# --------------------------------------------------------------------------- aggregation
def test_means_and_stds_over_seeds(tmp_path):
    make_run(tmp_path, "s0", SEED0, *FURL, "env.seed=0", finished=True)
    make_run(tmp_path, "s1", SEED1, *FURL, "env.seed=1", finished=True)
    groups = group_runs(find_runs([tmp_path]))
    assert [group.label for group in groups] == ["FuRL ρ=0.05"]
    expected = {"ras": [100.0, 70 / 150 * 100], "ttfs": [151.0, 161.0],
                "tt50s": [200.0, 259.0]}
    for metric, values in expected.items():
        row = rows_by(build_table(groups, metric), "drawer-open")["FuRL ρ=0.05"]
        assert float(row["mean"]) == pytest.approx(sum(values) / 2, rel=1e-5)
        # sample std of two values: |a - b| / sqrt(2)
        assert float(row["std"]) == pytest.approx(abs(values[0] - values[1]) / math.sqrt(2),
                                                  rel=1e-5)
        assert (row["n"], row["runs"], row["status"]) == ("2", "2", "complete")


def test_incomplete_run_is_shown_with_its_episode_count(tmp_path):
    make_run(tmp_path, "s0", SEED0, *FURL, "env.seed=0", finished=True)
    make_run(tmp_path, "s1", SEED1, *FURL, "env.seed=1", finished=True)
    make_run(tmp_path, "s2", [True] * 120, *FURL, "env.seed=2")  # killed at 120 of 300
    make_run(tmp_path, "rho1", [True] * 80, *FURL, "reward.rho=1.0", "env.seed=0")
    table = build_table(group_runs(find_runs([tmp_path])), "ras")
    rows = rows_by(table, "drawer-open")
    partial = rows["FuRL ρ=0.05"]
    assert partial["n"] == "2" and partial["runs"] == "3" and partial["status"] == "partial"
    assert float(partial["mean"]) == pytest.approx((100 + 70 / 150 * 100) / 2)
    assert partial["without_value"] == "seed 2: 120/300 episodes"
    assert partial["difference"] == ""  # no comparison for a partial cell
    unfinished = rows["FuRL ρ=1"]
    assert (unfinished["mean"], unfinished["std"], unfinished["status"]) == ("", "", INCOMPLETE)
    markdown = table_markdown(table)
    row = markdown_row(markdown, "drawer-open")
    assert row[1] == "73.3 ± 37.7 (n=2); 1 incomplete: 120/300 ep"
    assert row[2] == "1 incomplete: 80/300 ep"
    assert markdown_row(markdown, "Average")[1:] == ["—", "—"]
    assert run_value(find_runs([tmp_path / "s2"])[0], "ras").status == INCOMPLETE


def test_extended_run_is_not_finished(tmp_path):
    """A finished run extended with resume=true train.episodes=... keeps its old summary.json
    while it runs on."""
    run_dir = make_run(tmp_path, "r", SEED0 + [True] * 50, *FURL)
    (run_dir / "summary.json").write_text(json.dumps({"episodes": 300}))
    [run] = find_runs([run_dir])
    assert (run.episodes, run.finished) == (350, False)
    (run_dir / "summary.json").write_text(json.dumps({"episodes": 350}))
    assert find_runs([run_dir])[0].finished


def test_ttfs_censored_below_the_horizon_and_capped_at_it(tmp_path):
    short = make_run(tmp_path, "short", [False] * 120, *FURL, "env.seed=0")
    long = make_run(tmp_path, "long", [False] * 1000, *FURL, "env.seed=1", finished=True)
    few = make_run(tmp_path, "few", [True] * 10 + [False] * 50, *FURL, "env.seed=2")
    [short_run], [long_run], [few_run] = (find_runs([path]) for path in (short, long, few))
    assert run_value(short_run, "ttfs").status == CENSORED
    assert (run_value(long_run, "ttfs").value, run_value(long_run, "tt50s").value) == (1000, 1000)
    assert run_value(few_run, "ttfs").value == 1
    assert run_value(few_run, "tt50s").status == CENSORED
    table = build_table(group_runs(find_runs([tmp_path])), "ttfs")
    # Kaplan-Meier by hand: one event at 1 among 3 runs at risk (S = 2/3), then only censored
    # runs (at 120 and at the horizon): the share still waiting never falls to one half. A cell
    # with a censored run has no mean: no stand-in is averaged.
    [cell] = table.cells.values()
    assert (cell.mean, cell.std) == (None, None)
    assert (cell.time_to_event.median, cell.time_to_event.reached,
            cell.time_to_event.runs) == (None, 1, 3)
    assert markdown_row(table_markdown(table), "drawer-open")[1] == (
        "median not reached (1 of 3 reached), Kaplan-Meier; 1 censored > 120 ep; no mean")


def test_kaplan_meier_median_of_a_censored_cell(tmp_path):
    # TT50S of four 200-episode runs: 120, 150, 180 and one censored > 200. By hand: at 120,
    # 4 at risk, S = 3/4; at 150, 3 at risk, S = 3/4 * 2/3 = 1/2: the median is 150, the
    # first time S is at most one half. With 180 as well S = 1/4; the censored run never
    # changes it. No mean, since the censored run's time is unknown.
    for seed, first in enumerate((70, 100, 130)):
        make_run(tmp_path, f"s{seed}", [False] * first + [True] * (200 - first), *FURL,
                 f"env.seed={seed}")
    make_run(tmp_path, "s3", [True] * 40 + [False] * 160, *FURL, "env.seed=3")
    [group] = group_runs(find_runs([tmp_path]))
    table = build_table([group], "tt50s")
    cell = table.cells["drawer-open", group.label]
    assert [value.value for value in cell.runs[:3]] == [120, 150, 180]
    assert cell.mean is None and cell.time_to_event == TimeToEvent(150.0, 3, 4)
    assert "median 150 (3 of 4 reached), Kaplan-Meier; 1 censored > 200 ep; no mean" in \
        table_markdown(table)
    assert (rows_by(table, "drawer-open")[group.label]["median"],
            rows_by(table, "drawer-open")[group.label]["reached"]) == ("150", "3")


def test_runs_differing_in_rho_are_never_merged(tmp_path):
    make_run(tmp_path, "a/s0", SEED0, *FURL, "env.seed=0", "train.episodes=300")
    # process keys differ (episodes, threads, logger, checkpoint interval): same configuration
    make_run(tmp_path, "b/s1", SEED1, *FURL, "env.seed=1", "train.episodes=2000",
             "train.threads=1", "logger.backend=none", "train.checkpoint_every=10")
    make_run(tmp_path, "c/s0", SEED1, *FURL, "env.seed=0", "reward.rho=1.0")
    make_run(tmp_path, "c/s1", SEED1, *FURL, "env.seed=1", "reward.rho=1")  # int 1 is 1.0
    groups = group_runs(find_runs([tmp_path]))
    assert [(group.label, len(group.runs)) for group in groups] == [("FuRL ρ=0.05", 2),
                                                                    ("FuRL ρ=1", 2)]
    assert distinguishing_keys([group.settings for group in groups]) == ["reward.rho"]
    assert "Keys that tell them apart: reward.rho." in grouping_markdown(groups)


def test_same_configuration_and_seed_twice_is_refused(tmp_path):
    make_run(tmp_path, "a", SEED0, *FURL)
    make_run(tmp_path, "other", SEED1, *FURL)  # env.seed 0 too, other episodes
    with pytest.raises(ValueError, match="count that seed twice"):
        group_runs(find_runs([tmp_path]))


def test_a_run_copied_into_two_studies_counts_once(tmp_path):
    make_run(tmp_path / "study_a", "s0", SEED0, *FURL, "env.seed=0")
    make_run(tmp_path / "study_b", "s0", SEED0, *FURL, "env.seed=0")
    make_run(tmp_path / "study_b", "s1", SEED1, *FURL, "env.seed=1")
    [group] = group_runs(find_runs([tmp_path / "study_a", tmp_path / "study_b"]))
    assert [(run.seed, run.path.parent.name) for run in group.runs] == [(0, "study_a"),
                                                                       (1, "study_b")]


def test_labels_read_like_the_thesis(tmp_path):
    make_run(tmp_path, "sac", SEED0, "preset=sac", "protocol=stage2")
    make_run(tmp_path, "best", SEED0, "preset=best", "protocol=stage2")
    make_run(tmp_path, "p2", SEED0, "preset=p2", "protocol=stage2", "reward.baseline=tailored")
    make_run(tmp_path, "d3", SEED0, "preset=d3", "protocol=stage2", "reward.positional=none")
    make_run(tmp_path, "small", SEED0, *FURL, "encoder.name=metaworld_small")
    make_run(tmp_path, "stage1", SEED0, "preset=furl", "protocol=stage1")
    labels = {group.runs[0].path.name: group.label for group in group_runs(find_runs([tmp_path]))}
    assert labels == {
        "sac": "SAC [stage2]", "best": "FuRL ρ=1 + D3 λ=4 (b_g) [liv] [stage2]",
        "p2": "P2 ρ=0.05 (b_t) [liv] [stage2]", "d3": "D3 λ=80 ρ=0.05 (b_t) [liv] [stage2]",
        "small": "FuRL ρ=0.05 [metaworld_small] [stage2]",
        "stage1": "FuRL ρ=0.05 [liv] [stage1]"}


def test_best_is_bold_highest_ras_lowest_ttfs(tmp_path):
    make_run(tmp_path, "a", SEED0, *FURL)  # RAS 100, TTFS 151
    make_run(tmp_path, "b", SEED1, *FURL, "reward.rho=1.0")  # RAS 46.7, TTFS 161
    groups = group_runs(find_runs([tmp_path]))
    ras_row = markdown_row(table_markdown(build_table(groups, "ras")),
                           "drawer-open")
    ttfs_row = markdown_row(table_markdown(build_table(groups, "ttfs")),
                            "drawer-open")
    assert ras_row[1:] == ["**100.0** (n=1)", "46.7 (n=1)"]
    assert ttfs_row[1:] == ["**151** (n=1)", "161 (n=1)"]
    # a row's best needs every run of the cell: the partial cell is not bold even if higher
    make_run(tmp_path, "c", [True] * 300, *FURL, "reward.rho=2.0", "env.seed=0")
    make_run(tmp_path, "d", [True] * 30, *FURL, "reward.rho=2.0", "env.seed=1")
    groups = group_runs(find_runs([tmp_path]))
    row = markdown_row(table_markdown(build_table(groups, "ras")), "drawer-open")
    assert row[1] == "**100.0** (n=1)" and row[3].startswith("100.0 (n=1)")


# --------------------------------------------------------------------------- published values
def test_published_cells_match_the_thesis_text():
    tables = {table.number: table for table in published_tables()}
    assert sorted(tables, key=lambda number: int(number.split(".")[1])) == [
        f"5.{number}" for number in range(2, 13)]
    cell = tables["5.2"].rows["door-open"][1]  # "591 ± 286" (r_P2)
    assert (cell.mean, cell.std) == (591.0, 286.0)
    cell = tables["5.3"].rows["push"][2]  # "1000 ± 0" (r_P3)
    assert (cell.mean, cell.std) == (1000.0, 0.0)
    assert tables["5.6"].rows["push"][2].mean == 56.5  # rho = 1.0
    assert tables["5.9"].rows["button-press-topdown"][4].mean == 84.8  # lambda = 150
    assert tables["5.11"].rows["window-close"][2].mean == 77.2  # r_D4, b_g
    assert tables["5.12"].rows["drawer-open"][4].mean == 91.8  # rho = 1.0, lambda = 4.0
    assert tables["5.12"].average == (40.9, 63.8, 78.1, 79.2, 80.0, 77.9)


def test_published_average_rows_are_the_mean_of_their_tasks():
    for table in published_tables():
        assert list(table.rows) == list(EVALUATION_TASKS), table.number
        # every cell and the average are rounded to the printed precision
        tolerance = 1.0 if table.metric in ("ttfs", "tt50s") else 0.1
        for column, average in enumerate(table.average):
            mean = np.mean([cells[column].mean for cells in table.rows.values()])
            assert abs(mean - average) <= tolerance, (table.number, column)


def test_published_repeats_agree_and_budgets_match_table_5_1():
    for table in published_tables():  # raises if a configuration's tables disagree
        for column in table.columns:
            assert find_published(column.configuration, table.metric) is not None
    sac = find_published(Configuration(None, None, protocol="stage2"), "ras")
    assert sac.tables == ("5.4", "5.5", "5.7", "5.8", "5.9", "5.10", "5.12")
    assert sac.cells["door-open"].mean == 35.2 and sac.average == 40.9
    budgets = {"drawer-open": 300, "door-open": 400, "window-open": 200, "window-close": 200,
               "push": 1000, "button-press-topdown": 400}
    assert {task: get_task(task).ras_budget for task in EVALUATION_TASKS} == budgets


def test_published_value_matched_and_difference(tmp_path):
    make_run(tmp_path, "s0", SEED0, *FURL, "env.seed=0", "encoder.name=metaworld_small")
    make_run(tmp_path, "s1", SEED1, *FURL, "env.seed=1", "encoder.name=metaworld_small")
    make_run(tmp_path, "p2", SEED0, "preset=p2", "protocol=stage2", "reward.rho=0.1")
    groups = group_runs(find_runs([tmp_path]))
    table = build_table(groups, "ras")
    rows = rows_by(table, "drawer-open")
    furl = rows["FuRL ρ=0.05 [metaworld_small]"]
    assert (furl["published_tables"], furl["published_mean"]) == ("5.4 5.5 5.6", "41.7")
    assert float(furl["difference"]) == pytest.approx((100 + 70 / 150 * 100) / 2 - 41.7)
    assert rows["P2 ρ=0.1 (b_g) [liv]"]["published_mean"] == ""  # rho 0.1: not in the thesis
    markdown = table_markdown(table)
    # Welch's interval, the thesis's 4 seeds given our spread (it prints no std), computed by
    # scipy on a stand-in sample with the thesis's mean and our std.
    ours = np.array([100.0, 70 / 150 * 100])
    stand_in = 41.7 + (np.array([-1.0, 1.0, -1.0, 1.0]) * ours.std(ddof=1)
                       * math.sqrt(3 / 4))
    low, high = scipy_stats.ttest_ind(ours, stand_in, equal_var=False).confidence_interval()
    assert ("| FuRL ρ=0.05 [metaworld_small] | drawer-open | 73.3 ± 37.7 (n=2) | 41.7 | "
            f"+31.6 [{low:+.1f}, {high:+.1f}]: not resolved "
            "| 5.4, 5.5, 5.6 | encoder metaworld_small (thesis: liv) |") in markdown
    assert "with a spread like ours where the thesis prints no std" in markdown
    # stage 1 with D3 matches Table 5.2, whose baseline the thesis does not state
    make_run(tmp_path, "d3", [False] * 270 + [True], "preset=d3", "protocol=stage1",
             "reward.baseline=generic")
    [d3] = group_runs(find_runs([tmp_path / "d3"]))
    ttfs = build_table([d3], "ttfs")
    row = rows_by(ttfs, "drawer-open")["FuRL ρ=0.05 + D3 λ=80 (b_g)"]
    assert (row["published_tables"], row["published_mean"], row["published_std"],
            row["difference"]) == ("5.2", "271", "29", "0")
    assert "does not state this column's baseline" in table_markdown(ttfs)


def test_a_cell_without_every_planned_seed_is_shown_not_judged(tmp_path):
    make_run(tmp_path, "s0", SEED0, *FURL, "env.seed=0", "encoder.name=metaworld_small")
    make_run(tmp_path, "s1", SEED1, *FURL, "env.seed=1", "encoder.name=metaworld_small")
    groups = group_runs(find_runs([tmp_path]))
    judged = rows_by(build_table(groups, "ras", planned_seeds=[0, 1]), "drawer-open")
    running = rows_by(build_table(groups, "ras", planned_seeds=[0, 1, 2, 3]), "drawer-open")
    label = "FuRL ρ=0.05"
    assert judged[label]["reading"] == "not resolved"
    assert running[label]["reading"] == ""  # 2 of the 4 planned seeds: not judged
    assert running[label]["difference"] == judged[label]["difference"]  # still shown
    assert running[label]["note"] == ("still running (no run yet of planned seeds 2, 3): "
                                      "shown, not judged; encoder metaworld_small (thesis: liv)")
    markdown = table_markdown(build_table(groups, "ras", planned_seeds=[0, 1, 2, 3]))
    assert "| 73.3 ± 37.7 (n=2) | 41.7 | +31.6 | 5.4, 5.5, 5.6 |" in markdown
    assert "not resolved" not in markdown


def test_missing_seeds_names_the_planned_seeds_with_no_run_in_plan_order():
    assert missing_seeds({1}, [3, 1, 0]) == (3, 0)
    assert missing_seeds({1}, None) == ()  # no plan: nothing is missing
    assert missing_seeds((), [0]) == (0,)


# --------------------------------------------------------------------------- rliable aggregates
def hand_scores(label: str, *tasks: list[float]) -> Scores:
    """Scores of one configuration: one list of run scores per task."""
    return Scores(label, tuple(f"task{index}" for index in range(len(tasks))),
                  tuple(np.array(task, dtype=float).reshape(-1, 1) for task in tasks), ())


def test_iqm_and_mean_match_a_hand_computation():
    scores = hand_scores("x", [0.9, 0.1, 0.4, 0.6], [0.2, 1.0, 0.7, 0.3])
    iqm, mean = aggregate_intervals(scores, reps=300, seed=0)
    # IQM: the 8 run scores sorted, 0.1 0.2 0.3 0.4 0.6 0.7 0.9 1.0; 25% (2) dropped at each
    # end; the mean of 0.3 0.4 0.6 0.7.
    assert iqm.estimate == pytest.approx((0.3 + 0.4 + 0.6 + 0.7) / 4)
    # Mean: of the task means 0.5 and 0.55.
    assert mean.estimate == pytest.approx((0.5 + 0.55) / 2)
    for interval in (iqm, mean):
        assert 0.1 <= interval.low < interval.estimate < interval.high <= 1.0
    assert aggregate_intervals(scores, reps=300, seed=0) == (iqm, mean)  # seeded
    # A task with more runs: the IQM pools runs (5 + 3 scores, 2 dropped at each end).
    uneven = hand_scores("x", [0.0, 0.5, 0.5, 0.5, 1.0], [0.8, 0.9, 0.2])
    iqm, mean = aggregate_intervals(uneven, reps=300, seed=0)
    assert iqm.estimate == pytest.approx((0.5 + 0.5 + 0.5 + 0.8) / 4)
    assert mean.estimate == pytest.approx((0.5 + (0.8 + 0.9 + 0.2) / 3) / 2)


def test_intervals_contain_the_estimate_and_shrink_with_more_seeds():
    seeds = [0.1, 0.35, 0.6, 0.9]
    widths = []
    for copies in (1, 4, 16):  # the same spread of scores, 4, 16 and 64 seeds per task
        scores = hand_scores("x", seeds * copies, [value / 2 for value in seeds] * copies)
        for interval in aggregate_intervals(scores, reps=400, seed=1):
            assert interval.low <= interval.estimate <= interval.high
        iqm, mean = aggregate_intervals(scores, reps=400, seed=1)
        widths.append((iqm.high - iqm.low, mean.high - mean.low))
    assert widths[0][0] > widths[1][0] > widths[2][0]
    assert widths[0][1] > widths[1][1] > widths[2][1]
    # One run per task: nothing to resample, the interval is the point.
    iqm, _ = aggregate_intervals(hand_scores("x", [0.25], [0.75]), reps=200)
    assert (iqm.low, iqm.estimate, iqm.high) == (0.5, 0.5, 0.5)


def test_probability_of_improvement_by_hand():
    better = hand_scores("x", [0.5, 0.6, 0.7], [0.9, 0.95])
    worse = hand_scores("y", [0.1, 0.2, 0.45, 0.3], [0.5, 0.8, 0.85])
    improvement = probability_of_improvement(better, worse, reps=300, seed=0)
    assert improvement.tasks == ("task0", "task1")
    assert (improvement.interval.estimate, improvement.interval.low,
            improvement.interval.high) == (1.0, 1.0, 1.0)  # better on every pair of runs
    assert probability_of_improvement(worse, better, reps=300).interval.estimate == 0.0
    # task 0: x 0.2, 0.6 against y 0.4, 0.6: pairs won 0 + (1 + 0.5 tie) = 1.5 of 4;
    # task 1: x 0.9 against y 0.3, 1.0: 1 of 2. Averaged: (0.375 + 0.5) / 2.
    mixed = probability_of_improvement(hand_scores("x", [0.2, 0.6], [0.9]),
                                       hand_scores("y", [0.4, 0.6], [0.3, 1.0]), reps=300)
    assert mixed.interval.estimate == pytest.approx((1.5 / 4 + 1 / 2) / 2)
    assert mixed.interval.low <= mixed.interval.estimate <= mixed.interval.high
    # Only the tasks both have count; none in common is said, not computed.
    other = Scores("z", ("task1", "task7"), (np.array([[0.0]]), np.array([[1.0]])), ())
    assert probability_of_improvement(other, worse, reps=50).tasks == ("task1",)
    apart = probability_of_improvement(Scores("z", ("task7",), (np.array([[1.0]]),), ()),
                                       worse, reps=50)
    assert apart.interval is None and "no scored run on y's tasks (task0, task1)" in apart.reason


def test_performance_profile_is_the_fraction_of_runs_above_tau():
    profile = performance_profile(hand_scores("x", [0.2, 0.5, 0.9], [0.45]), reps=300)
    at = {round(float(tau), 2): index for index, tau in enumerate(profile.taus)}
    assert profile.fraction[at[0.0]] == 1.0
    assert profile.fraction[at[0.4]] == pytest.approx(3 / 4)   # 0.45, 0.5, 0.9
    assert profile.fraction[at[0.5]] == pytest.approx(1 / 4)   # 0.9 (not 0.5 itself)
    assert profile.fraction[at[0.95]] == 0.0
    assert np.all(profile.low <= profile.fraction) and np.all(profile.fraction <= profile.high)


def test_scores_of_ras_and_of_ttfs_with_censored_runs_at_zero(tmp_path):
    make_run(tmp_path, "a", SEED0, *FURL, "env.seed=0")            # RAS 100 %, TTFS 151
    make_run(tmp_path, "b", [False] * 1000, *FURL, "env.seed=1")   # no success in 1,000
    make_run(tmp_path, "c", [False] * 120, *FURL, "env.seed=2")    # stopped at 120: censored
    runs = {run.path.name: run for run in find_runs([tmp_path])}
    assert run_score(runs["a"], "ras").score == pytest.approx(1.0)
    assert run_score(runs["a"], "ttfs").score == pytest.approx(1 - 151 / 1000)
    assert run_score(runs["a"], "tt50s").score == pytest.approx(1 - 200 / 1000)
    assert (run_score(runs["b"], "ttfs").score, run_score(runs["b"], "ttfs").status) == (
        0.0, "value")
    assert (run_score(runs["c"], "ttfs").score, run_score(runs["c"], "ttfs").status) == (
        0.0, CENSORED)
    assert (run_score(runs["c"], "ras").score, run_score(runs["c"], "ras").status) == (
        None, INCOMPLETE)
    [group] = group_runs(list(runs.values()))
    table = build_reliable_table([group], "ttfs", reps=200)
    scores = table.scores[group.label]
    assert (scores.scored, scores.censored, len(scores.unscored)) == (3, 1, 0)
    # A censored run's time is unobserved: no IQM or mean would do without a stand-in for it
    # (the analysis plan), while its profile ranks it 0, below every run that succeeded.
    assert group.label not in table.iqm and group.label not in table.mean
    assert table.no_mean == {group.label: "1 censored: no mean"}
    assert table.scored == [group.label]
    assert table.profiles[group.label].fraction[0] == pytest.approx(1 / 3)  # above tau = 0
    markdown = reliable_markdown(table)
    assert "| FuRL ρ=0.05 | 1 | 3 (1 censored) | — (1 censored: no mean) | — |" in markdown
    assert "1 − TTFS / 1000" in markdown and "its configuration gets no IQM or mean" in markdown
    # Without the censored run: the IQM of two scores trims none, their mean.
    [uncensored] = group_runs([runs["a"], runs["b"]])
    assert build_reliable_table([uncensored], "ttfs", reps=200).iqm[
        uncensored.label].estimate == pytest.approx((1 - 151 / 1000) / 2)
    ras = build_reliable_table([group], "ras", reps=200)
    assert ras.scores[group.label].scored == 2 and ras.iqm[group.label].estimate == 0.5
    assert "3 (" not in reliable_markdown(ras) and "2 (1 incomplete)" in reliable_markdown(ras)


def test_reliable_table_over_a_baseline_one_task_and_missing_ones(tmp_path):
    sac = ("preset=sac", "protocol=stage2")
    for seed in range(3):  # FuRL reaches its first success before SAC on every run
        make_run(tmp_path, f"furl{seed}", [False] * (10 + seed) + [True] * 300, *FURL,
                 f"env.seed={seed}")
        make_run(tmp_path, f"sac{seed}", [False] * (200 + seed) + [True] * 100, *sac,
                 f"env.seed={seed}")
    make_run(tmp_path, "door", [True] * 50, "preset=p2", "protocol=stage2",
             "env.task=door-open")
    groups = group_runs(find_runs([tmp_path]))
    assert [group.label for group in groups] == ["SAC", "FuRL ρ=0.05", "P2 ρ=0.05 (b_g)"]
    table = build_reliable_table(groups, "ttfs", reps=300, seed=2)
    assert table.baseline == "SAC" and table.no_baseline is None
    furl = table.improvements["FuRL ρ=0.05"]
    assert furl.tasks == ("drawer-open",)  # one task: the stratified bootstrap still works
    assert (furl.interval.estimate, furl.interval.low, furl.interval.high) == (1.0, 1.0, 1.0)
    assert table.improvements["P2 ρ=0.05 (b_g)"].interval is None
    markdown = reliable_markdown(table)
    assert "| SAC | 1 | 3 | " in markdown and "| baseline |" in markdown
    assert "| 1.00 [1.00, 1.00] |" in markdown
    assert "- P2 ρ=0.05 (b_g): no scored run on SAC's tasks (drawer-open)" in markdown
    rows = {row["configuration"]: row for row in reliable_rows(table).csv_rows()}
    assert rows["FuRL ρ=0.05"]["p_improvement"] == "1"
    assert float(rows["SAC"]["iqm"]) == pytest.approx(1 - 202 / 1000)  # 3 runs: their mean
    # another baseline; and one no configuration has
    assert build_reliable_table(groups, "ttfs", baseline="FuRL ρ=0.05",
                                reps=100).improvements["SAC"].interval.estimate == 0.0
    missing = build_reliable_table(groups[1:], "ttfs", reps=100)
    assert missing.improvements == {}
    assert "no configuration is labelled 'SAC'" in missing.no_baseline
    assert "No probability of improvement: no configuration is labelled 'SAC'" in (
        reliable_markdown(missing))
    # RAS: P2's run has 50 of door-open's 400 episodes, so no score and no comparison
    ras = build_reliable_table(groups, "ras", reps=100)
    assert ras.scored == ["SAC", "FuRL ρ=0.05"] and list(ras.improvements) == ["FuRL ρ=0.05"]
    unscored = build_reliable_table(groups, "ras", baseline="P2 ρ=0.05 (b_g)", reps=100)
    assert unscored.no_baseline == "P2 ρ=0.05 (b_g) has no scored run for RAS (%)"


# --------------------------------------------------------------------------- logs
def test_csv_logs_later_value_of_a_step_wins(tmp_path):
    run_dir = make_run(tmp_path, "r", SEED0, *FURL, logged={
        "sac/loss_qvalue": [(2000, 3.0), (1000, 5.0), (2000, 4.0)]})
    series = logged_scalars(run_dir)["sac/loss_qvalue"]
    assert series.steps.tolist() == [1000.0, 2000.0] and series.values.tolist() == [5.0, 4.0]


def test_metrics_jsonl_is_read_and_preferred_to_csv_logs(tmp_path):
    run_dir = make_run(tmp_path, "r", SEED0, *FURL, logged={"sac/loss_qvalue": [(1000, 9.0)]})
    (run_dir / "metrics.jsonl").write_text(
        '{"step": 500, "train/success": 0.0}\n'
        '{"step": 1000, "sac/loss_qvalue": 2.5, "sac/alpha": null, "train/success": 1.0}\n'
        '{"step": 1500, "sac/loss_qvalue": 2.0}\n'
        '{"step": 2000, "sac/loss_')  # killed mid-write: skipped
    scalars = logged_scalars(run_dir)
    assert sorted(scalars) == ["sac/alpha", "sac/loss_qvalue", "train/success"]
    assert scalars["sac/loss_qvalue"].steps.tolist() == [1000.0, 1500.0]
    assert scalars["sac/loss_qvalue"].values.tolist() == [2.5, 2.0]
    assert scalars["train/success"].values.tolist() == [0.0, 1.0]
    assert np.isnan(scalars["sac/alpha"].values).all()


# --------------------------------------------------------------------------- a real run
@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """A tiny stage-2 run with FuRL + D3 heads: one expert episode and three failed ones."""
    run_dir = tmp_path_factory.mktemp("real") / "run"
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose("config", overrides=[
            "env.max_episode_steps=20", "train.episodes=3", "train.random_steps=10",
            "encoder.name=state", "+encoder.options.dim=16", "sac.batch_size=16",
            "sac.hidden_sizes=[32,32]", "reward.batch_size=16", "reward.gap=3",
            "logger.backend=csv", "logger.log_every=5", "train.progress=false",
            "protocol=stage2", "train.preload_positives=1", "reward.positional=furl",
            "reward.directional=d3", f"output_dir={run_dir}"])
    torch.manual_seed(0)
    sac_temporal.train(cfg)
    return run_dir


def test_a_real_run_writes_metrics_jsonl_as_its_csv_logger_sees_them(real_run):
    """The run's metrics.jsonl against an independent sink of the same calls, TorchRL's
    CSVLogger: the same keys, steps and values."""
    from_file, from_csv = logged_scalars(real_run), csv_scalars(real_run)
    assert (real_run / "metrics.jsonl").is_file() and "sac/loss_qvalue" in from_file
    assert sorted(from_file) == sorted(from_csv)
    for key, series in from_csv.items():
        assert from_file[key].steps.tolist() == series.steps.tolist(), key
        np.testing.assert_allclose(from_file[key].values, series.values, rtol=1e-6)


def test_reward_curves_use_the_saved_heads(real_run):
    positive, negative = reward_curves(real_run)
    assert (positive.index, positive.kind, negative.index, negative.kind) == (0, EXPERT, 3,
                                                                              FAILED)
    config = json.loads((real_run / "config.json").read_text())["reward"]
    state = torch.load(real_run / "checkpoint.pt", weights_only=True)["reward"]
    reward = TemporalReward(16, state["goal_embedding"], state["baseline_embedding"],
                            positional="furl", directional="d3", rho=config["rho"],
                            lambda_=config["lambda_"], k=config["k"], alpha=config["alpha"])
    reward.load_state_dict(state)
    for episode in (positive, negative):
        stored = torch.load(real_run / "replay" / f"{episode.index:06d}.pt", weights_only=True)
        s = stored["embedding"].float()
        if episode.kind == FAILED:
            assert bool((stored["label"][1:] == NEGATIVE).all())
        expected_p, expected_d = [], []
        with torch.no_grad():
            for t in range(1, s.shape[0]):
                previous = s[max(t - reward.k, 0)]
                expected_p.append(float(reward.positional_reward(s[t], s[0], previous)))
                expected_d.append(float(reward.directional_reward(s[t], previous, s[0])))
        assert episode.steps.tolist() == list(range(1, s.shape[0]))
        np.testing.assert_allclose(episode.positional, expected_p, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(episode.directional, expected_d, rtol=1e-5, atol=1e-6)
    assert positive.first_success is not None
    with pytest.raises(ValueError, match="not a negative episode"):
        reward_curves(real_run, negative=0)


def test_reward_curves_give_a_sequence_reward_its_window():
    """d_sequence reads the last K embeddings: the curve's value at state t is the reward of the
    window s_{t-K+1} .. s_t padded with s_0 before the episode start, as the env gives it."""
    from temporal_torchrl.reports.reward_curves import episode_rewards

    torch.manual_seed(0)
    dim, length = 6, 4
    reward = TemporalReward(dim, torch.randn(dim), torch.randn(dim), positional="furl",
                            directional="d_sequence", options={"window": length}, k=2)
    s = torch.randn(9, dim)
    positional, directional = episode_rewards(reward, s)
    with torch.no_grad():
        for t in range(s.shape[0]):
            window = torch.stack([s[max(t - length + 1 + j, 0)] for j in range(length)])
            expected = reward.directional_reward(s[t], s[max(t - 2, 0)], s[0], window=window)
            assert directional[t] == pytest.approx(float(expected), abs=1e-6)
            assert positional[t] == pytest.approx(float(reward.positional_reward(
                s[t], s[0], s[max(t - 2, 0)])), abs=1e-6)


@pytest.mark.slow
def test_report_cli_end_to_end(tmp_path, real_run):
    sweep = tmp_path / "sweep"
    logged = {"sac/loss_qvalue": [(1000, 2.0), (2000, 1.5), (3000, 1.0)]}
    make_run(sweep, "furl/seed0", SEED0, *FURL, "env.seed=0", finished=True, logged=logged)
    seed1 = make_run(sweep, "furl/seed1", SEED1, *FURL, "env.seed=1")
    (seed1 / "metrics.jsonl").write_text("".join(  # a run of today: no CSV logs needed
        f'{{"step": {step}, "sac/loss_qvalue": {value}}}\n' for step, value in logged[
            "sac/loss_qvalue"]))
    make_run(sweep, "furl/seed2", [False] * 40, *FURL, "env.seed=2")
    make_run(sweep, "door/seed0", [True] * 400, *FURL, "env.task=door-open", finished=True)
    make_run(sweep, "sac/seed0", [False] * 300, "preset=sac", "protocol=stage2", finished=True)
    out = tmp_path / "report"
    result = subprocess.run(
        [sys.executable, str(RECIPES / "report.py"), str(sweep), "--out", str(out),
         "--metrics", "sac/loss_qvalue", "--figure-run", str(real_run), "--bootstrap", "300"],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "## Configurations" in result.stdout
    for name in ("success_curves.png", "metric_sac-loss_qvalue.png", "reward_curves.png",
                 "aggregate_ras.png", "performance_profiles.png",
                 "probability_of_improvement.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    # Every configuration has a censored TTFS and TT50S run: no IQM or mean, so no figure of them
    assert not (out / "aggregate_ttfs.png").exists() and not (out / "aggregate_tt50s.png").exists()
    assert "aggregate_ttfs.png" not in (out / "report.md").read_text()
    with (out / "aggregates.csv").open() as file:
        aggregates = {(row["metric"], row["configuration"]): row
                      for row in csv.DictReader(file)}
    # TTFS: SAC never succeeded in 300 episodes (score 0); FuRL's 4 runs all beat it on
    # drawer-open, the one task SAC has.
    furl = aggregates["ttfs", "FuRL ρ=0.05"]
    assert (furl["tasks"], furl["runs_scored"], furl["censored"]) == (
        "drawer-open door-open", "4", "1")
    assert (furl["p_improvement_tasks"], furl["baseline"]) == ("drawer-open", "SAC")
    # seeds 0, 1 (scores 0.849, 0.839) beat SAC's 0; seed 2 (censored, 0) ties it: 2.5 / 3
    assert float(furl["p_improvement"]) == pytest.approx(2.5 / 3)
    assert aggregates["ttfs", "SAC"]["iqm"] == "" and aggregates["ttfs", "SAC"]["censored"] == "1"
    assert float(aggregates["ras", "FuRL ρ=0.05"]["mean"]) == pytest.approx(
        ((1.0 + 70 / 150) / 2 + 1.0) / 2)  # drawer-open's 2 complete runs, door-open's 1
    with (out / "comparisons.csv").open() as file:
        comparisons = list(csv.DictReader(file))
    # SAC's one run has no seed error: the difference is given, no interval
    assert [(row["configuration"], row["baseline"], row["task"], row["n"], row["baseline_n"],
             row["difference_ci95_low"], row["pairs_won"], row["reading"])
            for row in comparisons] == [
        ("FuRL ρ=0.05", "SAC", "drawer-open", "2", "1", "", "2",
         "not resolved (a single run has no seed error)")]
    report_md = (out / "report.md").read_text()
    assert "## RAS (%): configurations compared on each task" in report_md
    assert "## Over tasks and seeds (rliable)" in report_md
    assert "(on 1 of its 2 tasks)" in report_md
    assert "![performance profiles](performance_profiles.png)" in report_md
    with (out / "ras.csv").open() as file:
        rows = {(row["task"], row["configuration"]): row for row in csv.DictReader(file)}
    assert rows["drawer-open", "FuRL ρ=0.05"]["without_value"] == "seed 2: 40/300 episodes"
    assert float(rows["door-open", "FuRL ρ=0.05"]["mean"]) == 100.0
    assert rows["door-open", "FuRL ρ=0.05"]["published_mean"] == "41.5"
    with (out / "runs.csv").open() as file:
        assert len(list(csv.DictReader(file))) == 5
    ttfs = (out / "ttfs.md").read_text()
    # SAC's one run is censored at 300 episodes, FuRL's seed 2 at 40. FuRL by hand: seed 2
    # leaves the runs at risk at 40, so at 151 two are at risk and S = 1/2: the median is 151.
    assert markdown_row(ttfs, "drawer-open")[1:] == [
        "median not reached (0 of 1 reached), Kaplan-Meier; 1 censored > 300 ep; no mean",
        "median 151 (2 of 3 reached), Kaplan-Meier; 1 censored > 40 ep; no mean"]
    report = (out / "report.md").read_text()
    assert "![running-average success](success_curves.png)" in report
    assert "(reward_curves.png)" in report


def test_missing_runs_and_metrics_are_named(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="looked for config.json"):
        find_runs([tmp_path / "empty"])
    make_run(tmp_path, "r", SEED0, *FURL, logged={"sac/loss_qvalue": [(1000, 1.0)]})
    with pytest.raises(SystemExit, match="no run logged it.*logged keys: sac/loss_qvalue"):
        report.main([str(tmp_path / "r"), "--out", str(tmp_path / "out"), "--metrics",
                     "sac/nothing", "--bootstrap", "10"])
    with pytest.raises(SystemExit, match="--baseline 'PPO': no configuration has that label; "
                       "the configurations are: 'FuRL ρ=0.05'"):
        report.main([str(tmp_path / "r"), "--out", str(tmp_path / "out"), "--baseline", "PPO"])
    assert not (tmp_path / "out").exists()  # checked before anything is written


@pytest.mark.parametrize("overrides", [
    ("reward.directional=d3", "reward.certainty_scaling=true"),
    ("reward.directional=d_sequence", "+reward.options.window=4"),
])
@pytest.mark.slow
def test_figure_run_loads_every_reward_setting(tmp_path, overrides):
    """report.py --figure-run on runs whose reward has settings beyond the names (a certainty-
    scaled D3, a d_sequence with a 4-state window): the curves are the trained reward's own
    forward on the stored episode, the reward built by the recipe's factory."""
    from temporal_torchrl.configs.rules import Devices
    from temporal_torchrl.encoders import load_encoder
    from temporal_torchrl.reports import reward_curves
    from temporal_torchrl.training import factories

    run_dir = tmp_path / "run"
    cfg = config(tmp_path, "train.episodes=2", "protocol=stage2", "train.preload_positives=1",
                 *overrides)
    sac_temporal.train(cfg)
    expert, failed = reward_curves(run_dir)
    trained = factories.make_reward(cfg, load_encoder("state", dim=16), Devices.of(cfg))
    trained.load_state_dict(torch.load(run_dir / "checkpoint.pt", weights_only=True)["reward"])
    stored = torch.load(run_dir / "replay" / "000000.pt", weights_only=True)
    embeddings = stored["embedding"].float()
    steps = torch.arange(len(embeddings))
    length = trained.window_length  # None: a reward that reads no window
    window = embeddings[(steps.unsqueeze(-1) - torch.arange(length - 1, -1, -1)).clamp_min(0)
                        ] if length else None
    with torch.no_grad():
        parts = trained(embeddings, embeddings[:1].expand_as(embeddings),
                        embeddings[(steps - cfg.reward.k).clamp_min(0)],
                        torch.zeros(len(embeddings), 1, dtype=torch.bool), window=window)
    np.testing.assert_allclose(expert.directional, parts["directional_reward"][1:, 0].numpy(),
                               rtol=1e-5, atol=1e-6)
    assert failed.kind == FAILED
    out = tmp_path / "report"
    result = subprocess.run(
        [sys.executable, str(RECIPES / "report.py"), str(run_dir), "--out", str(out),
         "--figure-run", str(run_dir), "--bootstrap", "200"],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert (out / "reward_curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_keys_a_run_never_read_do_not_split_a_configuration(tmp_path):
    """SAC renders nothing, so its encoder and frame size are unread; a run without evaluations
    reads no eval.*; a run older than env.goal ran the fixed goal."""
    make_run(tmp_path, "a", SEED0, "preset=sac", "protocol=stage2", "env.seed=0")
    make_run(tmp_path, "b", SEED1, "preset=sac", "protocol=stage2", "env.seed=1",
             "encoder.name=metaworld_small", "env.image_size=64", "eval.episodes=3")
    old = make_run(tmp_path, "c", SEED1, "preset=sac", "protocol=stage2", "env.seed=2")
    config = json.loads((old / "config.json").read_text())
    del config["env"]["goal"], config["eval"]
    (old / "config.json").write_text(json.dumps(config))
    make_run(tmp_path, "d", SEED0, *FURL, "env.seed=0", "encoder.name=metaworld_small")
    make_run(tmp_path, "e", SEED1, *FURL, "env.seed=1")  # a VLM run reads its encoder
    groups = group_runs(find_runs([tmp_path]))
    assert sorted(len(group.runs) for group in groups) == [1, 1, 3]
