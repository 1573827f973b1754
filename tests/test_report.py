"""Reports over runs (temporal_torchrl.experiments, recipes/report.py) on hand-made run
directories with known success sequences, and one tiny real run for the reward curves."""

import csv
import json
import math
import os
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import report
import sac_temporal
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from temporal_torchrl.data import NEGATIVE
from temporal_torchrl.envs import EVALUATION_TASKS, get_task
from temporal_torchrl.experiments import (
    Configuration,
    bootstrap_ci,
    build_table,
    find_published,
    find_runs,
    group_runs,
    logged_scalars,
    published_tables,
    reward_curves,
    run_value,
)
from temporal_torchrl.experiments.aggregate import CENSORED, INCOMPLETE
from temporal_torchrl.experiments.reward_curves import EXPERT, FAILED
from temporal_torchrl.experiments.runs import distinguishing_keys
from temporal_torchrl.experiments.tables import grouping_markdown, table_markdown, table_rows
from temporal_torchrl.rewards import TemporalReward

RECIPES = Path(__file__).resolve().parents[1] / "recipes"


# seed 0: 150 failures then 150 successes -> RAS(300; 150) = 100 %, TTFS 151, TT50S 200.
SEED0 = [False] * 150 + [True] * 150
# seed 1: 160 failures then success, failure, ... -> 70 of episodes 151..300: RAS 46.67 %,
# TTFS 161, TT50S 161 + 2 * 49 = 259.
SEED1 = [False] * 160 + [True, False] * 70


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@cache
def _composed(overrides: tuple[str, ...]) -> str:
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose("config", overrides=list(overrides))
    return json.dumps(OmegaConf.to_container(cfg, resolve=True))


def make_run(root: Path, name: str, successes, *overrides: str, finished: bool = False,
             logged: dict | None = None) -> Path:
    """A run directory as the recipe writes it: config.json, episodes.csv, summary.json when
    ``finished``, CSV logs of ``logged`` ({key: [(step, value)]})."""
    run_dir = root / name
    run_dir.mkdir(parents=True)
    config = json.loads(_composed(tuple(overrides)))
    config["output_dir"] = str(run_dir)
    (run_dir / "config.json").write_text(json.dumps(config))
    with (run_dir / "episodes.csv").open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["episode", "env_steps", "success", "return", "mean_vlm_reward",
                         "stage"])
        for episode, success in enumerate(successes, start=1):
            writer.writerow([episode, 500 * episode, int(success), -500 + int(success), 0.0, 2])
    if finished:
        (run_dir / "summary.json").write_text(json.dumps({"episodes": len(successes)}))
    for key, points in (logged or {}).items():
        path = run_dir / "logs" / run_dir.name / "scalars" / f"{key}.csv"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(f"{step},{value}\n" for step, value in points))
    return run_dir


FURL = ("preset=furl", "protocol=stage2")


def rows_by(table, task):
    return {row["configuration"]: row for row in table_rows(table) if row["task"] == task}


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
        row = rows_by(build_table(groups, metric, resamples=200), "drawer-open")["FuRL ρ=0.05"]
        assert float(row["mean"]) == pytest.approx(sum(values) / 2, rel=1e-5)
        # sample std of two values: |a - b| / sqrt(2)
        assert float(row["std"]) == pytest.approx(abs(values[0] - values[1]) / math.sqrt(2),
                                                  rel=1e-5)
        assert (row["n"], row["runs"], row["status"]) == ("2", "2", "complete")


def test_bootstrap_ci_is_right_and_deterministic():
    # Resampling [0, 100] twice gives means 0, 50, 100 with probabilities 1/4, 1/2, 1/4.
    assert bootstrap_ci([[0.0, 100.0]], resamples=4000, seed=0) == (0.0, 100.0)
    values = [41.0, 55.0, 47.0, 60.0, 38.0, 52.0, 66.0, 44.0]
    ci = bootstrap_ci([values], resamples=500, seed=3)
    assert ci == bootstrap_ci([values], resamples=500, seed=3)
    assert ci != bootstrap_ci([values], resamples=500, seed=4)
    assert min(values) <= ci[0] < np.mean(values) < ci[1] <= max(values)
    assert bootstrap_ci([[5.0]]) is None
    # The Average row's CI: tasks resampled separately, centred on the mean of task means.
    low, high = bootstrap_ci([values, [10.0, 12.0]], resamples=2000, seed=0)
    assert low < (np.mean(values) + 11.0) / 2 < high


