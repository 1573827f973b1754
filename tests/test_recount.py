"""The standard-library recount of Table 5.12 (docs/results/table_5_12/recount.py) against the
committed report: two independent computations of every cell's RAS from the same runs."""

import csv
import importlib.util
import json
from pathlib import Path
from statistics import mean

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
ROOTS = [RESULTS / "sac_column" / "runs", RESULTS / "window_close_cpu_study" / "runs",
         RESULTS / "table_5_12" / "runs"]


def load_recount():
    spec = importlib.util.spec_from_file_location("recount",
                                                  RESULTS / "table_5_12" / "recount.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_cell_of_the_report_is_the_recounts():
    recount = load_recount()
    runs = recount.unique_runs([str(root) for root in ROOTS])
    with (RESULTS / "table_5_12" / "runs.csv").open() as file:
        labels = {(row["task"], row["seed"], Path(row["path"]).parent.name): row["configuration"]
                  for row in csv.DictReader(file)}
    by_cell = {}
    for run in runs:
        label = labels[run["task"], str(run["seed"]), run["configuration"]]
        by_cell.setdefault((run["task"], label), []).append(run["ras"])
    with (RESULTS / "table_5_12" / "ras.csv").open() as file:
        cells = [row for row in csv.DictReader(file) if row["task"] != "Average"]
    assert len(cells) == len(by_cell) >= 11
    for cell in cells:
        ours = by_cell[cell["task"], cell["configuration"]]
        assert len(ours) == int(cell["n"])
        assert mean(ours) == pytest.approx(float(cell["mean"]), abs=1e-8)


def write_run(root: Path, successes: list[int], task: str = "door-open", seed: int = 0) -> Path:
    run = root / task / "sac_stage2" / f"seed{seed}"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"env": {"task": task, "seed": seed}}))
    rows = "".join(f"{index + 1},{success}\n" for index, success in enumerate(successes))
    (run / "episodes.csv").write_text("episode,success\n" + rows)
    return run


def test_budget_duplicates_and_conflicts(tmp_path):
    recount = load_recount()
    # door-open's budget is 400: a run of 450 episodes is scored at episode 400, not 450
    row = recount.recount(write_run(tmp_path / "a", [0] * 250 + [1] * 150 + [0] * 50))
    assert (row["ras"], row["release_window"], row["ttfs"], row["tt50s"]) == (
        100.0, 100 * 145 / 150, 251, 300)
    short = recount.recount(write_run(tmp_path / "b", [1] * 399, seed=1))
    assert short["ras"] is None and short["ttfs"] == 1
    # the same run under two roots counts once; a different one under the same name stops it
    write_run(tmp_path / "c", [0] * 250 + [1] * 150 + [0] * 50)
    assert len(recount.unique_runs([str(tmp_path / "a"), str(tmp_path / "c")])) == 1
    write_run(tmp_path / "d", [1] * 400)
    with pytest.raises(SystemExit, match="two runs with different episodes.csv"):
        recount.unique_runs([str(tmp_path / "a"), str(tmp_path / "d")])