def test_cell_ci_contains_mean(tmp_path):
    for seed, offset in enumerate((0, 3, 7)):
        make_run(tmp_path, f"s{seed}", [False] * (150 + offset) + [True] * (150 - offset),
                 *FURL, f"env.seed={seed}")
    table = build_table(group_runs(find_runs([tmp_path])), "ras", resamples=500, seed=1)
    row = rows_by(table, "drawer-open")["FuRL ρ=0.05"]
    assert float(row["ci95_low"]) <= float(row["mean"]) <= float(row["ci95_high"])
    assert row == rows_by(build_table(group_runs(find_runs([tmp_path])), "ras", resamples=500,
                                      seed=1), "drawer-open")["FuRL ρ=0.05"]


def test_incomplete_run_is_shown_with_its_episode_count(tmp_path):
    make_run(tmp_path, "s0", SEED0, *FURL, "env.seed=0", finished=True)
    make_run(tmp_path, "s1", SEED1, *FURL, "env.seed=1", finished=True)
    make_run(tmp_path, "s2", [True] * 120, *FURL, "env.seed=2")  # killed at 120 of 300
    make_run(tmp_path, "rho1", [True] * 80, *FURL, "reward.rho=1.0", "env.seed=0")
    table = build_table(group_runs(find_runs([tmp_path])), "ras", resamples=200)
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
    table = build_table(group_runs(find_runs([tmp_path])), "ttfs", resamples=200)
    assert markdown_row(table_markdown(table), "drawer-open")[1] == \
        "500 ± 706 (n=2); 1 censored: > 120 ep"


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
    make_run(tmp_path, "copy", SEED0, *FURL)
    with pytest.raises(ValueError, match="count that seed twice"):
        group_runs(find_runs([tmp_path]))


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
    ras_row = markdown_row(table_markdown(build_table(groups, "ras", resamples=10)),
                           "drawer-open")
    ttfs_row = markdown_row(table_markdown(build_table(groups, "ttfs", resamples=10)),
                            "drawer-open")
    assert ras_row[1:] == ["**100.0** (n=1)", "46.7 (n=1)"]
    assert ttfs_row[1:] == ["**151** (n=1)", "161 (n=1)"]
    # a row's best needs every run of the cell: the partial cell is not bold even if higher
    make_run(tmp_path, "c", [True] * 300, *FURL, "reward.rho=2.0", "env.seed=0")
    make_run(tmp_path, "d", [True] * 30, *FURL, "reward.rho=2.0", "env.seed=1")
    groups = group_runs(find_runs([tmp_path]))
    row = markdown_row(table_markdown(build_table(groups, "ras", resamples=10)), "drawer-open")
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
    table = build_table(groups, "ras", resamples=100)
    rows = rows_by(table, "drawer-open")
    furl = rows["FuRL ρ=0.05 [metaworld_small]"]
    assert (furl["published_tables"], furl["published_mean"]) == ("5.4 5.5 5.6", "41.7")
    assert float(furl["difference"]) == pytest.approx((100 + 70 / 150 * 100) / 2 - 41.7)
    assert rows["P2 ρ=0.1 (b_g) [liv]"]["published_mean"] == ""  # rho 0.1: not in the thesis
    markdown = table_markdown(table)
    assert ("| FuRL ρ=0.05 [metaworld_small] | drawer-open | 73.3 ± 37.7 (n=2) | 41.7 | +31.6 "
            "| 5.4, 5.5, 5.6 | encoder metaworld_small (thesis: liv) |") in markdown
    # stage 1 with D3 matches Table 5.2, whose baseline the thesis does not state
    make_run(tmp_path, "d3", [False] * 270 + [True], "preset=d3", "protocol=stage1",
             "reward.baseline=generic")
    [d3] = group_runs(find_runs([tmp_path / "d3"]))
    ttfs = build_table([d3], "ttfs", resamples=10)
    row = rows_by(ttfs, "drawer-open")["FuRL ρ=0.05 + D3 λ=80 (b_g)"]
    assert (row["published_tables"], row["published_mean"], row["published_std"],
            row["difference"]) == ("5.2", "271", "29", "0")
    assert "does not state this column's baseline" in table_markdown(ttfs)


# --------------------------------------------------------------------------- logs
def test_csv_logs_later_value_of_a_step_wins(tmp_path):
    run_dir = make_run(tmp_path, "r", SEED0, *FURL, logged={
        "sac/loss_qvalue": [(2000, 3.0), (1000, 5.0), (2000, 4.0)]})
    series = logged_scalars(run_dir)["sac/loss_qvalue"]
    assert series.steps.tolist() == [1000.0, 2000.0] and series.values.tolist() == [5.0, 4.0]


def test_wandb_offline_run_is_read(tmp_path, monkeypatch):
    from torchrl.record.loggers.wandb import WandbLogger

    monkeypatch.setenv("WANDB_SILENT", "true")
    logger = WandbLogger("run", offline=True, save_dir=str(tmp_path), project="test")
    # enough rows that records cross wandb's 32 KiB blocks
    for step in range(300):
        logger.log_scalar("sac/loss_qvalue", step / 7, step=1000 * step)
        logger.log_scalar("train/success", float(step % 2), step=500 * step)
    logger.experiment.finish()
    # wandb's service process writes the file; teardown waits for it (finish alone may return
    # before the last records are flushed on a loaded machine).
    import wandb

    wandb.teardown()
    assert sum(path.stat().st_size for path in tmp_path.rglob("*.wandb")) > 32 * 1024
    scalars = logged_scalars(tmp_path)
    assert scalars["sac/loss_qvalue"].steps.tolist() == [1000.0 * step for step in range(300)]
    np.testing.assert_allclose(scalars["sac/loss_qvalue"].values, np.arange(300) / 7)
    assert scalars["train/success"].values.tolist() == [float(step % 2) for step in range(300)]


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
    from temporal_torchrl.experiments.reward_curves import episode_rewards

    torch.manual_seed(0)
    dim, length = 6, 4
    reward = TemporalReward(dim, torch.randn(dim), torch.randn(dim), positional="furl",
                            directional="d_sequence", window_length=length, k=2)
    s = torch.randn(9, dim)
    positional, directional = episode_rewards(reward, s)
    with torch.no_grad():
        for t in range(s.shape[0]):
            window = torch.stack([s[max(t - length + 1 + j, 0)] for j in range(length)])
            expected = reward.directional_reward(s[t], s[max(t - 2, 0)], s[0], window=window)
            assert directional[t] == pytest.approx(float(expected), abs=1e-6)
            assert positional[t] == pytest.approx(float(reward.positional_reward(
                s[t], s[0], s[max(t - 2, 0)])), abs=1e-6)


def test_report_cli_end_to_end(tmp_path, real_run):
    sweep = tmp_path / "sweep"
    logged = {"sac/loss_qvalue": [(1000, 2.0), (2000, 1.5), (3000, 1.0)]}
    make_run(sweep, "furl/seed0", SEED0, *FURL, "env.seed=0", finished=True, logged=logged)
    make_run(sweep, "furl/seed1", SEED1, *FURL, "env.seed=1", logged=logged)
    make_run(sweep, "furl/seed2", [False] * 40, *FURL, "env.seed=2")
    make_run(sweep, "door/seed0", [True] * 400, *FURL, "env.task=door-open", finished=True)
    out = tmp_path / "report"
    result = subprocess.run(
        [sys.executable, str(RECIPES / "report.py"), str(sweep), "--out", str(out),
         "--metrics", "sac/loss_qvalue", "--figure-run", str(real_run), "--bootstrap", "300"],
        capture_output=True, text=True, timeout=120, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert result.returncode == 0, result.stderr
    assert "## Configurations" in result.stdout
    for name in ("success_curves.png", "metric_sac-loss_qvalue.png", "reward_curves.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    with (out / "ras.csv").open() as file:
        rows = {(row["task"], row["configuration"]): row for row in csv.DictReader(file)}
    assert rows["drawer-open", "FuRL ρ=0.05"]["without_value"] == "seed 2: 40/300 episodes"
    assert float(rows["door-open", "FuRL ρ=0.05"]["mean"]) == 100.0
    assert rows["door-open", "FuRL ρ=0.05"]["published_mean"] == "41.5"
    with (out / "runs.csv").open() as file:
        assert len(list(csv.DictReader(file))) == 4
    ttfs = (out / "ttfs.md").read_text()
    assert markdown_row(ttfs, "drawer-open")[1] == "156 ± 7 (n=2); 1 censored: > 40 ep"
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
    assert not (tmp_path / "out").exists()  # checked before anything is written
